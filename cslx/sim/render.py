"""Rendered scenes with exact ground truth: the project's laboratory.

A steel wall (locally the plane z_w = 0, optionally a tower's cylinder) carries weld beads
with a circular-arc cap (10–25 mm wide, 1–3 mm high): straight welds and T-intersections.
A wall-climbing robot carries the cross structured-light sensor (`cslx.sensor`); each pixel's
ray (with the lens distortion) is cast onto the surface, which is lit by ambient light,
near-grey sunlight (diffuse, a broad sheen and sharp glints on the rippled bead, hard
shadows) and the two laser sheets, whose Gaussian thickness profile is evaluated at the
surface point's distance to each plane. Speckle, lens blur, shot and read noise, clipping
and 8-bit quantisation follow.

Ground truth is exact, not "the brightest pixel": for the horizontal stripe, per image
column, the sub-pixel row where the real surface meets plane 0 (a root-find along the
column, each evaluation a root-found ray cast, float64), and its 3-D point; per row for the
vertical stripe and plane 1; NaN where the stripe is absent (off the image, outside the
fan, or in the laser's shadow behind a bead).
"""

from __future__ import annotations

import io
import math
import os
import zipfile
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..files import atomic_directory, atomic_write
from ..sensor import Sensor, default_sensor, load_sensor, save_sensor
from .scene import (
    MAX_WELDS,
    RobotPose,
    World,
    camera_to_world,
    stripe_truth,
)
from .shade import (
    Conditions,
    Nuisance,
    draw_conditions,
    expose,
    quantise,
    surface_radiance,
)
from .truth import true_weld_line

__all__ = [
    "HARD_NUISANCES",
    "NUISANCES",
    "Nuisance",
    "RobotPose",
    "World",
    "camera_to_world",
    "load_dataset",
    "make_world",
    "random_pose",
    "random_world",
    "render_dataset",
    "render_frame",
    "stripe_truth",
    "write_dataset",
]

#: Red laser with small green/blue leakage (default) and a 520 nm green laser.
LASER_RGB = {
    "red": (1.0, 0.07, 0.04),
    "green": (0.12, 1.0, 0.2),
    "blue": (0.04, 0.18, 1.0),  # 450 nm: the Bayer green filter leaks a little
}

NUISANCES: dict[str, Nuisance] = {
    "clean": Nuisance(),
    "sunny": Nuisance(
        ambient=150.0, sun=300.0, sun_tilt_deg=35.0, sheen=130.0, glint=150.0, laser_power=260.0
    ),
    "glare": Nuisance(
        ambient=120.0, sun=180.0, sun_tilt_deg=32.0, sheen=60.0, glint=3000.0, laser_power=250.0
    ),
    "shadow": Nuisance(
        ambient=90.0, sun=350.0, sun_tilt_deg=40.0, sheen=120.0, glint=150.0, shadow=1.0
    ),
}
#: Hard conditions of the robust-extraction benchmark (`experiments.robust_extraction`), kept
#: apart from `NUISANCES` so that the presets' data sets and the "mixed" draw are unchanged:
#: green and blue lasers in sunlight, a saturated core (clipped to white over 3–15 px), and a
#: thin faint stripe over a printed black-and-white target.
HARD_NUISANCES: dict[str, Nuisance] = {
    "green": NUISANCES["sunny"]._replace(laser_rgb=LASER_RGB["green"]),
    "blue": NUISANCES["sunny"]._replace(laser_rgb=LASER_RGB["blue"]),
    "saturated": Nuisance(laser_power=2500.0, sheet_fwhm_mm=1.4),
    "saturated_sunny": NUISANCES["sunny"]._replace(laser_power=2500.0, sheet_fwhm_mm=1.4),
    "printed": Nuisance(
        ambient=150.0, printed=1.0, sheet_fwhm_mm=0.5, laser_power=90.0, speckle=0.4
    ),
}
#: "mixed" draws one of the presets above per frame.
NUISANCE_NAMES = (*NUISANCES, "mixed")


