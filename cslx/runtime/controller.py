"""Path-following controller for the differential-drive wall-climbing robot.

Law (FOLLOW). With the weld's lateral offset e (mm, y_r of the weld at the horizontal
stripe, + = weld to the left) and heading θ (rad, weld direction relative to x_r, CCW +):

    ω = k_heading · θ + k_offset · v · e

Linearised about the line (robot lateral error d = −e at the stripe, heading error ψ = −θ,
ḋ = v ψ, ψ̇ = ω) this is d̈ + k_heading ḋ + k_offset v² d = 0 plus extra damping from the
stripe being a look-ahead point L ahead of the wheels (L = 150 mm in the default rig): the
offset there is e = −(d + L ψ), so the closed loop is

    s² + (k_heading + k_offset v L) s + k_offset v² = 0,

damping ratio ζ = k_heading / (2 v √k_offset) + L √k_offset / 2, independent of v for the
look-ahead part. The tracked quantity is e itself (the look-ahead point's distance from the
weld), which decays at the rate k_offset v L. The defaults (k_offset = 1/40² mm⁻²,
k_heading = 0.05 s⁻¹) give ζ ≈ 1.9 and e a time constant of 1 / (k_offset v L) ≈ 0.36 s at
30 mm/s (the slower mode, the robot's heading, ≈ L / v = 5 s). With 1/80² (ζ ≈ 1, e's time
constant 1.4 s) the kinematic loop (this controller, a unicycle, 0.3 mm measurement noise,
4 mm and 3° initial error) ended 0.41 mm mean / 0.59 mm max off after 5 s; with 1/40²
0.11 / 0.34 mm (issue 12: tracking error mean ≤ 0.5 mm, max ≤ 2 mm). An unknown heading
(NaN) drops the heading term: the look-ahead alone still converges, and at the same rate
(k_heading adds 0.05 s⁻¹ to the k_offset v L ≈ 2.8 s⁻¹ of damping): from a look-ahead error
of 1.5–2.6 mm at rest (the end of a turn) the kinematic loop's error over the next 40
frames was the same within 0.04 mm with the heading known, unknown, or unknown for 20
frames (issue 12: the tracker reports no heading for the first ≈ 20–30 frames on the bar).

Speed: v = v_nominal scaled by confidence between `min_confidence` (stop) and
`full_confidence`; then limits on v, ω, their accelerations and each wheel's speed (the
curvature is kept when a wheel saturates). While the confidence falls from one update to the
next the speed may not rise (in every state).

Never blind. An update is a *confident observation* when it carries a finite offset with
confidence ≥ `min_confidence`; in APPROACH_JUNCTION and TURN, where the horizontal stripe is
expected to have left the followed bead (it runs `Rig.lookahead_mm` ahead, past the end of
the stem), a frame whose stripe profile was measured (``sensor_ok``: not black, saturated,
lost or stripe-less) or that sights the junction counts too — it confirms the plate ahead is
where odometry says. After `blind_stop_s` (default 0.5 s) of updates without one, the
command is an immediate stop (v = ω = 0) in every state; the state and the junction
distance are kept, and the first confident observation resumes the manoeuvre. `dt` is the
caller's measured time between frames (frame timestamps or the clock), never assumed.

T-junction state machine:
FOLLOW → (junction seen, confident) → APPROACH: keep following at `approach_speed` (default the
nominal speed: the vertical stripe sees the junction from ≈ 205 to 100 mm ahead, 70 sightings
at 1.5 mm per frame, and the braking limit below slows the robot in time; once x_j <
`lookahead_mm` + `stem_end_mm` the stripe is past the stem's end and an offset that leaves the
stem's last confident line, dead-reckoned, by more than `stem_gate_mm` is ignored), the
junction distance x_j along the robot's axis (a sighting x on the vertical stripe, at y_r =
y_v, plus y_v · tan θ: the crossing weld is perpendicular to the followed one, whose heading is
θ; taking the sighting as the axis distance, the robots of Figure 22's sunny runs at dev seeds
2201 and 2203, 0.9° and 1.1° off the stem, came to rest 1.44 and 1.32 mm past the T, with it
−0.06 and −0.18 mm) is dead-reckoned (x_j −= v dt) between sightings and reset by each sighting
that agrees with it within `junction_gate_mm` (issue 12: in rendered sunlight a stray report
where the stripes cross, 42 mm from the truth, pushed the turn past the T), or by three
rejected sightings in a row that agree with each other (the first sighting was the stray one);
when x_j ≤ `turn_radius_mm` + `junction_tolerance_mm` + the braking distance v²/(2 `accel_max`)
(the robot brakes while it starts turning; without that term it came to rest ≈ 1.3–2.9 mm past
the T in Figure 22's runs) → TURN. In place (turn_radius_mm = 0) the robot turns where it comes
to rest, so it brakes onto x_j: the trigger is x_j ≤ tolerance + the discrete braking distance
+ one frame's travel, and each TURN frame's speed is the largest from which braking at
`accel_max` still stops within the dead-reckoned x_j (issue 12: the former fixed ramp stopped
wherever the trigger fell within a frame's travel, −1.25 to +0.2 mm, −0.55 mm mean, in a
kinematic sweep at 30 mm/s and 20 fps). TURN: rotate by 90° plus the followed weld's last
heading estimate (the crossing weld is perpendicular to the weld, not to the robot: a 1°
heading left the look-ahead point 150 mm·sin 1.7° ≈ 4.4 mm off the new weld after the turn) —
the last within `square_deg` of the robot's heading: a tracker that restarts on the bar near
the T reports it ≈ 90° off (Figure 22, glare, one run at `6826bfa`: an 88° estimate at
confidence 0.21, twenty frames before the turn, took the turn to 100° and left the look-ahead
point 22.8 mm off the new weld; the robot keeps the weld within a few degrees, so a larger
heading is not the followed weld's) — ± (`turn_direction` +1 left/CCW, −1 right) in place
(turn_radius_mm = 0) or on an arc; the turned angle is integrated from the commanded ω, or from
the measured heading when the caller passes it → FOLLOW, ignoring junction sightings for
`junction_ignore_mm` of travel. The turn ends on the crossing weld as the stripe sees it: once
the observed offset e (confident, the weld about square) puts the rest of the turn,
`turn_direction` · atan(e / `lookahead_mm`), within `turn_finish_deg` of the odometric rest,
that is the rest (`_finish_on_weld`), so the look-ahead point lands on the new weld whatever
the stop position and the followed weld's heading estimate left. The error after the turn is
largest on its first frame and decays from there with the look-ahead's time constant (FOLLOW
above); the odometric end left it 1.44 mm at Figure 22's dev seed 2201 in glare: 0.92 mm of
stop past the bar's centre line plus 150 mm · tan 0.20° of heading estimate.

Pure Python; no I/O.
"""

