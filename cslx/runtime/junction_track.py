"""Temporal confirmation of T-junction sightings: a crossing weld fixed in the world.

The vertical stripe's crossing-bead detector (`cslx.runtime.junction.crossing_feature`, run
in the compiled pipeline) gives at most one sighting per frame, x_r of the crossing weld.
The crossing weld does not move on the plate, so its sightings, each moved by the robot's
odometry since it was made (x −= d per frame), stay at one x_r. `JunctionTrack` (cslx's own
rule; the paper gives none):

- confirm: a sighting that agrees within `tol_mm` with `confirm_min` − 1 earlier ones of
  the last `window` frames confirms a junction there (`KalmanConfig.junction_confirm_min`
  3: two chance-agreeing glare sightings made a false T at dev seed 7305, flank, glare);
- hold: a confirmed junction is reported, at the median of its supporting sightings (moved
  to now); once `hold_min_support` sightings support it (before that only in frames with a
  sighting), for up to `hold` frames after its last supporting sighting while it lies inside
  the vertical stripe's measured extent — single frames without a sighting (sun, glare, a
  low crossing bead on the stem's flank) no longer drop the report;
- the farther one wins: a newly confirmed junction at a larger x_r than the held one
  replaces it. The crossing weld ends the followed weld, so it is the farthest crossing
  feature on the stripe; an artefact on the stem's flank (dev seed 1202, sun: 1.4–1.8 mm
  bumps fixed on the plate ≈ 40 mm before the bar) is nearer;
- never seen before: the crossing weld is fixed on the plate and the robot approaches it, so
  the stripe has seen its place from the far edge of the view on. A new junction whose place
  was inside the view (`margin_mm` from either end of the stripe's measured extent) for more
  than `unseen_mm` of travel before its first sighting is an artefact that appeared
  mid-view (the flank bumps above, sun and glare: 24–27 mm unseen; the bar ≤ 10.5 mm on the
  dev seeds, missed where it first enters the view).
- beyond the followed weld: the crossing weld ends the followed weld, which the horizontal
  stripe still sees at x_r = `x_min_mm` (the tracker's x_ref), so a new junction nearer than
  that is an artefact (dev seed 1203, flank, glare: bumps at 121–124 mm confirmed before the
  bar was in view); a held junction is still reported when it comes nearer.
- odometry moves sightings as the plate points they are: x −= d, then the turn δ about the
  robot, x ← cos δ · x + sin δ · y with y the vertical stripe's y_r (≈ −39 mm on the default
  rig). The ±3.5° heading wobble of the rendered approaches turns by up to 0.27° a frame,
  which moves the crossing weld on the stripe by 0.19 mm a frame against x −= d alone;
  a held position, the median of up to 10 frames of sightings, lagged up to ≈ 1 mm behind.
- where the stripes cross: the horizontal stripe meets the wall at x_r = x_ref (150 mm on
  the default rig) and crosses the vertical stripe there. A crossing weld within
  `crossing_zone` of that point (x_r from x_ref + zone[0] to x_ref + zone[1]) is measured
  against a profile that the other stripe's light and the end of the followed weld disturb:
  on the rendered approaches at dev seeds 7301, 7302 and 7305 (`JunctionTrack` numbers in
  `cslx.runtime.line_filter.KalmanConfig`) its sightings there were 2–4 mm too far on
  average, up to 9.5 mm, against ≤ 0.5 mm mean bias before it. Those sightings still
  confirm and hold the junction, but once `min_clear` sightings outside the zone support
  it, its position is the median of the last `window` of those, moved by odometry (the
  plate point does not move; in Figure 22 the controller dead-reckoned to the last report,
  4.4 mm too far in sun at dev seed 2201, and the robot turned 4.4 mm past the T).
- along the bar (`bar_slope`, `KalmanConfig.junction_bar_slope`): each sighting is also
  kept as the plate point (x_r, y_r) where the stripe crossed the bar's centre line,
  carried by odometry in both coordinates; once ≥ 10 of the held junction's points spread
  ≥ 3 mm across the stripe (the robot turned: ≈ 1° at 180 mm) and the slope k of a Tukey-robust
  line through them (the bar, `robust_line`) exceeds twice its standard deviation, the
  reported position is where that line meets the stripe's current line on the wall, not
  their median x_r. The x_r-only carry assumes the bar is perpendicular to the stripe in
  the current robot frame; a bar at 60° or 120° to the stem, or any bar while the robot
  turns, slides along the stripe instead. Issue 12 audit
  (experiments/tracking_generality.py, fresh seed 7400, clean, 40 frames): T at 60° the
  report 5–9 mm behind the sightings, T recall 21.9 %, 16 false T frames; simulated
  (tests/runtime/test_oblique_t.py, 0.25° of turn a frame, 0.5 mm scatter): max / mean
  error at 60° 8.6 / 4.1 → 2.0 / 0.35 mm, at 90° 2.1 / 0.81 → 0.49 / 0.26 mm. Without
  the slope test 2 of 51 dev runs (1203 and 7326 beside sunny) gained a false T frame:
  the first line through 12 sightings scattered ±3 mm, k 1.36 ± 0.82, 3.9 mm short; with
  it and 5 points, 7326 kept it: 6–9 sightings of a bar entering the view, short at
  first while the robot turned, k 0.65 ± 0.09 for a bar at 90°, 2.5 mm short.
- an oblique bar from fewer points (`bar_oblique_points`,
  `KalmanConfig.junction_bar_oblique_points` 6): a bar at 120° is in view 9 frames at fresh
  seed 7400, too few for the 10-point line, and its crossing with the stripe slides
  0.7–1.5 mm a frame against 1.5 mm of travel, so the median falls 3–4 mm behind. With 6–9
  points the line is taken only if its slope is ≥ `bar_oblique_deg` (15°) from square,
  beyond `bar_oblique_sigma` (3) standard deviations, and the line passes nearer the newest
  sighting than their median x_r does (`bar_newest`). 7326 beside sunny's false T had
  k 0.65–0.69 ± 0.13–0.16 over 6–9 points (33° from square, 5σ: the slope test alone kept it,
  as did 6 points without any test) with the newest sightings 2.6 and 4.2 mm off that line
  and nearer the median. Replays (`experiments.junction_ramp --variant`, one recording per
  run, T recall % / false T frames, 10 points → this): 12 dev runs (48 frames; 7326 beside
  clean and sunny, 1201, 7320, 7322, 7323, 7325 beside sunny, 1202, 1203, 7321, 7324, 7327
  flank sunny) every score identical, the report changed in 3 frames (7326 beside sunny 2,
  7321 flank sunny 1; with 25° from square 2, with 7 points 2);
  fresh seeds (40 frames) T at 120° 7400 clean 66.7 / 3 → 100 / 0, sunny 55.6 / 7 → 100 / 3,
  T at 60° 7400 sunny 93.8 / 2 → 96.9 / 1; unchanged 120° 7401–7405 clean (88.9 / 0, 94.1 /
  1, 61.5 / 6, 100 / 0, 100 / 0), 7401 and 7403 sunny (88.9 / 0, 100 / 1), 60° 7400 and
  7401 clean (96.9 / 1, 97.3 / 0). Not taken: 7 points (120° 7400 clean 88.9 / 1, sunny
  77.8 / 5); no angle test, 2σ (60° sunny 100 / 0, but 10 changed reports over 11 dev runs).
"""

