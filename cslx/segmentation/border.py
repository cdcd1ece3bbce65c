"""A turned stripe leaving the frame across its search axis: centres up to the border.

A stripe turned against the image axes (a rolled cross) leaves the frame across its search
axis: a 45° horizontal stripe meets the top or bottom border, and its last columns' profiles
are cut there. The smoothing across (σ, symmetric padding) merges the cut profile with its
mirror image into one ridge on the border, so the first pass has no candidate for the last
σ_t or so (saturated, σ 6: the 6–12 px next to the border), and `crossing` drops what is
within `crossing.EDGE` of it and interpolates what is within `crossing.CUT_WIDTHS` σ_t.
Diagnosis (rig roll45 of `experiments.ood_extraction`, development seeds 7583–7585, frames
0–7, both stripes; misses and gross centres by region): of 35–136 lost centres a condition
and stripe, 76–100 % lay within 12 px of the border across (clean H 37 of 38, V 39 of 46;
saturated H 102 of 121, V 119 of 124), the rest at the fan's ends inside the frame (H, 1–19),
on the border along (V, 0–15) and on clipped pixels (V sunny / saturated, 5–7).

`extend` sets, at each end of the path, the centres closer than `FIT_WIDTHS` σ_t + `FIT_PX`
to the border across (σ_t from the final pass's σ and measured width) by a line (`FIT_DEG`,
below) through the next `FIT_LEN` centres inside, out to the border (`MARGIN`: the outer
pixels' edge, half a pixel past their centres), where:
- the fit's slope is at least `MIN_SLOPE` (the stripe meets the border obliquely; an aligned
  stripe's ends are left alone, so the default rig's frames do not change);
- the fit meets the border within `REACH` × that distance of its support (a path ending far
  from the border is a fan's end, `ends` and `orient.trim_ends` handle those), and before the
  frame's end along: a path that ends at the border along has whole profiles there (before
  this check, roll35/saturated H 7809/3 was followed 60–70 px from the border across over
  the 11 columns next to the left border, 8 gross centres: the support's slope 0.74, the
  truth's ≈ 0.6) — unless the line is then still within the cut zone of the border across
  (`CORNER`: the stripe leaves by a corner, its last profiles cut as well);
- the path's own centres nearer the border lie within `ZONE_TOL` px of the fit (median): a
  surface corner between the support and the border (roll35/saturated V, seed 7577, frames
  1, 3 and 7: slope 0.75 inside, 0.52 beyond row 61) put the extrapolation 1–3.4 px off, 15–17
  gross centres a frame; the gate leaves such an end as it was (0.5 px caught two of the three
  frames); it is what makes the line safe: without it the line set 17 gross centres on clean V
  frames 3 and 7 (the stripe bends there, a surface's, not the lens's: the truth's quadratic
  term over those supports 2.5–3.6e-3 px per centre², the median end's 1.7e-5);
- each centre's image (bilinear, the second pass's monochrome image) is at least
  `LIT_SHARE` × the support's median, or a clipped pixel left unfilled (a clipped run that
  touches the border has no second flank to fill it from: a hole in R − G); the first dark
  one ends the stripe (its fan ends before the border), and path centres beyond are dropped;
- the image agrees with the line (`_measured`, `MEASURE_TOL`, `MEASURE_WINDOW`): on the
  profiles along the stripe's search axis, parallel to the border and so whole where the
  profiles across are cut, a half-maximum centroid gives the stripe's position at each
  centre; where the mean offset over a window of 12 leaves the line by > 1.5 px, the
  extension ends at the window's start. A single centre's offset is too noisy to gate by (a
  median 0.28 px, p90 0.75 px, where the line was right), the window's mean is not. It sees
  the bend the zone test cannot: on roll45/saturated V 7808/3 the truth turns ≈ 26 rows
  before the border (slope 0.82 → 0.67) and the path's own centres there follow the straight
  trend (smoothed along the path), so the zone test passed and the line set 14 gross centres,
  up to 2.7 px off. Cost: `extend` 14.6 → 25.5 ms a stripe (median over the 80
  development frame-stripes of 7576–7577 and 7583–7585, load ≈ 9).
The centres set keep their σ where larger, else the path's median σ; new ones get the
path's median strength.

Why a line, not a quadratic (`FIT_DEG`; branch border11b). The fit is extrapolated k centres
beyond a support of L = `FIT_LEN`: a bias δ on the support (the cut or sunny profile shifts
the path's centres by 0.1–0.3 px, smoothly) grows at the border by ≈ (1 + 2k/L) for a line and
≈ (1 + 2k/L)² and more for a quadratic, whose curvature then fits the bias, not the stripe.
The quadratic added 30 gross centres on 7 of the 160 development frame-stripes (seeds
7576–7577, 7583–7585, 7800–7804, frames 0–7; 0.6–15 px from the border, 0.9–3.7 px off): where
the truth is straight, the line through the same support was 0.02–0.4 px off (roll35/sunny V
7576/3: quadratic 1.20 px, line 0.02 px at k = 27; roll45/saturated H 7585/1: 1.7 vs 0.4 px at
k = 22); where the truth bends beyond the path's centres (roll35/saturated V 7577/5, k 36–44;
roll45/saturated V 7802/1), the line's zone test rejects the end the quadratic's passed. The
truth is nearly straight at most ends: over the 205 qualifying ends (slope, support) of those
frames the median |quadratic term| of the true centres is 1.7e-5 px per centre², and a line
through them meets the truth at the border within 0.01 px (median); the ends that do bend (10
%, by ≥ 1.1 px: surface corners, T-junctions) are the zone test's. Tried, not kept (seeds
7576–7577 and 7583–7585, frames 0–7; gross added, detection against the line's): the quadratic
with its extrapolation cut where it leaves the line by > 0.5 px (0 added, 0–0.9 % less), or
within 0.5 / 0.7 × L of the support (0 / 1 added, 0.1–4.1 % less), or a zone test on the
zone's 5 centres nearest the border (roll35/saturated V still 5 → 11); a 60-centre support
(roll45/saturated H 0 → 3); the line with the 0.5 px cut, the 5-centre zone test at 0.15 px or
a zone of ≥ 3 centres required (also 7800–7804: 0 added either way, 0–1.4 % less); a centre
re-measured on the image along the border-parallel axis (a half-maximum centroid of the raw
image's column at the extrapolated position: 0.28 px median disagreement on centres whose fit
was within 0.3 px, too noisy to gate by).

The line alone added fewer gross centres than the quadratic but not none (development 78 →
14, all on 7808/3 V; held out 33 → 30 and 18 → 9): where the truth bends before the border,
the path's own centres there are smoothed onto the straight trend and the zone test passes;
the check against the image along the border (above) takes those (development 14 → 0). With
it, on held-out seeds never looked at before (7870–7874, frames 0–3), 0 gross centres added
in all 10 condition-stripes and detection up in each (e.g. roll45/saturated H 96.79 → 99.71 %,
V 95.36 → 99.77 %); on the two earlier held-out sets 1 added (roll45/saturated V 7862/3, a
centre 0.1 px from the border 1.0 mm off). So `robust.BORDER` is on.

Evidence: the module docstring of `experiments/ood_extraction.py`.
"""

