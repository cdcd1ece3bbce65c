"""The weld's heading from the recent path of accepted bead centres (the tracker's window).

`cslx.runtime.tracker`'s module docstring describes the model; the tuning is in
`cslx.runtime.line_filter.KalmanConfig` (`heading_*`). The accepted bead centres of the last
`heading_window_mm` of travel, carried into the current robot frame by odometry, lie on the
weld line; a robust line through them (`cslx.runtime.line_filter.robust_line`) gives θ with
its standard deviation, fused into the filter as a heading measurement.

It is fused only on a frame whose bead the filter accepted. The window holds no news on a
frame without one, and on a frame whose bead the gate rejected after the filter coasted (no
bead while the horizontal stripe lay along the crossing weld of a T), fusing it let what was
left of the window, a short line of centres now 35–60 mm behind, set the heading while
coasting had broadened the filter's: Figure 22's closed loop, sunny, dev seed 2204, with the
toe-corrected bead centre of `cslx.runtime.bead` (a development version): after 31 mm
without beads one rejected bead fused 2.20° ± 0.33° (16 centres 90.7–115.6 mm ahead of the
robot; the filter's heading 1.19° ± 2.89°, the true one 1.10°) and the robot coasted the
next 75 mm with 2.19°, 1.8 mm off at the T (closed-loop error after the turn 4.00 mm max;
with this rule 0.69 mm, the bead also limited to toes within its half width; seed 2201 with
that bead: 18.98 → 0.76 mm). With the cap-model bead of `cslx.runtime.weld`: 48 development
tracking sequences (seeds 7301, 7302, 7305, 1201–1203) identical. Figure 22, error after the
turn, mean / max, fusing on rejected frames → not: sunny 2203 and 2204 and shadow 2201
identical; glare 2201 0.385 / 1.529 → 0.215 / 0.872 mm, glare 2204 0.248 / 0.946 → 0.240 /
0.842 mm, shadow 2203 0.227 / 1.050 → 0.177 / 0.780 mm, shadow 2204 0.204 / 0.677 → 0.192 /
0.784 mm, clean 2203 0.123 / 0.760 → 0.137 / 0.859 mm (clean 2201 identical); sunny 2201
0.280 / 0.715 → 0.332 / 1.368 mm: there the stale window was fused on three rejected frames
while coasting, once away from the true heading (1.48° → 1.63°, true 0.91°) and once towards
it (→ 1.21°); without them the robot coasted with 1.46° and came onto the bar 0.65 mm
farther off its centre line; glare 2203 0.060 / 0.178 → 0.077 / 0.503 mm, although the
heading carried into the coast was nearer the truth (1.14° against 1.26°, true 1.09°). In
each pair the last junction report was the same; the error after the turn varies with the
path of the coast to the T, by ±0.6 mm either way here.
"""

from __future__ import annotations

import math

import numpy as np

from .line_filter import KalmanConfig, WeldLineFilter, carry, robust_line

__all__ = ["PathHeading", "predicted_sd"]

NAN = math.nan


def predicted_sd(x: np.ndarray, w: np.ndarray, sigma: float) -> float:
    """Standard deviation (rad, small angles) of a weighted least-squares line's slope through
    points at positions x whose lateral noise has variance sigma² / w (`KalmanConfig`,
    `heading_sd_model`): sigma / √(Σ wᵢ (xᵢ − x̄_w)²), x̄_w = Σ wᵢ xᵢ / Σ wᵢ. inf when the
    points have no spread."""
    x, w = np.asarray(x, float), np.asarray(w, float)
    sw = float(w.sum())
    if sw <= 0:
        return math.inf
    xm = float(w @ x) / sw
    sxx = float(w @ (x - xm) ** 2)
    return sigma / math.sqrt(sxx) if sxx > 0 else math.inf


class PathHeading:
    """Accepted bead centres (x_r, y_r, weight, width) of the recent path, current robot frame.

    `move(d, δ)` per frame carries them by odometry and forgets those more than
    `heading_window_mm` behind x_ref; `update(filter, …)` adds this frame's bead when the
    filter accepted it and then fuses the window's heading (module docstring). A restart of
    the filter (a new weld, a re-acquisition) forgets the window.
    """

    def __init__(self, config: KalmanConfig, x_ref: float):
        self.c = config
        self.x_ref = float(x_ref)
        self.reset()

    def reset(self) -> None:
        self.points = np.zeros((0, 4))
        self._restarts = 0
        self._var = math.inf  # the last fused window's heading variance, rad², grown by travel
        # the same window's variance as the measurement model predicts it (`predicted_sd`
        # with the centres' confidence weights), grown by travel like `_var`: what the
        # tracker reports as the heading's uncertainty (`KalmanConfig.heading_valid_model`)
        self.model_var = math.inf

    def move(self, d: float, delta: float) -> None:
        if not len(self.points):
            return
        self._var += self.c.q_heading**2 * abs(d)
        self.model_var += self.c.q_heading**2 * abs(d)
        x, y = carry(self.points[:, 0], self.points[:, 1], d, delta)
        self.points = np.stack([x, y, *self.points[:, 2:].T], 1)
        self.points = self.points[self.points[:, 0] >= self.x_ref - self.c.heading_window_mm]

    def update(
        self,
        kf: WeldLineFilter,
        x: float,
        y: float,
        confidence: float,
        width: float,
        accepted: bool,
    ) -> tuple[float, float]:
        """Add an accepted bead and fuse the window's heading into `kf`.

        Returns the window's (heading, standard deviation) in degrees, NaNs where none was
        fused (the bead rejected, too few centres, or their span under
        `heading_min_span_mm`)."""
        c = self.c
        if kf.restarts != self._restarts:  # a new weld or a re-acquisition: forget the old
            self._restarts = kf.restarts
            self.points = np.zeros((0, 4))
            self._var = self.model_var = math.inf
        if not accepted:
            return NAN, NAN
        row = np.array([[x, y, max(confidence, 0.05), width]])
        self.points = h = np.concatenate([self.points, row])
        if c.heading_window_mm <= 0 or len(h) < 6 or np.ptp(h[:, 0]) < c.heading_min_span_mm:
            return NAN, NAN
        w = h[:, 2]
        if c.heading_width_tol > 0:
            m = np.median(h[:, 3])
            w = w / (1.0 + ((h[:, 3] - m) / (c.heading_width_tol * m)) ** 4)
        sd_pred = predicted_sd(h[:, 0], w, c.sigma_meas)
        if c.heading_max_sd_deg > 0 and not sd_pred <= math.radians(c.heading_max_sd_deg):
            return NAN, NAN
        _, th, sd = robust_line(
            h[:, 0],
            h[:, 1],
            w,
            self.x_ref,
            c.heading_scale_floor_mm,
            c.heading_tukey_c,
            c_refine=c.heading_tukey_refine,
        )
        if not math.isfinite(th):
            return NAN, NAN
        if c.heading_sd_model:
            sd = max(sd, sd_pred)
        if kf.update_heading(th, sd, gain=1.0 / self._var if c.heading_gain_only else 0.0):
            self._var = max(sd, math.radians(c.sigma_heading_floor_deg)) ** 2
            self.model_var = sd_pred**2
        return math.degrees(th), math.degrees(sd)