from __future__ import annotations

import math

import numpy as np

from .line_filter import carry, robust_line

__all__ = ["JunctionTrack", "cut_by_view"]


def cut_by_view(x: float, width: float, extent: tuple | None, margin: float) -> bool:
    """True if a crossing bead at x of this width (both as measured) reaches within `margin`
    of the far end of the vertical stripe's measured extent: cut by the view, its measured
    centre is the visible part's, not the weld's (`KalmanConfig.junction_cut_margin_mm`;
    margin < 0: never)."""
    return extent is not None and margin >= 0 and x + 0.5 * width >= extent[1] - margin


class JunctionTrack:
    """Sightings → a confirmed, held junction (module docstring). x in mm, frames as ints."""

    def __init__(
        self,
        window: int,
        tol_mm: float,
        hold: int,
        unseen_mm: float = math.inf,
        margin_mm: float = 10.0,
        hold_min_support: int = 1,
        x_min_mm: float = -math.inf,
        crossing_zone: tuple[float, float] | None = None,
        min_clear: int = 3,
        keep_clear: int | None = None,
        fuse: str = "median",
        confirm_min: int = 2,
        bar_slope: bool = False,
        bar_min_points: int = 10,
        bar_oblique_points: int | None = None,
        bar_oblique_deg: float = 15.0,
        bar_oblique_sigma: float = 3.0,
        bar_newest: bool = True,
    ):
        self.window, self.tol, self.hold = int(window), float(tol_mm), int(hold)
        self.unseen_mm, self.margin = float(unseen_mm), float(margin_mm)
        self.hold_min_support = int(hold_min_support)
        self.x_min = float(x_min_mm)
        self.zone = None if crossing_zone is None else tuple(map(float, crossing_zone))
        self.min_clear = int(min_clear)
        self.keep_clear = int(window if keep_clear is None else keep_clear)
        if fuse not in ("median", "mean"):
            raise ValueError(f"fuse must be 'median' or 'mean', got {fuse!r}")
        self.fuse = fuse
        self.confirm_min = max(int(confirm_min), 2)
        self.bar_slope = bool(bar_slope)
        self.bar_min_points = int(bar_min_points)  # fewest plate points for the bar's line
        # fewer points for an oblique bar's line: None never; the newest-sighting test on or
        # off (`_on_bar`, module docstring)
        self.bar_oblique_points = bar_oblique_points
        self.bar_oblique_tan = math.tan(math.radians(float(bar_oblique_deg)))
        self.bar_oblique_sigma = float(bar_oblique_sigma)
        self.bar_newest = bool(bar_newest)
        self.stripe_y = 0.0  # y_r of the vertical stripe (mm), from `update`
        self.stripe_line = (0.0, 0.0)  # the stripe on the wall, y_r = y0 + m x_r
        self.reset()

    @classmethod
    def from_config(cls, c, x_ref: float, **overrides) -> JunctionTrack:
        """The tracker's track (`Tracker.reset`): the junction settings of `KalmanConfig` ``c``
        about the stripe's x_ref; keyword arguments replace them (the replays in
        `experiments.junction_errors` and `experiments.junction_ramp`)."""
        kw = dict(
            hold_min_support=c.junction_hold_min_support,
            x_min_mm=x_ref,
            crossing_zone=tuple(x_ref + z for z in c.junction_crossing_zone_mm),
            keep_clear=c.junction_keep_clear,
            fuse=c.junction_fuse,
            confirm_min=c.junction_confirm_min,
            bar_slope=c.junction_bar_slope,
            bar_oblique_points=c.junction_bar_oblique_points,
            bar_oblique_deg=c.junction_bar_oblique_deg,
        )
        kw.update(overrides)
        window, hold = c.junction_window, c.junction_hold
        return cls(window, c.junction_tol_mm, hold, c.junction_unseen_mm, **kw)

    def reset(self) -> None:
        self.sightings: list[tuple[int, float]] = []  # (frame, x moved to now)
        self.support: list[tuple[int, float]] = []  # the held junction's sightings
        self.clear: list[tuple[int, float]] = []  # its last sightings made outside the zone
        self._made_clear: set[int] = set()  # frames whose sighting was outside the zone
        self.points: dict[int, tuple[float, float]] = {}  # each sighting as a plate point
        self.last = -(10**9)  # frame of its last supporting sighting
        self.travelled = 0.0  # mm since the start
        self.history: list[tuple[int, float, float, float]] = []  # (frame, travelled, extent)

    def move(self, d: float, delta: float = 0.0) -> None:
        """The robot advanced d mm and turned δ rad (CCW +): plate points on the stripe move
        to x ← cos δ · (x − d) + sin δ · y (module docstring)."""
        y = self.stripe_y
        self.sightings = [(f, carry(x, y, d, delta)[0]) for f, x in self.sightings]
        self.travelled += d
        self.support = [(f, carry(x, y, d, delta)[0]) for f, x in self.support]
        self.clear = [(f, carry(x, y, d, delta)[0]) for f, x in self.clear]
        self.points = {f: carry(x, yp, d, delta) for f, (x, yp) in self.points.items()}

    @property
    def x(self) -> float:
        if not self.support:
            return math.nan
        held = self.clear if len(self.clear) >= self.min_clear else self.support
        if self.bar_slope:
            x = self._on_bar([f for f, _ in held])
            if math.isfinite(x):
                return x
        return self._fused([x for _, x in held])

    def _on_bar(self, frames: list[int]) -> float:
        """Where the line through these sightings' plate points (the crossing weld's centre
        line, `bar_slope`) meets the stripe now; NaN with fewer than `bar_min_points` (10)
        points, under 3 mm of spread along the stripe, or no slope beyond twice its standard
        deviation. From `bar_oblique_points` (6) points on, fewer than `bar_min_points` pass
        only for a clearly oblique bar that explains the newest sighting better than the
        median (module docstring, "an oblique bar from fewer points")."""
        pts = np.array([self.points[f] for f in frames if f in self.points])
        fewest = self.bar_min_points
        if self.bar_oblique_points is not None:
            fewest = min(fewest, int(self.bar_oblique_points))
        # too few points, or no spread along the stripe: no slope
        if len(pts) < fewest or np.ptp(pts[:, 1]) < 3.0:
            return math.nan
        y0, m = self.stripe_line
        # x = a + k (y − y_s), Tukey-robust, then the intersection with y = y0 + m x
        ys = y0 + m * float(np.median(pts[:, 0]))
        a, th, sd = robust_line(pts[:, 1], pts[:, 0], np.ones(len(pts)), ys, 0.5, 3.0)
        if not (math.isfinite(a) and math.isfinite(th)):
            return math.nan
        k = math.tan(th)
        sd_k = sd * (1.0 + k * k)  # the standard deviation of tan θ
        if abs(k) < 2.0 * sd_k:  # no slope beyond its noise
            return math.nan  # the median: a bar ⟂ the stripe
        if len(pts) < self.bar_min_points:  # few points: a clearly oblique bar only
            xn, yn = pts[-1]  # the newest sighting: the line must explain it better
            if (
                abs(k) < max(self.bar_oblique_tan, self.bar_oblique_sigma * sd_k)
                or self.bar_newest
                and abs(xn - a - k * (yn - ys)) >= abs(xn - float(np.median(pts[:, 0])))
            ):
                return math.nan
        # a + k (y0 + m x − ys) = x
        den = 1.0 - k * m
        return (a + k * (y0 - ys)) / den if abs(den) > 0.1 else math.nan

    def _fused(self, xs: list[float]) -> float:
        """The held position from its sightings (all moved to now): their median, or with
        `fuse="mean"` the mean of those within `tol_mm` of the median (the sightings of a
        crossing bead scatter ≈ 2 mm with a tail ≈ 3 mm short; in Figure 22 the median of
        the clear ones was 0.2 mm farther than their mean; issue 12 notes)."""
        med = float(np.median(xs))
        if self.fuse == "median":
            return med
        near = [x for x in xs if abs(x - med) <= self.tol]
        return float(np.mean(near)) if near else med

    def _in_zone(self, x: float) -> bool:
        return self.zone is not None and self.zone[0] <= x <= self.zone[1]

    def _keep_clear(self, sightings: list[tuple[int, float]]) -> None:
        """Add those of `sightings` made outside the zone to `clear` (the last `window`)."""
        new = [(f, x) for f, x in sightings if f in self._made_clear]
        self.clear = [*self.clear, *new][-self.keep_clear :]

    def update(
        self,
        now: int,
        x: float | None,
        extent: tuple[float, float] | None,
        stripe_y: float | None = None,
        stripe_line: tuple[float, float] | None = None,
    ) -> float:
        """Add this frame's sighting (None: none); the junction's x_r to report, else NaN.

        extent: (min, max) x_r of the vertical stripe's measured points this frame.
        stripe_y: the vertical stripe's y_r this frame (mm), for `move`'s turn; None keeps it.
        """
        if stripe_y is not None and math.isfinite(stripe_y):
            self.stripe_y = float(stripe_y)
        if stripe_line is not None and all(map(math.isfinite, stripe_line)):
            self.stripe_line = (float(stripe_line[0]), float(stripe_line[1]))
        else:
            self.stripe_line = (self.stripe_y, 0.0)
        self.sightings = [(f, xo) for f, xo in self.sightings if now - f <= self.window]
        self.support = [(f, xo) for f, xo in self.support if now - f <= self.window]
        self._made_clear = {f for f in self._made_clear if now - f <= self.window}
        live = {f for f, _ in (*self.sightings, *self.support, *self.clear)}
        self.points = {f: p for f, p in self.points.items() if f in live}
        held = bool(self.support) and now - self.last <= self.hold
        if x is not None and math.isfinite(x):
            agree = [(f, xo) for f, xo in self.sightings if abs(xo - x) <= self.tol]
            self.sightings.append((now, x))
            y0, m = self.stripe_line
            self.points[now] = (x, y0 + m * x)
            if not self._in_zone(x):
                self._made_clear.add(now)
            if held and abs(x - self.x) <= self.tol:
                self.support.append((now, x))
                self._keep_clear([(now, x)])
                self.last = now
            elif (
                len(agree) + 1 >= self.confirm_min
                and (not held or x > self.x + self.tol)
                and self._fresh(x, agree)
            ):
                self.support = [*agree, (now, x)]
                self.clear = []
                self._keep_clear(self.support)
                self.last = now
        if extent is not None:
            self.history = [*self.history[-4 * self.window :], (now, self.travelled, *extent)]
        held = bool(self.support) and now - self.last <= self.hold
        if len(self.support) < self.hold_min_support:
            held = held and self.last == now  # too few sightings yet: only when seen
        xj = self.x
        if not held or extent is None or not extent[0] <= xj <= extent[1]:
            return math.nan
        return xj

    def _fresh(self, x: float, agree: list[tuple[int, float]]) -> bool:
        """False if x is nearer than `x_min_mm`, or the plate where it lies was in view for
        > `unseen_mm` of travel unseen."""
        if x < self.x_min:
            return False
        f0 = min(f for f, _ in agree)
        d0 = next((dd for f, dd, *_ in self.history if f == f0), None)
        if d0 is None:
            return True
        inside = [
            dd
            for f, dd, lo, hi in self.history
            if f < f0 and lo + self.margin <= x + self.travelled - dd <= hi - self.margin
        ]
        return not inside or d0 - min(inside) <= self.unseen_mm