from __future__ import annotations

import numpy as np

__all__ = ["FIT_WIDTHS", "MIN_SLOPE", "extend"]

#: Centres closer than `FIT_WIDTHS` σ_t + `FIT_PX` (px across) to the border are replaced by
#: the line through the path's centres beyond that distance (`FIT_LEN` of them).
FIT_WIDTHS = 2.5
FIT_PX = 2.0
FIT_LEN = 30
FIT_DEG = 1
#: Largest median distance (px) of the path's own centres nearer the border from the fit.
ZONE_TOL = 0.3
#: Smallest |slope| (px across per centre) of that line: a stripe that meets the border
#: obliquely (`crossing.MIN_SLOPE`).
MIN_SLOPE = 0.22
#: An extrapolated centre needs the image at it ≥ `LIT_SHARE` × the median at the support's
#: centres (the stripe is there, not past its fan's end).
LIT_SHARE = 0.5
#: The line must meet the border within `REACH` × that distance (px across) of the support.
REACH = 2.0
#: The line is followed while it lies at least `MARGIN` px inside the outer pixel centres
#: across: −0.5 is the outer pixels' edge, where the image (and the truth of `cslx.sim`)
#: ends. At 0 the last centre an end, inside the outer pixel, was lost (−0.5 recovers 42 of
#: the 221 lost on the 80 development frame-stripes of `experiments.roll_losses`, seed
#: 7800, frames 0–3; no gross centre added).
MARGIN = -0.5
#: The frame's end along may come first where the line is then within `CORNER` × the cut
#: zone (`FIT_WIDTHS` σ_t + `FIT_PX`) of the border across: the stripe leaves by a corner
#: (same frames: 39 lost in 5 ends, e.g. roll35/saturated V 7802/0 rows 0–16, 2–10 px from
#: the border across). 0: the line must leave the frame across first. The path that ended
#: at the border along 60–70 px inside (7809/3 H, the check's reason) stays refused.
CORNER = 1.0
#: The extension ends where the stripe measured on the profiles along the border
#: (`_measured`) lies, on average over `MEASURE_WINDOW` centres, more than `MEASURE_TOL` px
#: across from the line (a bend the path's smoothed centres hide).
MEASURE_TOL = 1.5
MEASURE_WINDOW = 12


