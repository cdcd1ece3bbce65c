"""The second pass's reference path at the bead's toes (issue 11, the p95; opt-in, off).

Why the toes are off (`experiments/toe_leak.py`, development seeds 7100–7117, frames 0–2, 54
frames; pixel error signed by the true path's curvature at its bends, |t[j+5] − 2t[j] +
t[j−5]| > 0.1 px, H / V): the first pass's path p is rounded towards the chord by its 6 px
smoothing along the image axis, +0.178 / +0.184 px at the bends (toe pool ±10 centres: mean
+0.116 / +0.127, RMS 0.201 / 0.215). Each column's own centre (`refine.refine_centres`
without the along-path average) is unbiased there, around p (+0.009 / −0.005 px at the
bends, toe mean +0.003 / −0.002) and around the ground truth (+0.005 / +0.000): the ground
truth's definition (plane ∩ surface per column) agrees with the rendered profile's
centre, Steger's σ across the stripe does not bias the kink, and the linking picks the
right ridge (errors ≈ 0.2 px, not gross). The along-path average (σ 6) around p returns
p + G∗(c − p) and keeps +0.070 / +0.072 px of the rounding at the bends (toe RMS 0.143 /
0.144), the final smoothing adds +0.016 / +0.025 (output +0.086 / +0.097; toe RMS 0.132 /
0.124, p90 of |error| 0.224 / 0.195 px). Around the true path instead: +0.013 / +0.031 after
the whole pass, toe RMS 0.084 / 0.076, p90 0.138 / 0.122. So the toes' error is the first
pass's rounding leaking through the along-path average (a little more from the final
smoothing), and a reference path without it would take ≈ 40 % off the toes' RMS.

`raw_reference` (`RAW_REFERENCE`): re-measure around the sided local-polynomial smoothing
(`path.smooth_path`, which keeps a kink) of the columns' own centres, within `RAW_CAP` px of
p. Development frames (54, `experiments/tail_structure.py`, H / V median / p95 mm, gross
centres; detection 100 / 99.90 % throughout): off 0.0269 / 0.1285, 0.0290 / 0.1342, 4 / 11;
on, c 2: 0.0264 / 0.1257, 0.0287 / 0.1328, 8 / 15 (toes' signed mean +0.040 → +0.014 /
+0.052 → +0.035 px, but their RMS 0.134 → 0.147 / 0.124 → 0.135 in a float32 replica of the
stages: the raw centres' speckle
moves the reference); c 6 (`RAW_CORRELATION`): 0.0266 / 0.1259, 0.0288 / 0.1339, 4 / 12
(glare H gross 0 → 3, V 0 → 2; sunny V 11 → 10). 1–2 % off the p95 with more gross
centres, as the earlier attempts at the toes (`robust.REFINE_PASSES`), so it stays off.
On a synthetic parabola with a bend and little noise it is worse than the rounded first pass
(0.33 against 0.12 px at the bend, tests/segmentation/test_refine.py): there the path's
scatter (a second difference) measures the curvature, and the windows grow over the bend.
Also measured and not kept: a Gaussian local quadratic instead of the Gaussian mean along
the path (equivalent kernel G(3 − t²/σ²)/2, which follows a curved offset; synthetic kink
of slope change 0.2 rounded by G 6: leak 0.278 → 0.203 px at σ 6, noise × 1.32): 0.0294 /
0.1397, 0.0287 / 0.1490, gross 16 / 10 (a kink is not a quadratic; the noise dominates);
an unsharp reference p + α(p − G∗p) (synthetic: leak 0.279 → 0.233 px at α 1, σ 6).
"""

from __future__ import annotations

import jax.numpy as jnp

__all__ = ["RAW_CAP", "RAW_CORRELATION", "RAW_REFERENCE", "raw_reference"]

#: Re-measure around the smoothed per-column centres instead of the first pass's path (off).
RAW_REFERENCE = False
#: Largest move (px) of the reference from the first pass's path.
RAW_CAP = 1.0
#: The smoothing's correlation c (`path.smooth_path`) for the per-column centres.
RAW_CORRELATION = 2.0


def raw_reference(mono, pos, use, *, sigma: float, axis: int):
    """The reference path of the re-measurement (module docstring): each column's own centre
    (`refine.refine_centres` with no along-path average, so none of the first pass's rounding
    at a toe passes), smoothed by the sided local polynomials that keep a kink
    (`path.smooth_path`), within `RAW_CAP` px of `pos`; `pos` where not `use`."""
    from .path import smooth_path
    from .refine import LINES, REFINE_HALVES, refine_centres
    from .ridges import PATH_HALF_WINDOW, _path_scatter

    raw, found = refine_centres(mono, pos, use, sigma=sigma, sigma_along=0.0, axis=axis)
    ok = use & found
    raw = jnp.where(ok, raw, jnp.nan_to_num(pos))
    scatter = _path_scatter(raw, ok, 2 * PATH_HALF_WINDOW)
    kw = dict(correlation=RAW_CORRELATION, halves=REFINE_HALVES, sided=True, lines=LINES)
    ref = smooth_path(raw, use, scatter, support=ok, **kw)[0]
    ref = pos + jnp.clip(jnp.nan_to_num(ref - pos), -RAW_CAP, RAW_CAP)
    return jnp.where(use, ref, pos)
