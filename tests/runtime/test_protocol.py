"""Robot protocol: CRC check value, round trips, resynchronisation, corruption detection."""

import math
import random
import struct

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cslx.runtime.protocol import (
    HEADER_SIZE,
    SYNC,
    Ack,
    Decoder,
    Heartbeat,
    Observation,
    ProtocolError,
    RobotState,
    Stop,
    StopReason,
    VelocityCommand,
    crc16_ccitt_false,
    decode_one,
    encode,
    messages_equal,
)

f32 = st.floats(width=32, allow_nan=True, allow_infinity=True)
f64 = st.floats(allow_nan=True, allow_infinity=True)
f32_finite = st.floats(width=32, allow_nan=False, allow_infinity=False)
f64_finite = st.floats(allow_nan=False, allow_infinity=False)
u8 = st.integers(0, 255)
messages = st.one_of(
    st.builds(Observation, f64, f32, f32, f32, f32, st.booleans(), f32, f32),
    st.builds(VelocityCommand, st.integers(0, 1), f32_finite, f32_finite),
    st.builds(Heartbeat, f64_finite),
    st.builds(Ack, st.integers(0, 0xFFFF), st.integers(0, 1)),
    st.builds(Stop, u8),
    st.builds(RobotState, f64, f32, f32, f32, f32, f32, st.booleans(), u8),
)
seqs = st.integers(0, 0xFFFF)