def _sample(img, j, p):
    """img[j, p] (axis 0 along, axis 1 across) by linear interpolation across (clamped)."""
    m = img.shape[1]
    p = np.clip(p, 0.0, m - 1.0)
    i0 = np.clip(np.floor(p).astype(int), 0, m - 2)
    f = p - i0
    return img[j, i0] * (1 - f) + img[j, i0 + 1] * f


def _measured(img, clipped, j, q, b, width):
    """Across position of the stripe at along `j`, measured where the line puts it at `q`
    (slope `b` across per centre): on each of the profiles along the stripe's search axis
    through the columns round(q) − 1 … + 1 (parallel to the border across, so whole where the
    profiles across are cut), the half-maximum centroid within 3 σ_t / |b| + 2 of where the
    line crosses it (clipped pixels at the profile's maximum), moved back to along `j` by the
    slope; the median of those found, NaN if none."""
    n, m = img.shape
    out = []
    for p in range(int(round(q)) - 1, int(round(q)) + 2):
        if not 0 <= p < m:
            continue
        jf = j + (p - q) / b
        w = int(np.ceil(3.0 * width / abs(b))) + 2
        lo, hi = int(np.floor(jf)) - w, int(np.ceil(jf)) + w + 1
        if lo < 0 or hi > n:
            continue
        v = img[lo:hi, p].astype(float)
        c = clipped[lo:hi, p]
        if c.any():
            v = np.where(c, v[~c].max() if (~c).any() else 1.0, v)
        base = np.median(np.concatenate([v[:3], v[-3:]]))
        wt = np.clip(v - 0.5 * (base + v.max()), 0, None)
        if wt.sum() > 0:
            out.append(p + b * (j - np.sum(wt * np.arange(lo, hi)) / wt.sum()))
    return np.median(out) if out else np.nan


