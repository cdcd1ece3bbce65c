"""The one per-frame loop: tracker → controller → robot link, odometry, time and the log.

`TrackingLoop.step(frame)` runs one frame through the compiled tracker
(`cslx.runtime.tracker.Tracker`), the path controller (`cslx.runtime.PathController`) and,
when a `RobotLink` is given, sends the observation and the velocity command over the serial
link. `cslx track` and the closed-loop simulation (`cslx.sim.closed_loop`) both drive it, so
there is one copy of each piece:

- **time**: each frame's time t is its capture timestamp when the caller has one (video
  position, a camera's grab time, lock-step simulated time), else the loop's clock
  (`time.monotonic`) when `step` is called. dt = t − t_previous is what the tracker's
  prediction and the controller (its acceleration limits and the blind-stop timer) use;
  the nominal 1/fps (`cslx.config.Motion`) only for the first frame or a timestamp that
  does not advance (dt ≤ 0 or not finite: a broken clock must not stall or reverse the
  robot). A frame that was lost still advances the time.
- **odometry**: from the robot's latest telemetry (`RobotLink.latest_state`), the forward
  distance and heading change since the previous frame in the previous robot frame; without
  telemetry the tracker falls back to the nominal speed × dt.
- **watchdog**: the link's low-confidence watchdog is fed the controller's notion of a
  confident observation (`PathController.blind_s` is 0), so dead-reckoning to a confirmed
  T-junction over a measured plate does not trip it while corrupt frames do.
- **log**: one row per frame read or lost (`TrackLog`, the tracking-log contract of
  docs/contracts.md, then the extras `med_steps,status,…,v_mm_s,omega_rad_s,state`),
  appended and flushed per row so that an interrupted run leaves a complete log.

Nothing here imports the simulation or OpenCV; the caller owns the frame source.
"""

from __future__ import annotations

import csv
import dataclasses
import math
import time
from collections.abc import Callable
from typing import Any

from ..config import MOTION, Motion
from .controller import Command, PathController
from .tracker import LOG_FIELDS, Observation

__all__ = ["LoopConfig", "LoopStep", "TrackLog", "TrackingLoop", "odometry_between"]

#: Columns the loop adds after the tracker's (`Observation.log_row`).
LOOP_FIELDS = ("v_mm_s", "omega_rad_s", "state", "dt_s")


@dataclasses.dataclass(frozen=True)
class LoopConfig:
    """Settings of the per-frame loop.

    motion: nominal speed and frame rate (`cslx.config.Motion`), for the first frame's dt.
    ack_timeout_s: wait this long for the robot's ACK of each command (lock-step
        simulation); None sends without waiting (a live robot).
    """

    motion: Motion = MOTION
    ack_timeout_s: float | None = None


@dataclasses.dataclass
class LoopStep:
    """What one `TrackingLoop.step` did: the observation, the command, dt and odometry."""

    observation: Observation
    command: Command
    dt: float
    odometry: tuple[float, float] | None
    sent: bool = False


def odometry_between(
    previous: tuple[float, float, float], current: tuple[float, float, float]
) -> tuple[float, float]:
    """Forward distance (mm, along the previous heading) and heading change (rad, wrapped).

    Poses are (x mm, y mm, heading rad CCW) on the wall, as in `RobotState` telemetry.
    """
    x0, y0, h0 = previous
    x1, y1, h1 = current
    d = (x1 - x0) * math.cos(h0) + (y1 - y0) * math.sin(h0)
    dh = h1 - h0
    return d, math.atan2(math.sin(dh), math.cos(dh))


def _fmt(x) -> str:
    if isinstance(x, float):
        return "nan" if math.isnan(x) else f"{x:.4f}"
    return str(x)