def _nuisance(nuisance: str | Nuisance, rng: np.random.Generator | None = None) -> Nuisance:
    if isinstance(nuisance, Nuisance):
        return nuisance
    if nuisance == "mixed":
        rng = rng or np.random.default_rng(0)
        return NUISANCES[list(NUISANCES)[int(rng.integers(len(NUISANCES)))]]
    if nuisance in HARD_NUISANCES:
        return HARD_NUISANCES[nuisance]
    if nuisance not in NUISANCES:
        raise ValueError(f"unknown nuisance {nuisance!r}; choose one of {NUISANCE_NAMES}")
    return NUISANCES[nuisance]


def _rng(rng) -> np.random.Generator:
    return rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)


# ----------------------------------------------------------------------------- worlds, poses


def make_world(
    welds: list[tuple[tuple[float, float], float, float, float, bool]],
    *,
    radius_mm: float = math.inf,
    rng: np.random.Generator | int = 0,
) -> World:
    """Build a `World` from welds ((x, y) point, direction angle rad, width mm, height mm, half).

    Args:
        welds: at most `MAX_WELDS` entries; `half` makes a weld that starts at its point.
        radius_mm: radius of a cylindrical wall (a tower, axis along y_w); inf for a plane.
        rng: seeds the brushed-metal texture of the plate.
    """
    if not 1 <= len(welds) <= MAX_WELDS:
        raise ValueError(f"a world holds 1 to {MAX_WELDS} welds, got {len(welds)}")
    rng = _rng(rng)
    pts = np.zeros((MAX_WELDS, 2))
    dirs = np.tile([1.0, 0.0], (MAX_WELDS, 1))
    widths = np.full(MAX_WELDS, 10.0)
    heights = np.zeros(MAX_WELDS)
    half = np.zeros(MAX_WELDS)
    for k, (p, ang, w, h, hf) in enumerate(welds):
        if w <= 0 or h <= 0 or h > w / 2:
            raise ValueError(f"weld {k}: need 0 < height ≤ width/2, got width {w}, height {h}")
        pts[k] = p
        dirs[k] = (math.cos(ang), math.sin(ang))
        widths[k], heights[k], half[k] = w, h, float(hf)
    tex = rng.normal(size=(128, 128))
    # Mild smoothing so that bilinear look-ups give streaks rather than salt and pepper.
    tex = 0.5 * tex + 0.25 * (np.roll(tex, 1, 0) + np.roll(tex, -1, 0))
    tex /= tex.std()
    curvature = 0.0 if not math.isfinite(radius_mm) else 1.0 / radius_mm
    return World(
        points=pts,
        dirs=dirs,
        widths=widths,
        heights=heights,
        half=half,
        curvature=np.asarray(curvature),
        texture=tex,
        brush_angle=np.asarray(rng.uniform(0, np.pi)),
    )


def random_world(kind: str, rng=None, *, radius_mm: float = math.inf) -> World:
    """A random straight weld or T-intersection on a plate.

    "straight": weld 0 runs through the origin along x_w (± 8°). "cross": weld 0 ends at the
    junction J = origin coming from −x_w (the stem the robot follows), weld 1 (the bar)
    crosses it at 90° ± 8°. Widths 10–25 mm, heights 1–3 mm.
    """
    rng = _rng(rng)
    if kind not in ("straight", "cross"):
        raise ValueError(f"kind must be 'straight' or 'cross', got {kind!r}")
    phi = np.deg2rad(rng.uniform(-8, 8))

    def bead():
        w = rng.uniform(10, 25)
        return w, min(rng.uniform(1, 3), w / 2)

    if kind == "straight":
        w, h = bead()
        welds = [((0.0, 0.0), phi, w, h, False)]
    else:
        w0, h0 = bead()
        w1, h1 = bead()
        bar = phi + np.pi / 2 + np.deg2rad(rng.uniform(-8, 8))
        welds = [((0.0, 0.0), phi + np.pi, w0, h0, True), ((0.0, 0.0), bar, w1, h1, False)]
    return make_world(welds, radius_mm=radius_mm, rng=rng)


