"""Weld-bead features from one laser stripe's 3-D profile, and T-junctions from both stripes.

Section 4.3 of the paper tracks the weld from the stripe profile but gives no algorithm; this
module is cslx's own, in five steps per stripe (all fixed-size, jit/vmap-able):

1. **Base plate** — the profile's points (robot frame, mm) are written as (s, z) with s the
   coordinate along the stripe (y_r for the horizontal stripe, x_r for the vertical one).
   The plate is the line z = c0 + c1 s fitted by iteratively reweighted least squares: a
   few Huber iterations from the least-squares start (convex, so they converge even when
   the bead biases the start), then Tukey-biweight iterations that give the bead (a
   one-sided outlier) zero weight. The scale is 1.4826·MAD of the residuals, floored.
2. **Height** — every point in plate-aligned coordinates (t along the plate, h normal to
   it, positive out of the wall).
3. **Bead** — a run of points with h above `threshold_mm` (~0.3 mm), bounded on both sides
   by plate points (a run that touches an end of the profile is only part of a bead, or a
   stripe lying along a bead, and is not reported); invalid points inside a run (glints,
   dropouts) do not break it, nor, with `WeldConfig.min_plate_mm`, points far below the
   plate or a plate stretch shorter than that (`cslx.runtime.bead_run.plate_points`). Of
   the runs, the one with the largest area Σh is the bead.
4. **Cap** — a circle fitted to the run (algebraic Kåsa fit, then Gauss–Newton on the
   geometric distance). Width = the chord where the circle meets the plate (h = 0), so the
   toes below the threshold are extrapolated; height (reinforcement) = the circle's apex;
   centre = the apex as a 3-D robot-frame point.
5. **Position** — the cap model (a circular cap standing on the plate: centre, half-chord,
   height) fitted by Gauss–Newton with Tukey weights to the bead *and* the plate within
   `cap_margin_mm` around it (`_cap_fit`): where a glint or a clipped core hides part of the
   bead the missing points count for nothing and the plate where the cap would stand counts
   against it, so the bead's centre stays where the visible flanks and toes put it (rendered
   sunlight, issue 12: the circle fitted to the run alone moved with the visible half).

Junctions. `weld_features` finds the crossing weld of a T on the vertical stripe with
`cslx.runtime.junction.crossing_feature`, from the crossing bead's far side, so that it is
found both where the vertical stripe runs on bare plate beside the followed weld (the default
rig: 40 mm to its right) and where it runs along the followed bead's flank.

Heading. One frame of the cross sensor does not observe the weld's heading robustly: the
horizontal stripe crosses the followed weld at one point, and the vertical stripe runs on
bare plate beside it (the default rig) or along it (where the cross-section is flat on the
crown and the lateral position ambiguous). `weld_line_from_features` therefore fits the
line through several bead centres — the tracker's recent horizontal-stripe centres carried
into the current robot frame by odometry — and reports offset and heading; with one point
it reports the offset and a NaN heading. A Kalman filter over (offset, heading) in the
tracker is the intended consumer. Where the vertical stripe crosses the bead's flank, one
frame does see the heading: `heading_from_vertical` (host NumPy) matches the vertical
stripe's heights against the cross-section the horizontal stripe measured, shifted along
the weld by tan θ; it returns NaN where that is ambiguous (on the crown of a centred weld
only |θ| is seen) or uninformative (bare plate).
"""

from __future__ import annotations

import functools
import math
from typing import TYPE_CHECKING, NamedTuple

import jax
import jax.numpy as jnp

from ..pytree import pytree_dataclass, static
from .bead_run import largest_run as _largest_run
from .bead_run import plate_points, side_cover, steep_points
from .small_ops import masked_median, one_function, solve_spd
from .vertical_heading import heading_from_vertical

if TYPE_CHECKING:  # annotations only (strings at run time): no jaxtyping import
    from jaxtyping import Array, ArrayLike, Bool, Float
__all__ = ["WeldConfig", "WeldFeature", "WeldLine", "plate_fit", "stripe_feature"]
__all__ += ["weld_features", "weld_line_from_features", "heading_from_vertical"]

