"""RobotLink + RobotSimulator over a real pseudo-terminal, and pyserial's loop://. No mocks."""

import math
import os
import threading
import time

import pytest
import serial

from cslx.runtime.link import RobotLink
from cslx.runtime.protocol import (
    Decoder,
    Heartbeat,
    Observation,
    RobotState,
    StopReason,
    VelocityCommand,
    encode,
    messages_equal,
)
from cslx.sim.robot import RobotSimulator, SimulatorConfig


def wait_for(predicate, timeout=2.0, period=0.01):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(period)
    return predicate()


def arc(pose, v, w, t):
    x, y, th = pose
    if w == 0:
        return x + v * t * math.cos(th), y + v * t * math.sin(th), th
    return (
        x + v / w * (math.sin(th + w * t) - math.sin(th)),
        y - v / w * (math.cos(th + w * t) - math.cos(th)),
        th + w * t,
    )


class Feeder:
    """A stand-in vision loop: feeds the watchdog at 50 Hz with a settable confidence."""

    def __init__(self, link, confidence=0.9):
        self.link, self.confidence = link, confidence
        self.running = True
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self):
        while self.running:
            self.link.feed(self.confidence)
            time.sleep(0.02)

    def stop(self):
        self.running = False
        self.thread.join()


def test_loopback_round_trip():
    got = []
    obs = Observation(12.5, -3.25, 1.5, 14.0, 2.0, True, 60.0, 0.875)
    with RobotLink("loop://", on_message=got.append, heartbeat_period_s=0.05) as link:
        seq = link.send_observation(obs)
        assert wait_for(lambda: any(f.seq == seq for f in got))
        assert wait_for(lambda: any(isinstance(f.message, Heartbeat) for f in got))
    mine = [f for f in got if f.seq == seq]
    assert len(mine) == 1 and messages_equal(mine[0].message, obs.quantized())
    assert link.decoder_stats.crc_errors == 0


@pytest.fixture
def lockstep():
    cfg = SimulatorConfig(realtime=False, wheel_accel=1e12, command_timeout_s=5.0)
    with RobotSimulator(pose=(100.0, -50.0, 0.3), config=cfg) as sim:
        with RobotLink(sim.port, stall_timeout_s=5.0, low_conf_timeout_s=5.0) as link:
            yield sim, link


def test_commands_move_robot_exactly(lockstep):
    """Unicycle and wheel commands over the pty integrate to the closed-form arcs."""
    sim, link = lockstep
    start = sim.pose()
    seq = link.send_command(50.0, 0.25)  # float32-exact values
    assert link.wait_ack(seq, 1.0)
    sim.advance(2.0)
    expected = arc(start, 50.0, 0.25, 2.0)
    assert sim.pose() == pytest.approx(expected, abs=1e-6)

    seq = link.send_wheels(30.0, 50.0)  # v = 40, ω = 20/200 = 0.1
    assert link.wait_ack(seq, 1.0)
    sim.advance(1.5)
    expected = arc(expected, 40.0, 0.1, 1.5)
    assert sim.pose() == pytest.approx(expected, abs=1e-6)
    # telemetry reports the same pose (float32 on the wire)
    assert wait_for(lambda: link.latest_state is not None and link.latest_state.t_s >= 3.5 - 1e-6)
    st = link.latest_state
    assert (st.x_mm, st.y_mm, st.heading_rad) == pytest.approx(expected, rel=1e-6, abs=1e-4)
    assert (st.left_mm_s, st.right_mm_s) == (30.0, 50.0) and not st.stopped


def test_wheel_speed_limit_keeps_curvature(lockstep):
    sim, link = lockstep
    assert link.wait_ack(link.send_wheels(200.0, 100.0), 1.0)
    st = sim.advance(0.1)
    assert (st.left_mm_s, st.right_mm_s) == pytest.approx((80.0, 40.0))


def test_watchdog_stops_robot_when_vision_stalls():
    with RobotSimulator() as sim, RobotLink(sim.port, stall_timeout_s=0.3) as link:
        feeder = Feeder(link)
        assert link.wait_ack(link.send_command(40.0, 0.0), 1.0)
        assert wait_for(lambda: sim.state().left_mm_s > 0)
        time.sleep(0.3)
        feeder.stop()  # the vision loop hangs; the link keeps its heartbeat going
        t_stall = time.monotonic()
        assert wait_for(lambda: sim.state().stopped, timeout=2.0)
        assert time.monotonic() - t_stall < 0.3 + 0.5
        assert sim.state().stop_reason == StopReason.VISION_STALL
        assert link.tripped is StopReason.VISION_STALL
        x = sim.pose()[0]
        assert link.send_command(40.0, 0.0) is None  # suppressed while tripped
        time.sleep(0.3)
        assert sim.pose()[0] == x  # stays put (heartbeats keep its own timeout away)
        link.feed(0.9)  # vision is back
        assert link.tripped is None
        feeder = Feeder(link)
        assert link.wait_ack(link.send_command(40.0, 0.0), 1.0)
        assert wait_for(lambda: sim.pose()[0] > x + 2.0)
        feeder.stop()