def random_pose(world: World, kind: str, rng=None, sensor: Sensor | None = None) -> RobotPose:
    """A robot pose that puts the followed weld (weld 0) under the horizontal stripe.

    Lateral offset ±20 mm, heading ±8° from the weld, roll/pitch ±2°, stand-off ±10 mm.
    For "cross" the junction lies ahead of the horizontal stripe and on the vertical one,
    so that both stripes cross a bead.
    """
    rng = _rng(rng)
    sensor = sensor or default_sensor()
    dirs = np.asarray(world.dirs, float)
    ang = math.atan2(dirs[0, 1], dirs[0, 0])
    if kind == "cross":
        ang += math.pi  # weld 0 is stored pointing back from the junction
    heading = ang + np.deg2rad(rng.uniform(-8, 8) if kind == "straight" else rng.uniform(-5, 5))
    lateral = rng.uniform(-20, 20) if kind == "straight" else rng.uniform(-12, 12)
    x_stripe = float(np.asarray(sensor.T_cr)[0])
    if kind == "straight":
        along = rng.uniform(-300, 300)
    else:
        # Junction between 30 mm and 60 mm ahead of the horizontal stripe (the vertical
        # stripe sees about 60 mm ahead of it on the default rig).
        along = -(x_stripe + rng.uniform(30, 60))
    e = np.array([math.cos(ang), math.sin(ang)])
    n = np.array([-e[1], e[0]])
    p = np.asarray(world.points, float)[0] + along * e - lateral * n
    return RobotPose(
        float(p[0]),
        float(p[1]),
        float(heading),
        float(rng.uniform(-10, 10)),
        float(np.deg2rad(rng.uniform(-2, 2))),
        float(np.deg2rad(rng.uniform(-2, 2))),
    )


# ----------------------------------------------------------------------------- one frame


def _as_f32(tree):
    return jax.tree_util.tree_map(
        lambda x: jnp.asarray(x, jnp.float32) if eqx.is_inexact_array_like(x) else x, tree
    )


@eqx.filter_jit
def _render_kernel(sensor, world, pose, nz, cond, key, ss, printed=False):
    bg, laser, _ = surface_radiance(sensor, world, pose, nz, cond, ss, printed)
    return quantise(expose(bg, laser, nz, key))


def _nz_arrays(nz: Nuisance) -> Nuisance:
    return Nuisance(*[jnp.asarray(v, jnp.float32) for v in nz])


def render_image(
    sensor: Sensor,
    world: World,
    pose: RobotPose,
    nuisance: str | Nuisance = "clean",
    seed: int = 0,
    *,
    scene_seed: int | None = None,
    supersample: int = 1,
) -> np.ndarray:
    """The rendered RGB uint8 (H, W, 3) image alone (no ground truth); see `render_frame`."""
    nz = _nuisance(nuisance, np.random.default_rng(seed))
    scene_rng = np.random.default_rng([17, seed if scene_seed is None else scene_seed])
    cond = draw_conditions(scene_rng, world, nz)
    key = jax.random.key(int(seed) % (2**31))
    img = _render_kernel(
        _as_f32(sensor),
        _as_f32(world),
        RobotPose(*[jnp.float32(v) for v in pose]),
        _nz_arrays(nz),
        _as_f32(Conditions(*[np.asarray(c) for c in cond])),
        key,
        int(supersample),
        bool(nz.printed != 0),
    )
    return np.array(img)