HORIZONTAL_AXIS, VERTICAL_AXIS = 1, 0  # the stripes run along y_r and x_r


@pytree_dataclass
class WeldConfig:
    """Settings of the bead detector (mm unless stated; a pytree without equinox, issue 13).

    threshold_mm: height above the plate that starts a bead run (~0.3 mm).
    min_height_mm / min_width_mm / max_width_mm: a bead outside these is not found.
    min_points: fewest points above the threshold in a bead run.
    sigma_floor_mm: lowest plate-noise scale used by the robust fit.
    fit_scale_mm: circle-fit RMS at which its confidence factor is 0.5.
    junction_min_confidence: a vertical-stripe bead at least this confident is a junction.
    n_huber / n_tukey / n_cap: IRLS iterations; cap-model Gauss–Newton steps (static).
    n_gauss_newton / n_robust: Gauss–Newton steps per circle fit, and Tukey reweightings of
        the circle fit (its residual scale: 1.4826·MAD, at least twice the plate noise).
    centre: the bead's position: "cap" (the cap model fitted to the bead and the plate
        within `cap_margin_mm` of it, `_cap_fit`), "toes" (midpoint of the threshold
        crossings) or "apex" (of the circle fitted to the run alone); see `stripe_feature`.
    crossing_mask_mm: vertical-stripe points this close (x_r) to the horizontal stripe are
        left out of the junction search (`weld_features`). 8 mm rather than 5 (issue 12):
        where the stripes cross, the horizontal stripe's light moved the vertical stripe's
        points over ≈ 142–152 mm for a crossing at 150 mm (rendered glare, flank, dev seed
        7302), and a 2.9 mm bump 4.6 mm before the crossing, with the masked gap and the
        plate beyond it, passed for a crossing bead: 11 and 9 false T frames in the flank
        glare and shadow runs of dev seed 7302, none with 8 mm (recall there 96.9 → 100 %).
        The other 46 dev runs (seeds 7301, 7302, 7305, 1201–1203, both placements, every
        nuisance; experiments/tracking_diagnostics.py) were identical in every measure.
    crossing_background_mm: on the vertical stripe, heights are measured against the lowest
        point within this distance beyond (`cslx.runtime.junction.crossing_feature`); 0 uses
        the plate line alone. It must exceed the bar's half width (≈ 7–8 mm rendered) so
        that the apex reaches the plate past the far toe. Dev flank seeds 1201–1203 (12 runs),
        T recall 91.0 % with 0: 8 mm 99.7, 12 mm 99.5, 16 mm 99.5 % (0 false reports), 20 mm
        97.9 % with 3 false (a longer window reaches lower points beyond flank bumps).
    crossing_ramp_max: a crossing bead's apex fails where the plate-line height one
        `crossing_background_mm` before it exceeds the apex's by more than this share of
        its height (the stripe running off the followed bead's flank, not a bar;
        `cslx.runtime.junction`, "ramp test"); inf: off.
    crossing_cap_max / crossing_bump_mm: a crossing bead's fitted cap is at most this ×
        its half width high (a circular cap is no taller than a half disc), and a candidate
        without plate on its near side loses to a farther one with plate on both sides and
        an apex this high (`cslx.runtime.junction`, "run-off test", issue 12); inf: off
        (the default: with 1.0 / 1.0 a clean still frame's T was lost, the module's notes).
    side_cover_power: p > 0: the confidence × (min(L, R) / max(L, R))^p, L and R the share
        of the valid points with a prior weight > 0 on each side of the bead's centre, out
        to its half-chord + `cap_margin_mm` (`bead_run.side_cover`): a bead one of whose flanks the
        pipeline weighted out is placed by the other alone. 0 (off) here; 2 in the tracker's
        pipeline (`cslx.runtime.pipeline_config.tracking_config`, the evidence there).
    min_plate_mm: > 0: a bead run ends only at a stretch of plate points this long, and a
        point below the plate by more than `threshold_mm` is no plate point
        (`cslx.runtime.bead_run.plate_points`); 0 (off) here, the tracker's in
        `tracking_config`.
    cap_slope_weight / cap_slope_factor: < 1: points steeper than factor × the cap's toe
        weigh this in its fit (`bead_run.steep_points`); off (1) here and in the tracker.
    """

    threshold_mm: float = 0.3
    min_height_mm: float = 0.5
    min_width_mm: float = 4.0
    max_width_mm: float = 40.0
    min_points: int = 6
    sigma_floor_mm: float = 0.02
    fit_scale_mm: float = 0.15
    junction_min_confidence: float = 0.3
    n_huber: int = static(5)
    n_tukey: int = static(8)
    n_gauss_newton: int = static(4)
    n_robust: int = static(3)
    centre: str = static("cap")
    crossing_mask_mm: float = 8.0
    cap_margin_mm: float = 4.0
    crossing_background_mm: float = 12.0
    crossing_ramp_max: float = 0.4
    crossing_cap_max: float = static(math.inf)
    crossing_bump_mm: float = static(math.inf)
    n_cap: int = static(8)
    side_cover_power: float = static(0.0)
    min_plate_mm: float = static(0.0)
    cap_slope_weight: float = static(1.0)
    cap_slope_factor: float = 1.5


