"""Serial link from the vision computer to the robot: framing, heartbeat, watchdog, reconnect.

`RobotLink` opens any pyserial URL (`serial.serial_for_url`: a device such as /dev/ttyUSB0,
a pty path, `loop://`, `socket://…`) and runs two threads:

- **I/O thread**: reads and decodes incoming frames (ACK, ROBOT_STATE, …), keeps the latest
  robot state, and on an I/O error (port gone, pty closed) closes the port and reopens it
  with exponential backoff (`reconnect_min_s` … `reconnect_max_s`) — the process survives;
  writes while disconnected return None and are counted. The first frame after a reconnect
  is STOP(LINK_ERROR). A message the protocol cannot encode is refused (`ProtocolError`,
  counted as `encode_errors`) without resetting the port.
- **Watchdog thread**: sends HEARTBEAT every `heartbeat_period_s`, and sends STOP when the
  vision loop has not called `feed()` / `send_observation()` for `stall_timeout_s`
  (StopReason.VISION_STALL) or the fed confidence stayed below `min_confidence` for
  `low_conf_timeout_s` (StopReason.LOW_CONFIDENCE). While tripped it suppresses velocity
  commands and repeats the STOP until the robot ACKs it; a fresh confident feed clears it.

Closing (or leaving the `with` block) sends STOP(OPERATOR) first. No numerics here; pyserial
is imported lazily.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable

from .protocol import (
    Ack,
    Decoder,
    Frame,
    Heartbeat,
    Message,
    Observation,
    ProtocolError,
    RobotState,
    Stop,
    StopReason,
    VelocityCommand,
    encode,
)

__all__ = ["RobotLink"]

log = logging.getLogger("cslx.runtime.link")


class RobotLink:
    """Protocol endpoint on the vision side (module docstring). Thread-safe."""

    def __init__(
        self,
        port: str,
        baudrate: int = 115200,
        *,
        stall_timeout_s: float = 0.5,
        min_confidence: float = 0.3,
        low_conf_timeout_s: float = 1.0,
        heartbeat_period_s: float = 0.1,
        stop_retry_s: float = 0.2,
        reconnect_min_s: float = 0.05,
        reconnect_max_s: float = 2.0,
        read_timeout_s: float = 0.02,
        on_message: Callable[[Frame], None] | None = None,
    ):
        if not port:
            raise ValueError("RobotLink needs a port (device path or pyserial URL)")
        for name, value in dict(
            stall_timeout_s=stall_timeout_s,
            low_conf_timeout_s=low_conf_timeout_s,
            heartbeat_period_s=heartbeat_period_s,
            reconnect_min_s=reconnect_min_s,
        ).items():
            if not value > 0:
                raise ValueError(f"{name} must be positive, got {value}")
        self.port = port
        self.baudrate = baudrate
        self.stall_timeout_s = stall_timeout_s
        self.min_confidence = min_confidence
        self.low_conf_timeout_s = low_conf_timeout_s
        self.heartbeat_period_s = heartbeat_period_s
        self.stop_retry_s = stop_retry_s
        self.reconnect_min_s = reconnect_min_s
        self.reconnect_max_s = reconnect_max_s
        self.read_timeout_s = read_timeout_s
        self.on_message = on_message

        self._ser = None
        self._io_lock = threading.RLock()  # guards _ser and writes
        # set once a (re)connection is complete (its STOP written and recorded), cleared on loss
        self._up = threading.Event()
        self._state_lock = threading.Lock()
        self._acked = threading.Condition(self._state_lock)
        self._seq = 0
        self._decoder = Decoder()
        self._running = threading.Event()
        self._threads: list[threading.Thread] = []
        self._last_feed = time.monotonic()
        self._low_since: float | None = None
        self._tripped: StopReason | None = None
        self._stop_seq: int | None = None
        self._stop_sent_at = 0.0
        self._acks: dict[int, float] = {}  # acked seq → time, in arrival order
        self.latest_state: RobotState | None = None
        self.latest_state_time: float | None = None
        #: STOPs sent: (monotonic time, StopReason)
        self.stops_sent: list[tuple[float, StopReason]] = []
        self.stats = dict(
            sent=0, send_failures=0, suppressed=0, reconnects=0, io_errors=0, encode_errors=0
        )

    # connection ------------------------------------------------------------------------------
    def _connect(self, reconnect: bool = False) -> bool:
        """Open the port. After a loss (`reconnect`), STOP(LINK_ERROR) is the first frame
        written, before any other thread can send: the robot may have missed commands and
        must not act on stale ones; the next command resumes motion."""
        import serial  # lazy: the runtime shell owns I/O, importing cslx must not need it

        try:
            ser = serial.serial_for_url(
                self.port, baudrate=self.baudrate, timeout=self.read_timeout_s, write_timeout=0.5
            )
        except (OSError, ValueError) as e:
            log.debug("cannot open %s: %s", self.port, e)
            return False
        with self._io_lock:
            self._ser = ser
            self._decoder.reset()
            if reconnect:
                self.stats["reconnects"] += 1
                self.send_stop(StopReason.LINK_ERROR)
            # last: a reader of `connected` sees the reconnect counted and its STOP recorded
            # (unless writing the STOP already lost the port again)
            if self._ser is ser:
                self._up.set()
        return True

    def _drop(self, why: str) -> None:
        with self._io_lock:
            ser, self._ser = self._ser, None
            self._up.clear()
        if ser is not None:
            self.stats["io_errors"] += 1
            log.warning("robot link %s lost: %s", self.port, why)
            try:
                ser.close()
            except OSError:
                pass

    @property
    def connected(self) -> bool:
        """The port is open and, after a loss, the reconnection is complete."""
        return self._up.is_set()

    def open(self) -> RobotLink:
        """Open the port (raises OSError if it cannot be opened now) and start the threads."""
        if self._running.is_set():
            return self
        if not self._connect():
            raise OSError(f"cannot open robot port {self.port!r}")
        self._running.set()
        self._last_feed = time.monotonic()
        self._threads = [
            threading.Thread(target=self._io_loop, name="robot-link-io", daemon=True),
            threading.Thread(target=self._watchdog_loop, name="robot-link-watchdog", daemon=True),
        ]
        for t in self._threads:
            t.start()
        log.info("robot link open on %s at %d Bd", self.port, self.baudrate)
        return self

    def close(self, stop: bool = True, ack_timeout_s: float = 0.3) -> None:
        """Send STOP(OPERATOR) (waiting briefly for its ACK), stop the threads, close."""
        if stop and self._running.is_set():
            seq = self.send_stop(StopReason.OPERATOR)
            if seq is not None:
                self.wait_ack(seq, ack_timeout_s)
        self._running.clear()
        for t in self._threads:
            t.join(timeout=2.0)
        self._threads = []
        with self._io_lock:
            ser, self._ser = self._ser, None
            self._up.clear()
        if ser is not None:
            try:
                ser.close()
            except OSError:
                pass
        log.info("robot link on %s closed", self.port)

    def __enter__(self) -> RobotLink:
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()

    # sending ---------------------------------------------------------------------------------
    def send(self, message: Message) -> int | None:
        """Frame and write one message; its sequence number, or None if the link is down.

        A message the protocol cannot carry (`ProtocolError`: a float beyond float32, a
        non-finite command, an out-of-range code) is refused and counted
        (`stats["encode_errors"]`) without touching the port: it is the caller's bug, not a
        link fault. A refused VELOCITY_COMMAND is replaced by STOP(FAULT), since the robot
        must not keep driving on the previous command.
        """
        with self._io_lock:
            seq = self._seq
            try:
                frame = encode(message, seq)
            except ProtocolError as e:
                refused = e
            else:
                refused = None
                self._seq = (self._seq + 1) % 65536
                ser = self._ser
                if ser is None:
                    self.stats["send_failures"] += 1
                    return None
                try:
                    ser.write(frame)
                except Exception as e:  # noqa: BLE001 — pyserial raises several types here
                    self.stats["send_failures"] += 1
                    self._drop(f"write failed: {e}")
                    return None
        if refused is not None:
            self.stats["encode_errors"] += 1
            log.error("not sent: %s", refused)
            if isinstance(message, VelocityCommand):
                self.send_stop(StopReason.FAULT)
            return None
        self.stats["sent"] += 1
        return seq

    def send_observation(self, obs: Observation) -> int | None:
        """Send what the tracker saw; also feeds the watchdog with its confidence."""
        self.feed(obs.confidence)
        return self.send(obs)

    def send_command(self, v_mm_s: float, omega_rad_s: float) -> int | None:
        """VELOCITY_COMMAND (v, ω); None if suppressed by the watchdog or link down."""
        return self._command(VelocityCommand.unicycle(v_mm_s, omega_rad_s))

    def send_wheels(self, left_mm_s: float, right_mm_s: float) -> int | None:
        """VELOCITY_COMMAND in wheel mode."""
        return self._command(VelocityCommand.wheels(left_mm_s, right_mm_s))

    def _command(self, cmd: VelocityCommand) -> int | None:
        if self._tripped is not None:
            self.stats["suppressed"] += 1
            return None
        return self.send(cmd)

    def send_stop(self, reason: StopReason = StopReason.OPERATOR) -> int | None:
        seq = self.send(Stop(int(reason)))
        with self._state_lock:
            self._stop_seq, self._stop_sent_at = seq, time.monotonic()
            self.stops_sent.append((time.monotonic(), StopReason(reason)))
        return seq

    def wait_ack(self, seq: int, timeout_s: float = 0.5) -> bool:
        """Block until the robot ACKed frame `seq` (True) or the timeout passed (False)."""
        deadline = time.monotonic() + timeout_s
        with self._acked:
            while seq not in self._acks:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._acked.wait(left)
            return True

    # watchdog --------------------------------------------------------------------------------
    def feed(self, confidence: float = 1.0) -> None:
        """Tell the watchdog the vision loop is alive, with its latest confidence."""
        now = time.monotonic()
        confident = math.isfinite(confidence) and confidence >= self.min_confidence
        with self._state_lock:
            self._last_feed = now
            if confident:
                self._low_since = None
            elif self._low_since is None:
                self._low_since = now
            clear = confident and self._tripped is not None
            if clear:
                reason, self._tripped = self._tripped, None
        if clear:
            log.info("vision recovered after %s: commands resume", reason.name)

    @property
    def tripped(self) -> StopReason | None:
        """Why the watchdog stopped the robot, or None while all is well."""
        return self._tripped

    def _trip(self, reason: StopReason, detail: str) -> None:
        with self._state_lock:
            if self._tripped is not None:
                return
            self._tripped = reason
        log.warning("watchdog: %s (%s): sending STOP to the robot", reason.name, detail)
        self.send_stop(reason)

    def _watchdog_loop(self) -> None:
        last_hb = 0.0
        tick = min(self.heartbeat_period_s, self.stall_timeout_s, self.low_conf_timeout_s) / 4
        while self._running.is_set():
            now = time.monotonic()
            if now - last_hb >= self.heartbeat_period_s:
                last_hb = now
                self.send(Heartbeat(time.time()))
            with self._state_lock:
                stalled = now - self._last_feed
                low = None if self._low_since is None else now - self._low_since
            if stalled > self.stall_timeout_s:
                self._trip(StopReason.VISION_STALL, f"no frame for {stalled:.2f} s")
            elif low is not None and low > self.low_conf_timeout_s:
                self._trip(StopReason.LOW_CONFIDENCE, f"confidence low for {low:.2f} s")
            with self._state_lock:
                stop_seq, stop_at = self._stop_seq, self._stop_sent_at
                unacked = stop_seq is None or stop_seq not in self._acks
                tripped = self._tripped
            if tripped is not None and unacked and now - stop_at > self.stop_retry_s:
                log.info("repeating STOP (%s): not acknowledged yet", tripped.name)
                self.send_stop(tripped)
            time.sleep(tick)

    # receiving -------------------------------------------------------------------------------
    def _io_loop(self) -> None:
        backoff = self.reconnect_min_s
        while self._running.is_set():
            ser = self._ser
            if ser is None:
                if self._connect(reconnect=True):
                    backoff = self.reconnect_min_s
                    log.warning("robot link %s re-established: STOP(LINK_ERROR) sent", self.port)
                    if self._tripped is not None:
                        self.send_stop(self._tripped)
                else:
                    time.sleep(backoff)
                    backoff = min(2 * backoff, self.reconnect_max_s)
                continue
            try:
                data = ser.read(max(1, ser.in_waiting))
            except Exception as e:  # noqa: BLE001 — SerialException, OSError, TypeError on close
                if self._running.is_set():
                    self._drop(f"read failed: {e}")
                continue
            if data:
                for frame in self._decoder.feed(data):
                    self._dispatch(frame)

    def _dispatch(self, frame: Frame) -> None:
        msg = frame.message
        if isinstance(msg, Ack):
            with self._acked:
                self._acks.pop(msg.seq, None)
                self._acks[msg.seq] = time.monotonic()
                if len(self._acks) > 4096:  # seqs wrap at 65536: keep only recent ACKs
                    for old in list(self._acks)[:3072]:
                        del self._acks[old]
                self._acked.notify_all()
        elif isinstance(msg, RobotState):
            self.latest_state, self.latest_state_time = msg, time.monotonic()
        if self.on_message is not None:
            try:
                self.on_message(frame)
            except Exception:  # noqa: BLE001 — a user callback must not kill the reader
                log.exception("on_message callback failed")

    @property
    def decoder_stats(self):
        return self._decoder.stats
