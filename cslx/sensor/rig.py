"""The structured-light sensor: camera + one or two laser planes + camera-to-robot transform.

Plane i is `a x + b y + c z + 1 = 0` in the camera frame, mm (eq. (1)). Triangulation
follows correction 3 of docs/corrections.md (the paper's eq. (27) drops the depth): for the
unit ray r of an undistorted pixel, the camera-frame point is X_c = −r / (n·r) with
n = (a, b, c), and the robot-frame point is X_r = R_cr X_c + T_cr.

The paper's sensor is a cross (two planes: the horizontal stripe's first); a single line
laser has one plane. `Sensor.stripes` says which stripe each row of `planes` belongs to;
`triangulate` takes the stripe (or its index 0/1) and finds the row, and says clearly when
the sensor has no plane for it. `Sensor.require_planes` is the check for users that need
the cross (the tracker). The calibration file is `cslx.sensor.calibration_file`
(docs/contracts.md).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np

from ..pytree import pytree_dataclass, static
from .camera import Camera, pixel_to_ray

if TYPE_CHECKING:  # annotations only (strings at run time): no jaxtyping import
    from jaxtyping import Array, ArrayLike, Float

__all__ = [
    "CalibrationError",
    "Sensor",
    "cross_projector_planes",
    "default_mount",
    "default_sensor",
    "triangulate",
    "plane_angle_deg",
]

#: Table 4 of the paper with v0 corrected (docs/corrections.md, correction 2).
TABLE4_K = ((922.435, 0.0, 329.168), (0.0, 917.356, 270.566), (0.0, 0.0, 1.0))
TABLE4_DIST = (-0.291459, 0.157027, -1.354e-4, -2.682e-4)


class CalibrationError(ValueError):
    """A calibration file or calibration input that cannot be used, with the reason."""


@pytree_dataclass(eq=False)
class Sensor:
    """Camera, its laser planes (a cross: two; a line laser: one) and the camera-to-robot transform.

    An immutable pytree like `cslx.sensor.camera.Camera` (a frozen dataclass, not an
    `equinox.Module`: the tracker's start-up, issue 13).

    Attributes:
        camera: intrinsics and distortion.
        planes: (P, 3) plane coefficients (a, b, c), P = 1 or 2. With the default `stripes`,
            row 0 makes the horizontal stripe (one centre per image column) and row 1 the
            vertical stripe (one per row).
        R_cr: (3, 3) rotation camera → robot.
        T_cr: (3,) translation camera → robot, mm.
        stripes: which stripe ("h" or "v") each row of `planes` draws; None (the default)
            means ("h", "v")[:P], the calibration file's "horizontal first".
    """

    camera: Camera
    planes: Float[Array, "p 3"]
    R_cr: Float[Array, "3 3"]
    T_cr: Float[Array, 3]
    stripes: tuple[str, ...] | None = static(None)

    @property
    def plane_stripes(self) -> tuple[str, ...]:
        """The stripe ("h"/"v") of each row of `planes`."""
        if self.stripes is not None:
            return tuple(self.stripes)
        return ("h", "v")[: self.planes.shape[0]]

    @property
    def n_planes(self) -> int:
        return int(self.planes.shape[0])

    def has_plane(self, stripe) -> bool:
        """Whether the sensor has a laser plane for `stripe` ("h"/"v", a `Stripe`, 0 or 1)."""
        return _stripe_code(stripe) in self.plane_stripes

    def plane_index(self, stripe) -> int:
        """Row of `planes` of `stripe` ("h"/"v", a `cslx.config.Stripe`, or its index 0/1).

        Raises:
            CalibrationError: the sensor has no plane for that stripe (a one-line sensor).
        """
        code = _stripe_code(stripe)
        have = self.plane_stripes
        if code not in have:
            raise CalibrationError(
                f"this sensor has no laser plane for the {_LABEL[code]} stripe: its calibration "
                f"holds {len(have)} plane(s), for the {' and '.join(_LABEL[c] for c in have)} "
                "stripe; use that stripe, or calibrate with a laser that draws this one"
            )
        return have.index(code)

    def require_planes(self, n: int, purpose: str) -> None:
        """Raise `CalibrationError` with clear words unless the sensor has at least `n` planes.

        For the users that need the cross (`purpose`, e.g. "tracking": the horizontal stripe
        finds the weld, the vertical one the junctions ahead).
        """
        have = self.plane_stripes
        if len(have) < n:
            raise CalibrationError(
                f"{purpose} needs {n} laser planes (the cross: horizontal and vertical stripe), "
                f"but this calibration holds {len(have)} "
                f"({', '.join(_LABEL[c] for c in have) or 'none'}); calibrate the cross "
                "projector (`cslx calibrate --laser-images …` with both lines on the board)"
            )

    def to_robot(self, X_c: Float[Array, "*b 3"]) -> Float[Array, "*b 3"]:
        """Camera-frame points → robot frame: X_r = R_cr X_c + T_cr."""
        return X_c @ self.R_cr.T + self.T_cr

    def triangulate(
        self, uv: Float[Array, "*b 2"], plane: int, *, robot_frame: bool = False
    ) -> Float[Array, "*b 3"]:
        """See `triangulate`."""
        return triangulate(self, uv, plane, robot_frame=robot_frame)


_LABEL = {"h": "horizontal", "v": "vertical"}


def _stripe_code(stripe) -> str:
    """ "h" or "v" from a `Stripe`, "h"/"v"/"horizontal"/"vertical", or the index 0/1."""
    from ..config import Stripe

    try:
        return Stripe.parse(int(stripe) if isinstance(stripe, np.integer) else stripe).value
    except ValueError as e:
        raise ValueError(f"plane/stripe: {e}") from None


def triangulate(
    sensor: Sensor, uv: Float[Array, "*b 2"], plane, *, robot_frame: bool = False
) -> Float[Array, "*b 3"]:
    """Intersect the viewing rays of pixels with a laser plane (correction 3 of eq. (27)).

    Args:
        sensor: the calibrated sensor.
        uv: distorted pixel coordinates (OpenCV convention); NaN propagates.
        plane: the stripe whose plane to use: 0 or "h" (a `cslx.config.Stripe`) for the
            horizontal stripe, 1 or "v" for the vertical one; mapped to the row of
            `sensor.planes` by `Sensor.plane_index` (the same row for a cross sensor).
        robot_frame: return X_r = R_cr X_c + T_cr instead of the camera-frame point.

    Returns:
        3-D points in mm. A ray parallel to the plane gives a non-finite value.

    Raises:
        CalibrationError: a one-plane sensor asked for the stripe it has no plane for.
    """
    ray = pixel_to_ray(uv, sensor.camera, normalize=False)
    n = sensor.planes[sensor.plane_index(plane)].astype(ray.dtype)
    denom = ray @ n
    safe = jnp.where(denom == 0, jnp.ones_like(denom), denom)
    X_c = jnp.where((denom == 0)[..., None], jnp.nan, -ray / safe[..., None])
    return sensor.to_robot(X_c) if robot_frame else X_c


def plane_angle_deg(n1: ArrayLike, n2: ArrayLike) -> float:
    """Angle between two planes' normals in degrees, in [0, 90]."""
    n1 = np.asarray(n1, float)
    n2 = np.asarray(n2, float)
    c = abs(n1 @ n2) / (np.linalg.norm(n1) * np.linalg.norm(n2))
    return math.degrees(math.acos(min(1.0, c)))


def cross_projector_planes(
    origin: ArrayLike, target: ArrayLike, roll_deg: float = 0.0
) -> np.ndarray:
    """Planes (a, b, c) of an orthogonal cross projector, camera frame.

    The projector sits at `origin` (mm, camera frame) and aims its axis d at `target`. Its
    two sheets both contain d and are mutually orthogonal: sheet 0 spans d and e_x (the
    camera x axis made orthogonal to d, rotated by `roll_deg` about d) and therefore draws
    the horizontal stripe; sheet 1 spans d and e_y = d × e_x and draws the vertical stripe.
    Neither plane may pass through the camera centre (the a x + b y + c z + 1 = 0 form cannot
    hold such a plane), which needs an origin off both sheets through the camera axis.
    """
    P = np.asarray(origin, float)
    d = np.asarray(target, float) - P
    d /= np.linalg.norm(d)
    ex = np.array([1.0, 0.0, 0.0]) - d[0] * d
    ex /= np.linalg.norm(ex)
    ey = np.cross(d, ex)
    th = math.radians(roll_deg)
    ex, ey = math.cos(th) * ex + math.sin(th) * ey, -math.sin(th) * ex + math.cos(th) * ey
    planes = []
    for n in (ey, ex):  # sheet 0 contains ex, so its normal is ey; sheet 1 the reverse
        offset = n @ P
        if abs(offset) < 1e-9:
            raise CalibrationError("a laser plane passes through the camera centre")
        planes.append(-n / offset)
    return np.stack(planes)


def default_mount(
    standoff_mm: float = 230.0, ahead_mm: float = 150.0
) -> tuple[np.ndarray, np.ndarray]:
    """Camera-to-robot transform of the default rig: the camera looks straight at the wall.

    Robot frame (docs/contracts.md): x_r forward, y_r left, z_r out of the wall. The camera's image
    u axis points to the robot's right (x_c = −y_r), v axis backwards (y_c = −x_r) and its
    optical axis into the wall (z_c = −z_r), so the horizontal stripe crosses a weld that
    runs along the direction of travel. The optical centre is `standoff_mm` above the wall
    and `ahead_mm` ahead of the robot's reference point.
    """
    R_cr = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    T_cr = np.array([ahead_mm, 0.0, standoff_mm])
    return R_cr, T_cr


def default_sensor(dtype=None) -> Sensor:
    """The rendered rig: Table 4's intrinsics (correction 2) and an orthogonal cross projector.

    Table 4's printed planes are 81° apart, not 89.998° (correction 2), so the renderer gets
    its own projector: 60 mm off the optical axis along −x and −y of the camera (a baseline
    of 85 mm) and aimed at the wall 230 mm away (the stand-off of the paper's Table 5), which
    gives a ≈ 15–25° triangulation angle for each sheet.

    The projector aims 40 mm to the side of the optical axis (x_c = +40 mm, the robot's
    right): the horizontal stripe still crosses the followed weld in the middle of the image,
    while the vertical stripe runs beside that weld on bare plate, so a crossing weld ahead
    shows on it as a bead with plate on both sides (a T-junction is then unambiguous; with
    the cross centred on the weld the vertical stripe would lie along the bead's crown).
    """
    R_cr, T_cr = default_mount()
    planes = cross_projector_planes(origin=(-60.0, -60.0, 0.0), target=(40.0, 0.0, 230.0))
    return sensor_from_arrays(TABLE4_K, TABLE4_DIST, planes, R_cr, T_cr, (640, 480), dtype=dtype)


def sensor_from_arrays(K, dist, planes, R_cr, T_cr, image_size, dtype=None, stripes=None) -> Sensor:
    """Build a `Sensor` from plain arrays (no validation; see `load_sensor` for that).

    `planes` is (P, 3) (a single (3,) plane is taken as P = 1); `stripes` names the stripe of
    each row (default ("h", "v")[:P]).
    """
    dtype = dtype or jax.dtypes.canonicalize_dtype(np.float64)
    traced = any(isinstance(x, jax.core.Tracer) for x in (K, dist, planes, R_cr, T_cr))
    # Concrete values: NumPy, then one `jax.device_put` per leaf (no XLA program at start-up)
    xp = jnp if traced else np
    place = (lambda x: x) if traced else jax.device_put
    camera = Camera.from_matrix(xp.asarray(K, dtype), xp.asarray(dist, dtype), image_size)
    planes = xp.asarray(planes, dtype).reshape(-1, 3)
    if stripes is not None:
        stripes = tuple(_stripe_code(s) for s in stripes)
        if len(stripes) != planes.shape[0] or len(set(stripes)) != len(stripes):
            raise CalibrationError(
                f"stripes {list(stripes)} do not name the {planes.shape[0]} plane(s) one each"
            )
        if stripes == ("h", "v")[: planes.shape[0]]:
            stripes = None  # the default order: keep one pytree structure for the cross
    return Sensor(
        camera=camera,
        planes=place(planes),
        R_cr=place(xp.asarray(R_cr, dtype)),
        T_cr=place(xp.asarray(T_cr, dtype)),
        stripes=stripes,
    )