class WeldFeature(NamedTuple):
    """The bead seen on one stripe (robot frame, mm). Values are NaN where found is False.

    found: a bead was detected. centre: (3,) apex of the bead cap. position: the apex's
    coordinate along the stripe (y_r for the horizontal stripe, x_r for the vertical one).
    width, height: chord at the plate and reinforcement. confidence: [0, 1].
    noise_mm: robust scale of the plate residuals.
    """

    found: Bool[Array, ""]
    centre: Float[Array, 3]
    position: Float[Array, ""]
    width: Float[Array, ""]
    height: Float[Array, ""]
    confidence: Float[Array, ""]
    noise_mm: Float[Array, ""]


class WeldLine(NamedTuple):
    """The followed weld line: y_r at x_ref (offset, mm), heading (deg, CCW + from x_r)."""

    offset_mm: Float[Array, ""]
    heading_deg: Float[Array, ""]
    heading_valid: Bool[Array, ""]


def _feature(found, centre, pos, width, height, confidence, sigma, dtype) -> WeldFeature:
    """A `WeldFeature` whose measurements are NaN where nothing was `found`."""
    nan = jnp.asarray(jnp.nan, dtype)
    return WeldFeature(
        found=found,
        centre=jnp.where(found, centre, nan),
        position=jnp.where(found, pos, nan),
        width=jnp.where(found, width, nan),
        height=jnp.where(found, height, nan),
        confidence=confidence.astype(dtype),
        noise_mm=sigma,
    )


def _check_profile(points, valid, name):
    points = jnp.asarray(points)
    valid = jnp.asarray(valid)
    if points.ndim != 2 or points.shape[-1] != 3:
        raise ValueError(f"{name}: points must have shape (N, 3), got {points.shape}")
    if valid.shape != points.shape[:1]:
        raise ValueError(f"{name}: valid must have shape ({points.shape[0]},), got {valid.shape}")
    if not jnp.issubdtype(points.dtype, jnp.floating):
        raise ValueError(f"{name}: points must be floating point, got {points.dtype}")
    return points, valid.astype(bool) & jnp.all(jnp.isfinite(points), axis=-1)