from __future__ import annotations

import dataclasses
import enum
import math

from ..config import MOTION, RIG

__all__ = ["ControllerConfig", "Command", "PathController", "State", "wheel_speeds"]

#: The in-place turn plans its braking onto x_j at this fraction of `accel_max`: the rest is
#: headroom to brake harder when the measured travel (`travelled_mm`) shows the wheels lag
#: the command (planned at the limit itself, a half-frame lag ended 0.75 mm past the T).
_BRAKE_PLAN = 0.8


class State(enum.Enum):
    FOLLOW = "follow"
    APPROACH_JUNCTION = "approach_junction"
    TURN = "turn"


@dataclasses.dataclass(frozen=True)
class ControllerConfig:
    """Gains and limits (mm, s, rad)."""

    v_nominal: float = MOTION.speed_mm_s
    v_max: float = 60.0
    omega_max: float = 0.5
    accel_max: float = 60.0  # mm/s²
    alpha_max: float = 1.5  # rad/s²
    wheel_max: float = 80.0  # mm/s, each wheel
    track_mm: float = 200.0  # wheel separation
    k_offset: float = 1.0 / 40.0**2  # rad/mm² (ω per v per mm offset)
    k_heading: float = 0.05  # 1/s
    min_confidence: float = 0.2
    full_confidence: float = 0.6
    approach_speed: float = MOTION.speed_mm_s
    turn_direction: int = +1  # +1 left (CCW), −1 right
    turn_rate: float = 0.3  # rad/s during TURN
    turn_radius_mm: float = 0.0  # 0 = in place
    junction_tolerance_mm: float = 0.5
    junction_ignore_mm: float = 150.0
    junction_min_confidence: float = 0.3
    junction_gate_mm: float = 15.0  # a later sighting farther than this from x_j is ignored
    blind_stop_s: float = 0.5  # s without a confident observation → stop
    lookahead_mm: float = RIG.lookahead_mm  # x_r of the observed offset (`Tracker.lookahead_mm`)
    # the end of the TURN may move by up to this much to land the look-ahead point on the
    # crossing weld as observed (`PathController._finish_on_weld`); 0: odometry alone.
    # Figure 22 (`experiments/fig22_tracking.py` defaults), dev seeds 2201 / 2203 / 2204,
    # every nuisance, paired runs, odometry alone → 3°: tracking error after the turn, worst
    # max 1.437 → 0.572 mm (glare 2201 1.437 → 0.138, clean 2204 1.043 → 0.135), median max
    # 0.288 → 0.150, mean over the 12 runs 0.139 → 0.106 mm; all turned, no blind stop. Not
    # better everywhere: glare 2204 0.105 / 0.214 → 0.234 / 0.440 mm (mean / max): the
    # tracker's offset of the bar was 0.47 mm off when the turn ended, and the turn lands on
    # the estimate. The turn's end moved by ≤ 0.56° in the 12 runs; 3° leaves room for a
    # 1° heading estimate error (2.6 mm at 150 mm) and rejects the old weld's prediction
    # (≈ 90° off)
    turn_finish_deg: float = 3.0
    # a weld heading beyond this (deg, from the robot's) is not the followed weld's: it
    # neither sets the turn's extra angle nor ends a turn (module docstring, TURN)
    square_deg: float = 15.0
    # APPROACH_JUNCTION: once the junction x_j is nearer than `lookahead_mm` + this, the
    # horizontal stripe lies beyond the stem's end (at the bar or past it) and its offset is not
    # the followed weld's unless it keeps to the stem's line as last confidently observed,
    # dead-reckoned by the commands (`stem_gate_mm`; module docstring); ≈ the bar's half width.
    # Found on a projector rolled 25° (`experiments/closed_loop_roll.py`), whose leaning stripe
    # crosses the bar obliquely: the tracker took pieces of the bar for the stem and reported
    # offsets of −250 … +550 mm, confident enough to steer
    stem_end_mm: float = 10.0
    # … and there an offset further than this from that line is ignored (the robot goes
    # straight, dead-reckoning); the tracker's own prediction, which follows the same line,
    # passes
    stem_gate_mm: float = 3.0

    def __post_init__(self):
        if self.turn_direction not in (-1, 1):
            raise ValueError(
                f"turn_direction must be +1 (left) or -1 (right), got {self.turn_direction}"
            )
        names = ("v_max", "omega_max", "accel_max", "alpha_max", "wheel_max", "track_mm")
        for name in (*names, "blind_stop_s"):
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")
        if not self.full_confidence > self.min_confidence:
            raise ValueError("full_confidence must exceed min_confidence")


