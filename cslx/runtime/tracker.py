"""The weld tracker the robot runtime imports: compiled pipeline + state + a small Kalman filter.

`Tracker.from_calibration(path_or_sensor)` compiles `cslx.runtime.pipeline` once at start-up (the
compile time is logged; with JAX's persistent compilation cache, which the entry point sets
with `cslx.environment.configure(compile_cache=...)`, a second start-up loads the program
instead of compiling it, without importing or tracing the pipeline: `cslx.runtime.compiled`),
then `step(frame)` runs one
frame: the pipeline state (MED filters warm-started frame to frame, the tracking bands) stays
on the device, and one small vector (`cslx.runtime.pipeline.SUMMARY_FIELDS`) comes back to the host.

Weld-line model (section 4.3 of the paper gives none; this is cslx's). In the robot frame
(docs/contracts.md) the followed weld is the line y_r = e + tan θ · (x_r − x_ref), with x_ref the
x_r where the horizontal stripe meets the wall (150 mm on the default rig): e is the
lateral offset (mm, + = weld to the robot's left) and θ the heading (rad, CCW +). A Kalman
filter over s = (e, θ):

- predict, per frame, from the robot's motion since the last frame: forward distance d
  (mm) and heading change δ (rad, CCW +), from telemetry when the caller passes
  ``odometry``, else nominal ``speed_mm_s`` × dt (dt from the caller, else 1/fps; 30 mm/s at
  20 fps = 1.5 mm) and δ = 0. To first order the line seen from the moved robot is
  e' = e + d·θ − x_ref·δ, θ' = θ − δ, i.e. F = [[1, d], [0, 1]] with the input
  (−x_ref δ, −δ); process noise Q = diag(q_e², q_θ²)·|d| (a random walk per mm travelled:
  weld waviness and odometry error) + a small floor.
- update with the horizontal stripe's bead centre (x_c, y_c) of this frame: y_c = e + θ (x_c −
  x_ref) + noise, H = [1, x_c − x_ref], R = σ_meas² / max(confidence, 0.05).
  The confidence is divided by u² for a bead whose width is off the median of the recent
  accepted beads by u·`width_tol` of it (|u| > 1; `width_memory` beads, relearnt after a run of
  odd widths, i.e. a new weld).
  One frame observes only e (x_c ≈ x_ref); θ becomes observable through the d·θ term, i.e.
  through the bead centres of past frames carried into the current frame by odometry —
  the same information as a line fit through them (`cslx.runtime.weld.weld_line_from_features`).
- gating that re-acquires: an innovation beyond `gate` standard deviations is rejected, and
  the rejected centres are kept, carried into the current robot frame by odometry like the
  state. As soon as the last `reset_after` (3) rejected centres in a row agree with each
  other (their spread at x_ref ≤ 2 `consistent_mm`: a new weld after a T-junction turn, a
  lateral jump, or a wrong prediction that locked the truth out) the filter restarts at
  their mean, moved to x_ref with the current heading, with a broad covariance. The last
  `trend_after` (4) rejected centres lying on a straight line in time (each within
  `consistent_mm` of it: a steady drift that the lagging prediction keeps rejecting, such as
  faster lateral motion than the filter expects, or a turn seen without odometry) restart it
  at the line's latest value, on frames without odometry only. A run of rejections that
  agree in neither way (clutter) restarts it only after `give_up_after` frames.
  Where the rejected centres, carried by odometry, lie on a line whose direction
  contradicts the current heading (re-acquiring the crossing weld during the turn at a T,
  while the heading is still the old weld's, ≈ 90° off) the restart takes the line's
  heading and its standard deviation instead (`WeldLineFilter._restart_heading`).

- the bead near the line: on a frame whose bead the gate would reject, the bead is refitted
  on the profile without the other beads far from the predicted line
  (`cslx.runtime.bead_near`, `near_refit_mm`): the pipeline takes the largest bead, which
  beside an oblique T's bar is the bar.

- direct heading (`use_vertical_heading`): where the vertical stripe sees the weld's
  direction (`cslx.runtime.weld.heading_from_vertical`), that heading is fused as a
  measurement of θ (standard deviation at least `sigma_heading_floor_deg`, gated like the
  centres). Without odometry a rotation of the robot is otherwise seen only as an offset
  change of x_ref·δ (150 mm lever), which the filter cannot tell from a heading.

- heading from the recent path (`heading_window_mm`, default 60 mm): the accepted bead
  centres of the last 60 mm of travel, carried into the current robot frame by odometry,
  lie on the weld line; a robust (Tukey-biweight) line through them, weighted by confidence
  and by how far each bead's width departs from their median width (a bead whose flank a
  glint hides is narrow or wide and off-centre), gives θ with its standard deviation, fused
  as a heading measurement each frame. A straight weld has no lag this way (odometry, not
  the filter's random walk, carries the past); the window is forgotten when the filter
  restarts, and fused only on frames whose bead was accepted (`cslx.runtime.path_heading`
  says why). Numbers in `KalmanConfig`.

Reported heading is NaN until its standard deviation is below `heading_valid_deg` (0.8°), the
standard deviation (`Observation.heading_sd_deg`) being the filter's and at least the last fused
path window's as its centres' confidence and spacing predict it (`KalmanConfig.heading_valid_model`:
a window of unconfident beads waits for more path).

Confidence ∈ [0, 1]: the bead detector's confidence (square-rooted: the product of four
factors in `cslx.runtime.weld` is ≈ 0.2–0.7 on good rendered frames) when a bead was accepted,
otherwise the previous value × `decay` per frame (the prediction stays useful for a few
frames); times 1 / (1 + (σ_e / 2 mm)²). Frames that cannot be used at all (None, wrong size or
dtype, or failing the `FrameGates`: black, saturated, no stripe) give confidence 0, NaN
values, `stripe_ok` False and a log line; `step` never raises on a frame. `stripe_ok` is
True for a frame whose stripe profile was measured, bead or not (the controller's evidence
that the plate is where odometry says while it dead-reckons through a T-junction).

Junction: the pipeline flags a crossing bead on the vertical stripe at x_r = x_j; a
sighting counts if that bead is at least `junction_min_height_mm` high, and the tracker
reports it once two sightings within `junction_window` frames agree within
`junction_tol_mm` after moving the older one by odometry (x_j −= d, then the turn δ about
the robot at the vertical stripe's y_r), which suppresses single-frame false alarms; once
three sightings support it, it holds the junction through up to `junction_hold` frames
without a sighting; a farther confirmed junction replaces a nearer one, and one whose place
was in view unseen for > 20 mm of travel, or nearer than x_ref (where the horizontal stripe
still sees the followed weld), is ignored; sightings where the two stripes cross (x_r within
`junction_crossing_zone_mm` of x_ref) hold a junction but do not move one that sightings
outside that zone place (`cslx.runtime.junction_track.JunctionTrack`).

Steger's σ (`auto_sigma`): on the first frame after a start or `reset` with both stripes
(checked on the first 8 frames, then every 16th: `check_due`), the stripes' width is measured
and σ chosen for it (`cslx.runtime.stripe_width`: the rule and the rig audit), the colour
weights checked (`auto_weights`, `cslx.runtime.stripe_colour`: a green or blue laser is dark
in R − G); each (σ, weights) other than the configured one is compiled once and kept.

The filter (`WeldLineFilter`) and its tuning (`KalmanConfig`): `cslx.runtime.line_filter`.
"""

