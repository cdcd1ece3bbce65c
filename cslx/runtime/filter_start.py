"""How the weld-line filter starts: never captured by one implausible bead (issue 12).

A cold `WeldLineFilter` (the first frame, or the first after `Tracker.reset`) starts on the
first bead with a broad covariance (`init_offset_std` 2 mm), so a wrong first bead is mostly
outvoted by the next one. Two rules make the start hold
beyond that (`KalmanConfig.start_agree`, `KalmanConfig.start_width_mm`):

- consensus of the first beads (`odd_first`, `start_agree` = K ≥ 3): the first K beads
  from a cold start (the gate's rejected ones too, carried into the current robot frame by
  odometry like the state) are compared at x_ref along the current heading; when the
  later K − 1 lie within 2 `consistent_mm` of each other (the spread the re-acquiring gate
  calls agreement, `WeldLineFilter._reacquire`) and the first lies farther than that from
  their confidence-weighted mean, the filter restarts on the later ones as if the first
  had never been seen. Two beads alone cannot say which of them is wrong, so nothing is
  done before the K-th.
- a plausible first bead (`may_start`, `start_width_mm` = (lo, hi), off by default): a cold
  filter starts only on a bead whose width lies in the weld's nominal range, or on two
  beads in a row that agree with each other (position within 2 `consistent_mm` at x_ref,
  width within `width_tol` of their mean): a real bead outside the range (a weld wider
  than configured) starts one frame later, never not at all. Until then the tracker
  reports no offset (NaN), which costs the estimate share. The range is the user's: the
  code knows no nominal bead width (`WeldConfig`'s 4–40 mm is what the detector accepts at
  all, and the 31 mm bead below passes it).

What the first bead does (issue 12, rendered T approaches, `experiments.tracking_sequences`):
the filter's estimate on frame 0 *is* the first bead's measurement, so no start rule that
keeps an estimate on frame 0 can change that frame's error; with the broad start
covariance frame 1 already weighs the second bead ≈ 0.9 (fresh seed 7743 flank sunny:
frame 0's bead 31.1 mm wide against the true 18.6, −2.97 mm off; filter −2.98 / −0.39 /
−0.16 mm on frames 0 / 1 / 2 with the next beads −0.05 / −0.01 mm off). The first bead
does not capture the filter beyond frame 1 unless it lies outside the gate (≈ 8 mm at
the start covariance): then the true beads are rejected until three agree and the filter
restarts on the 4th bead; `start_agree` 3 restarts on the 3rd
(tests/runtime/test_filter_start.py).

Both rules off by default. `experiments/start_rule.py`, each variant against the default
on the same pipeline outputs, development runs (seeds 7301, 7302, 7305, 1201–1206 and
7740–7743, both placements, every nuisance; 48 frames):

- `start_agree` 3 (and 4): one run of the 104 changes, 7743 flank sunny, offset mean
  0.1874 → 0.1960 mm (4: 0.1984), its max (2.98 mm, frame 0) unchanged: frame 2
  −0.16 → −0.02 mm, but 10 of frames 3–13 farther off, by up to 0.10 mm (the restart
  re-opens the start covariance of offset and heading on frame 2; frame 3 +0.20 → +0.28,
  frame 7 −0.05 → −0.15; frame 5 +0.14 → +0.11). No verdict changes; every other run
  identical; the mean over the runs unchanged to 0.0001 mm.
- `start_width_mm` (9.6, 24), the rendered beads' 12–20 mm ± `width_tol`: 4 runs change,
  each by the first frame's estimate: 7743 flank sunny offset max 2.976 → 0.290 mm (mean
  0.187 → 0.131), 7743 flank glare 1.161 → 0.250 (mean 0.097 → 0.079), 7743 flank shadow
  0.310 → 0.311 and 7741 flank sunny (first bead 27.2 mm) 0.384 → 0.384 mm, all four
  estimate 100 → 97.9 % (one frame of 48: the goal is ≥ 98 %). Goal misses over the 104
  runs: offset max 3 → 1 (7305 flank glare's 1.46 mm first bead is 14.6 mm wide), estimate
  0 → 4. A real wide bead outside the range starts a frame later
  (`experiments.tracking_generality` bead_wide, dev seed 7400, 22–26 mm: clean frame 0's
  bead 24.4 mm, estimate 100 → 96.9 % of 32 frames, offset mean / max 0.070 / 0.148 →
  0.073 / 0.168 mm; sunny (24.0 mm) identical); `start_agree` 3 / 4 identical there.

Final check on fresh seeds 7950–7953 (32 runs, never used before; rendered frames 0–2
only, `--frames 3`, where both rules decide: the width rule on a cold filter, the
consensus on its 3rd bead; a rule that decided nothing changes nothing after): the
default is unchanged (both rules off); `start_agree` 3 decided in every run and restarted
in none, `start_width_mm` refused no first bead: identical in all 32 runs. (`start_agree`
4 decides on frame 3, not rendered.)
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["may_start", "move", "odd_first", "step"]


def _at_ref(beads: np.ndarray, theta: float, x_ref: float) -> np.ndarray:
    """y_r of beads (n, ≥ 2: x_r, y_r, …) moved to x_ref along heading θ."""
    return beads[:, 1] - math.tan(theta) * (beads[:, 0] - x_ref)


def odd_first(beads: np.ndarray, theta: float, x_ref: float, tol_mm: float) -> bool:
    """Whether the first of the start beads (K, 3: x_r, y_r, confidence; current robot
    frame) is the odd one out: the later K − 1 ≥ 2 agree (spread ≤ 2 tol_mm at x_ref along
    θ) and the first lies more than 2 tol_mm from their confidence-weighted mean."""
    if len(beads) < 3:
        return False
    y = _at_ref(beads, theta, x_ref)
    rest, w = y[1:], np.maximum(beads[1:, 2], 0.05)
    if np.ptp(rest) > 2.0 * tol_mm:
        return False
    return bool(abs(y[0] - float(w @ rest) / float(w.sum())) > 2.0 * tol_mm)


def may_start(
    bead: tuple[float, float, float],
    previous: tuple[float, float, float] | None,
    width_range: tuple[float, float] | None,
    width_tol: float,
    tol_mm: float,
) -> bool:
    """Whether a cold filter may start on this bead (x_r, y_r, width; current robot frame):
    always without `width_range`; else if its width lies in the range, or if `previous`
    (the bead of the frame before, carried by odometry, same fields) agrees with it: y_r at
    x_ref (heading 0: a cold filter has none) within 2 tol_mm, widths within width_tol of
    their mean."""
    if width_range is None:
        return True
    _, y, width = bead
    lo, hi = width_range
    if math.isfinite(width) and lo <= width <= hi:
        return True
    if previous is None or not (math.isfinite(width) and math.isfinite(previous[2])):
        return False
    near = abs(y - previous[1]) <= 2.0 * tol_mm  # both near x_ref, heading unknown
    mean = 0.5 * (width + previous[2])
    return near and abs(width - previous[2]) <= width_tol * mean


def move(kf, carry) -> None:
    """Carry the filter's start beads and refused first bead by the robot's motion
    (``carry(x, y)`` → (x, y) in the new robot frame, `line_filter.carry`)."""
    kf.start_beads = [np.array([*carry(b[0], b[1]), b[2]]) for b in kf.start_beads]
    if kf.waiting is not None:
        kf.waiting = (*carry(kf.waiting[0], kf.waiting[1]), kf.waiting[2])


def step(kf, x_c: float, y_c: float, confidence: float, width: float) -> bool | None:
    """The start rules' part of `WeldLineFilter.update`: True / False when they decide
    this bead's fate (a cold start or its refusal, a restart on the agreeing beads), None
    when the ordinary update goes on (module docstring)."""
    c = kf.c
    if kf.x is None:
        bead = (x_c, y_c, width)
        if not may_start(bead, kf.waiting, c.start_width_mm, c.width_tol, c.consistent_mm):
            kf.waiting = bead
            return False
        kf.start(y_c)
        kf.waiting = None
        kf.start_beads = [np.array([x_c, y_c, confidence])] if c.start_agree >= 3 else []
        return True
    if not kf.start_beads:
        return None
    kf.start_beads.append(np.array([x_c, y_c, confidence]))
    if len(kf.start_beads) < c.start_agree:
        return None
    beads = np.array(kf.start_beads)
    kf.start_beads = []
    if not odd_first(beads, float(kf.x[1]), kf.x_ref, c.consistent_mm):
        return None
    kf.start(float(beads[1, 1]))  # a cold start on the second bead: the first never seen
    for b in beads[2:]:
        kf.update(*b)
    return True
