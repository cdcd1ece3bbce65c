"""The crossing weld of a T-junction on the vertical stripe, for any placement of the cross.

The vertical stripe runs along x_r. Approaching a T, the crossing weld (the bar) lies across
it; what lies on the stripe before the bar depends on where the cross sits relative to the
followed weld (the stem):

- beside the weld (the default rig: 40 mm to its right), bare plate: the bar is a cap bounded
  by plate on both sides;
- along the stem's flank: the flank's height (anything from the crown to the toe, changing
  with the heading) up to the bar, and the bar's cap on top of it.

Beyond the bar (larger x_r, towards the end of the stem) there is plate in both cases. So the
bar is found from its far side (cslx's own rule). Heights are taken above the plate line
(`plate_fit`) less the lowest point within `WeldConfig.crossing_background_mm` beyond each
point: where the stripe runs mostly on the flank the plate line sits on the flank, and the
bar, measured against that line, came out 0.9–1.0 mm high (true 1.91, dev seed 1202), while
against the plate just past its far toe it is measured whole and a bump on the flank only
against the flank beyond it. Every run of points above the
threshold whose far end (largest x_r) is bounded by plate is a candidate; within half the
largest bead width of that far toe, its highest point is the bar's apex if the profile falls
from it towards the toe by the apex height and rises to it from the near side (the flank of
a stem that the stripe leaves slowly has no such apex); the cap model
(`cslx.runtime.weld._cap_fit`) is fitted to the points from just before the apex to beyond
the toe, and its centre is the junction's x_r. Of the candidates the highest apex wins.

The ramp test (issue 12, `WeldConfig.crossing_ramp_max`): where the vertical stripe crosses
the followed bead at a shallow angle (the cross near the bead's toe: the rig's 6° between
the stripe and x_r and the ±3.5° heading wobble of the rendered approaches make 0.1–0.3 mm
across the bead per mm along the stripe), it climbs the near flank, runs over the crown and
off the far flank onto the plate over 25–70 mm. Against the lowest point within the
background length beyond, every point of that falling stretch stands ≈ its slope ×
`crossing_background_mm` high, ≈ 1 mm on the rendered beads, and noise gives it an apex that
passes the rise test: the false T frames of `experiments.tracking_generality`'s
``cross_toe`` (fresh seed 7400: 7 clean, 12 sunny) were such run-offs 20–30 mm before the
bar (1.0–1.7 mm high, 21–36 mm wide). There the plate-line height keeps rising towards the
near side: its mean within ±`RAMP_HALF_MM` one background length before the apex exceeds
the mean at the apex by about the apex height, while before a bar it is lower (plate, or a
flank below the bar's cap) or level (the stem's crown); an apex fails where the excess is
over `crossing_ramp_max` × its height (no points there: no test). Evidence, the rendered
``cross_toe`` approaches (fresh seeds 7400–7420, 40 frames, clean / sunny;
`experiments.junction_ramp` replays the detector on each frame's recorded points, which
reproduced the tracker's sightings and T scores exactly): false T frames 14 → 7 clean and
33 → 5 sunny (the rest, where looked at: bar sightings 3–6 mm short at 7402 and 7406 clean,
and at 7410 sunny a run-off that falls steeply from a plateau, which looks like a stem
ending at a bar); T recall unchanged but at 7411 sunny, 72.7 → 50.0 %, where the bar sits
at the foot of the stem's run-off and two of its sightings fail. The other audit conditions
(base, cross on the flank and crown, T at 60° and 120°; fresh seeds 7400–7402) and 51
development runs (seeds 1201–1206, 7301–7302, 7320–7327, both placements, every nuisance)
are unchanged in every T score. Confirmed on fresh seeds 7440–7445 (not used to choose it;
12 runs): false T frames 5 → 0, T recall unchanged. 0.6: 14 / 21 false frames (clean /
sunny); 0.3 (seeds 7400–7410) also cleared 7410 sunny but lost bar sightings at 7406
(recall −4.3 % clean and sunny, one more false frame). The false T's of dev seed 1205
(flank, glare and sunny) are another mechanism and stay (glare frame 12: corrupt points dip
to z_r ≈ −3 mm past the bump, so that it stands high above the far side).

The run-off test (issue 12, `WeldConfig.crossing_bump_mm`, `crossing_cap_max`): where the
vertical stripe runs along the followed bead's flank, the heading's wobble takes it off the
flank onto the plate 20–50 mm before the bar. That run-off is a step from bead height to the
plate, not a bump: there is no plate on its near side. Sun cuts its points and glare adds
ripples and dips below the plate past it, so that, measured against the lowest point beyond,
it passed the rise and ramp tests and stood higher than the bar (dev seed 1205, cross on the
flank, glare frames 16–17: the run-off at x_r 159–160 mm, 2.6–2.7 mm high, won over the bar
at 208 mm, 2.5–2.8 mm). Each candidate is therefore also asked whether it is bounded by plate
on its near side: a point within its apex-to-toe distance + `cap_margin_mm` before its apex
at most `threshold_mm` above the mean plate-line height over `cap_margin_mm` past its far toe.
A candidate that is not (a step) is dropped where a bounded candidate at least
`crossing_bump_mm` high (the tracker's own minimum sighting height,
`KalmanConfig.junction_min_height_mm`, 1 mm) ends farther along the stripe: the crossing weld
ends the followed weld, so a step nearer than a bead with plate on both sides is the stem's
run-off. A step with no such bump beyond it still competes (a bar on the stem's flank, where
the flank reaches the bar, has no plate before it either). And a fitted cap taller than
`crossing_cap_max` × its half width is no bead (a circular cap is at most a half disc;
`cslx.sim.render.make_world` requires height ≤ width / 2): 1205 flank sunny frames 7–8 fitted
8.2 and 10.7 mm high caps 8.5 and 5.9 mm wide to stray sunlit points past a cut run-off.
Evidence, `experiments.junction_runoff` (the detector replayed on each frame's recorded
vertical-stripe points; the replay without both tests reproduced the tracker's T scores on
every run), dev seeds 7301, 7302, 7305, 1201–1206, 7740–7743, T recall % / false T frames:
flank (52 runs) runs missing a T goal 5 → 4, false T frames 30 → 20; changed 1205 glare
81.8 / 14 → 90.9 / 11, 1205 sunny 93.9 / 7 → 100 / 0 (the cap test alone: 93.9 / 0), 1201
sunny 96.9 / 0 → 100 / 0. Beside (40 runs; 1204–1206 not run) 3 → 5 runs missing, false
frames 4 → 6: 1203 shadow 100 / 0 → 96.9 / 1, 7743 shadow 100 / 0 → 96.7 / 1, 7741 glare
96.7 / 1 → 93.3 / 1 (the shadow frames looked at lost their bar sighting: the bar, not
plate-bounded there, lost to a farther candidate that then found nothing). The same
with `crossing_bump_mm` 0.8 or 1.2 and `crossing_cap_max` 0.8. One check on fresh seeds
7960–7963 (never used before; 32 runs, both placements, every nuisance): runs missing a T
goal 3 → 2, false T frames 9 → 3, mean recall 98.94 → 99.67 %; 7963 flank glare 76.7 / 0 →
100 / 0, 7960 flank glare 92.9 / 8 → 92.9 / 2, no other run changed. Still missing, other
mechanisms: 1205 flank glare's 11 false frames (sightings on the stem before the bar is in
view, where no bar is there to win), 7743 flank glare (the bar's sightings 3 mm far while it
enters the view), 7740 flank sunny (no sightings on its last frames). Not taken: ranking
every bounded candidate above every step (a 0.6–0.9 mm bump on the flank or on the plate
beyond outranked the bar on the flank: 40 of 52 flank runs missed recall); dropping steps
altogether (49 of 52 missed); the bump at least half the step's height (glare's stray
points lift the step's apex: 1205 flank glare recall 87.9 %); a missing near side counted
as plate (the three beside runs above unchanged).

Both tests are off by default (the fields inf; the program then computes neither): on a clean
rendered still frame (tests/runtime/test_tracker.py, `render_scenes` seed 41, the second
frame, a cross, true bar at x_r 203.3 mm) the run-off test dropped the bar for a farther
plate-bounded candidate (its only effect) and no T was confirmed in three sightings; with
``crossing_bump_mm`` inf the T is reported at 204.9 mm, and the cap test alone changes
nothing there. A step on the stem's flank reaching the bar is the case the
test cannot tell from a run-off; until it can, the detector is as before this test, and the
figures above are what the option gives.

The apex tests run on the first `MAX_TOES` toes rather than on every point (a 16 × 480
instead of a 480 × 480 comparison, twice): `crossing_feature` 1.23 → 0.76 ms in an
interleaved A/B run at load ≈ 20 (issue 13), with identical features on 84 rendered
frames; a profile with more toes takes the tests on every point (`lax.cond`).

In the tracking program (`cslx.runtime.weld.weld_features`) everything after the order along
x_r runs as one compiled function (``one_call``; `cslx.runtime.small_ops.one_function`):
the apex tests take one toe at a time and the full far-side search one point at a time,
since a (toe, point) or (point, point) array's float minima went to XLA's library
reductions, which keep a loop from compiling as one function; and the order comes without
a sort where x_r rises or falls along the rows (`_x_order`). Issue 13, `experiments.ab_weld`
(200 tracking frames each of the sunny and glare videos, seeds 0 and 555, 600 interleaved
calls, load 6.5): weld features 0.715 → 0.614 ms median, outputs identical bit for bit;
tracking mode with MED (`experiments.ab_tracking`, 300 interleaved frames, load 5.8) 4.13 →
3.97 ms median, outputs identical.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from ..reductions import first_argmax
from .small_ops import one_function
from .weld import (
    VERTICAL_AXIS,
    WeldConfig,
    WeldFeature,
    _cap_fit,
    _check_profile,
    _feature,
    plate_fit,
)

__all__ = ["crossing_feature"]


#: Toes whose apex test runs on the short path of `crossing_feature` (more take the long one).
MAX_TOES = 16


def _first_indices(mask: Bool[Array, " n"], k: int) -> Array:
    """Indices of the first ``k`` true entries of ``mask`` in order, ``n`` past the last."""
    n = mask.shape[0]
    rank = jnp.cumsum(mask.astype(jnp.int32))  # 1-based rank of each true entry
    slot = jnp.arange(1, k + 1, dtype=jnp.int32)
    hit = mask[None, :] & (rank[None, :] == slot[:, None])
    return jnp.min(jnp.where(hit, jnp.arange(n)[None, :], n), axis=1)


def _window_mean(t, v, ok, centre, half: float):
    """Mean of ``v`` over the ``ok`` points with |t − centre| ≤ ``half``, and whether any."""
    m = ok & (jnp.abs(t - centre) <= half)
    n = jnp.sum(m.astype(v.dtype))
    return jnp.sum(jnp.where(m, v, 0.0)) / jnp.maximum(n, 1.0), n > 0


#: Half-length (mm) of the stretches whose mean plate-line height the ramp test compares.
RAMP_HALF_MM = 2.0


def _best_apex(rows, toe, t, h, ok, nxt_c, config: WeldConfig, hp=None):
    """The highest apex among the candidate toes ``rows`` (indices; ``n`` = no toe).

    For each toe: its apex (the highest point within half the largest bead width before
    it), the toe's position and the tests of `crossing_feature`'s docstring; with ``hp``
    (heights above the plate line), the ramp test too. Returns (index
    of the best toe's apex, apex t, toe t, apex height, whether any toe passed);
    the first of equal toes wins, as an arg-max over all points picks it. Where no toe
    passed, nothing is found and the values only feed outputs that `_feature` masks.
    """
    n = t.shape[0]
    live = rows < n
    r = jnp.clip(rows, 0, n - 1)
    half_max = 0.5 * config.max_width_mm

    def one_toe(i):
        dt = t - t[i]  # point's t minus the toe's t
        apex, _ = first_argmax(jnp.where(ok & (dt <= 0.0) & (dt >= -half_max), h, -jnp.inf))
        t_apex = t[apex]
        half = 0.5 * (t[i] + t[nxt_c[i]]) - t_apex
        # rises to the apex from the near side: the lowest point in the half-width before it
        near = ok & (t < t_apex) & (t >= t_apex - half)
        # the ramp test: plate-line height one background length before the apex less at it
        if hp is None:
            ramp = jnp.asarray(-jnp.inf, h.dtype)
        else:
            z_apex, at_apex = _window_mean(t, hp, ok, t_apex, RAMP_HALF_MM)
            back = t_apex - config.crossing_background_mm
            z_back, at_back = _window_mean(t, hp, ok, back, RAMP_HALF_MM)
            ramp = jnp.where(at_apex & at_back, z_back - z_apex, -jnp.inf)
        # the run-off test: plate on the near side too, i.e. a point within the apex-to-toe
        # distance + `cap_margin_mm` before the apex at most `threshold_mm` above the mean
        # plate-line height over `cap_margin_mm` past the far toe
        if hp is None or not math.isfinite(config.crossing_bump_mm):
            bounded = jnp.asarray(True)
        else:
            t_toe = 0.5 * (t[i] + t[nxt_c[i]])
            m = config.cap_margin_mm
            far, at_far = _window_mean(t, hp, ok, t_toe + 0.5 * m, 0.5 * m)
            reach = ok & (t < t_apex) & (t >= 2.0 * t_apex - t_toe - m)
            low_near = jnp.min(jnp.where(reach, hp, jnp.inf))
            bounded = at_far & (low_near <= far + config.threshold_mm)
        return apex, jnp.min(jnp.where(near, h, jnp.inf)), jnp.any(near), ramp, bounded

    # one toe at a time: a (toe, point) array's float minima and maxima went to XLA's
    # library reductions, which keep the caller's loop from compiling as one function
    apex, h_before, has_near, ramp, bounded = jax.lax.map(one_toe, r)
    h_apex = h[apex]
    t_apex = t[apex]
    t_toe = 0.5 * (t[r] + t[nxt_c[r]])  # between the last bead point and the first plate point
    half = t_toe - t_apex
    rise = h_apex - jnp.where(has_near, h_before, h_apex)
    good = (
        live
        & toe[r]
        & (h_apex >= config.min_height_mm)
        & (2.0 * half >= config.min_width_mm)
        & (2.0 * half <= config.max_width_mm)
        & (rise >= 0.15 * h_apex)
        & (ramp <= config.crossing_ramp_max * h_apex)
    )
    # a step (no plate before it) nearer than a good bump at least crossing_bump_mm high
    # is the followed bead's run-off, not the bar (module docstring, "run-off test")
    if math.isfinite(config.crossing_bump_mm):
        bump = good & bounded & (h_apex >= config.crossing_bump_mm)
        far_bump = jnp.max(jnp.where(bump, t_toe, -jnp.inf))
        good = good & (bounded | (t_toe >= far_bump))
    k = jnp.argmax(jnp.where(good, h_apex, -jnp.inf))
    return apex[k], t_apex[k], t_toe[k], h_apex[k], jnp.any(good)


#: Points after each one that `_above_far_side` searches on its short path (more: the long one).
FAR_BAND = 64


def _far_low(t, h, ok, width, band: int):
    """Lowest h among the points j ≥ i, j < i + ``band`` with 0 ≤ t_j − t_i ≤ ``width``, per i.

    The same comparisons and minimum as over every j, restricted to ``band`` shifted copies
    (an (n, band) rather than an (n, n) array); ``band`` = n is the full search.
    """
    n = t.shape[0]
    if band >= n:  # one point j at a time (a loop, no (n, n) array: see `_best_apex`)

        def point(j, low):
            dt = t[j] - t
            keep = ok[j] & (dt >= 0.0) & (dt <= width)
            return jnp.minimum(low, jnp.where(keep, h[j], jnp.inf))

        return jax.lax.fori_loop(0, n, point, jnp.full((n,), jnp.inf, h.dtype))
    pad = lambda x, v: jnp.concatenate([x, jnp.full((band,), v, x.dtype)])  # noqa: E731
    tp, hp, okp = pad(t, jnp.inf), pad(h, jnp.inf), pad(ok, False)
    low = jnp.full((n,), jnp.inf, h.dtype)
    for d in range(band):
        dt = jax.lax.slice_in_dim(tp, d, d + n) - t
        keep = jax.lax.slice_in_dim(okp, d, d + n) & (dt >= 0.0) & (dt <= width)
        low = jnp.minimum(low, jnp.where(keep, jax.lax.slice_in_dim(hp, d, d + n), jnp.inf))
    return low


def _above_far_side(
    t: Float[Array, " n"], h: Float[Array, " n"], ok: Bool[Array, " n"], width: Float[Array, ""]
) -> tuple[Float[Array, " n"], Float[Array, " n"]]:
    """Height above the lowest point within ``width`` beyond (larger ``t``; cslx's own rule).

    Beyond the bar there is plate in every placement, so the bar's apex is measured against
    the plate just past its far toe, and a bump on the followed bead's flank against the flank
    beyond it, rather than both against one plate line (which sits on the flank where the
    stripe runs mostly on it). ``width`` ≤ 0 returns ``h``.

    Where t rises strictly along the valid points (they are sorted by x_r, and the plate's
    tilt is small) and the first valid point ``FAR_BAND`` or more places after each one lies
    more than ``width`` beyond it, every point within ``width`` beyond point i is among the
    ``FAR_BAND`` after it, and the search runs there alone (`_far_low`, the same values);
    otherwise over every point (`lax.cond`). The rendered vertical stripe holds ≈ 50 points
    in 12 mm (0.255 mm a row, sunny video seed 0).
    """
    n = t.shape[0]
    if n > FAR_BAND:
        idx = jnp.arange(n)
        # strictly rising: each valid t above every valid t before it
        before = jax.lax.cummax(jnp.where(ok, t, -jnp.inf))
        before = jnp.concatenate([jnp.full((1,), -jnp.inf, t.dtype), before[:-1]])
        rising = jnp.all(~ok | (t > before))
        # the first valid point FAR_BAND or more places after each one lies beyond width
        first_ok = jax.lax.cummin(jnp.where(ok, idx, n), reverse=True)
        j = jnp.concatenate([first_ok[FAR_BAND:], jnp.full((FAR_BAND,), n, first_ok.dtype)])
        t_far = t[jnp.clip(j, 0, n - 1)]
        short = jnp.all(~ok | (j >= n) | (t_far - t > width))
        low = jax.lax.cond(
            rising & short,
            lambda: _far_low(t, h, ok, width, FAR_BAND),
            lambda: _far_low(t, h, ok, width, n),
        )
    else:
        low = _far_low(t, h, ok, width, n)
    low = jnp.where((width > 0.0) & ok & jnp.isfinite(low), low, 0.0)
    return h - low, low


def _monotone_order(key: Float[Array, " n"], valid: Bool[Array, " n"]):
    """(``jnp.argsort(key)``, True) where the valid keys rise or fall strictly along the
    profile, without a sort; (anything, False) otherwise. Invalid keys are +inf.

    The stable order is then the valid points in index order (rising) or in reverse
    (falling), followed by the invalid ones in index order; the k-th valid point is the first
    index where the running count of valid points reaches k (a binary search, exact).
    """
    n = key.shape[0]
    j = jnp.arange(n, dtype=jnp.int32)
    inf = jnp.full((1,), jnp.inf, key.dtype)
    low = jnp.concatenate([inf, jax.lax.cummin(key)[:-1]])  # least valid key before each
    high = jnp.concatenate([-inf, jax.lax.cummax(jnp.where(valid, key, -jnp.inf))[:-1]])
    rising = jnp.all(~valid | (key > high))
    falling = jnp.all(~valid | (key < low))
    n_valid = jnp.sum(valid.astype(jnp.int32))
    count_valid = jnp.cumsum(valid.astype(jnp.int32))
    count_invalid = jnp.cumsum((~valid).astype(jnp.int32))
    k_valid = jnp.where(rising, j + 1, n_valid - j)
    first = functools.partial(jnp.searchsorted, side="left", method="scan")
    order = jnp.where(
        j < n_valid, first(count_valid, k_valid), first(count_invalid, j - n_valid + 1)
    )
    return order.astype(jnp.int32), rising | falling


def _x_order(key, valid, one_call: bool):
    """``jnp.argsort(key)`` (stable), sort-free where the valid keys are monotone (rendered
    vertical stripe: x_r falls along the rows on 390 of 400 frames, sunny video seeds 0 and
    555); XLA's CPU sort of 480 keys took ≈ 50 µs (a comparator call per comparison)."""
    fast, monotone = (
        one_function(_monotone_order, key, valid) if one_call else _monotone_order(key, valid)
    )
    return jax.lax.cond(monotone, lambda: fast, lambda: jnp.argsort(key).astype(jnp.int32))


def crossing_feature(
    points: Float[Array, "n 3"],
    valid: Bool[Array, " n"],
    config: WeldConfig = WeldConfig(),
    *,
    one_call: bool = False,
) -> WeldFeature:
    """The crossing bead on the vertical stripe, found from its far side (module docstring).

    Args:
        points: (H, 3) robot-frame points of the vertical stripe (mm), any order along it.
        valid: (H,) which points exist.
        config: `cslx.runtime.weld.WeldConfig` (threshold, height and width limits, cap fit).
        one_call: run everything after the sort along x_r as one function
            (`cslx.runtime.small_ops.one_function`): the same values; not
            reverse-differentiable (a while loop), so off by default.
    Returns:
        `WeldFeature` with position = the crossing weld's x_r; jit/vmap-able.
    """
    points, valid = _check_profile(points, valid, "crossing_feature")
    P = jnp.where(valid[:, None], points, 0.0)
    # sort along x_r (far = large x) so that runs and toes do not depend on the row order
    key = jnp.where(valid, P[:, VERTICAL_AXIS], jnp.inf)
    order = _x_order(key, valid, one_call)
    rest = functools.partial(_crossing, config=config)
    return one_function(rest, P, valid, order) if one_call else rest(P, valid, order)


def _crossing(P, valid, order, *, config: WeldConfig) -> WeldFeature:
    """`crossing_feature` on a profile ``P`` (zero where not ``valid``) and its x_r order."""
    dtype = P.dtype
    n = P.shape[0]
    w0 = valid.astype(dtype)
    n_valid = jnp.sum(w0)
    x_raw, z = P[:, VERTICAL_AXIS], P[:, 2]
    x_mean = jnp.sum(w0 * x_raw) / jnp.maximum(n_valid, 1.0)
    x = jnp.where(valid, x_raw - x_mean, 0.0)[order]
    z = z[order]
    ok = valid[order]
    (c0, c1), sigma = plate_fit(x, z, ok, config)
    norm = jnp.sqrt(1.0 + c1 * c1)
    t = (x + c1 * (z - c0)) / norm
    hp = (z - c0 - c1 * x) / norm  # height above the plate line
    h, level = _above_far_side(t, hp, ok, config.crossing_background_mm)

    above = ok & (h > config.threshold_mm)
    below = ok & ~above
    idx = jnp.arange(n)
    # far toe of each run: an above point whose next valid point (larger x) is plate
    next_valid = jax.lax.cummin(jnp.where(ok, idx, n), reverse=True)
    nxt = jnp.concatenate([next_valid[1:], jnp.full((1,), n)])
    nxt_c = jnp.clip(nxt, 0, n - 1)
    toe = above & (nxt < n) & below[nxt_c]

    # the apex tests of every toe, on the first MAX_TOES toes only: the same values (more
    # toes than that, seen on no rendered frame, take the tests on every point as before)
    def tests(rows):
        return _best_apex(rows, toe, t, h, ok, nxt_c, config, hp)

    if n > MAX_TOES:
        n_toes = jnp.sum(toe.astype(jnp.int32))
        rows = _first_indices(toe, MAX_TOES)
        apex, ta, tt, hb, any_good = jax.lax.cond(
            n_toes <= MAX_TOES, lambda: tests(rows), lambda: tests(idx)
        )
    else:
        apex, ta, tt, hb, any_good = tests(idx)

    # the cap model on the far half of the bar and the plate beyond it
    hw = jnp.maximum(tt - ta, 0.5 * config.min_width_mm)
    sel = ok & (t >= ta - 0.25 * hw) & (t <= tt + config.cap_margin_mm)
    p, wr = _cap_fit(
        jnp.where(sel, t, 0.0),
        jnp.where(sel, h, 0.0),
        sel.astype(dtype),
        jnp.stack([ta, hw, hb]),
        sigma,
        config.n_cap,
    )
    a, c, H = p[0], jnp.abs(p[1]), jnp.abs(p[2])
    width, height = 2.0 * c, H
    fit_ok = jnp.all(jnp.isfinite(p)) & (jnp.abs(a - ta) < hw)
    found = (
        any_good
        & fit_ok
        & (height >= config.min_height_mm)
        & (width >= config.min_width_mm)
        & (width <= config.max_width_mm)
    )
    if math.isfinite(config.crossing_cap_max):
        found = found & (height <= config.crossing_cap_max * 0.5 * width)
    # back to (x, z): the apex of the cap
    x_c = (a - c1 * height) / norm
    z_c = c0 + (c1 * a + height + level[apex]) / norm
    pos = x_c + x_mean
    y_c = jnp.sum(jnp.where(sel, P[order, 1], 0.0)) / jnp.maximum(jnp.sum(sel), 1.0)
    centre = jnp.stack([pos, y_c, z_c]).astype(dtype)
    # confidence: share of the far half-cap's points the fit kept × contrast over the noise
    n_sel = jnp.sum(sel.astype(dtype))
    kept = jnp.sum(jnp.where(wr > 0.5, 1.0, 0.0)) / jnp.maximum(n_sel, 1.0)
    f_contrast = 1.0 - jnp.exp(-jnp.maximum(height, 0.0) / (10.0 * sigma))
    f_points = jnp.clip(n_sel / 15.0, 0.0, 1.0)
    confidence = jnp.where(found, kept * f_contrast * f_points, 0.0)
    return _feature(found, centre, pos, width, height, confidence, sigma, dtype)