def render_frame(
    sensor: Sensor,
    world: World,
    pose: RobotPose,
    nuisance: str | Nuisance = "clean",
    seed: int = 0,
    *,
    scene_seed: int | None = None,
    supersample: int = 1,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Render one frame and its exact ground truth.

    Args:
        sensor: the cross structured-light sensor (camera, planes, camera→robot transform).
        world: the wall and its welds.
        pose: the robot's pose on the wall.
        nuisance: a preset name of `NUISANCES` (or "mixed") or a `Nuisance`.
        seed: seeds the noise and speckle (and the scene conditions unless `scene_seed`).
        scene_seed: seeds the sun direction and shadow edges; keep it fixed over a video.
        supersample: rays per pixel along each axis (area integration).

    Returns:
        image: RGB uint8 (H, W, 3).
        gt: `h_v` (W,), `h_xyz` (W, 3), `v_u` (H,), `v_xyz` (H, 3) (camera frame, mm; NaN
        where absent), `pose` (6,), and the tracking truth of `true_weld_line`
        (`offset_mm`, `heading_deg`, `junction_x_mm`, `bead_width_mm`, `bead_height_mm`).
    """
    nz = _nuisance(nuisance, np.random.default_rng(seed))
    image = render_image(
        sensor, world, pose, nz, seed, scene_seed=scene_seed, supersample=supersample
    )
    h_v, h_xyz, v_u, v_xyz = stripe_truth(sensor, world, pose, nz.fan_half_deg)
    gt = dict(h_v=h_v, h_xyz=h_xyz, v_u=v_u, v_xyz=v_xyz, pose=np.asarray(pose, float))
    line = true_weld_line(world, pose, sensor)
    gt.update({k: np.asarray(v, float) for k, v in line.items()})
    return image, gt


def _stack_gt(gts: list[dict]) -> dict[str, np.ndarray]:
    return {k: np.stack([g[k] for g in gts]) for k in gts[0]}


def render_dataset(
    kind: str,
    nuisance: str | Nuisance = "clean",
    n_frames: int = 10,
    seed: int = 0,
    sensor: Sensor | None = None,
    *,
    progress: bool = False,
    supersample: int = 1,
    laser: str | tuple[float, float, float] | None = None,
    power: float | None = None,
) -> tuple[np.ndarray, dict[str, np.ndarray], Sensor]:
    """Render `n_frames` independent random scenes of one kind ("straight" or "cross").

    Frame i uses the generator `default_rng([seed, i])` for its world and pose, so a data
    set is reproducible and its frames do not depend on `n_frames`.

    Returns:
        images (F, H, W, 3) uint8, the ground truth of `render_frame` stacked on a leading
        frame axis, and the sensor.
    """
    sensor = sensor or default_sensor()
    images, gts = [], []
    it = range(n_frames)
    if progress:
        from tqdm import tqdm

        it = tqdm(it, desc=f"render {kind}/{nuisance if isinstance(nuisance, str) else 'custom'}")
    for i in it:
        rng = np.random.default_rng([seed, i])
        world = random_world(kind, rng)
        pose = random_pose(world, kind, rng, sensor)
        nz = _with_laser(_nuisance(nuisance, rng), laser, power)
        img, gt = render_frame(sensor, world, pose, nz, seed=int(rng.integers(2**31)))
        images.append(img)
        gts.append(gt)
    return np.stack(images), _stack_gt(gts), sensor


def _with_laser(nz: Nuisance, laser, power) -> Nuisance:
    if laser is not None:
        rgb = LASER_RGB[laser] if isinstance(laser, str) else tuple(float(c) for c in laser)
        nz = nz._replace(laser_rgb=rgb)
    if power is not None:
        nz = nz._replace(laser_power=float(power))
    return nz


# ----------------------------------------------------------------------------- files


def _write_npz(path: str, arrays: dict[str, np.ndarray]) -> None:
    """np.savez with fixed zip timestamps, so the same arrays give the same bytes."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, arr in arrays.items():
            data = io.BytesIO()
            np.lib.format.write_array(data, np.asanyarray(arr), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            zf.writestr(info, data.getvalue())
    with atomic_write(path, "wb") as f:
        f.write(buf.getvalue())


def write_dataset(
    out_dir: str | os.PathLike,
    images: np.ndarray,
    gt: dict[str, Any],
    sensor: Sensor,
    names: list[str] | None = None,
    extra: dict[str, Any] | None = None,
) -> list[str]:
    """Write rendered data per docs/contracts.md: PNG frames, `sensor.json`, `gt.npz`.

    Args:
        out_dir: created if missing. Written atomically (`cslx.files.atomic_directory`):
            on a failure nothing in it changes.
        images: (F, H, W, 3) uint8 RGB.
        gt: arrays with a leading frame axis (`h_v`, `h_xyz`, `v_u`, `v_xyz`, …) or any other
            arrays (calibration poses); written to `gt.npz` with `frames` (the file names).
        sensor: the true calibration, written as `sensor.json`.
        names: PNG file names (default `frame_00000.png`, …).
        extra: more arrays for `gt.npz`.

    Returns:
        The file names of the frames.
    """
    import cv2

    images = np.asarray(images)
    if images.ndim != 4 or images.shape[-1] != 3 or images.dtype != np.uint8:
        raise ValueError(f"images must be (F, H, W, 3) uint8, got {images.shape} {images.dtype}")
    names = list(names) if names is not None else [f"frame_{i:05d}.png" for i in range(len(images))]
    if len(names) != len(images):
        raise ValueError(f"{len(names)} names for {len(images)} images")
    for name in names:
        if os.path.basename(name) != name or name in ("", ".", "..", "sensor.json", "gt.npz"):
            raise ValueError(f"frame name {name!r} must be a plain file name")
    arrays = {k: np.asarray(v) for k, v in gt.items()}
    arrays.update({k: np.asarray(v) for k, v in (extra or {}).items()})
    arrays["frames"] = np.asarray(names, dtype=str)
    # Everything is staged in a hidden folder and moved in at the end, `gt.npz` last: a
    # failure leaves `out_dir` as it was, and a `gt.npz` always lists frames that exist.
    with atomic_directory(out_dir, last=("gt.npz",)) as stage:
        for name, img in zip(names, images, strict=True):
            if not cv2.imwrite(os.path.join(stage, name), np.ascontiguousarray(img[..., ::-1])):
                raise OSError(f"cannot write {os.path.join(out_dir, name)}")
        save_sensor(sensor, os.path.join(stage, "sensor.json"))
        _write_npz(os.path.join(stage, "gt.npz"), arrays)
    return names


def load_dataset(directory: str | os.PathLike) -> tuple[np.ndarray, dict[str, np.ndarray], Sensor]:
    """Read a directory written by `write_dataset` / `cslx render`: (images, gt, sensor).

    Raises:
        FileNotFoundError: the directory, `gt.npz`, `sensor.json` or a listed frame is missing.
    """
    import cv2

    directory = os.fspath(directory)
    if not os.path.isdir(directory):
        raise FileNotFoundError(f"{directory}: no such data set directory")
    gt_path = os.path.join(directory, "gt.npz")
    if not os.path.exists(gt_path):
        raise FileNotFoundError(f"{gt_path}: missing (not a `cslx render` output?)")
    with np.load(gt_path, allow_pickle=False) as z:
        gt = {k: z[k] for k in z.files}
    if "frames" not in gt:
        raise ValueError(f"{gt_path}: no 'frames' array naming the PNG files")
    images = []
    for name in gt["frames"]:
        p = os.path.join(directory, str(name))
        img = cv2.imread(p, cv2.IMREAD_COLOR)
        if img is None:
            raise FileNotFoundError(f"{p}: frame listed in gt.npz is missing or unreadable")
        images.append(img[..., ::-1])
    sensor = load_sensor(os.path.join(directory, "sensor.json"))
    return np.ascontiguousarray(np.stack(images)), gt, sensor