from __future__ import annotations

import collections
import dataclasses
import logging
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from ..config import MOTION
from .bead_near import near_for, refit_near
from .junction_track import JunctionTrack, cut_by_view
from .line_filter import (
    KalmanConfig,
    WeldLineFilter,
    fit_line,
    offset_at_stripe,
    stripe_x_on_axis,
    width_weight,
)
from .path_heading import PathHeading
from .step_program import step_program
from .stripe_colour import choose_weights
from .stripe_width import check_due, choose_sigma, stripe_widths, with_frame_sigma
from .weld import heading_from_vertical

__all__ = ["FrameGates", "KalmanConfig", "Observation", "Tracker", "LOG_FIELDS", "tracking_config"]

#: The tracking-log columns of docs/contracts.md ("Tracking log"), in order.
LOG_FIELDS = (
    "frame",
    "source",
    "t_s",
    "offset_mm",
    "heading_deg",
    "bead_width_mm",
    "bead_height_mm",
    "junction",
    "junction_x_mm",
    "confidence",
    "latency_ms",
)

NAN = math.nan


@dataclasses.dataclass(frozen=True)
class FrameGates:
    """Quality gates that mark a whole frame unusable (confidence 0, `stripe_ok` False).

    min_brightness: mean grey level (0..255) below which the frame is black.
    max_saturated: largest share of pixels with a channel at 255.
    min_valid_fraction: a stripe needs a centre in this share of its columns (rows):
        Steger's noise floor leaves stray centres in ≈ 20 % of rows on uniform noise,
        while a real stripe gives a centre in nearly every one.
    """

    min_brightness: float = 3.0
    max_saturated: float = 0.5
    min_valid_fraction: float = 0.3


