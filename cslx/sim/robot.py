"""A differential-drive wall-climbing robot on the far end of a real pseudo-terminal.

The simulator owns the pty master (`os.openpty()`); the vision side opens `sim.port`, a
stable symlink to the slave device (like udev's /dev/serial/by-id links), so that after a
simulated link loss (`disconnect()` closes the pty, `reconnect()` opens a new one and moves
the link) the same path works again. It speaks cslx.runtime.protocol:

- VELOCITY_COMMAND → new wheel targets (unicycle or wheel mode), ACK; a command in an
  undefined mode (or with non-finite values) is refused: the robot stops
  (StopReason.FAULT) and answers ACK with status 1;
- STOP → wheels to zero at once, ACK; a later command resumes;
- HEARTBEAT → keeps the command timeout from firing;
- it sends ROBOT_STATE telemetry every `state_period_s` (and after each `advance`), and
  stops itself (StopReason.COMMAND_TIMEOUT) when neither a command nor a heartbeat came for
  `command_timeout_s`.

Kinematics: wheel speeds are clamped to ±wheel_max (keeping their ratio, i.e. the
curvature), ramp towards their targets at wheel_accel, optionally get multiplicative slip
noise, and the pose (x, y mm, heading rad CCW from +x, on the wall plane) is integrated
exactly along arcs. In `realtime` mode the thread integrates with the wall clock; otherwise
the caller advances simulated time with `advance(dt)` (lock-step closed-loop simulation).
"""

from __future__ import annotations

import dataclasses
import math
import os
import random
import select
import tempfile
import threading
import time
import tty

from ..runtime.protocol import (
    Ack,
    Decoder,
    Heartbeat,
    RobotState,
    Stop,
    StopReason,
    VelocityCommand,
    encode,
)

__all__ = ["RobotSimulator", "SimulatorConfig"]


@dataclasses.dataclass(frozen=True)
class SimulatorConfig:
    """Robot and timing parameters (mm, s, rad)."""

    track_mm: float = 200.0
    wheel_max: float = 80.0
    wheel_accel: float = 400.0  # mm/s² per wheel
    slip_noise: float = 0.0  # relative std of each wheel's effective speed
    command_timeout_s: float = 0.5
    state_period_s: float = 0.05
    step_s: float = 0.005  # integration step and thread poll period
    realtime: bool = True
    seed: int = 0