def _end(pos, valid, img, clipped, img_shape, width, reverse: bool):
    """(indices, positions) of the centres set by the line at one end of the path, or None."""
    n, m = len(pos), img_shape[1]
    order = np.arange(n)[::-1] if reverse else np.arange(n)
    idx = order[valid[order]]
    d = FIT_WIDTHS * width + FIT_PX
    p = pos[idx]
    k = np.flatnonzero((p >= d) & (p <= m - 1 - d))
    if k.size < FIT_LEN:
        return None
    support = idx[k[:FIT_LEN]]
    b = np.polyfit(support, pos[support], 1)[0]
    if abs(b) < MIN_SLOPE:
        return None
    coef = np.polyfit(support - support[0], pos[support], FIT_DEG)
    zone = idx[: k[0]]  # the path's own centres between the support and the border
    if zone.size >= 3:
        off = np.median(np.abs(pos[zone] - np.polyval(coef, zone - support[0])))
        if off > ZONE_TOL:
            return None  # a corner between: the fit does not carry over (module docstring)
    step = -1 if reverse else 1
    reach = int(np.ceil((REACH * d + 1.0) / abs(b))) + 1  # centres to the border, at most
    # where the reach runs past the frame along, the line must have left it across by the
    # frame's end: else the path ends at the border along (intact profiles, not cut ones)
    j_out = int(np.clip(support[0] - step * reach, 0, n - 1))
    q_out = np.polyval(coef, j_out - support[0])
    inner = CORNER * d  # a corner: the line still within the cut zone at the frame's end
    if inner <= q_out <= m - 1 - inner:
        return None  # the line does not meet the border across within the reach
    img, clipped = img(), clipped()  # only now on the host (a turned stripe at the border)
    plateau = np.median(_sample(img, support, pos[support]))
    js, qs = [], []
    j = support[0] - step
    while 0 <= j < n:
        q = np.polyval(coef, j - support[0])
        if q < MARGIN or q > m - 1 - MARGIN:
            break  # left the frame across
        lit = _sample(img, np.array([j]), np.array([q]))[0] >= LIT_SHARE * plateau
        if not (lit or clipped[j, int(np.clip(round(q), 0, m - 1))]):
            break  # the fan's end near the border
        js.append(j)
        qs.append(q)
        j -= step
    # the image along the border against the line: cut where a window's mean leaves it
    off = [q - _measured(img, clipped, i, q, b, width) for i, q in zip(js, qs, strict=True)]
    off = np.array(off)
    for i in range(len(js)):
        w = off[max(0, i - MEASURE_WINDOW + 1) : i + 1]
        w = w[np.isfinite(w)]
        if w.size >= min(4, i + 1) and abs(np.mean(w)) > MEASURE_TOL:
            del js[max(0, i - MEASURE_WINDOW + 1) :], qs[max(0, i - MEASURE_WINDOW + 1) :]
            break
    if not js:
        return None
    return np.array(js), np.array(qs)


def extend(pos, valid, sigma, strength, img, clipped, width, axis: int = 1):
    """(pos, valid, sigma, strength) with the path's ends that leave the frame across the
    search axis set by the fit through the centres further inside, up to the border
    (module docstring). `img` (H, W): the monochrome image; `clipped` (H, W): its clipped
    pixels left unfilled; `width`: σ_t (px); `axis` 0 for "h" (one centre per column), 1
    for "v". Both images come to the host only where an end qualifies; where none is set, the
    inputs come back as they were (same arrays, so the default rig's frames are unchanged)."""
    given = (pos, valid, sigma, strength)
    pos = np.array(pos, float)
    valid = np.array(valid, bool)
    sigma = np.array(sigma, float)
    strength = np.array(strength, float)
    host = {}

    def on_host(name, x, dtype):
        if name not in host:  # search orientation: axis 0 along the stripe
            host[name] = np.asarray(x, dtype).T if axis == 0 else np.asarray(x, dtype)
        return host[name]

    images = (lambda: on_host("img", img, float), lambda: on_host("clip", clipped, bool))
    shape = np.shape(img)[::-1] if axis == 0 else np.shape(img)
    if valid.sum() < 2 * FIT_LEN:
        return given
    z = float(np.median(strength[valid]))
    s = float(np.median(sigma[valid]))
    changed = False
    for reverse in (False, True):
        r = _end(np.nan_to_num(pos), valid, *images, shape, width, reverse)
        if r is None:
            continue
        changed = True
        j, q = r
        beyond = np.arange(j[-1] + 1, len(pos)) if reverse else np.arange(j[-1])
        valid[beyond] = False
        pos[beyond] = np.nan
        pos[j] = q
        sigma[j] = np.where(valid[j], np.maximum(sigma[j], s), s)
        strength[j] = np.where(valid[j], strength[j], z)
        valid[j] = True
    return (pos, valid, sigma, strength) if changed else given