@dataclasses.dataclass
class Observation:
    """What the tracker reports for one frame (docs/contracts.md, tracking log; NaN = unknown).

    frame: index of the frame (0, 1, …). t: capture time, s. offset_mm, heading_deg: the
    filtered weld line (y_r where the stripe crosses it, `offset_at_stripe`). heading_sd_deg:
    its sd (reported even while the heading, NaN, is ≥ `KalmanConfig.heading_valid_deg`).
    bead_width_mm, bead_height_mm: this frame's bead (NaN if none).
    junction, junction_x_mm, junction_y_mm: a confirmed crossing weld, its x_r and the y_r
    where it was measured (the vertical stripe). confidence: [0, 1].
    latency_ms: wall time of `step`. med_steps: MED fixed-point steps (h + v) this frame.
    status: "ok", "no bead", or why the frame was unusable. raw: the pipeline's per-frame
    values (`cslx.runtime.pipeline.SUMMARY_FIELDS`) plus `measured_offset_mm` (this frame's bead
    y_r moved to x_ref with the filtered heading) and `accepted` (the update was used).
    """

    frame: int
    t: float
    offset_mm: float = NAN
    heading_deg: float = NAN
    heading_sd_deg: float = NAN
    bead_width_mm: float = NAN
    bead_height_mm: float = NAN
    junction: bool = False
    junction_x_mm: float = NAN
    junction_y_mm: float = NAN
    confidence: float = 0.0
    latency_ms: float = NAN
    med_steps: int = 0
    status: str = "ok"
    stripe_ok: bool = False
    raw: dict[str, float] = dataclasses.field(default_factory=dict)

    def to_message(self):
        """The `cslx.runtime.Observation` sent over the serial link."""
        from .protocol import Observation as Message

        return Message(
            self.t,
            self.offset_mm,
            self.heading_deg,
            self.bead_width_mm,
            self.bead_height_mm,
            bool(self.junction),
            self.junction_x_mm,
            self.confidence,
        )

    def log_row(self, source: str = "") -> dict[str, Any]:
        """One row of the tracking log: the docs/contracts.md columns, then the extras."""
        row = {
            "frame": self.frame,
            "source": source,
            "t_s": self.t,
            "offset_mm": self.offset_mm,
            "heading_deg": self.heading_deg,
            "bead_width_mm": self.bead_width_mm,
            "bead_height_mm": self.bead_height_mm,
            "junction": int(bool(self.junction)),
            "junction_x_mm": self.junction_x_mm,
            "confidence": self.confidence,
            "latency_ms": self.latency_ms,
            "med_steps": self.med_steps,
            "status": self.status,
            "stripe_ok": int(bool(self.stripe_ok)),
            "heading_sd_deg": self.heading_sd_deg,
        }
        keys = (
            "measured_offset_mm",
            "h_confidence",
            "v_x_mm",
            "v_confidence",
            "v_height_mm",
            "v_heading_deg",
        )
        for k in (*keys, "used_roi"):
            row[k] = self.raw.get(k, NAN)
        return row


def tracking_config():
    """The tracker's default pipeline settings: `cslx.runtime.pipeline_config.tracking_config`
    (its docstring holds the evidence for each setting). Imported on call, so importing the
    tracker does not import JAX."""
    from .pipeline_config import tracking_config as default

    return default()