class RobotSimulator:
    """Simulated robot speaking the cslx protocol over a pty; thread-safe pose access."""

    def __init__(
        self,
        pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
        config: SimulatorConfig | None = None,
        link_path: str | None = None,
    ):
        self.config = config or SimulatorConfig()
        self._lock = threading.RLock()
        self._pose = tuple(float(p) for p in pose)
        self._wheels = [0.0, 0.0]
        self._targets = [0.0, 0.0]
        self._stopped = True
        self._stop_reason = int(StopReason.OPERATOR)
        self._sim_time = 0.0
        self._rng = random.Random(self.config.seed)
        self._decoder = Decoder()
        self._seq = 0
        self._master: int | None = None
        self._slave: int | None = None
        self._tmpdir = None
        if link_path is None:
            self._tmpdir = tempfile.TemporaryDirectory(prefix="cslx-robot-")
            link_path = os.path.join(self._tmpdir.name, "robot.tty")
        self.port = link_path
        self._thread: threading.Thread | None = None
        self._running = threading.Event()
        self._last_contact = time.monotonic()
        #: every message received, in order: (monotonic time, seq, message)
        self.received: list[tuple[float, int, object]] = []
        #: every stop executed: (sim time, StopReason code)
        self.stops: list[tuple[float, int]] = []
        #: commands refused (undefined mode)
        self.rejected = 0
        self._open_pty()

    # pty management ---------------------------------------------------------------------
    def _open_pty(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no line discipline, before anyone opens it
        os.set_blocking(master, False)
        tmp = self.port + ".new"
        if os.path.lexists(tmp):
            os.unlink(tmp)
        os.symlink(os.ttyname(slave), tmp)
        os.replace(tmp, self.port)  # atomic: the link never sees a missing path mid-swap
        with self._lock:
            self._master, self._slave = master, slave
            self._decoder = Decoder()

    def _close_pty(self) -> None:
        with self._lock:
            fds = (self._master, self._slave)
            self._master = self._slave = None
        for fd in fds:
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass

    @property
    def device(self) -> str | None:
        """The current slave device path (changes on reconnect)."""
        with self._lock:
            return os.ttyname(self._slave) if self._slave is not None else None

    def disconnect(self) -> None:
        """Simulate link loss: close the pty; the vision side's reads and writes fail."""
        self._close_pty()
        if os.path.lexists(self.port):
            os.unlink(self.port)

    def reconnect(self) -> None:
        """End a simulated link loss: a new pty appears at the same `port` path."""
        if self._master is None:
            self._open_pty()

    @property
    def connected(self) -> bool:
        return self._master is not None

    # lifecycle -----------------------------------------------------------------------------
    def start(self) -> RobotSimulator:
        if self._thread is None:
            self._running.set()
            self._last_contact = time.monotonic()
            self._thread = threading.Thread(target=self._run, name="robot-sim", daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        self._running.clear()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        self._close_pty()
        if os.path.lexists(self.port):
            os.unlink(self.port)
        if self._tmpdir is not None:
            self._tmpdir.cleanup()
            self._tmpdir = None

    def __enter__(self) -> RobotSimulator:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # state ---------------------------------------------------------------------------------
    def pose(self) -> tuple[float, float, float]:
        """True pose (x mm, y mm, heading rad), a consistent snapshot."""
        with self._lock:
            return self._pose

    def set_pose(self, pose: tuple[float, float, float]) -> None:
        with self._lock:
            self._pose = tuple(float(p) for p in pose)

    def state(self) -> RobotState:
        with self._lock:
            x, y, th = self._pose
            return RobotState(
                self._sim_time, x, y, th, *self._wheels, self._stopped, self._stop_reason
            )

    @property
    def sim_time(self) -> float:
        with self._lock:
            return self._sim_time

    # kinematics ----------------------------------------------------------------------------
    def _set_targets(self, left: float, right: float) -> None:
        c = self.config
        peak = max(abs(left), abs(right))
        if peak > c.wheel_max:
            left, right = left * c.wheel_max / peak, right * c.wheel_max / peak
        self._targets = [left, right]
        self._stopped = False

    def _halt(self, reason: int) -> None:
        self._targets = [0.0, 0.0]
        self._wheels = [0.0, 0.0]
        if not self._stopped or reason != self._stop_reason:
            self.stops.append((self._sim_time, int(reason)))
        self._stopped = True
        self._stop_reason = int(reason)

    def _integrate(self, dt: float) -> None:
        c = self.config
        while dt > 1e-12:
            h = min(dt, c.step_s)
            dt -= h
            for i in range(2):
                dv = self._targets[i] - self._wheels[i]
                self._wheels[i] += max(-c.wheel_accel * h, min(c.wheel_accel * h, dv))
            left, right = self._wheels
            if c.slip_noise > 0:
                left *= 1.0 + c.slip_noise * self._rng.gauss(0.0, 1.0)
                right *= 1.0 + c.slip_noise * self._rng.gauss(0.0, 1.0)
            v, w = (left + right) / 2.0, (right - left) / c.track_mm
            x, y, th = self._pose
            if abs(w) < 1e-9:
                x, y = x + v * h * math.cos(th), y + v * h * math.sin(th)
            else:
                th2 = th + w * h
                x += v / w * (math.sin(th2) - math.sin(th))
                y -= v / w * (math.cos(th2) - math.cos(th))
                th = th2
            self._pose = (x, y, th)
            self._sim_time += h

    def advance(self, dt: float) -> RobotState:
        """Lock-step mode: integrate `dt` seconds of simulated time, send telemetry."""
        if self.config.realtime:
            raise RuntimeError("advance() is for realtime=False simulators")
        with self._lock:
            self._integrate(dt)
        self._send_state()
        return self.state()

    # I/O -----------------------------------------------------------------------------------
    def _send(self, message) -> None:
        with self._lock:
            fd = self._master
            frame = encode(message, self._seq)
            self._seq = (self._seq + 1) % 65536
        if fd is None:
            return
        try:
            os.write(fd, frame)
        except (BlockingIOError, OSError):
            pass  # nobody reading (buffer full) or pty closed: telemetry is best-effort

    def inject_bytes(self, data: bytes) -> None:
        """Write raw bytes towards the vision side (line noise, corrupted frames in tests)."""
        with self._lock:
            fd = self._master
        if fd is not None:
            os.write(fd, data)

    def _send_state(self) -> None:
        self._send(self.state())

    def _handle(self, seq: int, msg) -> None:
        now = time.monotonic()
        self.received.append((now, seq, msg))
        with self._lock:
            if isinstance(msg, VelocityCommand):
                self._last_contact = now
                if msg.mode == VelocityCommand.WHEELS:
                    left, right = msg.a, msg.b
                elif msg.mode == VelocityCommand.UNICYCLE:
                    half = msg.b * self.config.track_mm / 2.0
                    left, right = msg.a - half, msg.a + half
                else:  # an undefined mode: refuse it, and stop (the sender is confused)
                    left = right = math.nan
                    self.rejected += 1
                if math.isfinite(left) and math.isfinite(right):
                    self._set_targets(left, right)
                    status = 0
                else:
                    self._halt(StopReason.FAULT)
                    status = 1
                ack = Ack(seq, status)
            elif isinstance(msg, Stop):
                self._halt(msg.reason)
                ack = Ack(seq, 0)
            elif isinstance(msg, Heartbeat):
                self._last_contact = now
                ack = None
            else:
                ack = None
        if ack is not None:
            self._send(ack)

    def _run(self) -> None:
        c = self.config
        last = time.monotonic()
        last_state = 0.0
        while self._running.is_set():
            with self._lock:
                fd = self._master
            data = b""
            if fd is None:
                time.sleep(c.step_s)
            else:
                try:
                    ready, _, _ = select.select([fd], [], [], c.step_s)
                    if ready:
                        data = os.read(fd, 4096)
                except (OSError, ValueError):
                    time.sleep(c.step_s)  # closed under us by disconnect()
            for frame in self._decoder.feed(data) if data else ():
                self._handle(frame.seq, frame.message)
            now = time.monotonic()
            with self._lock:
                if c.realtime:
                    self._integrate(now - last)
                if not self._stopped and now - self._last_contact > c.command_timeout_s:
                    self._halt(StopReason.COMMAND_TIMEOUT)
            last = now
            if now - last_state >= c.state_period_s:
                last_state = now
                self._send_state()