def _crc_bitwise(data: bytes) -> int:
    """Textbook bit-at-a-time CRC-16/CCITT-FALSE, independent of the table version."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


def test_crc_check_value():
    assert crc16_ccitt_false(b"123456789") == 0x29B1
    assert crc16_ccitt_false(b"") == 0xFFFF


@given(st.binary(max_size=200))
@settings(deadline=None)  # wall-clock limits fail on a loaded machine
def test_crc_matches_bitwise_reference(data):
    assert crc16_ccitt_false(data) == _crc_bitwise(data)


def test_frame_layout_is_as_documented():
    frame = encode(Stop(StopReason.VISION_STALL), seq=0x1234)
    assert frame[:2] == SYNC
    length, mtype, seq = struct.unpack_from("<HBH", frame, 2)
    assert (length, mtype, seq) == (1, 0x05, 0x1234)
    assert frame[HEADER_SIZE] == 1
    assert struct.unpack("<H", frame[-2:])[0] == crc16_ccitt_false(frame[2:-2])
    assert len(frame) == HEADER_SIZE + 1 + 2


@given(messages, seqs)
@settings(deadline=None)  # wall-clock limits fail on a loaded machine
def test_round_trip(msg, seq):
    frame = decode_one(encode(msg, seq))
    assert frame.seq == seq
    assert messages_equal(frame.message, msg.quantized())


@given(st.lists(st.tuples(messages, seqs), min_size=1, max_size=8), st.data())
@settings(suppress_health_check=[HealthCheck.too_slow], deadline=None)
def test_stream_with_garbage_and_random_chunking(items, data):
    """Garbage between frames and arbitrary chunk boundaries lose no frame."""
    stream = bytearray()
    for msg, seq in items:
        # Garbage that may contain sync bytes but is never a valid frame by construction
        # except with CRC-collision probability; hypothesis does not search CRCs.
        stream += data.draw(st.binary(max_size=20))
        stream += encode(msg, seq)
    dec = Decoder()
    got = []
    pos = 0
    while pos < len(stream):
        n = data.draw(st.integers(1, 40))
        got += dec.feed(bytes(stream[pos : pos + n]))
        pos += n
    # Every real frame must come back, in order, possibly with spurious ones only in the
    # astronomically unlikely case of garbage that carries a valid CRC.
    expected = [(seq, msg.quantized()) for msg, seq in items]
    it = iter(got)
    for seq, msg in expected:
        for frame in it:
            if frame.seq == seq and messages_equal(frame.message, msg):
                break
        else:
            pytest.fail(f"frame {seq} {msg} lost; got {got}")
    assert dec.stats.frames == len(got)


def test_resync_counts_skipped_bytes_and_keeps_split_sync():
    a, b = encode(Heartbeat(1.0), 1), encode(Ack(1), 2)
    dec = Decoder()
    assert dec.feed(b"\x00\x11\x22" + a[:1]) == []  # lone first sync byte is kept
    assert dec.stats.bytes_skipped == 3 and dec.pending == 1
    frames = dec.feed(a[1:] + b"xyz" + b)
    assert [f.seq for f in frames] == [1, 2]
    assert dec.stats.bytes_skipped == 6


def test_truncated_frame_followed_by_good_frame():
    obs = Observation(3.0, 1.5, -2.0, 12.0, 2.0, True, 40.0, 0.9)
    good = encode(obs, 7)
    cut = encode(obs, 6)[:-9]  # truncated in the payload
    dec = Decoder()
    frames = dec.feed(cut + good)
    assert [f.seq for f in frames] == [7]
    assert dec.stats.crc_errors + dec.stats.bad_length >= 1
    assert dec.pending == 0


def test_crc_failure_is_counted_and_next_frame_survives():
    bad = bytearray(encode(VelocityCommand.unicycle(30.0, 0.1), 1))
    bad[HEADER_SIZE + 2] ^= 0x40
    dec = Decoder()
    frames = dec.feed(bytes(bad) + encode(Stop(0), 2))
    assert [f.seq for f in frames] == [2]
    assert dec.stats.crc_errors == 1


def test_bad_length_rejected_before_crc():
    """A header claiming a huge length must not swallow the frames behind it."""
    bogus = SYNC + struct.pack("<HBH", 60000, 0x01, 9)
    wrong_for_type = SYNC + struct.pack("<HBH", 3, 0x05, 9)  # STOP has 1 byte
    dec = Decoder()
    frames = dec.feed(bogus + wrong_for_type + encode(Heartbeat(2.0), 10))
    assert [f.seq for f in frames] == [10]
    assert dec.stats.bad_length == 2


def test_unknown_type_with_valid_crc_is_skipped_whole():
    body = struct.pack("<HBH", 4, 0x7E, 3) + b"\xa5\x5a\x00\x00"
    frame = SYNC + body + struct.pack("<H", crc16_ccitt_false(body))
    dec = Decoder()
    frames = dec.feed(frame + encode(Ack(3), 4))
    assert [f.seq for f in frames] == [4]
    assert dec.stats.unknown_type == 1


@given(messages, seqs, st.sets(st.integers(0, 8 * 40 - 1), min_size=1, max_size=3))
@settings(deadline=None)  # wall-clock limits fail on a loaded machine
def test_up_to_three_bit_flips_never_give_a_wrong_message(msg, seq, flips):
    """CRC-16/CCITT has Hamming distance 4 at these lengths and the length is checked
    against the type, so 1–3 flipped bits anywhere in a frame are always detected; the
    good frame behind it still decodes."""
    frame = bytearray(encode(msg, seq))
    for bit in flips:
        if bit < 8 * len(frame):
            frame[bit // 8] ^= 1 << (bit % 8)
    if bytes(frame) == encode(msg, seq):
        return
    dec = Decoder()
    trailer = encode(Heartbeat(123.0), (seq + 1) % 65536)
    got = dec.feed(bytes(frame) + trailer)
    assert [f.message for f in got] == [Heartbeat(123.0)]


def test_random_corruption_false_acceptance_rate():
    """Heavier corruption (random byte overwrites) is caught at ≈ CRC-collision rate.

    Each trial overwrites 2–6 random bytes after the sync word of a random frame; a false
    acceptance needs a 16-bit CRC collision (p ≈ 1.5e-5 per frame), so 20 000 trials expect
    ≈ 0.3 of them; more than 3 would mean a real weakness.
    """
    rng = random.Random(1234)
    false_accepts = 0
    trials = 20000
    for _ in range(trials):
        msg = Observation(*(rng.uniform(-100, 100) for _ in range(5)), True, 5.0, 0.5)
        good = encode(msg, rng.randrange(65536))
        frame = bytearray(good)
        for _ in range(rng.randint(2, 6)):
            frame[rng.randrange(2, len(frame))] = rng.randrange(256)
        if bytes(frame) == good:
            continue
        dec = Decoder()
        false_accepts += len(dec.feed(bytes(frame)))
    assert false_accepts <= 3


def test_encode_rejects_bad_input():
    with pytest.raises(ProtocolError, match="sequence"):
        encode(Stop(0), 70000)
    with pytest.raises(ProtocolError, match="cannot encode"):
        encode(Ack(seq=-1), 1)
    with pytest.raises(ProtocolError, match="float32 range"):  # was an OverflowError
        encode(Observation(0.0, 1e39, 0.0, 0.0, 0.0, False, 0.0, 1.0), 1)
    with pytest.raises(ProtocolError, match="must be finite"):
        encode(VelocityCommand.unicycle(float("nan"), 0.0), 1)
    with pytest.raises(ProtocolError, match="must be finite"):
        encode(Heartbeat(float("inf")), 1)
    with pytest.raises(ProtocolError, match="mode = 2 is undefined"):
        encode(VelocityCommand(2, 1.0, 1.0), 1)
    with pytest.raises(ProtocolError, match="outside 0..255"):
        encode(Stop(256), 1)
    with pytest.raises(ProtocolError, match="not a number"):
        encode(Heartbeat("soon"), 1)
    with pytest.raises(ProtocolError, match="not a protocol message"):
        encode("hello", 1)
    with pytest.raises(ProtocolError, match="exactly one"):
        decode_one(encode(Stop(0), 1)[:-1])


def test_values_the_wire_carries_are_accepted():
    """NaN means "unknown" in observations and telemetry; the float32 limit itself passes;
    NumPy scalars and IntEnum codes encode like Python numbers."""
    import numpy as np

    big = float(np.finfo(np.float32).max)
    obs = Observation(np.float64(1.5), np.float32(big), float("nan"), 0.0, 0.0, True, 0.0, 1.0)
    assert messages_equal(decode_one(encode(obs, 1)).message, obs.quantized())
    assert decode_one(encode(Stop(StopReason.LINK_ERROR), 2)).message == Stop(3)
    assert decode_one(encode(Ack(np.uint16(7), np.int64(1)), 3)).message == Ack(7, 1)


def _frame_with_payload(mtype: int, payload: bytes, seq: int = 5) -> bytes:
    body = struct.pack("<HBH", len(payload), mtype, seq) + payload
    return SYNC + body + struct.pack("<H", crc16_ccitt_false(body))


def test_decoder_rejects_undefined_values_with_valid_crc():
    """A CRC-valid command with an undefined mode, an ACK with an undefined status or a flag
    byte other than 0/1 is dropped (bad_payload) and never reaches the robot; the good frame
    behind it decodes. A non-finite command is passed on: the robot stops on it (FAULT)."""
    bad = [
        _frame_with_payload(0x02, struct.pack("<Bff", 7, 10.0, 0.0)),  # mode 7
        _frame_with_payload(0x04, struct.pack("<HB", 3, 9)),  # ACK status 9
        _frame_with_payload(0x01, struct.pack("<dffffBff", 0, 0, 0, 0, 0, 2, 0, 1)),  # flag 2
        _frame_with_payload(0x10, struct.pack("<dfffffBB", 0, 0, 0, 0, 0, 0, 5, 0)),  # flag 5
    ]
    nan_cmd = _frame_with_payload(0x02, struct.pack("<Bff", 0, float("nan"), 0.0), seq=6)
    dec = Decoder()
    got = dec.feed(b"".join(bad) + nan_cmd + encode(Stop(0), 8))
    assert [f.seq for f in got] == [6, 8]
    assert dec.stats.bad_payload == len(bad)
    assert math.isnan(got[0].message.a)
    with pytest.raises(ProtocolError):
        decode_one(bad[0])


#: Fuzz sizes: corrupted frames per class (≥ 10⁵ in all, a few seconds).
FUZZ_FLIPS = 100_000
FUZZ_TRUNCATED = 20_000


def _fuzz_pool(rng: random.Random, n: int) -> list[bytes]:
    """`n` valid frames of every message type with random field values and sequence numbers."""

    def f():
        return rng.choice([rng.uniform(-1e3, 1e3), rng.uniform(-1e30, 1e30), float("nan"), 0.0])

    def finite():
        return rng.uniform(-1e4, 1e4)

    makers = [
        lambda: Observation(finite(), f(), f(), f(), f(), rng.random() < 0.5, f(), rng.random()),
        lambda: VelocityCommand(rng.randint(0, 1), finite(), finite()),
        lambda: Heartbeat(finite()),
        lambda: Ack(rng.randrange(65536), rng.randint(0, 1)),
        lambda: Stop(rng.randrange(7)),
        lambda: RobotState(finite(), f(), f(), f(), f(), f(), rng.random() < 0.5, rng.randrange(7)),
    ]
    return [encode(rng.choice(makers)(), rng.randrange(65536)) for _ in range(n)]


def test_fuzz_corrupted_frames_never_crash_or_false_accept_and_resync_in_one_frame():
    """≥ 10⁵ corrupted frames through one streaming decoder, each followed by a good frame:
    1–3 flipped bits anywhere (sync, header, payload, CRC), then truncations at every length.

    No exception; no frame with flipped bits is ever accepted; and the good frame right
    behind every corrupted one decodes, in order (resynchronisation within one frame). The
    one exception is inherent to any framing: a truncated frame whose missing tail happens to
    equal the first bytes of the next frame *is* the complete original frame; it is then
    decoded (the true message, not a false one) and the next frame is lost."""
    rng = random.Random(20260)
    pool = _fuzz_pool(rng, 3000)
    trailers = [encode(Heartbeat(float(i)), i) for i in range(1000)]
    stream = bytearray()
    expected = []
    truncated_originals = set()
    intact_sync = 0
    for i in range(FUZZ_FLIPS + FUZZ_TRUNCATED):
        good = rng.choice(pool)
        frame = bytearray(good)
        if i < FUZZ_FLIPS:
            for bit in rng.sample(range(8 * len(frame)), rng.randint(1, 3)):
                frame[bit // 8] ^= 1 << (bit % 8)
            assert frame != good
            intact_sync += frame[:2] == SYNC
        else:
            frame = frame[: rng.randrange(1, len(frame))]
            truncated_originals.add(good)
        stream += frame
        k = i % len(trailers)
        stream += trailers[k]
        expected.append(k)
    dec = Decoder()
    got = []
    pos = 0
    while pos < len(stream):  # arbitrary chunking, as a serial port delivers bytes
        n = rng.randint(1, 512)
        got += dec.feed(bytes(stream[pos : pos + n]))
        pos += n
    assert FUZZ_FLIPS + FUZZ_TRUNCATED >= 100_000
    trailer_set = set(trailers)
    beats = [f for f in got if encode(f.message, f.seq) in trailer_set]
    others = [f for f in got if encode(f.message, f.seq) not in trailer_set]
    # 0 false accepts: anything but a trailer is a truncated frame restored byte for byte
    assert all(encode(f.message, f.seq) in truncated_originals for f in others)
    assert len(others) <= 10  # ≈ 1/256 of the 1-byte truncations, a few in 20 000
    # resync: every trailer, in order, none twice, except one per restored truncated frame
    seqs = [f.seq for f in beats]
    it = iter(expected)
    assert all(any(k == s for k in it) for s in seqs)  # a subsequence of `expected`
    assert len(expected) - len(seqs) == len(others)
    # every flipped frame that kept its sync word was rejected and counted; the others were
    # skipped as noise while hunting for a sync word
    assert dec.stats.dropped >= intact_sync
