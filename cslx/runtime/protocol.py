"""Binary protocol between the vision computer and the wall-climbing robot (see PROTOCOL.md).

Every frame on the wire is

    sync  0xA5 0x5A          2 bytes
    len   uint16 LE          payload length in bytes
    type  uint8              message type (MessageType)
    seq   uint16 LE          sender's sequence number, wraps at 65536
    payload                  `len` bytes, little-endian struct (below)
    crc   uint16 LE          CRC-16/CCITT-FALSE over len, type, seq and payload

Each message type has a fixed payload size; a frame whose `len` does not match its type is
rejected before its CRC is read, so a corrupted length can never make the decoder swallow a
good frame that follows. The streaming `Decoder` resynchronises on the next sync word after
garbage, truncated or corrupted frames and counts what it dropped (`DecoderStats`).

Field domains are checked on both sides (`_Message.check`): the encoder raises
`ProtocolError` for a value the wire cannot carry (a float beyond float32, a non-finite
command or heartbeat time, an integer out of its field's range, an undefined
VELOCITY_COMMAND mode or ACK status); the decoder drops a CRC-valid frame with an undefined
mode or status or a flag byte other than 0/1 (`bad_payload`), so an undefined mode is
never executed.

Standard library only (struct, binascii), no numerics, no I/O.
"""

from __future__ import annotations

import binascii
import dataclasses
import enum
import math
import operator
import struct
from typing import ClassVar

__all__ = [
    "SYNC",
    "HEADER_SIZE",
    "MAX_PAYLOAD",
    "MessageType",
    "StopReason",
    "Observation",
    "VelocityCommand",
    "Heartbeat",
    "Ack",
    "Stop",
    "RobotState",
    "Message",
    "Frame",
    "DecoderStats",
    "Decoder",
    "ProtocolError",
    "crc16_ccitt_false",
    "encode",
    "decode_one",
    "messages_equal",
]

SYNC = b"\xa5\x5a"
_HEADER = struct.Struct("<HBH")  # len, type, seq (after the sync word)
HEADER_SIZE = len(SYNC) + _HEADER.size  # 7
CRC_SIZE = 2
MAX_PAYLOAD = 64
MIN_FRAME = HEADER_SIZE + CRC_SIZE


class ProtocolError(ValueError):
    """A message that cannot be encoded or a frame that cannot be decoded."""