def _wls(A, b, w, eps, dot=False):
    """(AᵀWA + eps I)⁻¹ AᵀW b for tiny systems; no sqrt(w), so zero weights keep finite
    gradients.

    The normal equations' n(n + 1)/2 + n sums Σ w aᵢ aⱼ, Σ w aᵢ b are reductions of the
    products rather than two matrix products (`AᵀW A`, `AᵀW b`): XLA's CPU backend ran
    those as library dot calls on (n, N) operands, and the cap model's (3, 640) weighted
    Jacobian as a kernel split over two threads, which waits for the other thread on the
    shared CPU (issue 13; weld features 1.110 → 1.045 ms, 600 interleaved calls on 12
    tracking frames, load 5.6). One sum per product, not one reduction of their (k, N)
    stack: jaxlib 0.10 hands that stack to its YNNPACK library (a 9 × 640 reduce for n = 3),
    and a loop holding a library call is not compiled as one function
    (`cslx.environment.small_loops`): the circle's robust refit and both cap fits ran as
    ≈ 30 tasks a trip. With the sums, weld features and profile clean-up 1.455 → 1.342 ms
    (p10 0.865 → 0.810; 600 interleaved calls, load 9). Values to float32 rounding (video
    seed 0: outputs within 1.4e-4); the 48 dev T approaches (7301, 7302, 7305, 1201–1203):
    the rounding moved a few ill-posed flank-sunny frames' bead up to 0.92 mm, the filtered
    offset ≤ 0.035 mm, each run's scores equal (offset mean ±0.005 mm; max, heading, T).
    ``dot``: the matrix products
    (the centre's third coordinate, once per stripe: that 3 × 3 system is nearly singular,
    and its float32 rounding moved x_r by 2e-4 mm and the tracker's offset by 1.6e-4 mm).
    """
    n = A.shape[-1]
    if dot:
        Aw = A * w[:, None]
        return solve_spd(Aw.T @ A + eps * jnp.eye(n, dtype=A.dtype), Aw.T @ b)
    cols = [A[:, i] for i in range(n)]
    wc = [w * c for c in cols]
    terms = [wc[i] * cols[j] for i in range(n) for j in range(i, n)] + [c * b for c in wc]
    S = jnp.stack([jnp.sum(term) for term in terms])
    M = [[None] * n for _ in range(n)]
    k = 0
    for i in range(n):
        for j in range(i, n):
            M[i][j] = M[j][i] = S[k] + eps if i == j else S[k]
            k += 1
    return solve_spd(jnp.stack([jnp.stack(row) for row in M]), S[k:])


def _wls_line(s, z, w):
    """Weighted least-squares line z = c0 + c1 s (s pre-centred)."""
    return _wls(jnp.stack([jnp.ones_like(s), s], -1), z, w, 1e-9)


def _masked_median(x, mask):
    # The robust scale is a weighting constant of IRLS: no gradient through the sort.
    return masked_median(x, mask)


def plate_fit(
    s: Float[Array, " n"], z: Float[Array, " n"], valid: Bool[Array, " n"], config: WeldConfig
) -> tuple[Float[Array, 2], Float[Array, ""]]:
    """Robust line z = c0 + c1 s through the plate points (Huber, then Tukey IRLS).

    Args:
        s: (N,) coordinate along the stripe, mm (centred by the caller for conditioning).
        z: (N,) height z_r, mm.
        valid: (N,) which points exist.
    Returns:
        (c0, c1) and the robust residual scale σ (mm, ≥ sigma_floor_mm).

    The loops of this module stay rolled: unrolled (`fori_loop(..., unroll=True)` here, in
    the circle, its robust refit and the cap fit) the weld features went 2.06 → 3.09 ms
    (600 interleaved calls on 12 tracking frames, load 7; issue 13).
    """
    w0 = valid.astype(s.dtype)
    floor = jnp.asarray(config.sigma_floor_mm, s.dtype)

    def scale(c):
        r = z - c[0] - c[1] * s
        return r, jnp.maximum(1.4826 * _masked_median(jnp.abs(r), valid), floor)

    def body(i, c):
        r, sigma = scale(c)
        u = r / sigma
        huber = jnp.minimum(1.0, 1.345 / jnp.maximum(jnp.abs(u), 1e-12))
        tukey = jnp.square(jnp.clip(1.0 - jnp.square(u / 4.685), 0.0, 1.0))
        w = jnp.where(i < config.n_huber, huber, tukey) * w0
        # A degenerate weight set (all rejected) keeps the previous estimate.
        ok = jnp.sum(w) > 2.0
        return jnp.where(ok, _wls_line(s, z, jnp.where(ok, w, w0)), c)

    c = _wls_line(s, z, w0)
    c = jax.lax.fori_loop(0, config.n_huber + config.n_tukey, body, c)
    return c, scale(c)[1]