def test_watchdog_stops_robot_when_confidence_stays_low():
    with (
        RobotSimulator() as sim,
        RobotLink(sim.port, min_confidence=0.4, low_conf_timeout_s=0.4) as link,
    ):
        feeder = Feeder(link, confidence=0.9)
        assert link.wait_ack(link.send_command(30.0, 0.1), 1.0)
        time.sleep(0.2)
        feeder.confidence = 0.1
        t_low = time.monotonic()
        # a brief dip that recovers must not stop the robot
        assert not wait_for(lambda: sim.state().stopped, timeout=0.2)
        feeder.confidence = 0.9
        time.sleep(0.2)
        assert not sim.state().stopped
        feeder.confidence = 0.1
        t_low = time.monotonic()
        assert wait_for(lambda: sim.state().stopped, timeout=2.0)
        assert 0.4 <= time.monotonic() - t_low < 0.4 + 0.5
        assert sim.state().stop_reason == StopReason.LOW_CONFIDENCE
        feeder.stop()


def test_robot_stops_itself_without_commands_or_heartbeats():
    cfg = SimulatorConfig(command_timeout_s=0.2)
    with RobotSimulator(config=cfg) as sim:
        with serial.serial_for_url(sim.port, timeout=0.05) as port:
            port.write(encode(VelocityCommand.unicycle(20.0, 0.0), 1))
            assert wait_for(lambda: not sim.state().stopped)
            assert wait_for(lambda: sim.state().stopped, timeout=1.0)
            assert sim.state().stop_reason == StopReason.COMMAND_TIMEOUT
            # the robot acknowledged the command on the wire
            dec, acks = Decoder(), []
            for _ in range(20):
                acks += [f.message for f in dec.feed(port.read(256)) if hasattr(f.message, "seq")]
            assert any(a.seq == 1 and a.status == 0 for a in acks)


def test_link_survives_pty_loss_and_reconnects():
    with (
        RobotSimulator() as sim,
        RobotLink(sim.port, stall_timeout_s=5.0, reconnect_max_s=0.2) as link,
    ):
        assert link.wait_ack(link.send_command(10.0, 0.0), 1.0)
        first_device = sim.device
        sim.disconnect()
        assert wait_for(lambda: not link.connected, timeout=2.0)
        assert link.send_command(10.0, 0.0) is None  # counted, not raised
        assert link.stats["send_failures"] >= 1
        time.sleep(0.3)  # a few failed reconnect attempts with backoff
        sim.reconnect()
        assert wait_for(lambda: link.connected, timeout=3.0)
        assert link.stats["reconnects"] >= 1
        # the first frame on the new port is STOP(LINK_ERROR), and the robot obeys it
        assert any(r is StopReason.LINK_ERROR for _, r in link.stops_sent)
        assert wait_for(lambda: sim.state().stop_reason == StopReason.LINK_ERROR, timeout=2.0)
        seq = link.send_command(10.0, 0.0)
        assert seq is not None and link.wait_ack(seq, 1.0)
        assert wait_for(lambda: link.latest_state is not None and not link.latest_state.stopped)
        assert sim.device is not None and os.path.realpath(sim.port) == sim.device
        assert first_device is not None


def test_garbage_on_the_line_is_skipped():
    with RobotSimulator() as sim, RobotLink(sim.port, stall_timeout_s=5.0) as link:
        assert wait_for(lambda: link.latest_state is not None)
        good = encode(RobotState(1.0, 2.0, 3.0, 0.5, 0.0, 0.0, True, 0), 999)
        corrupt = bytearray(good)
        corrupt[10] ^= 0x01
        sim.inject_bytes(b"\x00\xa5noise\xa5\x5a\xff" + bytes(corrupt) + good[:-3])
        before = link.latest_state_time
        assert wait_for(lambda: link.decoder_stats.crc_errors >= 1)
        assert link.decoder_stats.bytes_skipped > 5
        assert wait_for(lambda: link.latest_state_time > before)  # telemetry still flows


def test_clean_close_sends_stop():
    with RobotSimulator() as sim:
        link = RobotLink(sim.port).open()
        link.feed(1.0)
        assert link.wait_ack(link.send_command(25.0, 0.0), 1.0)
        assert wait_for(lambda: not sim.state().stopped)
        link.close()
        assert wait_for(lambda: sim.state().stopped)
        assert sim.state().stop_reason == StopReason.OPERATOR
        assert link.stops_sent[-1][1] is StopReason.OPERATOR


def test_open_errors():
    with pytest.raises(OSError, match="cannot open robot port"):
        RobotLink("/nonexistent/ttyUSB9").open()
    with pytest.raises(ValueError, match="stall_timeout_s"):
        RobotLink("loop://", stall_timeout_s=0)


def test_unencodable_messages_are_refused_without_resetting_the_link():
    """A float beyond float32 or a NaN command is a ProtocolError: counted, never an I/O
    error, the port stays open; a refused command stops the robot (STOP FAULT)."""
    with RobotSimulator() as sim, RobotLink(sim.port, stall_timeout_s=5.0) as link:
        link.feed(1.0)
        assert link.wait_ack(link.send_command(30.0, 0.0), 1.0)
        assert wait_for(lambda: not sim.state().stopped)
        huge = Observation(1.0, 1e39, 0.0, 0.0, 0.0, False, 0.0, 0.9)
        assert link.send_observation(huge) is None
        assert link.send_command(float("nan"), 0.0) is None
        assert link.stats["encode_errors"] == 2
        assert link.stats["io_errors"] == 0 and link.stats["reconnects"] == 0
        assert link.connected
        assert wait_for(lambda: sim.state().stopped and sim.state().stop_reason == StopReason.FAULT)
        # the link still works
        assert link.wait_ack(link.send_command(20.0, 0.0), 1.0)
        assert wait_for(lambda: not sim.state().stopped)
