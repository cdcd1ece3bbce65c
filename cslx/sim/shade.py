"""Image formation of rendered scenes: light, steel, laser sheets, speckle and the sensor.

All light levels are in digital numbers (DN) of the 8-bit camera for a white Lambertian
surface; the steel's albedo scales them down. Values over 255 clip, which is how sunlight
and glints saturate and how a strong laser's core turns white (R = G = B = 255).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..sensor import Sensor
from ..sensor.camera import pixel_to_ray
from .scene import (
    RobotPose,
    World,
    bead_profile,
    camera_to_world,
    cast_rays,
    fan_angle,
    laser_lit,
    projector_axis,
    projector_origin,
    robot_to_world,
    surface_gradient,
)

SUN_RGB = (1.0, 0.975, 0.94)  # near-grey daylight (paper, section 2.2: R ≈ G ≈ B)
PLATE_RGB = (0.33, 0.33, 0.34)
BEAD_RGB = (0.30, 0.285, 0.27)


class Nuisance(NamedTuple):
    """Knobs of the image formation (all light levels in DN for a white Lambertian surface).

    Attributes:
        ambient: diffuse sky/room light.
        sun: direct sunlight on a surface facing the sun (0: none).
        sun_tilt_deg: sun angle from the wall normal (its azimuth is drawn per scene).
        sheen: broad specular lobe of the steel under the sun: a smooth, partly saturating
            wash over the image.
        glint: sharp specular lobe of the rippled bead: small white saturated glints.
        shadow: 1 puts a hard-edged shadow (of the robot's body) over part of the view.
        texture: contrast of the brushed-metal and dirt albedo.
        speckle: laser speckle contrast in [0, 1]; speckle_px its grain size (pixels).
        laser_power: peak red DN of the stripe on the plain plate at the image centre;
            above 255 / (green leakage) the core clips to white.
        laser_rgb: camera response (R, G, B) to the laser; red with small green/blue
            leakage by default, e.g. (0.12, 1.0, 0.2) for a 520 nm green laser.
        sheet_fwhm_mm: full width at half maximum of the sheet's Gaussian thickness profile.
        fan_half_deg: half fan angle of each sheet (no light beyond it); fan_falloff_deg the
            1/e² angle of the intensity's fall-off along the fan.
        psf_px: Gaussian lens blur (σ, pixels).
        read_noise: sensor read noise (σ, DN); electrons_per_dn sets the shot noise
            (variance = signal / electrons_per_dn, DN²).
        vignetting: weight of the cos⁴ fall-off towards the image corners.
        printed: weight in [0, 1] of a printed black-and-white target (a chequer of
            `printed_mm` squares, turned with the brushing angle) over the steel: a
            high-contrast texture whose black squares also absorb the laser, so a thin
            stripe's contrast flips along its length. 0 (default) leaves the image unchanged.
        printed_mm: side of the printed squares (mm).
    """

    ambient: float = 110.0
    sun: float = 0.0
    sun_tilt_deg: float = 40.0
    sheen: float = 0.0
    glint: float = 0.0
    shadow: float = 0.0
    texture: float = 0.12
    speckle: float = 0.5
    speckle_px: float = 1.2
    laser_power: float = 230.0
    laser_rgb: tuple[float, float, float] = (1.0, 0.07, 0.04)
    sheet_fwhm_mm: float = 1.0
    fan_half_deg: float = 30.0
    fan_falloff_deg: float = 60.0
    psf_px: float = 0.6
    read_noise: float = 1.2
    electrons_per_dn: float = 25.0
    vignetting: float = 1.0
    printed: float = 0.0
    printed_mm: float = 6.0


class Conditions(NamedTuple):
    """Random but fixed conditions of a scene: sun direction (world) and shadow edges.

    The shadow is where both half-planes `normals[i] · xy_r > offsets[i]` hold (robot frame,
    so the robot's own shadow moves with it), with a penumbra of `penumbra_mm`.
    """

    sun_dir: Float[Array, 3]
    shadow_normals: Float[Array, "2 2"]
    shadow_offsets: Float[Array, 2]
    penumbra_mm: Float[Array, ""]


def draw_conditions(rng: np.random.Generator, world: World, nuisance: Nuisance) -> Conditions:
    """Draw the sun's azimuth and the shadow's edges of one scene."""
    d = np.asarray(world.dirs, float)[0]
    if nuisance.glint > 0:
        # Glints show where the bead's normal halves sun and view: light across the weld.
        az = np.arctan2(d[1], d[0]) + np.pi / 2 * rng.choice([-1, 1]) + rng.normal(0, 0.3)
    else:
        az = rng.uniform(0, 2 * np.pi)
    tilt = np.deg2rad(nuisance.sun_tilt_deg + rng.uniform(-8, 8))
    sun = np.array([np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), np.cos(tilt)])
    # Two edges of the robot body's shadow crossing the view (x_r 90–220 mm, |y_r| < 80 mm).
    a0 = rng.uniform(0, 2 * np.pi)
    a1 = a0 + rng.uniform(0.6, 1.4) * rng.choice([-1, 1])
    normals = np.array([[np.cos(a0), np.sin(a0)], [np.cos(a1), np.sin(a1)]])
    centre = np.array([rng.uniform(120, 190), rng.uniform(-40, 40)])
    offsets = normals @ centre
    return Conditions(sun, normals, offsets, np.asarray(rng.uniform(0.3, 1.2)))


def pixel_grid(image_size, ss: int, dtype) -> Float[Array, "hh ww 2"]:
    """Sample positions of `ss`×`ss` supersampling, OpenCV pixel convention."""
    W, H = image_size
    off = (jnp.arange(ss, dtype=dtype) + 0.5) / ss - 0.5
    u = (jnp.arange(W, dtype=dtype)[:, None] + off).reshape(-1)
    v = (jnp.arange(H, dtype=dtype)[:, None] + off).reshape(-1)
    uu, vv = jnp.meshgrid(u, v)
    return jnp.stack([uu, vv], -1)


def _downsample(img, ss):
    if ss == 1:
        return img
    H, W = img.shape[0] // ss, img.shape[1] // ss
    return img.reshape(H, ss, W, ss, *img.shape[2:]).mean(axis=(1, 3))


def _bilinear_wrap(table, i, j):
    T = table.shape[0]
    i0 = jnp.floor(i)
    j0 = jnp.floor(j)
    fi, fj = i - i0, j - j0
    i0 = i0.astype(jnp.int32) % T
    j0 = j0.astype(jnp.int32) % T
    i1, j1 = (i0 + 1) % T, (j0 + 1) % T
    return (
        table[i0, j0] * (1 - fi) * (1 - fj)
        + table[i1, j0] * fi * (1 - fj)
        + table[i0, j1] * (1 - fi) * fj
        + table[i1, j1] * fi * fj
    )


def _albedo_texture(xy, world):
    """Brushed steel (fine streaks along the brushing direction) times large-scale dirt."""
    c, s = jnp.cos(world.brush_angle), jnp.sin(world.brush_angle)
    along = xy[..., 0] * c + xy[..., 1] * s
    across = -xy[..., 0] * s + xy[..., 1] * c
    tex = world.texture.astype(xy.dtype)
    brushed = _bilinear_wrap(tex, across / 0.12, along / 2.5)
    dirt = _bilinear_wrap(tex, xy[..., 0] / 9.0 + 37.0, xy[..., 1] / 9.0 + 11.0)
    return brushed, dirt


def _printed(xy, world, square_mm):
    """Reflectance of a printed chequer (0.06 black, 0.8 white) turned by the brush angle."""
    c, s = jnp.cos(world.brush_angle), jnp.sin(world.brush_angle)
    a = (xy[..., 0] * c + xy[..., 1] * s) * (jnp.pi / square_mm)
    b = (-xy[..., 0] * s + xy[..., 1] * c) * (jnp.pi / square_mm)
    # Sharp but not aliased edges: ≈ 0.05 mm transition.
    edge = jax.nn.sigmoid(jnp.sin(a) * jnp.sin(b) * (square_mm / 0.05))
    return 0.06 + 0.74 * edge


def _gauss_blur_fft(img, sigma):
    """Gaussian blur (σ in pixels) of an (H, W, …) image by FFT (periodic edges, padded)."""
    H, W = img.shape[:2]
    pad = 8
    x = jnp.pad(img, ((pad, pad), (pad, pad)) + ((0, 0),) * (img.ndim - 2), mode="edge")
    fy = jnp.fft.fftfreq(x.shape[0])
    fx = jnp.fft.rfftfreq(x.shape[1])
    g = jnp.exp(-2 * (jnp.pi * sigma) ** 2 * (fy[:, None] ** 2 + fx[None, :] ** 2))
    g = g.reshape(g.shape + (1,) * (img.ndim - 2))
    X = jnp.fft.rfft2(x, axes=(0, 1))
    y = jnp.fft.irfft2(X * g, s=x.shape[:2], axes=(0, 1))
    return y[pad : pad + H, pad : pad + W].astype(img.dtype)


def surface_radiance(
    sensor: Sensor,
    world: World,
    pose: RobotPose,
    nz: Nuisance,
    cond: Conditions,
    ss: int,
    printed: bool = False,
) -> tuple[Float[Array, "h w 3"], Float[Array, "h w"], Float[Array, "h w 2"]]:
    """Background RGB (DN), laser irradiance (DN before colour) and the planes' values
    f_i = n_i·X_c + 1 at each pixel, by casting every (sub)pixel's ray onto the surface.

    `printed` (static) switches the printed target of `Nuisance.printed` on; off, the program
    is the one without it (bit-identical images for every other condition)."""
    cam = sensor.camera
    dt = sensor.planes.dtype
    R_wc, C_w = camera_to_world(sensor, pose)
    uv = pixel_grid(cam.image_size, ss, dt)
    ray_c = pixel_to_ray(uv, cam)
    ray_w = ray_c @ R_wc.T
    t = cast_rays(C_w, ray_w, world, n_march=4, n_refine=8)
    X_c = t[..., None] * ray_c
    X_w = C_w + t[..., None] * ray_w
    xy = X_w[..., :2]

    # Geometry of the bead under the point: ripples (chevrons) along the weld.
    cap, s_along, across = bead_profile(xy, world)
    k = jnp.argmax(cap, axis=-1)
    on_bead = jnp.clip(jnp.max(cap, axis=-1) / 0.15, 0.0, 1.0)
    s_k = jnp.take_along_axis(s_along, k[..., None], -1)[..., 0]
    a_k = jnp.take_along_axis(across, k[..., None], -1)[..., 0]
    w_k = world.widths.astype(dt)[k]
    phase = 2 * jnp.pi * (s_k + 0.8 * a_k * a_k / w_k) / 2.2
    grad = surface_gradient(xy, world)
    grad = grad + (on_bead * 0.12 * jnp.sin(phase))[..., None] * world.dirs.astype(dt)[k]
    normal = jnp.concatenate([-grad, jnp.ones_like(grad[..., :1])], -1)
    normal = normal / jnp.linalg.norm(normal, axis=-1, keepdims=True)
    view = -ray_w

    brushed, dirt = _albedo_texture(xy, world)
    tex = (1 + nz.texture * brushed) * (1 + 0.6 * nz.texture * dirt)
    plate = jnp.asarray(PLATE_RGB, dt)
    bead = jnp.asarray(BEAD_RGB, dt) * (1 + 0.08 * jnp.cos(phase))[..., None]
    albedo = tex[..., None] * (plate + on_bead[..., None] * (bead - plate))
    # Printed target: white (0.8) and black (0.06) squares.
    if printed:
        ink = _printed(xy, world, nz.printed_mm)
        albedo = albedo * (1 - nz.printed) + nz.printed * ink[..., None]

    # Sun and shadow (the shadow edges live in the robot frame).
    R_wr, t_wr = robot_to_world(pose, dt)
    xy_r = ((X_w - t_wr) @ R_wr)[..., :2]
    sd = xy_r @ cond.shadow_normals.T.astype(dt) - cond.shadow_offsets.astype(dt)
    inside = jax.nn.sigmoid(jnp.min(sd, axis=-1) / (0.25 * cond.penumbra_mm.astype(dt)))
    lit = 1 - nz.shadow * inside
    sun = cond.sun_dir.astype(dt)
    half = sun + view
    half = half / jnp.linalg.norm(half, axis=-1, keepdims=True)
    ndl = jnp.maximum(normal @ sun, 0.0)
    ndh = jnp.maximum(jnp.sum(normal * half, -1), 0.0)
    sun_rgb = jnp.asarray(SUN_RGB, dt)
    diffuse = (nz.ambient * (0.6 + 0.4 * normal[..., 2]))[..., None] * albedo
    diffuse = diffuse + (nz.sun * lit * ndl)[..., None] * albedo * sun_rgb
    # Glints: a sharp lobe on the rippled bead, broken into spots by its rough texture.
    spots = jnp.maximum(_bilinear_wrap(world.texture.astype(dt), s_k / 0.7, a_k / 0.7), 0.0)
    spec = nz.sheen * ndh**20 + nz.glint * (0.1 + 0.9 * on_bead) * spots**2 * ndh**300
    bg = diffuse + (lit * spec * (ndl > 0))[..., None] * sun_rgb

    # Laser: Gaussian sheet profile from the distance to each plane, fan fall-off, 1/r, cosine.
    P_c = projector_origin(sensor)
    P_w = R_wc @ P_c + C_w
    to_p = P_w - X_w
    r = jnp.linalg.norm(to_p, axis=-1)
    inc = jnp.maximum(jnp.sum(normal * to_p, -1) / r, 0.0)
    d_axis = projector_axis(sensor)
    r0 = 230.0 / d_axis[2]  # the axis meets a wall 230 mm away
    inc0 = jnp.abs(d_axis[2])
    shadowed = laser_lit(X_w, P_w, world, n_samples=8, tol=1e-4)
    w0 = nz.sheet_fwhm_mm / 1.1774
    fan_half = jnp.deg2rad(nz.fan_half_deg)
    fan_e = jnp.deg2rad(nz.fan_falloff_deg)
    laser = jnp.zeros_like(r)
    fvals = []
    for i in range(2):
        n_i = sensor.planes[i]
        f_i = X_c @ n_i + 1
        fvals.append(f_i)
        dist = f_i / jnp.linalg.norm(n_i)
        theta = fan_angle(X_c, sensor, i)
        fan = jnp.exp(-2 * (theta / fan_e) ** 2) * (jnp.abs(theta) <= fan_half)
        laser = laser + jnp.exp(-2 * (dist / w0) ** 2) * fan
    surface = tex * 0.5 + 0.5
    if printed:
        surface = surface * (1 - nz.printed) + nz.printed * ink / 0.8
    laser = laser * nz.laser_power * (r0 / r) * (inc / inc0) * shadowed * surface

    vign = 1 - nz.vignetting * (1 - ray_c[..., 2] ** 4)
    bg = bg * vign[..., None]
    laser = laser * vign
    return _downsample(bg, ss), _downsample(laser, ss), jnp.stack(fvals, -1)[::ss, ::ss]


def speckle_field(key, shape, grain_px, dtype):
    """Fully developed speckle |h ∗ (n₁ + i n₂)|² with unit mean and grain ≈ `grain_px`."""
    k1, k2 = jax.random.split(key)
    re = jax.random.normal(k1, shape, dtype)
    im = jax.random.normal(k2, shape, dtype)
    field = jnp.stack([re, im], -1)
    field = _gauss_blur_fft(field, grain_px / 2)
    inten = jnp.sum(field * field, -1)
    return inten / jnp.mean(inten)


def expose(
    bg: Float[Array, "h w 3"], laser: Float[Array, "h w"], nz: Nuisance, key
) -> Float[Array, "h w 3"]:
    """Speckle, lens blur, shot and read noise: the sensor's signal in DN (not yet clipped)."""
    dt = bg.dtype
    k_sp, k_noise = jax.random.split(key)
    sp = speckle_field(k_sp, laser.shape, nz.speckle_px, dt)
    laser = laser * (1 + nz.speckle * (sp - 1))
    img = bg + laser[..., None] * jnp.asarray(nz.laser_rgb, dt)
    img = _gauss_blur_fft(img, nz.psf_px)
    img = jnp.maximum(img, 0.0)
    # Shot (Poisson, Gaussian approximation) and read noise are independent: one draw with
    # their summed variance.
    sigma = jnp.sqrt(img / nz.electrons_per_dn + nz.read_noise**2)
    return img + sigma * jax.random.normal(k_noise, img.shape, dt)


def quantise(img: Float[Array, "h w 3"]) -> Array:
    """8-bit quantisation with clipping (saturation)."""
    return jnp.clip(jnp.round(img), 0, 255).astype(jnp.uint8)


# ----------------------------------------------------------------------------- checkerboard


def checkerboard_radiance(
    sensor: Sensor,
    ray: Float[Array, "hh ww 3"],
    R_bc: Float[Array, "3 3"],
    t_bc: Float[Array, 3],
    laser_on: bool,
    nz: Nuisance,
    pattern: tuple[int, int],
    square: float,
    ss: int,
    lines: tuple[int, ...] = (0, 1),
) -> tuple[Float[Array, "h w 3"], Float[Array, "h w"]]:
    """A printed checkerboard (board→camera X_c = R X_b + t) on a dark wall, ss×ss supersampled.

    `ray` holds the unit rays of the supersampled pixel grid (`pixel_grid`, `pixel_to_ray`),
    computed once for all poses. `lines`: the rows of `sensor.planes` whose sheets are on
    (both for the cross; one for a single line laser).

    The board has (cols+1)×(rows+1) squares around the inner corners (i·square, j·square, 0)
    and a white margin of half a square.
    """
    dt = sensor.planes.dtype
    R = R_bc.astype(dt)
    t = t_bc.astype(dt)
    nb = R[:, 2]  # board normal in the camera frame
    tt = (t @ nb) / jnp.maximum(ray @ nb, 1e-9)
    X_c = tt[..., None] * ray
    X_b = (X_c - t) @ R
    cols, rows = pattern
    x, y = X_b[..., 0] / square, X_b[..., 1] / square
    on_squares = (x > -1) & (x < cols) & (y > -1) & (y < rows)
    on_board = (x > -1.5) & (x < cols + 0.5) & (y > -1.5) & (y < rows + 0.5) & (tt > 0)
    black = (jnp.floor(x) + jnp.floor(y)) % 2 == 0
    refl = jnp.where(on_squares & black, 0.06, 0.8)
    refl = jnp.where(on_board, refl, 0.12)
    shade = nz.ambient * (0.85 + 0.15 * jnp.abs(ray @ nb))
    bg = (shade * refl)[..., None] * jnp.ones(3, dt)
    laser = jnp.zeros_like(tt)
    if laser_on:
        w0 = nz.sheet_fwhm_mm / 1.1774
        for i in lines:
            n_i = sensor.planes[i]
            dist = (X_c @ n_i + 1) / jnp.linalg.norm(n_i)
            laser = laser + jnp.exp(-2 * (dist / w0) ** 2)
        laser = laser * nz.laser_power * refl / 0.8 * on_board
    return _downsample(bg, ss), _downsample(laser, ss)