def _circle_fit(t, h, w, n_iter):
    """Circle through weighted points: Kåsa algebraic fit, then Gauss–Newton (geometric).

    Returns centre (a, b), radius R and the weighted RMS geometric residual.
    """
    W = jnp.sum(w)
    tm = jnp.sum(w * t) / jnp.maximum(W, 1e-12)
    x = t - tm
    # x² + h² + D x + E h + F = 0 → linear in (D, E, F)
    A = jnp.stack([x, h, jnp.ones_like(x)], -1)
    D, E, F = _wls(A, -(x * x + h * h), w, 1e-9)
    a, b = -D / 2, -E / 2
    R = jnp.sqrt(jnp.maximum(a * a + b * b - F, 1e-12))

    def gn(_, p):
        a, b, R = p
        dx, dh = x - a, h - b
        d = jnp.sqrt(jnp.maximum(dx * dx + dh * dh, 1e-12))
        r = d - R
        J = jnp.stack([-dx / d, -dh / d, -jnp.ones_like(d)], -1)
        step = _wls(J, -r, w, 1e-9)
        new = p + step
        good = jnp.all(jnp.isfinite(new)) & (new[2] > 0)
        return jnp.where(good, new, p)

    a, b, R = jax.lax.fori_loop(0, n_iter, gn, jnp.stack([a, b, R]))
    d = jnp.sqrt(jnp.maximum(jnp.square(x - a) + jnp.square(h - b), 1e-12))
    rms = jnp.sqrt(jnp.sum(w * jnp.square(d - R)) / jnp.maximum(W, 1e-12))
    return a + tm, b, R, rms


def _cap_model(p, t):
    """Height of a circular cap (centre a, half-chord c, height H) on the plate h = 0."""
    a, c, H = p[0], jnp.abs(p[1]) + 1e-3, jnp.abs(p[2]) + 1e-3
    R = (c * c + H * H) / (2.0 * H)
    inside = jnp.square(t - a) < c * c
    top = jnp.sqrt(jnp.maximum(R * R - jnp.square(t - a), 1e-9)) - (R - H)
    return jnp.where(inside, top, 0.0)


def _cap_fit(t, h, w, p0, sigma, n_iter, extra=None):
    """The cap (a, c, H) that best explains the heights h(t), plate points included.

    Gauss–Newton on the vertical residuals with Tukey weights (scale 1.4826·MAD, at least
    2σ): a point of the plate where the cap would stand counts against it, a stretch of the
    profile that is missing (a glint) counts for nothing, and points that no cap explains
    (a centre on the wrong ridge) lose their weight. ``extra(p)``: more weights per step.
    """

    def res(p):
        return h - _cap_model(p, t)

    def body(_, carry):
        p, wr = carry
        r = jax.lax.stop_gradient(res(p))
        scale = jnp.maximum(1.4826 * _masked_median(jnp.abs(r), w > 0), 2.0 * sigma)
        u = r / (4.685 * scale)
        wr = w * jnp.square(jnp.clip(1.0 - u * u, 0.0, 1.0))
        wr = wr if extra is None else wr * extra(p)
        J = -jax.jacfwd(_cap_model)(p, t)
        step = _wls(J, -res(p), wr, 1e-6)
        new = p + jnp.clip(step, -2.0, 2.0)
        good = jnp.all(jnp.isfinite(new))
        return jnp.where(good, new, p), wr

    p, wr = jax.lax.fori_loop(0, n_iter, body, (p0, w))
    return p, wr