def crc16_ccitt_false(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection, no final xor.

    Check value: crc16_ccitt_false(b"123456789") == 0x29B1. Computed by the standard
    library's `binascii.crc_hqx` (the same polynomial, unreflected, with a given initial
    value), in C; the tests compare it with a bit-at-a-time reference.
    """
    return binascii.crc_hqx(data, crc)


class MessageType(enum.IntEnum):
    OBSERVATION = 0x01
    VELOCITY_COMMAND = 0x02
    HEARTBEAT = 0x03
    ACK = 0x04
    STOP = 0x05
    ROBOT_STATE = 0x10


class StopReason(enum.IntEnum):
    """Why a STOP was sent. A STOP with a code not listed here still stops the robot."""

    OPERATOR = 0  # clean shutdown, Ctrl-C, explicit stop
    VISION_STALL = 1  # the vision loop stopped feeding the watchdog
    LOW_CONFIDENCE = 2  # confidence stayed below the threshold too long
    LINK_ERROR = 3  # RobotLink lost the port and re-opened it (sent first after reconnecting)
    COMMAND_TIMEOUT = 4  # robot side: no command or heartbeat in time
    JUNCTION = 5  # controller asked to stop at a junction
    FAULT = 6  # anything else


_F32_MAX = 3.4028234663852886e38  # largest finite float32
_INT_RANGE = {"B": (0, 0xFF), "H": (0, 0xFFFF)}


@dataclasses.dataclass(frozen=True)
class _Message:
    TYPE: ClassVar[MessageType]
    FORMAT: ClassVar[struct.Struct]
    #: float fields the encoder requires finite (elsewhere NaN means "unknown"); the decoder
    #: passes non-finite values on, so that the receiver can react (the robot stops: FAULT)
    FINITE: ClassVar[tuple[str, ...]] = ()
    #: integer fields restricted to a set of defined values
    CHOICES: ClassVar[dict[str, tuple[int, ...]]] = {}

    def check(self, sending: bool = True) -> str | None:
        """What makes this message impossible to send (or, with sending=False, to accept)."""
        codes = self.FORMAT.format.lstrip("<>=!@")
        for field, code in zip(dataclasses.fields(self), codes, strict=True):
            value = getattr(self, field.name)
            if code in "fd":
                try:
                    x = float(value)
                except (TypeError, ValueError):
                    return f"{field.name} = {value!r} is not a number"
                if sending and field.name in self.FINITE and not math.isfinite(x):
                    return f"{field.name} = {x} must be finite"
                if code == "f" and math.isfinite(x) and abs(x) > _F32_MAX:
                    return f"{field.name} = {x} is beyond the float32 range (±3.4e38)"
            else:
                try:
                    n = operator.index(value)  # int, bool, IntEnum, NumPy integers
                except TypeError:
                    return f"{field.name} = {value!r} is not an integer"
                lo, hi = _INT_RANGE[code]
                if not lo <= n <= hi:
                    return f"{field.name} = {n} is outside {lo}..{hi}"
                allowed = self.CHOICES.get(field.name)
                if allowed is not None and n not in allowed:
                    return f"{field.name} = {n} is undefined (allowed: {allowed})"
        return None

    def pack(self) -> bytes:
        why = self.check()
        if why is not None:
            raise ProtocolError(f"cannot encode {self!r}: {why}")
        try:
            return self.FORMAT.pack(*dataclasses.astuple(self))
        except (struct.error, OverflowError, TypeError, ValueError) as e:
            raise ProtocolError(f"cannot encode {self!r}: {e}") from None

    @classmethod
    def unpack(cls, payload: bytes):
        """Decode a payload; ProtocolError if it breaks the field rules (`check`)."""
        values = cls.FORMAT.unpack(payload)
        codes = cls.FORMAT.format.lstrip("<>=!@")
        for field, code, value in zip(dataclasses.fields(cls), codes, values, strict=True):
            if field.type in (bool, "bool") and code == "B" and value > 1:
                raise ProtocolError(f"{cls.__name__}.{field.name} = {value} is not 0 or 1")
        msg = cls(*values)
        why = msg.check(sending=False)
        if why is not None:
            raise ProtocolError(f"{cls.__name__}: {why}")
        return msg

    def quantized(self):
        """This message as the receiver decodes it (float32 fields rounded)."""
        return self.unpack(self.pack())


@dataclasses.dataclass(frozen=True)
class Observation(_Message):
    """What the vision side sees (docs/contracts.md tracking log fields). NaN = unknown.

    t_s: capture time, s (float64). offset_mm: y_r of the weld centre line at the horizontal
    stripe (+ = weld to the robot's left). heading_deg: weld direction relative to x_r, CCW +.
    width_mm/height_mm: bead. junction: a crossing weld is seen at x_r = junction_x_mm.
    confidence: [0, 1].
    """

    t_s: float
    offset_mm: float
    heading_deg: float
    width_mm: float
    height_mm: float
    junction: bool
    junction_x_mm: float
    confidence: float

    TYPE: ClassVar[MessageType] = MessageType.OBSERVATION
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<dffffBff")

    def __post_init__(self):
        object.__setattr__(self, "junction", bool(self.junction))


@dataclasses.dataclass(frozen=True)
class VelocityCommand(_Message):
    """Motion command. mode 0: (a, b) = (v mm/s, ω rad/s, CCW +); mode 1: (left, right) mm/s."""

    mode: int
    a: float
    b: float

    UNICYCLE: ClassVar[int] = 0
    WHEELS: ClassVar[int] = 1
    TYPE: ClassVar[MessageType] = MessageType.VELOCITY_COMMAND
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<Bff")
    FINITE: ClassVar[tuple[str, ...]] = ("a", "b")
    CHOICES: ClassVar[dict[str, tuple[int, ...]]] = {"mode": (0, 1)}

    @classmethod
    def unicycle(cls, v_mm_s: float, omega_rad_s: float) -> VelocityCommand:
        return cls(cls.UNICYCLE, v_mm_s, omega_rad_s)

    @classmethod
    def wheels(cls, left_mm_s: float, right_mm_s: float) -> VelocityCommand:
        return cls(cls.WHEELS, left_mm_s, right_mm_s)


@dataclasses.dataclass(frozen=True)
class Heartbeat(_Message):
    """Liveness of the sender; t_s is its clock, s."""

    t_s: float

    TYPE: ClassVar[MessageType] = MessageType.HEARTBEAT
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<d")
    FINITE: ClassVar[tuple[str, ...]] = ("t_s",)


@dataclasses.dataclass(frozen=True)
class Ack(_Message):
    """Acknowledges the frame with sequence number `seq`; status 0 = accepted, 1 = rejected."""

    seq: int
    status: int = 0

    TYPE: ClassVar[MessageType] = MessageType.ACK
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<HB")
    CHOICES: ClassVar[dict[str, tuple[int, ...]]] = {"status": (0, 1)}


@dataclasses.dataclass(frozen=True)
class Stop(_Message):
    """Stop the wheels now (StopReason code). A later VELOCITY_COMMAND resumes motion."""

    reason: int

    TYPE: ClassVar[MessageType] = MessageType.STOP
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<B")


@dataclasses.dataclass(frozen=True)
class RobotState(_Message):
    """Robot telemetry: pose on the wall (mm, rad, CCW +), wheel speeds (mm/s), stop state.

    stopped: the robot is halted by a STOP or its command timeout; stop_reason: the last
    StopReason code.
    """

    t_s: float
    x_mm: float
    y_mm: float
    heading_rad: float
    left_mm_s: float
    right_mm_s: float
    stopped: bool
    stop_reason: int

    TYPE: ClassVar[MessageType] = MessageType.ROBOT_STATE
    FORMAT: ClassVar[struct.Struct] = struct.Struct("<dfffffBB")

    def __post_init__(self):
        object.__setattr__(self, "stopped", bool(self.stopped))


Message = Observation | VelocityCommand | Heartbeat | Ack | Stop | RobotState
_CLASSES: dict[int, type[_Message]] = {
    c.TYPE: c for c in (Observation, VelocityCommand, Heartbeat, Ack, Stop, RobotState)
}
for _c in _CLASSES.values():
    assert _c.FORMAT.size <= MAX_PAYLOAD


@dataclasses.dataclass(frozen=True)
class Frame:
    """One decoded frame: the sender's sequence number and the message."""

    seq: int
    message: Message


def encode(message: Message, seq: int) -> bytes:
    """Serialise one message into a complete frame (sync … CRC)."""
    if type(message) not in _CLASSES.values():
        raise ProtocolError(f"not a protocol message: {message!r}")
    if not 0 <= int(seq) <= 0xFFFF:
        raise ProtocolError(f"sequence number {seq} outside 0..65535")
    payload = message.pack()
    body = _HEADER.pack(len(payload), message.TYPE, int(seq)) + payload
    return SYNC + body + struct.pack("<H", crc16_ccitt_false(body))


def decode_one(frame: bytes) -> Frame:
    """Decode exactly one complete frame; ProtocolError says what is wrong with it."""
    dec = Decoder()
    frames = dec.feed(frame)
    if len(frames) != 1 or dec.pending:
        raise ProtocolError(f"not exactly one valid frame ({dec.stats})")
    return frames[0]


@dataclasses.dataclass
class DecoderStats:
    """What the decoder accepted and dropped since it was created."""

    frames: int = 0  # valid frames returned
    bytes_skipped: int = 0  # bytes discarded while hunting for a sync word
    crc_errors: int = 0  # complete frames whose CRC did not match
    bad_length: int = 0  # headers whose length is impossible for their type
    unknown_type: int = 0  # valid-CRC frames of a type this decoder does not know
    bad_payload: int = 0  # valid-CRC frames whose payload breaks the field rules

    @property
    def dropped(self) -> int:
        return self.crc_errors + self.bad_length + self.unknown_type + self.bad_payload


class Decoder:
    """Streaming decoder: feed it any chunks of bytes, get the valid frames back.

    Resynchronisation: on a bad length or CRC the decoder drops only the first byte of the
    presumed sync word and hunts for the next one, so a truncated frame followed by a good
    frame loses only the truncated one.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.stats = DecoderStats()

    @property
    def pending(self) -> int:
        """Bytes buffered waiting for the rest of a frame."""
        return len(self._buf)

    def reset(self) -> None:
        """Forget buffered bytes (counted as skipped), e.g. after a reconnect."""
        self.stats.bytes_skipped += len(self._buf)
        self._buf.clear()

    def _skip(self, n: int) -> None:
        del self._buf[:n]
        self.stats.bytes_skipped += n

    def feed(self, data: bytes) -> list[Frame]:
        buf = self._buf
        buf += data
        out: list[Frame] = []
        while True:
            start = buf.find(SYNC)
            if start < 0:
                # Keep a trailing first sync byte: its partner may come in the next chunk.
                keep = 1 if buf[-1:] == SYNC[:1] else 0
                self._skip(len(buf) - keep)
                return out
            if start:
                self._skip(start)
            if len(buf) < HEADER_SIZE:
                return out
            length, mtype, seq = _HEADER.unpack_from(buf, len(SYNC))
            cls = _CLASSES.get(mtype)
            if length > MAX_PAYLOAD or (cls is not None and length != cls.FORMAT.size):
                self.stats.bad_length += 1
                self._skip(1)
                continue
            end = HEADER_SIZE + length + CRC_SIZE
            if len(buf) < end:
                return out
            body = bytes(buf[len(SYNC) : HEADER_SIZE + length])
            (crc,) = struct.unpack_from("<H", buf, HEADER_SIZE + length)
            if crc != crc16_ccitt_false(body):
                self.stats.crc_errors += 1
                self._skip(1)
                continue
            if cls is None:
                self.stats.unknown_type += 1
                del buf[:end]
                continue
            try:
                msg = cls.unpack(body[_HEADER.size :])
            except (struct.error, ValueError, TypeError):  # ProtocolError is a ValueError
                self.stats.bad_payload += 1
                del buf[:end]
                continue
            del buf[:end]
            self.stats.frames += 1
            out.append(Frame(seq, msg))


def messages_equal(a: Message, b: Message) -> bool:
    """Equality that treats NaN fields as equal (NaN means 'unknown' in this protocol)."""
    if type(a) is not type(b):
        return False
    for x, y in zip(dataclasses.astuple(a), dataclasses.astuple(b), strict=True):
        if isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y):
            continue
        if x != y:
            return False
    return True