class TrackLog:
    """The tracking log: CSV with the contract's columns first; one flushed row per frame."""

    def __init__(self, path: str):
        fields = [*Observation(0, 0.0).log_row(""), *LOOP_FIELDS]
        if tuple(fields[: len(LOG_FIELDS)]) != LOG_FIELDS:  # the contract, not an assumption
            raise RuntimeError("tracking-log columns out of order")
        self.path = path
        self.fields = fields
        self._file = open(path, "w", newline="", encoding="utf-8")  # noqa: SIM115
        self._writer = csv.DictWriter(self._file, fieldnames=fields)
        self._writer.writeheader()
        self._file.flush()
        self.rows = 0

    def write(self, row: dict[str, Any]) -> None:
        self._writer.writerow({k: _fmt(row.get(k, math.nan)) for k in self.fields})
        self._file.flush()
        self.rows += 1

    def close(self) -> None:
        if not self._file.closed:
            self._file.close()

    def __enter__(self) -> TrackLog:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class TrackingLoop:
    """Tracker → controller → link for one frame at a time (module docstring).

    Args:
        tracker: a `Tracker` (or anything with its `step(frame, dt=, odometry=, t=)`).
        controller: a `PathController` (default one built here).
        link: an open `RobotLink`, or None (dry run).
        log: a `TrackLog` (or a callable taking the row dict), or None.
        config: `LoopConfig`.
        clock: the time source for frames without a timestamp.
    """

    def __init__(
        self,
        tracker,
        controller: PathController | None = None,
        link=None,
        *,
        log: TrackLog | Callable[[dict], None] | None = None,
        config: LoopConfig | None = None,
        clock: Callable[[], float] = time.monotonic,
    ):
        self.tracker = tracker
        self.controller = controller or PathController()
        self.link = link
        self.log = log
        self.config = config or LoopConfig()
        self.clock = clock
        self.frames = 0
        self.lost = 0
        self._t: float | None = None
        self._t0: float | None = None
        self._pose: tuple[float, float, float] | None = None

    def _time(self, t: float | None) -> tuple[float, float]:
        now = self.clock() if t is None else float(t)
        nominal = 1.0 / self.config.motion.fps
        if self._t is None or not math.isfinite(now):
            dt = nominal
        else:
            dt = now - self._t
            if not (math.isfinite(dt) and dt > 0):
                dt = nominal
        if not math.isfinite(now):
            now = (self._t if self._t is not None else 0.0) + dt
        if self._t is not None and now <= self._t:
            now = self._t + dt
        self._t = now
        if self._t0 is None:
            self._t0 = now
        return now, dt

    def _odometry(self):
        """(d, δ) since the previous frame from telemetry, and the measured heading."""
        state = None if self.link is None else self.link.latest_state
        if state is None:
            return None, None
        pose = (state.x_mm, state.y_mm, state.heading_rad)
        odometry = None if self._pose is None else odometry_between(self._pose, pose)
        self._pose = pose
        return odometry, state.heading_rad

    def step(self, frame, source: str = "", t: float | None = None) -> LoopStep:
        """One frame (None for a frame that was lost: it still gets its log row).

        Args:
            frame: (H, W, 3) uint8 RGB, or None.
            source: the frame's name for the log (file name, "video:12", …).
            t: capture timestamp, s (monotonic within a run); None: the loop's clock now.
        """
        now, dt = self._time(t)
        odometry, heading = self._odometry()
        obs = self.tracker.step(frame, dt=dt, odometry=odometry, t=now - self._t0)
        if frame is None:
            self.lost += 1
        ctrl = self.controller
        cmd = ctrl.update(
            dt,
            obs.offset_mm,
            obs.heading_deg,
            obs.confidence,
            obs.junction,
            obs.junction_x_mm,
            robot_heading_rad=heading,
            sensor_ok=obs.stripe_ok,
            junction_y_mm=obs.junction_y_mm,
            travelled_mm=None if odometry is None else odometry[0],
        )
        sent = False
        if self.link is not None:
            self.link.send_observation(obs.to_message())
            if ctrl.blind_s == 0.0:
                self.link.feed(1.0)  # a confident observation for the controller
            seq = self.link.send_command(cmd.v_mm_s, cmd.omega_rad_s)
            sent = seq is not None
            if sent and self.config.ack_timeout_s is not None:
                self.link.wait_ack(seq, self.config.ack_timeout_s)
        if self.log is not None:
            row = obs.log_row(source)
            row.update(
                v_mm_s=cmd.v_mm_s, omega_rad_s=cmd.omega_rad_s, state=cmd.state.value, dt_s=dt
            )
            (self.log.write if isinstance(self.log, TrackLog) else self.log)(row)
        self.frames += 1
        return LoopStep(obs, cmd, dt, odometry, sent)