def stripe_feature(
    points: Float[Array, "n 3"],
    valid: Bool[Array, " n"],
    axis: int,
    config: WeldConfig = WeldConfig(),
    weights: Float[Array, " n"] | None = None,
    *,
    one_call: bool = False,
) -> WeldFeature:
    """The weld bead crossed by one stripe (module docstring: plate, height, run, cap).

    Args:
        points: (N, 3) triangulated stripe points in the robot frame, mm, in stripe order
            (image column order for the horizontal stripe, row order for the vertical).
        valid: (N,) which points were detected (invalid rows may hold anything, even NaN).
        axis: 1 for the horizontal stripe (position = y_r), 0 for the vertical (x_r).
        config: WeldConfig.
        weights: (N,) optional prior weights of the points in the circle's and the cap
            model's fits (steps 4 and 5; None: all 1): the pipeline gives a centre that a
            clipped-core fill placed less weight (`PipelineConfig.clip_weight`); one < 0.5
            leaves the point out of the confidence's coverage count.
        one_call: run steps 1–5 as one function (`cslx.runtime.small_ops.one_function`):
            the same values; not reverse-differentiable (a while loop), so off by default.
    Returns:
        WeldFeature; jit/vmap-able, differentiable in `points` for a fixed bead run.
    """
    if axis not in (0, 1):
        raise ValueError(
            f"axis must be 0 (x_r, vertical stripe) or 1 (y_r, horizontal), got {axis}"
        )
    points, valid = _check_profile(points, valid, "stripe_feature")
    P = jnp.where(valid[:, None], points, 0.0)
    w0 = valid.astype(P.dtype)
    s_raw, z = P[:, axis], P[:, 2]
    s_mean = jnp.sum(w0 * s_raw) / jnp.maximum(jnp.sum(w0), 1.0)
    s = jnp.where(valid, s_raw - s_mean, 0.0)
    # The centre's third coordinate comes from a linear fit q(s, z) over all valid points
    # (exact for points on one laser plane); its matrix products are a library call, which
    # would keep `one_function` from compiling the rest as one function.
    q = _wls(jnp.stack([jnp.ones_like(s), s, z], -1), P[:, 1 - axis], w0, 1e-6, dot=True)
    bead = functools.partial(_bead, valid=valid, axis=axis, config=config, weights=weights)
    return one_function(bead, P, s, s_mean, q) if one_call else bead(P, s, s_mean, q)