def _logger(log) -> Callable[[str], None]:
    if log is None:
        log = logging.getLogger("cslx.runtime.tracker")
    if isinstance(log, logging.Logger):
        return log.info
    return log


class Tracker:
    """Compiled per-frame pipeline, its device state, the weld-line filter and junction logic.

    Build it with `from_calibration`; call `step(frame)` per frame (module docstring).
    Attributes: sensor, config (`cslx.runtime.pipeline.PipelineConfig`), kalman (`KalmanConfig`),
    compile_s (start-up compile time, s), frame (frames stepped so far), x_ref (the weld
    line's reference abscissa, mm), lookahead_mm (where the stripe crosses the robot's axis:
    the controller's `ControllerConfig.lookahead_mm`).
    """

    def __init__(
        self,
        sensor,
        config=None,
        *,
        kalman: KalmanConfig | None = None,
        gates: FrameGates | None = None,
        speed_mm_s: float = MOTION.speed_mm_s,
        fps: float = MOTION.fps,
        roi: bool = True,
        auto_sigma: bool = True,
        auto_weights: bool = True,
        log: logging.Logger | Callable[[str], None] | None = None,
    ):
        import jax

        self._log = _logger(log)
        # float32 is the speed path (docs/metrics.md, performance notes). The cast runs in
        # NumPy: an eager `astype` is a small XLA program each, compiled (or read from the
        # persistent cache) at every start-up.
        self.sensor = jax.tree_util.tree_map(
            lambda x: jax.device_put(np.asarray(x, np.float32)) if isinstance(x, jax.Array) else x,
            sensor,
        )
        self._config = config
        self.kalman = kalman or KalmanConfig()
        self.gates = gates or FrameGates()
        self.speed_mm_s = float(speed_mm_s)
        self.fps = float(fps)
        width, height = self.sensor.camera.image_size
        self.image_shape = (int(height), int(width), 3)
        self.x_ref = float(np.asarray(self._stripe_x(), float))
        self.lookahead_mm = stripe_x_on_axis(self._wall, self.x_ref)
        self._roi, self.stripe_width_px = roi, (NAN, NAN)
        self.auto_sigma, self.auto_weights = bool(auto_sigma), bool(auto_weights)
        self._programs: dict[tuple, Any] = {}  # the compiled step per (Steger σ, weights)
        self.sigma0, self.weights0 = self._program(None)
        self.compile_s = self._compile_s
        self._near = near_for(self)  # compiled now, not on the first gated frame (bead_near)
        self.reset()

    def _program(self, sigma: float | None, weights=None) -> tuple:
        """Compile (or reload) the step with Steger's σ = `sigma` px and colour `weights`
        (None: the configured ones); once per (σ, weights) and tracker
        (`cslx.runtime.step_program`). Returns its (σ, weights)."""
        import jax

        height, width = self.image_shape[:2]
        if sigma is None:  # the default configuration is named, not built (no pipeline import)
            config = None
            setting = "tracking_config()" if self._config is None else repr(self._config)
        else:
            config = with_frame_sigma(self.config, sigma, height, width)
            config = dataclasses.replace(config, weights=tuple(weights or config.weights))
            setting = repr(config)
        t0 = time.perf_counter()
        compiled, args, meta = step_program(
            self.sensor, lambda: config or self.config, setting, self._roi, self.image_shape
        )
        self._compile_s = time.perf_counter() - t0
        self._state0 = tuple(args[1:])  # the same state for every σ
        self._fields, key = tuple(meta["fields"]), (meta["sigma"], tuple(meta["weights"]))
        self._programs[key] = compiled
        cache = jax.config.jax_compilation_cache_dir
        self._log(
            f"tracker: compiled the {width}×{height} pipeline (Steger σ {key[0]:g} px, "
            f"weights {key[1]}) "
            f"in {self._compile_s:.2f} s"
            + (f" (persistent cache {cache})" if cache else " (no persistent compile cache)")
        )
        return key

    def _choose_program(self, frame: np.ndarray) -> None:
        """This rig's step program: colour weights (`stripe_colour`), then σ (`stripe_width`)."""
        w0 = self.weights0
        weights, why = choose_weights(frame, w0) if self.auto_weights else (w0, "")
        widths = stripe_widths(frame, weights)
        if not all(math.isfinite(w) for w in widths):
            return  # no stripe to measure: the next frame tries again
        self._check_pending, self.stripe_width_px = False, widths
        size = min(self.image_shape[:2])
        sigma = choose_sigma(max(widths) if self.auto_sigma else NAN, self.sigma0, size)
        if weights != self.weights:
            self._log(f"tracker: colour weights {weights}: {why}")
        if sigma != self.sigma:
            self._log(f"tracker: stripes {widths[0]:.1f} / {widths[1]:.1f} px wide: σ {sigma:g} px")
        if (sigma, weights) not in self._programs:
            self._program(sigma, weights)
        self._compiled = self._programs[sigma, weights]
        self.sigma, self.weights = sigma, weights

    @property
    def config(self):
        """The pipeline's settings (`cslx.runtime.pipeline.PipelineConfig`); default
        `tracking_config()`, built on first use."""
        if self._config is None:
            self._config = tracking_config()
        return self._config

    @classmethod
    def from_calibration(cls, path_or_sensor, config=None, log=None, **kwargs) -> Tracker:
        """A tracker for a calibration JSON file (docs/contracts.md) or a `Sensor`.

        Keyword arguments go to `Tracker` (kalman, gates, speed_mm_s, fps, roi, auto_*).
        Raises `cslx.sensor.CalibrationError` for a bad file.
        """
        from ..sensor import Sensor, load_sensor

        sensor = path_or_sensor
        if not isinstance(sensor, Sensor):
            sensor = load_sensor(path_or_sensor)
        sensor.require_planes(2, "tracking")  # CalibrationError naming what is missing
        return cls(sensor, config, log=log, **kwargs)

    def _stripe_x(self) -> float:
        """x_r where the horizontal stripe meets the wall (z_r = 0) below the optical axis.

        `cslx.sensor.triangulate` of the principal point (u0, v0), in NumPy: its normalised
        coordinates are (0, 0), where distortion vanishes, so its ray is the optical axis
        (0, 0, 1) and the plane a x + b y + c z + 1 = 0 meets it at z = −1/c (eq. (27)).
        Running `triangulate` eagerly instead compiled ~20 small XLA programs at start-up
        (0.2–0.4 s on the 2-core machine, issue 13).
        """
        s = self.sensor
        n = np.asarray(s.planes, float)[s.plane_index(0)]
        n_r = np.asarray(s.R_cr, float) @ n  # the plane in the robot frame: on the wall z_r = 0
        self._wall = (n_r[0], n_r[1], 1.0 - n_r @ np.asarray(s.T_cr, float))  # `offset_at_stripe`
        X_c = np.array([0.0, 0.0, -1.0 / n[2]]) if n[2] != 0 else np.full(3, np.nan)
        return float(np.asarray(s.R_cr, float)[0] @ X_c + float(np.asarray(s.T_cr, float)[0]))

    def reset(self) -> None:
        """Forget everything learnt from past frames (state, filter, junction sightings)."""
        self._state = self._state0
        self.filter = WeldLineFilter(self.kalman, self.x_ref)
        self.frame = 0
        self._t = 0.0
        self._confidence = 0.0
        self._junctions = JunctionTrack.from_config(self.kalman, self.x_ref)
        self._widths: collections.deque[float] = collections.deque(maxlen=self.kalman.width_memory)
        self._odd_widths = 0
        self._path = PathHeading(self.kalman, self.x_ref)  # the recent accepted bead centres
        self._check_pending = self.auto_sigma or self.auto_weights  # again after a reset
        self.sigma, self.weights = self.sigma0, self.weights0
        self._compiled = self._programs[self.sigma0, self.weights0]

    def _width_factor(self, width: float) -> float:
        """Weight of a bead whose width departs from the recent accepted ones (docstring)."""
        c = self.kalman
        f = width_weight(width, self._widths, c.width_tol)
        if len(self._widths) < 5 or not math.isfinite(width):
            return f
        if f == 1.0:
            self._odd_widths = 0
            return f
        self._odd_widths += 1
        if self._odd_widths >= c.width_memory // 2:  # the weld changed (a turn): relearn
            self._widths.clear()
            self._odd_widths = 0
        return f

    # ------------------------------------------------------------------------------- step
    def _motion(self, dt, odometry) -> tuple[float, float]:
        if odometry is None:
            return self.speed_mm_s * dt, 0.0
        if isinstance(odometry, int | float):
            return float(odometry), 0.0
        d, delta = odometry
        return float(d), float(delta)

    def _bad(self, obs: Observation, why: str) -> Observation:
        obs.status = why
        obs.confidence = 0.0
        self._confidence = 0.0
        self._log(f"tracker: frame {obs.frame}: {why}")
        return obs

    def step(
        self, frame, *, dt: float | None = None, odometry=None, t: float | None = None
    ) -> Observation:
        """Process one frame; never raises on a bad frame (low-confidence observation).

        Args:
            frame: (H, W, 3) uint8 RGB image of the calibrated size (or anything else, which
                is reported as unusable).
            dt: seconds since the previous frame (default 1/fps).
            odometry: robot motion since the previous frame: forward distance in mm, or
                (distance mm, heading change rad CCW +) from telemetry; default nominal
                speed × dt, no turn.
            t: capture time, s (default: the previous t + dt).
        """
        start = time.perf_counter()
        dt = 1.0 / self.fps if dt is None or not dt > 0 else float(dt)
        self._t = self._t + dt if t is None else float(t)
        index, self.frame = self.frame, self.frame + 1
        obs = Observation(frame=index, t=self._t)
        d, delta = self._motion(dt, odometry)
        if index > 0:
            self.filter.predict(d, delta, odometry=odometry is not None)
            self._path.move(d, delta)
            self._junctions.move(d, delta)
        try:
            why = self._check(frame)
            if why is None:
                obs = self._measure(np.asarray(frame), obs, d)
            else:
                obs = self._bad(obs, why)
        except Exception as e:  # noqa: BLE001 — the loop must survive any frame
            obs = self._bad(obs, f"pipeline error: {type(e).__name__}: {e}")
        obs.latency_ms = 1000.0 * (time.perf_counter() - start)
        return obs

    def _check(self, frame) -> str | None:
        if frame is None:
            return "no frame"
        if not isinstance(frame, np.ndarray):
            kind = type(frame).__name__
            try:
                frame = np.asarray(frame)
            except Exception:  # noqa: BLE001
                return f"not an image ({kind})"
            if frame.ndim == 0 or frame.dtype.kind not in "uifb":
                return f"not an image ({kind})"
        if frame.shape != self.image_shape:
            return f"wrong frame shape {frame.shape}, expected {self.image_shape}"
        if frame.dtype != np.uint8:
            return f"wrong frame dtype {frame.dtype}, expected uint8"
        return None

    def _measure(self, frame: np.ndarray, obs: Observation, d: float) -> Observation:
        if self._check_pending and check_due(obs.frame):
            self._choose_program(frame)
        summary, points_h, points_v, *state = self._compiled(frame, *self._state)
        self._state = tuple(state)
        raw = dict(zip(self._fields, np.asarray(summary, float).tolist(), strict=True))
        obs.raw = raw
        obs.med_steps = int(raw["med_steps_h"] + raw["med_steps_v"])
        width, height = self.image_shape[1], self.image_shape[0]
        g = self.gates
        if raw["brightness"] < g.min_brightness:
            return self._bad(obs, "black frame")
        if raw["saturated"] > g.max_saturated:
            return self._bad(obs, f"saturated frame ({100 * raw['saturated']:.0f} % clipped)")
        f = g.min_valid_fraction
        if raw["n_valid_h"] < f * width and raw["n_valid_v"] < f * height:
            return self._bad(obs, "no stripe found")
        obs.stripe_ok = True

        kf = self.filter
        accepted = False
        raw["v_heading_deg"] = raw["v_heading_sd_deg"] = NAN
        if raw["h_found"] > 0.5:
            w = width_weight(raw["h_width_mm"], self._widths, self.kalman.width_tol)
            if not kf.innovation_ok(raw["h_x_mm"], raw["h_y_mm"], raw["h_confidence"] * w):
                refit_near(raw, np.asarray(points_h), self, self.config.weld)
            conf = raw["h_confidence"] * self._width_factor(raw["h_width_mm"])
            accepted = kf.update(raw["h_x_mm"], raw["h_y_mm"], conf, raw["h_width_mm"])
            if accepted and math.isfinite(raw["h_width_mm"]):
                self._widths.append(raw["h_width_mm"])
            wh = self._path.update(
                kf, raw["h_x_mm"], raw["h_y_mm"], conf, raw["h_width_mm"], accepted
            )
            raw["window_heading_deg"], raw["window_heading_sd_deg"] = wh
            obs.bead_width_mm, obs.bead_height_mm = raw["h_width_mm"], raw["h_height_mm"]
            if accepted and self.kalman.use_vertical_heading:
                th, sd = heading_from_vertical(
                    np.asarray(points_h),
                    np.asarray(points_v),
                    raw["h_y_mm"],
                    raw["h_width_mm"],
                    self.x_ref,
                )
                raw["v_heading_deg"], raw["v_heading_sd_deg"] = th, sd
                if math.isfinite(th):
                    kf.update_heading(math.radians(th), math.radians(sd))
        raw["accepted"] = float(accepted)
        if kf.initialised:
            theta = kf.x[1]
            raw["measured_offset_mm"] = raw["h_y_mm"] - math.tan(theta) * (
                raw["h_x_mm"] - self.x_ref
            )
        else:
            raw["measured_offset_mm"] = NAN
        c = self.kalman
        if accepted:
            self._confidence = math.sqrt(max(raw["h_confidence"], 0.0))
            obs.status = "ok"
        else:
            self._confidence *= c.decay
            obs.status = "no bead" if raw["h_found"] < 0.5 else "bead rejected (gate)"
        if kf.initialised:
            obs.offset_mm = offset_at_stripe(kf.x[0], math.tan(kf.x[1]), self.x_ref, self._wall)
            sd_e, sd_th = math.sqrt(kf.P[0, 0]), math.sqrt(kf.P[1, 1])
            if c.heading_valid_model and math.isfinite(self._path.model_var):
                sd_th = max(sd_th, math.sqrt(self._path.model_var))
            obs.heading_sd_deg = math.degrees(sd_th)
            if math.degrees(sd_th) < c.heading_valid_deg:
                obs.heading_deg = math.degrees(kf.x[1])
            obs.confidence = float(np.clip(self._confidence / (1.0 + (sd_e / 2.0) ** 2), 0.0, 1.0))
        self._junction(obs, raw, np.asarray(points_v))
        return obs

    def _junction(self, obs: Observation, raw: dict, points_v: np.ndarray) -> None:
        c = self.kalman
        tall = raw["v_height_mm"] >= c.junction_min_height_mm
        x = raw["v_x_mm"] if raw["junction"] > 0.5 and tall else None
        xs = points_v[:, 0][np.isfinite(points_v[:, 0])] if points_v.ndim == 2 else points_v[:0]
        extent = (float(xs.min()), float(xs.max())) if xs.size else None
        if x is not None and cut_by_view(x, raw["v_width_mm"], extent, c.junction_cut_margin_mm):
            x = None
        ys = points_v[:, 1][np.isfinite(points_v[:, 1])] if points_v.ndim == 2 else points_v[:0]
        y = float(np.median(ys)) if ys.size else None
        line = None
        if c.junction_bar_slope and points_v.ndim == 2:
            both = np.all(np.isfinite(points_v[:, :2]), axis=1)
            xy = points_v[both, :2]
            if len(xy) >= 10 and np.ptp(xy[:, 0]) > 0:
                line = fit_line(xy[:, 0], xy[:, 1])  # the stripe: y_r = y0 + m x_r
        xj = self._junctions.update(obs.frame, x, extent, y, line)
        if math.isfinite(xj):
            obs.junction = True
            obs.junction_x_mm = xj
            obs.junction_y_mm = self._junctions.stripe_y
