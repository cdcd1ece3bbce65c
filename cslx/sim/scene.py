"""Geometry of rendered scenes: wall, weld beads, poses, ray casting and exact stripe truth.

World frame: the wall is locally the plane z_w = 0 (optionally a cylinder whose axis runs
along y_w), z_w points out of the wall towards the robot. Weld beads are circular-arc caps on
it, so the surface is the height field z_w = S(x_w, y_w).

Robot frame (docs/contracts.md): x_r forward, y_r left, z_r out of the wall; a `RobotPose` places it
in the world. The camera pose follows from the sensor's camera→robot transform.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..sensor import Sensor
from ..sensor.camera import pixel_to_ray

#: Welds are padded to this many so that every world compiles to the same program.
MAX_WELDS = 3


class World(eqx.Module):
    """A steel wall carrying straight weld beads with a circular-arc cap.

    Weld k is the line p_k + s d_k in the wall plane (s ∈ ℝ, or s ≥ 0 when `half[k]` is 1,
    which makes a weld that starts at p_k with a rounded end; a T-intersection is a main weld
    plus a half weld that starts on its centre line). Unused slots have zero height.

    Attributes:
        points: (K, 2) a point on each centre line, world mm.
        dirs: (K, 2) unit directions in the wall plane.
        widths: (K,) bead widths, mm (10–25 in the paper's welds).
        heights: (K,) cap heights, mm (1–3); 0 marks an empty slot.
        half: (K,) 1 for a weld that starts at `points[k]` and runs along +dirs[k], else 0.
        curvature: () 1/R of a cylindrical wall with its axis along y_w (0: a plane).
        texture: (T, T) unit-variance noise table for the brushed-metal albedo.
        brush_angle: () direction of the brushing marks in the wall plane, rad.
    """

    points: Float[Array, "k 2"]
    dirs: Float[Array, "k 2"]
    widths: Float[Array, " k"]
    heights: Float[Array, " k"]
    half: Float[Array, " k"]
    curvature: Float[Array, ""]
    texture: Float[Array, "t t"]
    brush_angle: Float[Array, ""]


class RobotPose(NamedTuple):
    """Pose of the robot on the wall, world frame.

    `x`, `y` (mm) place the robot's reference point, `heading_rad` turns x_r about z_w
    (counter-clockwise), `standoff_mm_offset` lifts the robot (and camera) off the wall,
    `roll`/`pitch` (rad) tilt it about x_r / y_r (plate pose variation).
    """

    x: float
    y: float
    heading_rad: float
    standoff_mm_offset: float = 0.0
    roll: float = 0.0
    pitch: float = 0.0


def _rot_x(a):
    c, s = jnp.cos(a), jnp.sin(a)
    o, z = jnp.ones_like(c), jnp.zeros_like(c)
    return jnp.stack([jnp.stack([o, z, z]), jnp.stack([z, c, -s]), jnp.stack([z, s, c])])


def _rot_y(a):
    c, s = jnp.cos(a), jnp.sin(a)
    o, z = jnp.ones_like(c), jnp.zeros_like(c)
    return jnp.stack([jnp.stack([c, z, s]), jnp.stack([z, o, z]), jnp.stack([-s, z, c])])


def _rot_z(a):
    c, s = jnp.cos(a), jnp.sin(a)
    o, z = jnp.ones_like(c), jnp.zeros_like(c)
    return jnp.stack([jnp.stack([c, -s, z]), jnp.stack([s, c, z]), jnp.stack([z, z, o])])


def robot_to_world(pose: RobotPose, dtype) -> tuple[Float[Array, "3 3"], Float[Array, 3]]:
    """(R_wr, t_wr) with X_w = R_wr X_r + t_wr; R_wr = Rz(heading) Ry(pitch) Rx(roll)."""
    p = [jnp.asarray(v, dtype) for v in pose]
    R = _rot_z(p[2]) @ _rot_y(p[5]) @ _rot_x(p[4])
    return R, jnp.stack([p[0], p[1], p[3]])


def camera_to_world(sensor: Sensor, pose: RobotPose) -> tuple[Float[Array, "3 3"], Float[Array, 3]]:
    """(R_wc, C_w): X_w = R_wc X_c + C_w, C_w the optical centre in the world."""
    dtype = sensor.R_cr.dtype
    R_wr, t_wr = robot_to_world(pose, dtype)
    return R_wr @ sensor.R_cr, R_wr @ sensor.T_cr + t_wr


def projector_origin(sensor: Sensor) -> Float[Array, 3]:
    """The cross projector's centre, camera frame: the point of the two planes' common line
    with z_c = 0 (where `default_sensor` puts it)."""
    n = sensor.planes
    A = n[:, :2]
    xy = jnp.linalg.solve(A, -jnp.ones(2, n.dtype))
    return jnp.concatenate([xy, jnp.zeros(1, n.dtype)])


def projector_axis(sensor: Sensor) -> Float[Array, 3]:
    """Unit direction of the projector's axis (both planes contain it), towards +z_c."""
    d = jnp.cross(sensor.planes[0], sensor.planes[1])
    d = d / jnp.linalg.norm(d)
    return jnp.where(d[2] < 0, -d, d)


# ----------------------------------------------------------------------------- surface


def wall_z(xy: Float[Array, "*b 2"], world: World) -> Float[Array, "*b"]:
    """Height of the bare wall: 0 for a plane, −(R − √(R² − x²)) for a cylinder of radius R."""
    k = world.curvature.astype(xy.dtype)
    kx2 = jnp.minimum((k * xy[..., 0]) ** 2, 0.99)
    return -k * xy[..., 0] ** 2 / (1 + jnp.sqrt(1 - kx2))


def bead_profile(xy: Float[Array, "*b 2"], world: World) -> tuple[Array, Array, Array]:
    """Cap heights of every weld at xy: (…, K) heights, along-weld and across-weld coordinates.

    A circular-arc cap of width w and height h has radius ρ = (w²/4 + h²)/(2h); at distance d
    from the centre line its height is h − d²/(ρ + √(ρ² − d²)) (the stable form of
    √(ρ² − d²) − (ρ − h)), clipped at 0 beyond the toes. A half weld (s < 0 behind its start)
    measures d from its start point, which rounds its end.
    """
    dt = xy.dtype
    x, y = xy[..., 0], xy[..., 1]
    caps, alongs, acrosses = [], [], []
    # Unrolled over the few welds: elementwise (…)-shaped work fuses far better on the CPU
    # than (…, K, 2) intermediates.
    for k in range(world.heights.shape[0]):
        px, py = world.points[k, 0].astype(dt), world.points[k, 1].astype(dt)
        dx, dy = world.dirs[k, 0].astype(dt), world.dirs[k, 1].astype(dt)
        h = world.heights[k].astype(dt)
        w = world.widths[k].astype(dt)
        rx, ry = x - px, y - py
        s = rx * dx + ry * dy
        across = ry * dx - rx * dy
        end = (world.half[k] > 0) & (s < 0)
        d2 = jnp.where(end, rx * rx + ry * ry, across * across)
        hs = jnp.maximum(h, 1e-6)
        rho = (w * w / 4 + hs * hs) / (2 * hs)
        arg = rho * rho - d2
        pos = arg > 0
        root = jnp.where(pos, jnp.sqrt(jnp.where(pos, arg, 1.0)), 0.0)
        cap = jnp.where(h > 0, jnp.maximum(h - d2 / (rho + root), 0.0), 0.0)
        caps.append(cap)
        alongs.append(s)
        acrosses.append(across)
    return jnp.stack(caps, -1), jnp.stack(alongs, -1), jnp.stack(acrosses, -1)


def _max_cap(xy, world):
    cap = bead_profile(xy, world)[0]
    return jnp.max(cap, axis=-1)


def surface_z(xy: Float[Array, "*b 2"], world: World) -> Float[Array, "*b"]:
    """The surface height field S(x, y) = wall + max over welds of the bead cap (mm)."""
    return wall_z(xy, world) + _max_cap(xy, world)


def surface_gradient(xy: Float[Array, "*b 2"], world: World) -> Float[Array, "*b 2"]:
    """(∂S/∂x, ∂S/∂y) by forward-mode differentiation of the elementwise height field."""
    x, y = xy[..., 0], xy[..., 1]
    one = jnp.ones_like(x)
    _, gx = jax.jvp(lambda a: surface_z(jnp.stack([a, y], -1), world), (x,), (one,))
    _, gy = jax.jvp(lambda b: surface_z(jnp.stack([x, b], -1), world), (y,), (one,))
    return jnp.stack([gx, gy], axis=-1)


def _gap(origin, dirs, t, world):
    x = origin[0] + t * dirs[..., 0]
    y = origin[1] + t * dirs[..., 1]
    z = origin[2] + t * dirs[..., 2]
    return z - surface_z(jnp.stack([x, y], -1), world)


def cast_rays(
    origin: Float[Array, 3],
    dirs: Float[Array, "*b 3"],
    world: World,
    *,
    n_march: int = 16,
    n_refine: int = 14,
) -> Float[Array, "*b"]:
    """Ray parameter t of the first hit of origin + t·dir with the surface z = S(x, y).

    The bare wall is hit by a fixed point (its slope is small), then the ray is marched in
    `n_march` steps from above the highest bead down to the wall to bracket the first sign
    change of g(t) = z(t) − S(xy(t)), which is refined by the Illinois variant of regula
    falsi (superlinear, always bracketed; ≈1e-12 mm in float64 with the defaults).
    """
    dt = dirs.dtype
    origin = origin.astype(dt)
    rz = jnp.minimum(dirs[..., 2], -1e-6)

    def wall_step(_, t):
        xy = jnp.stack([origin[0] + t * dirs[..., 0], origin[1] + t * dirs[..., 1]], -1)
        return (wall_z(xy, world) - origin[2]) / rz

    t = jax.lax.fori_loop(0, 6, wall_step, -origin[2] / rz)
    hmax = jnp.max(world.heights).astype(dt)
    t_top = t - (hmax + 0.5) / (-rz)
    t_bot = t + 0.05 / (-rz)

    def march(i, state):
        a, ga, b, gb, found = state
        ti = t_top + (t_bot - t_top) * (i / n_march)
        gi = _gap(origin, dirs, ti, world)
        hit = (~found) & (gi <= 0)
        b = jnp.where(hit, ti, b)
        gb = jnp.where(hit, gi, gb)
        keep = (~found) & (gi > 0)
        a = jnp.where(keep, ti, a)
        ga = jnp.where(keep, gi, ga)
        return a, ga, b, gb, found | hit

    g0 = _gap(origin, dirs, t_top, world)
    init = (t_top, g0, t_bot, _gap(origin, dirs, t_bot, world), jnp.zeros(t.shape, bool))
    a, ga, b, gb, _ = jax.lax.fori_loop(1, n_march + 1, march, init)
    return _illinois(lambda tt: _gap(origin, dirs, tt, world), a, ga, b, gb, n_refine)


def _illinois(fun, a, fa, b, fb, n_iter):
    """Bracketed root of `fun` (fa > 0 ≥ fb elementwise) by Illinois regula falsi."""

    def step(_, state):
        a, fa, b, fb, side = state
        denom = fa - fb
        safe = jnp.where(denom == 0, 1.0, denom)
        c = jnp.where(denom == 0, 0.5 * (a + b), b - fb * (b - a) / -safe)
        c = jnp.clip(c, jnp.minimum(a, b), jnp.maximum(a, b))
        fc = fun(c)
        to_a = fc > 0
        # Illinois: halve the stale end's value when the same end is replaced twice in a row.
        fb = jnp.where(to_a & (side == 1), fb * 0.5, fb)
        fa = jnp.where(~to_a & (side == -1), fa * 0.5, fa)
        a = jnp.where(to_a, c, a)
        fa = jnp.where(to_a, fc, fa)
        b = jnp.where(to_a, b, c)
        fb = jnp.where(to_a, fb, fc)
        side = jnp.where(to_a, 1, -1).astype(jnp.int32)
        return a, fa, b, fb, side

    side = jnp.zeros(jnp.shape(a), jnp.int32)
    a, fa, b, fb, _ = jax.lax.fori_loop(0, n_iter, step, (a, fa, b, fb, side))
    return jnp.where(jnp.abs(fa) < jnp.abs(fb), a, b)


def laser_lit(
    X_w: Float[Array, "*b 3"],
    P_w: Float[Array, 3],
    world: World,
    *,
    n_samples: int = 12,
    tol: float = 1e-7,
) -> Float[Array, "*b"]:
    """True where the segment from surface point X_w to the projector P_w clears the surface.

    Samples the segment until it is above the highest bead; a point on a face turned away
    from the projector fails at the first sample (attached shadow), one behind a bead later
    (cast shadow).
    """
    dt = X_w.dtype
    l = P_w.astype(dt) - X_w
    l = l / jnp.linalg.norm(l, axis=-1, keepdims=True)
    lz = jnp.maximum(l[..., 2], 1e-3)
    s_max = (jnp.max(world.heights).astype(dt) + 0.2) / lz

    def sample(i, ok):
        frac = (i + 1) / n_samples
        s = s_max * frac * frac + 0.01 * (1 - frac)
        q = X_w + s[..., None] * l
        return ok & (q[..., 2] - surface_z(q[..., :2], world) > -tol)

    return jax.lax.fori_loop(0, n_samples, sample, jnp.ones(X_w.shape[:-1], bool))


def fan_angle(X_c: Float[Array, "*b 3"], sensor: Sensor, plane: int) -> Float[Array, "*b"]:
    """Angle (rad) of the projector ray to X_c from the projector axis, within sheet `plane`."""
    P = projector_origin(sensor).astype(X_c.dtype)
    d = projector_axis(sensor).astype(X_c.dtype)
    n = sensor.planes[plane].astype(X_c.dtype)
    n = n / jnp.linalg.norm(n)
    e = jnp.cross(n, d)  # in-sheet direction across the axis
    r = X_c - P
    return jnp.arctan2(r @ e, r @ d)


# ----------------------------------------------------------------------------- ground truth


def _stripe_truth(sensor, world, pose, plane, fan_half, n_scan, n_iter):
    """Exact stripe centre along every image column (plane 0) or row (plane 1).

    `plane` may be traced: both stripes share one compiled program, with max(W, H) lines
    (the surplus lines of the shorter axis are discarded by the caller).

    Along the line of pixels, f(s) = n·X(s) + 1 with X(s) the surface point seen by pixel s
    (a root-found ray cast). f changes sign where the surface meets the laser plane: bracket
    the first sign change on a scan of `n_scan` samples, then refine by Illinois regula
    falsi on the continuous pixel coordinate.
    """
    cam = sensor.camera
    W, H = cam.image_size
    dt = sensor.planes.dtype
    R_wc, C_w = camera_to_world(sensor, pose)
    n = sensor.planes[plane]
    is_h = plane == 0
    n_lines = max(W, H)
    length = jnp.where(is_h, H, W).astype(dt)
    fixed = jnp.arange(n_lines, dtype=dt)

    def f(s):
        fx = fixed * jnp.ones_like(s)
        uv = jnp.stack([jnp.where(is_h, fx, s), jnp.where(is_h, s, fx)], -1)
        ray_c = pixel_to_ray(uv, cam)
        t = cast_rays(C_w, ray_c @ R_wc.T, world)
        return t * (ray_c @ n) + 1, t, ray_c

    grid = -0.5 + length * jnp.linspace(0.0, 1.0, n_scan, dtype=dt)
    fg = f(grid[:, None] + jnp.zeros((1, n_lines), dt))[0]  # (n_scan, n_lines)
    pos = fg > 0
    change = pos[:-1] != pos[1:]
    has = jnp.any(change, axis=0)
    k = jnp.argmax(change, axis=0)
    a, b = grid[k], grid[k + 1]
    fa = jnp.take_along_axis(fg, k[None], 0)[0]
    fb = jnp.take_along_axis(fg, (k + 1)[None], 0)[0]
    # Orient each bracket so that f(a) > 0 ≥ f(b).
    flip = fa <= 0
    a, b = jnp.where(flip, b, a), jnp.where(flip, a, b)
    fa, fb = jnp.where(flip, fb, fa), jnp.where(flip, fa, fb)
    s = _illinois(lambda x: f(x)[0], a, fa, b, fb, n_iter)
    _, t, ray_c = f(s)
    X_c = t[..., None] * ray_c
    X_w = X_c @ R_wc.T + C_w
    P_w = R_wc @ projector_origin(sensor) + C_w
    theta = fan_angle(X_c, sensor, plane)
    valid = has & laser_lit(X_w, P_w, world) & (jnp.abs(theta) <= fan_half)
    s = jnp.where(valid, s, jnp.nan)
    X_c = jnp.where(valid[:, None], X_c, jnp.nan)
    return s, X_c


@eqx.filter_jit
def _truth_jit(sensor, world, pose, fan_half, n_scan):
    W, H = sensor.camera.image_size
    s, X = jax.vmap(lambda p: _stripe_truth(sensor, world, pose, p, fan_half, n_scan, 40))(
        jnp.arange(2)
    )
    return s[0, :W], X[0, :W], s[1, :H], X[1, :H]


def stripe_truth(sensor: Sensor, world: World, pose: RobotPose, fan_half_deg: float = 30.0):
    """Exact ground truth of both stripes, always computed in float64.

    Returns NumPy arrays `h_v` (W,), `h_xyz` (W, 3), `v_u` (H,), `v_xyz` (H, 3): for each
    image column the sub-pixel row where the surface meets plane 0 and that point (camera
    frame, mm), and the same per row for plane 1; NaN where the stripe is absent (off the
    image, outside the projector's fan, or in the laser's shadow).
    """
    with jax.enable_x64(True):
        f64 = lambda x: jnp.asarray(x, jnp.float64) if eqx.is_inexact_array_like(x) else x  # noqa: E731
        sensor64 = jax.tree_util.tree_map(f64, sensor)
        world64 = jax.tree_util.tree_map(f64, world)
        pose64 = RobotPose(*[jnp.asarray(v, jnp.float64) for v in pose])
        n_scan = max(sensor.camera.image_size) // 4 + 1
        out = _truth_jit(sensor64, world64, pose64, jnp.deg2rad(jnp.float64(fan_half_deg)), n_scan)
        return tuple(np.asarray(o) for o in out)


def weld_lines_robot(world: World, pose: RobotPose) -> tuple[np.ndarray, np.ndarray]:
    """Weld centre lines in the robot frame: points (K, 2) and unit directions (K, 2) on the
    robot's wall plane z_r = 0 (the world line z_w = 0 mapped into the robot frame)."""
    p = np.asarray(pose, float)
    R = _np_rot_z(p[2]) @ _np_rot_y(p[5]) @ _np_rot_x(p[4])
    t = np.array([p[0], p[1], p[3]])
    pts = np.asarray(world.points, float)
    dirs = np.asarray(world.dirs, float)
    P_w = np.concatenate([pts, np.zeros((len(pts), 1))], 1)
    D_w = np.concatenate([dirs, np.zeros((len(pts), 1))], 1)
    P_r = (P_w - t) @ R
    D_r = D_w @ R
    # Slide each point along its direction onto z_r = 0 (tilts are small).
    P_r = P_r - D_r * np.divide(
        P_r[:, 2:], D_r[:, 2:], where=np.abs(D_r[:, 2:]) > 1e-12, out=np.zeros_like(P_r[:, 2:])
    )
    D2 = D_r[:, :2] / np.linalg.norm(D_r[:, :2], axis=1, keepdims=True)
    return P_r[:, :2], D2


def _np_rot_x(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _np_rot_y(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _np_rot_z(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