def _bead(P, s, s_mean, q, *, valid, axis, config: WeldConfig, weights) -> WeldFeature:
    """Steps 1–5 of the module docstring on a profile prepared by `stripe_feature`."""
    dtype = P.dtype
    n = P.shape[0]
    w0 = valid.astype(dtype)
    n_valid = jnp.sum(w0)
    z = P[:, 2]

    # 1. plate, 2. plate-aligned coordinates (t along, h normal)
    (c0, c1), sigma = plate_fit(s, z, valid, config)
    norm = jnp.sqrt(1.0 + c1 * c1)
    t = (s + c1 * (z - c0)) / norm
    h = (z - c0 - c1 * s) / norm

    # 3. runs above the threshold, delimited by valid plate points
    above = valid & (h > config.threshold_mm)
    below = plate_points(t, h, valid, above, config.threshold_mm, config.min_plate_mm)
    run, run_area = _largest_run(h, above, below)
    n_run = jnp.sum(run.astype(dtype))

    # 4. circular cap, refitted with Tukey weights on its geometric residuals: the cap that
    # best explains the run, whatever a glint or a clipped core left in it
    w_run = run.astype(dtype)
    if weights is not None:  # prior weights (the cap model's below too)
        w_run = w_run * jnp.asarray(weights, dtype)
    t_run, h_run = jnp.where(run, t, 0.0), jnp.where(run, h, 0.0)
    a, b, R, rms = _circle_fit(t_run, h_run, w_run, config.n_gauss_newton)

    def robust(_, carry):
        a, b, R, rms, w = carry
        d = jnp.sqrt(jnp.maximum(jnp.square(t_run - a) + jnp.square(h_run - b), 1e-12)) - R
        d = jax.lax.stop_gradient(d)
        scale = jnp.maximum(1.4826 * _masked_median(jnp.abs(d), run), 2.0 * sigma)
        u = d / (4.685 * scale)
        w = w_run * jnp.square(jnp.clip(1.0 - u * u, 0.0, 1.0))
        ok = jnp.sum(w) >= 0.5 * config.min_points
        fit = _circle_fit(t_run, h_run, jnp.where(ok, w, w_run), config.n_gauss_newton)
        return (*fit, jnp.where(ok, w, w_run))

    a, b, R, rms, w_in = jax.lax.fori_loop(0, config.n_robust, robust, (a, b, R, rms, w_run))
    n_in = jnp.sum(jnp.where(w_in > 0.5, 1.0, 0.0))
    half2 = R * R - b * b
    height = b + R
    convex = b < jnp.sum(w_run * h) / jnp.maximum(n_run, 1.0)
    idx = jnp.arange(n)
    extent = jnp.max(jnp.where(run, t, -1e9)) - jnp.min(jnp.where(run, t, 1e9))
    width = jnp.where(half2 > 0, 2.0 * jnp.sqrt(jnp.maximum(half2, 1e-12)), extent)

    # Toes: where the run's ends cross the threshold, interpolated from the plate point
    # outside them. Their midpoint is the bead's centre on any symmetric cap whatever the
    # threshold, and it rests on the points nearest the plate, which the sheen and glints of
    # the cap (sun, glare) distort least.
    first = jnp.argmax(run)
    last = n - 1 - jnp.argmax(run[::-1])
    prev_below = jax.lax.cummax(jnp.where(below, idx, -1))[first]
    next_below = jax.lax.cummin(jnp.where(below, idx, n), reverse=True)[last]

    def cross(i_out, i_in):
        i_out = jnp.clip(i_out, 0, n - 1)
        t0, h0, t1, h1 = t[i_out], h[i_out], t[i_in], h[i_in]
        f = jnp.clip((config.threshold_mm - h0) / jnp.where(h1 > h0, h1 - h0, 1.0), 0.0, 1.0)
        return t0 + f * (t1 - t0)

    toes_mid = 0.5 * (cross(prev_below, first) + cross(next_below, last))
    # the cap model over the bead and the plate around it
    half0 = jnp.clip(0.5 * width, 0.5 * config.min_width_mm, 0.5 * config.max_width_mm)
    near = valid & (jnp.abs(t - a) < half0 + config.cap_margin_mm)
    w_cap = near.astype(dtype)
    if weights is not None:
        w_cap = w_cap * jnp.asarray(weights, dtype)
    extra = None  # points steeper than the cap's toe (`steep_points`)
    if config.cap_slope_weight != 1.0:
        extra = steep_points(t, h, valid, config.cap_slope_factor, config.cap_slope_weight)
    p_cap, _ = _cap_fit(
        jnp.where(near, t, 0.0),
        jnp.where(near, h, 0.0),
        w_cap,
        jnp.stack([a, half0, jnp.clip(height, 0.1, 10.0)]),
        sigma,
        config.n_cap,
        extra,
    )
    ok_cap = jnp.all(jnp.isfinite(p_cap)) & (jnp.abs(p_cap[0] - a) < half0)
    t_cap = jnp.where(ok_cap, p_cap[0], a)
    t_c = {"toes": toes_mid, "apex": a, "cap": t_cap}[config.centre]
    # Centre back to (s, z) and to 3-D: the third coordinate from a linear fit q(s, z) over
    # all valid points (exact for points on one laser plane).
    a = t_c
    s_c = (a - c1 * height) / norm
    z_c = c0 + (c1 * a + height) / norm
    other = 1 - axis
    q_c = q[0] + q[1] * s_c + q[2] * z_c
    pos = s_c + s_mean
    centre = jnp.zeros(3, dtype).at[axis].set(pos).at[other].set(q_c).at[2].set(z_c)

    found = (
        (run_area > 0)
        & (n_run >= config.min_points)
        & convex
        & (height >= config.min_height_mm)
        & (width >= config.min_width_mm)
        & (width <= config.max_width_mm)
        & jnp.isfinite(height)
        & jnp.isfinite(width)
    )
    # Confidence: circle-fit quality × bead contrast over the plate noise × coverage of the
    # run by detected points × share of the stripe that was detected at all.
    span = jnp.sum(
        ((idx >= jnp.argmax(run)) & (idx <= n - 1 - jnp.argmax(run[::-1]))).astype(dtype)
    )
    f_fit = 1.0 / (1.0 + jnp.square(rms / config.fit_scale_mm))
    f_contrast = 1.0 - jnp.exp(-jnp.maximum(height, 0.0) / (10.0 * sigma))
    f_cover = jnp.clip(n_in / jnp.maximum(span, 1.0), 0.0, 1.0) * jnp.clip(n_in / 15.0, 0, 1)
    f_valid = jnp.clip(n_valid / (0.5 * n), 0.0, 1.0)
    f_side = side_cover(t, valid, weights, t_cap, p_cap, half0, config)
    confidence = jnp.where(found, f_fit * f_contrast * f_cover * f_valid * f_side, 0.0)
    return _feature(found, centre, pos, width, height, confidence, sigma, dtype)