@dataclasses.dataclass(frozen=True)
class Command:
    """One control output: body velocities and the equivalent wheel speeds."""

    v_mm_s: float
    omega_rad_s: float
    left_mm_s: float
    right_mm_s: float
    state: State


def wheel_speeds(v: float, omega: float, track_mm: float) -> tuple[float, float]:
    """(left, right) wheel speeds, mm/s, of body velocity v (mm/s), ω (rad/s, CCW +)."""
    return v - omega * track_mm / 2.0, v + omega * track_mm / 2.0


def _clip(x: float, lo: float, hi: float) -> float:
    return min(max(x, lo), hi)


def _finite(x, default: float = 0.0) -> float:
    return float(x) if x is not None and math.isfinite(x) else default


class PathController:
    """Offset + heading → (v, ω) with limits, confidence slowdown and the T-junction turn."""

    def __init__(self, config: ControllerConfig | None = None):
        self.config = config or ControllerConfig()
        self.reset()

    def reset(self) -> None:
        self.state = State.FOLLOW
        self.v = 0.0
        self.omega = 0.0
        self.junction_x: float | None = None
        self._stray: list[float] = []  # junction sightings the gate rejected, dead-reckoned
        self.turned = 0.0
        self._turn_start_heading: float | None = None
        self._weld_heading = 0.0  # last finite heading of the followed weld, rad
        # the followed weld's line (offset mm, heading rad) at the last confident observation,
        # dead-reckoned since by the commands (`stem_end_mm`)
        self._stem_line: tuple[float, float] | None = None
        self._junction_y = 0.0  # y_r where the junction sightings are taken, mm
        self._predicted = 0.0  # v·dt taken off x_j at the last update (`travelled_mm`)
        self._turn_angle = math.pi / 2
        self._ignore_left = 0.0
        self.turns_completed = 0
        #: seconds since the last confident observation (module docstring, "Never blind")
        self.blind_s = 0.0
        self.blind_stops = 0
        self._last_confidence = 0.0
        self._cap = math.inf  # |v| may not exceed this in this update (confidence falling)

    def _limit(self, v_target: float, omega_target: float, dt: float) -> tuple[float, float]:
        c = self.config
        cap = min(c.v_max, self._cap)
        v_target = _clip(v_target, -cap, cap)
        omega_target = _clip(omega_target, -c.omega_max, c.omega_max)
        # wheel saturation: scale both to keep the curvature
        left, right = wheel_speeds(v_target, omega_target, c.track_mm)
        peak = max(abs(left), abs(right))
        if peak > c.wheel_max:
            v_target *= c.wheel_max / peak
            omega_target *= c.wheel_max / peak
        v = self.v + _clip(v_target - self.v, -c.accel_max * dt, c.accel_max * dt)
        omega = self.omega + _clip(omega_target - self.omega, -c.alpha_max * dt, c.alpha_max * dt)
        # the acceleration step from a saturated previous command may not exceed the wheels
        left, right = wheel_speeds(v, omega, c.track_mm)
        peak = max(abs(left), abs(right))
        if peak > c.wheel_max:
            v *= c.wheel_max / peak
            omega *= c.wheel_max / peak
        return v, omega

    def _follow(self, offset: float, heading_deg: float, speed: float) -> tuple[float, float]:
        c = self.config
        theta = math.radians(_finite(heading_deg))
        return speed, c.k_heading * theta + c.k_offset * speed * offset

    def update(
        self,
        dt: float,
        offset_mm: float,
        heading_deg: float = math.nan,
        confidence: float = 1.0,
        junction: bool = False,
        junction_x_mm: float = math.nan,
        robot_heading_rad: float | None = None,
        sensor_ok: bool = False,
        junction_y_mm: float = 0.0,
        travelled_mm: float | None = None,
    ) -> Command:
        """One control step of `dt` seconds from the latest observation.

        Args:
            dt: measured time since the previous update, s (> 0, finite).
            offset_mm, heading_deg, confidence, junction, junction_x_mm: the observation
                (docs/contracts.md tracking-log meanings; NaN = unknown).
            robot_heading_rad: measured robot heading (odometry), used to end the TURN;
                without it the commanded ω is integrated.
            sensor_ok: this frame's stripe profile was measured (the tracker's
                `Observation.stripe_ok`); counts as a confident observation only in
                APPROACH_JUNCTION and TURN (module docstring, "Never blind").
            junction_y_mm: y_r where `junction_x_mm` was measured (the vertical stripe's,
                `Observation.junction_y_mm`); the crossing weld, perpendicular to the
                followed one, meets the robot's axis at x_j + y · tan θ (θ the followed
                weld's heading).
            travelled_mm: the measured forward distance since the previous update
                (odometry); x_j, dead-reckoned with the commanded v·dt, is corrected by the
                difference (the wheels lag a braking command: Figure 22's simulated robot,
                400 mm/s² per wheel, went 0.3 mm past the commanded stop while it braked
                and started to turn).
        """
        if travelled_mm is not None and math.isfinite(travelled_mm):
            slip = self._predicted - float(travelled_mm)
            if self.junction_x is not None:
                self.junction_x += slip
            self._stray = [x + slip for x in self._stray]
        self._predicted = 0.0
        if junction_y_mm is not None and math.isfinite(junction_y_mm):
            self._junction_y = float(junction_y_mm)
        if not (dt > 0 and math.isfinite(dt)):
            raise ValueError(f"dt must be positive and finite, got {dt}")
        c = self.config
        if self._stem_line is not None:  # the last command's motion (e' = e + dθ − Lδ)
            e, th = self._stem_line
            d, delta = self.v * dt, self.omega * dt
            self._stem_line = (e + d * math.tan(th) - c.lookahead_mm * delta, th - delta)
        confidence = _finite(confidence)
        seen_offset = math.isfinite(offset_mm) if offset_mm is not None else False
        scale = _clip(
            (confidence - c.min_confidence) / (c.full_confidence - c.min_confidence), 0, 1
        )
        sighted = (
            bool(junction)
            and math.isfinite(_finite(junction_x_mm, math.nan))
            and self._ignore_left <= 0
        )
        confident = seen_offset and confidence >= c.min_confidence
        if self.state is not State.FOLLOW:
            confident = confident or bool(sensor_ok) or sighted
        # speed may not rise on a frame that is not confident or less confident than the last.
        # Dead-reckoning to a confirmed junction (APPROACH/TURN without a bead) the evidence
        # is the measured plate: its confidence is 1 with a stripe profile, else 0 (a
        # decaying bead confidence there would freeze the approach at a crawl).
        evidence = confidence
        if self.state is not State.FOLLOW and (not seen_offset or scale <= 0.0):
            evidence = 1.0 if (sensor_ok or sighted) else 0.0
        falling = evidence < self._last_confidence
        self._last_confidence = evidence
        self._cap = abs(self.v) if (falling or not confident) else math.inf
        self.blind_s = 0.0 if confident else self.blind_s + dt
        if self.blind_s > c.blind_stop_s:
            if self.v != 0.0 or self.omega != 0.0:
                self.blind_stops += 1
            if self.state is State.TURN and robot_heading_rad is None:
                self.turned += abs(self.omega) * dt  # the last interval's rotation
            self._advance_junction(self.v, dt)
            return self._emit(0.0, 0.0)  # blind: stop now, keep the state

        h = _finite(heading_deg, math.nan)
        if self.state is not State.TURN and math.isfinite(h) and abs(h) <= c.square_deg:
            self._weld_heading = math.radians(h)
        if self.state is State.TURN:
            if robot_heading_rad is not None:
                if self._turn_start_heading is None:
                    self._turn_start_heading = robot_heading_rad
                d = robot_heading_rad - self._turn_start_heading
                self.turned = abs(math.atan2(math.sin(d), math.cos(d)))
            else:
                self.turned += abs(self.omega) * dt
            remaining = self._turn_angle - self.turned
            if seen_offset and confidence >= c.min_confidence:
                remaining = self._finish_on_weld(float(offset_mm), heading_deg, remaining)
            if remaining <= 1e-3:
                self.state = State.FOLLOW
                self._ignore_left = c.junction_ignore_mm
                self.turns_completed += 1
                self.junction_x = None
                self._stray = []
                self._stem_line = None
                v_t, w_t = 0.0, 0.0
            else:
                # slow down near the end so the angle does not overshoot: |ω| ≤ √(α θ') with θ'
                # the remaining angle less what the last command still turns (one frame of
                # lag) and half the braking rate, as ω can fall only α·dt per frame (with
                # √(2 α θ) Figure 22's robot went on turning for 1–1.5° after the turn ended)
                ahead = max(remaining - abs(self.omega) * dt, 0.0)
                rate = min(c.turn_rate, math.sqrt(c.alpha_max * ahead), remaining / dt)
                w_t = c.turn_direction * rate
                v_t = rate * c.turn_radius_mm
                if c.turn_radius_mm == 0.0 and self.junction_x is not None:
                    # in place: brake onto the junction, not by a fixed ramp (module docstring)
                    v_t = min(self.v, self._stop_speed(self.junction_x, dt))
            v, w = self._limit(v_t, w_t, dt)
            self._advance_junction(v, dt)
            return self._emit(v, w)

        past_stem = (
            self.state is State.APPROACH_JUNCTION
            and self.junction_x is not None
            and self.junction_x < c.lookahead_mm + c.stem_end_mm
        )
        if seen_offset and scale > 0.0 and not past_stem and self.state is not State.TURN:
            self._stem_line = (float(offset_mm), math.radians(_finite(h, 0.0)))
        if past_stem and seen_offset:
            # the stripe is beyond the stem's end: an offset that leaves the stem's line as
            # last confidently observed (dead-reckoned) is not the followed weld's
            line = self._stem_line
            if line is None or abs(float(offset_mm) - line[0]) > c.stem_gate_mm:
                seen_offset = False
        if self.state is State.APPROACH_JUNCTION and (not seen_offset or scale <= 0.0):
            # The horizontal stripe runs 150 mm ahead: near the T it has passed the end of
            # the followed weld and sees no bead. Expected: go straight, dead-reckoning on
            # odometry, while the frames confirm the plate (else the blind stop above).
            if sighted:
                self._sight(float(junction_x_mm))
            v, w = self._limit(self._approach_speed(c.approach_speed), 0.0, dt)
            self._advance_junction(v, dt)
            if self._at_turning_point(dt):
                self._start_turn()
            return self._emit(v, w)
        if not seen_offset or scale <= 0.0:
            v, w = self._limit(0.0, 0.0, dt)  # lost the weld: brake, hold still
            self._advance_junction(v, dt)
            return self._emit(v, w)

        if self._ignore_left > 0:
            junction = False
        if junction and confidence >= c.junction_min_confidence and math.isfinite(junction_x_mm):
            self._sight(float(junction_x_mm))
            if self.state is State.FOLLOW:
                self.state = State.APPROACH_JUNCTION

        speed = c.v_nominal * scale
        if self.state is State.APPROACH_JUNCTION:
            if self._at_turning_point(dt):
                self._start_turn()
                v_t = 0.0
                if c.turn_radius_mm == 0.0:  # brake onto x_j (`_at_turning_point`)
                    v_t = min(self.v, self._stop_speed(self.junction_x, dt))
                v, w = self._limit(v_t, 0.0, dt)
                self._advance_junction(v, dt)
                return self._emit(v, w)
            speed = self._approach_speed(min(speed, c.approach_speed))
        v_t, w_t = self._follow(float(offset_mm), heading_deg, speed)
        v, w = self._limit(v_t, w_t, dt)
        self._advance_junction(v, dt)
        return self._emit(v, w)

    def _sight(self, x_mm: float) -> None:
        """A junction sighting: the first one sets x_j; later ones correct it only when they
        agree with the dead-reckoned x_j within `junction_gate_mm` (a stray report, e.g. where
        the two stripes cross, must not push the turning point back). x_j is where the
        crossing weld meets the robot's axis: the sighting, taken at y_r = y_v (the vertical
        stripe, ≈ −39 mm on the default rig), plus y_v · tan θ (module docstring)."""
        x_mm = x_mm + self._junction_y * math.tan(self._weld_heading)
        gate = self.config.junction_gate_mm
        if self.junction_x is None or abs(x_mm - self.junction_x) <= gate:
            self.junction_x = x_mm
            self._stray = []
            return
        # three rejected sightings in a row that agree with each other: x_j was wrong
        self._stray = [*self._stray[-2:], x_mm]
        if len(self._stray) == 3 and max(self._stray) - min(self._stray) <= gate:
            self.junction_x = x_mm
            self._stray = []

    def _approach_speed(self, speed: float) -> float:
        """Speed that can still brake (accel_max) to rest at the turning point."""
        c = self.config
        room = max(self.junction_x - c.turn_radius_mm, 0.0)
        return min(speed, math.sqrt(2.0 * c.accel_max * room))

    def _braking_distance(self, v: float, dt: float) -> float:
        """Distance covered after a frame at speed v while braking at the planned rate a'
        (`_BRAKE_PLAN` · `accel_max`): v falls by b = a'·dt a frame, so dt·Σ_{k≥1}
        max(v − k b, 0) (v²/(2a') − v·dt/2 when v is a multiple of b)."""
        b = _BRAKE_PLAN * self.config.accel_max * dt
        n = math.floor(v / b) if b > 0 else 0
        return dt * (n * v - b * n * (n + 1) / 2.0)

    def _stop_speed(self, room: float, dt: float) -> float:
        """The largest speed v this frame from which braking at the planned rate comes to rest
        within `room` (dt·v + the braking distance ≤ room; bisection, both increase with v)."""
        if room <= 0.0:
            return 0.0
        lo, hi = 0.0, room / dt
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            if dt * mid + self._braking_distance(mid, dt) <= room:
                lo = mid
            else:
                hi = mid
        return lo

    def _at_turning_point(self, dt: float) -> bool:
        """x_j (dead-reckoned past this frame's motion) within the tolerance plus what the
        robot needs to brake to rest, or one more frame at this speed would leave less.

        In place (turn_radius_mm = 0) the TURN then brakes onto x_j with `_stop_speed`
        (issue 12): the former fixed ramp, started once x_j ≤ tolerance + v²/(2a), stopped
        wherever the trigger fell within a frame's travel (v·dt = 1.5 mm in Figure 22):
        −0.55 mm mean, −1.25 to +0.2 mm, in a kinematic sweep of the start distance."""
        c = self.config
        stop = self._braking_distance(self.v, dt)
        if c.turn_radius_mm == 0.0:
            return self.junction_x <= c.junction_tolerance_mm + stop + self.v * dt
        stop = self.v * self.v / (2.0 * c.accel_max)
        return self.junction_x <= c.turn_radius_mm + c.junction_tolerance_mm + stop

    def _start_turn(self) -> None:
        self.state = State.TURN
        self.turned = 0.0
        self._turn_start_heading = None
        # the crossing weld is perpendicular to the followed one, not to the robot: turn by
        # 90° plus the followed weld's last heading (CCW +), at most 10° either way
        c = self.config
        extra = max(-0.175, min(0.175, c.turn_direction * self._weld_heading))
        self._turn_angle = math.pi / 2 + extra

    def _finish_on_weld(self, offset_mm: float, heading_deg: float, remaining: float) -> float:
        """The rest of the turn from the crossing weld's observed offset e (module docstring,
        TURN): an in-place rotation δ (CCW +) moves the weld's offset at the look-ahead L
        (`lookahead_mm`, where the stripe crosses the robot's axis) by −L·δ (the tracker's
        prediction, e' = e − x_ref δ, with L = x_ref on the default rig), so the look-ahead
        point lands on the weld after a further rotation `turn_direction` · atan(e / L). It replaces
        the odometric remainder when the two agree within `turn_finish_deg` (the observation
        is of the new weld, not the old one's prediction ≈ 90° off) and the weld is seen
        about square (|θ| ≤ `square_deg`, or its heading unknown). Returns the remaining angle."""
        c = self.config
        if c.turn_finish_deg <= 0.0:
            return remaining
        if math.isfinite(_finite(heading_deg, math.nan)) and abs(heading_deg) > c.square_deg:
            return remaining
        r = c.turn_direction * math.atan2(offset_mm, c.lookahead_mm)
        if abs(r - remaining) > math.radians(c.turn_finish_deg):
            return remaining
        self._turn_angle = self.turned + r
        return r

    def _advance_junction(self, v: float, dt: float) -> None:
        self._predicted += v * dt  # the motion assumed until the next update's odometry
        if self.junction_x is not None:
            self.junction_x -= v * dt
        self._stray = [x - v * dt for x in self._stray]
        self._ignore_left = max(0.0, self._ignore_left - abs(v) * dt)

    def stop(self) -> Command:
        """Immediate stop (no ramp), e.g. after the link sent STOP; the state is kept."""
        return self._emit(0.0, 0.0)

    def _emit(self, v: float, w: float) -> Command:
        self.v, self.omega = v, w
        left, right = wheel_speeds(v, w, self.config.track_mm)
        return Command(v, w, left, right, self.state)
