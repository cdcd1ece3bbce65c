"""The pty robot simulator refuses commands it does not understand (real pseudo-terminal)."""

import os
import struct
import time

import pytest

from cslx.runtime.protocol import SYNC, Ack, Decoder, MessageType, StopReason, crc16_ccitt_false
from cslx.sim.robot import RobotSimulator, SimulatorConfig


def _frame(type_: int, seq: int, payload: bytes) -> bytes:
    body = struct.pack("<HBH", len(payload), type_, seq) + payload
    return SYNC + body + struct.pack("<H", crc16_ccitt_false(body))


def _exchange(sim, data: bytes, seconds: float = 0.5) -> list:
    """Write raw bytes to the robot over its pty; the frames it answers within `seconds`."""
    fd = os.open(sim.port, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        os.write(fd, data)
        dec, frames, end = Decoder(), [], time.monotonic() + seconds
        while time.monotonic() < end:
            try:
                frames += dec.feed(os.read(fd, 4096))
            except BlockingIOError:
                time.sleep(0.01)
        return frames
    finally:
        os.close(fd)


@pytest.mark.parametrize("mode", [2, 7, 255])
def test_undefined_command_mode_is_refused(mode):
    cfg = SimulatorConfig(realtime=False, command_timeout_s=1e6)
    with RobotSimulator(config=cfg) as sim:
        # a CRC-valid VELOCITY_COMMAND frame whose mode byte is not defined by the protocol
        bad = _frame(MessageType.VELOCITY_COMMAND, 41, struct.pack("<Bff", mode, 50.0, 50.0))
        good = _frame(MessageType.VELOCITY_COMMAND, 42, struct.pack("<Bff", 0, 50.0, 0.0))
        answers = _exchange(sim, bad)
        acks = {f.message.seq: f.message.status for f in answers if isinstance(f.message, Ack)}
        assert acks.get(41, 1) != 0  # never accepted (refused by the robot, or not decoded)
        sim.advance(0.5)
        assert sim.pose() == (0.0, 0.0, 0.0)
        if 41 in acks:  # it reached the robot: refused and stopped with a fault
            assert sim.rejected == 1 and sim.stops[-1][1] == StopReason.FAULT
        # a defined mode still works afterwards
        answers = _exchange(sim, good)
        assert any(isinstance(f.message, Ack) and f.message.seq == 42 for f in answers)
        sim.advance(0.5)
        assert sim.pose()[0] > 5.0