@jax.jit
def weld_features(
    profile_h: Float[Array, "w 3"],
    valid_h: Bool[Array, " w"],
    profile_v: Float[Array, "h 3"],
    valid_v: Bool[Array, " h"],
    config: WeldConfig = WeldConfig(),
    weights_h: Float[Array, " w"] | None = None,
) -> tuple[WeldFeature, WeldFeature, Bool[Array, ""]]:
    """Beads on both stripes and the T-junction flag.

    Args:
        profile_h, valid_h: the horizontal stripe's points (W, 3) (robot frame, mm, column
            order) and mask; its bead is the followed weld, position = its y_r (the offset).
        profile_v, valid_v: the vertical stripe's (H, 3) points and mask; a bead here is a
            crossing weld (`cslx.runtime.junction.crossing_feature`: found from its far
            side, beside the followed weld or along its flank), position = its x_r.
        config: WeldConfig.
        weights_h: (W,) optional weights of the horizontal stripe's points in its bead's
            circle and cap fits (`stripe_feature`).
    Returns:
        (feature_h, feature_v, junction) with junction true when the vertical stripe crosses
        a bead with confidence ≥ config.junction_min_confidence.
    """
    from .junction import crossing_feature

    fh = stripe_feature(profile_h, valid_h, HORIZONTAL_AXIS, config, weights_h, one_call=True)
    # where the stripes cross, the vertical stripe's centres are pulled by the horizontal
    # one: in rendered sunlight every stray junction report lay within 10 mm of it
    x_h = masked_median(profile_h[:, VERTICAL_AXIS], valid_h)  # = nanmedian, no sort
    away = jnp.abs(profile_v[:, VERTICAL_AXIS] - x_h) > config.crossing_mask_mm
    keep_v = valid_v & (away | ~jnp.isfinite(x_h))  # crossing: one function, sort-free
    fv = crossing_feature(profile_v, keep_v, config, one_call=True)
    junction = fv.found & (fv.confidence >= config.junction_min_confidence)
    return fh, fv, junction


@jax.jit
def weld_line_from_features(
    centres: Float[ArrayLike, "k 3"],
    weights: Float[ArrayLike, " k"],
    x_ref: Float[ArrayLike, ""] = 150.0,
    min_spread_mm: float = 5.0,
) -> WeldLine:
    """Offset and heading of the weld line through bead centres (weighted least squares).

    Fits y_r = y0 + m (x_r − x_ref) to the centres (robot frame, mm) — typically the
    horizontal stripe's bead centres of recent frames moved into the current robot frame by
    odometry, weighted by confidence (0 for frames without a bead). offset = y0, heading =
    atan(m) in degrees, CCW positive (docs/contracts.md tracking log convention). When the weighted
    spread of x_r is below `min_spread_mm` (e.g. a single frame) the heading is not
    observable: offset is the weighted mean y_r, heading NaN, heading_valid False.
    """
    c = jnp.asarray(centres)
    w = jnp.where(jnp.all(jnp.isfinite(c), -1), jnp.asarray(weights, c.dtype), 0.0)
    c = jnp.where(w[:, None] > 0, c, 0.0)
    W = jnp.maximum(jnp.sum(w), 1e-12)
    x = c[:, 0] - x_ref
    y = c[:, 1]
    xm, ym = jnp.sum(w * x) / W, jnp.sum(w * y) / W
    sxx = jnp.sum(w * jnp.square(x - xm)) / W
    sxy = jnp.sum(w * (x - xm) * (y - ym)) / W
    valid = sxx > jnp.square(min_spread_mm)
    m = jnp.where(valid, sxy / jnp.where(valid, sxx, 1.0), 0.0)
    offset = jnp.where(jnp.sum(w) > 0, ym - m * xm, jnp.nan)
    heading = jnp.where(valid, jnp.degrees(jnp.arctan(m)), jnp.nan)
    return WeldLine(offset, heading, valid)
