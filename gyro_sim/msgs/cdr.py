"""A small CDR writer: ROS 2 messages as the exact bytes DDS carries, without rclpy.

ROS 2 serialises with OMG CDR (XCDR1), little endian: a 4-byte encapsulation header
(``00 01 00 00``), then the fields in order, each primitive aligned to its own size counted
from the end of the header; strings are a uint32 length (NUL included), the bytes and a NUL;
a sequence is a uint32 count, then its elements. Padding bytes are zero and nothing follows the
last field, so every reader (rclpy, rosbags, mcap-ros2-support) accepts the bytes, and the
node publishes and records the very same ones (tests compare them with all three).

Only what gyro_sim's messages need; their layouts are in :mod:`gyro_sim.msgs.messages`.
"""
from __future__ import annotations

import struct

import numpy as np

HEADER = b"\x00\x01\x00\x00"  # CDR, little endian, no options
_U32 = struct.Struct("<I")
_ZEROS = (b"", b"\0", b"\0\0", b"\0\0\0")
_TIME = struct.Struct("<iI")
_F64 = {k: struct.Struct(f"<{k}d") for k in (1, 3, 4, 6, 7)}
NS_PER_S = 1_000_000_000


class CdrWriter:
    """Append fields to one message's bytes (`bytes()` when done).

    record=True also notes where the stamps (`time`) and the float64 values (`f64_block`,
    `f64_seq`) went: `stamps` (byte offsets) and `floats` ((offset, count) pairs), so that a
    message of fixed layout can be refilled in place (:class:`Refill`).
    """

    __slots__ = ("buf", "stamps", "floats")

    def __init__(self, record: bool = False) -> None:
        self.buf = bytearray(HEADER)
        self.stamps: list[int] | None = [] if record else None
        self.floats: list[tuple[int, int]] | None = [] if record else None

    def align(self, n: int) -> None:
        pad = -(len(self.buf) - 4) % n
        if pad:
            self.buf += b"\0" * pad

    def u8(self, v: int) -> None:
        self.buf.append(v)

    def u32(self, v: int) -> None:
        self.align(4)
        self.buf += _U32.pack(v)

    def time(self, t_ns: int) -> None:
        """builtin_interfaces/Time of integer nanoseconds (int32 sec, uint32 nanosec)."""
        self.align(4)
        if self.stamps is not None:
            self.stamps.append(len(self.buf))
        self.buf += _TIME.pack(*divmod(int(t_ns), NS_PER_S))

    def string(self, s: str) -> None:
        b = s.encode()
        self.u32(len(b) + 1)
        self.buf += b
        self.buf.append(0)

    def strings(self, seq) -> None:
        self.u32(len(seq))
        for s in seq:
            self.string(s)

    def string_run(self, texts) -> None:
        """Strings one after another, each as `string` writes it (the same bytes), in one pass
        (a DiagnosticArray's keys and values: ~0.4 us a string less than `string`)."""
        buf = self.buf
        pack = _U32.pack
        for s in texts:
            b = s.encode()
            pad = -(len(buf) - 4) % 4
            if pad:
                buf += _ZEROS[pad]
            buf += pack(len(b) + 1)
            buf += b
            buf.append(0)

    def f64(self, *values: float) -> None:
        """Fixed-size float64 fields (a Vector3, a Pose ...): aligned to 8."""
        self.align(8)
        self.buf += _F64[len(values)].pack(*values)

    def f64_block(self, values: np.ndarray) -> None:
        """Consecutive float64 fields from an array (e.g. Vector3 + Quaternion = 7)."""
        self.align(8)
        a = np.ascontiguousarray(values, dtype="<f8")
        if self.floats is not None:
            self.floats.append((len(self.buf), a.size))
        self.buf += a.tobytes()

    def f64_seq(self, values) -> None:
        """sequence<float64>: the count, then (aligned to 8 when there are any) the values."""
        a = np.ascontiguousarray(values, dtype="<f8")
        self.u32(a.size)
        if a.size:
            self.align(8)
            if self.floats is not None:
                self.floats.append((len(self.buf), a.size))
            self.buf += a.tobytes()

    def raw(self, data: bytes) -> None:
        self.buf += data

    def header(self, t_ns: int, frame_id: str) -> None:
        """std_msgs/Header."""
        self.time(t_ns)
        self.string(frame_id)

    def __bytes__(self) -> bytes:
        return bytes(self.buf)

    def __len__(self) -> int:
        return len(self.buf)


class Refill:
    """Messages of fixed layout (names and sizes known), refilled per publication: the bytes of
    all of them, written once by recording writers, with new stamps and float64 values put in
    place. Same bytes as writing them afresh, in one vectorised pass.

    Every float64 sits 8-aligned after the 4-byte encapsulation header of its message, and every
    stamp 4-aligned: when each message's length keeps the next message's header on the same
    alignment (a multiple of 8; else the messages are laid out apart, each padded), the values
    go in through a float64 view of the bytes from offset 4 and the stamps through a uint32
    view, one index per value (not per byte).

    Parameters
    ----------
    writers : the messages, each a CdrWriter(record=True) already written (any stamp, any values)
    """

    def __init__(self, writers: list[CdrWriter]) -> None:
        stamps, floats, bounds, at = [], [], [], 0
        for w in writers:
            stamps += [at + o for o in w.stamps]
            floats += [at + o + 8 * np.arange(c) for o, c in w.floats]
            bounds.append((at, at + len(w.buf)))
            at += -(-len(w.buf) // 8) * 8  # the next message starts 8-aligned
        size = at + 8
        template = np.zeros(size, dtype=np.uint8)
        for w, (a, b) in zip(writers, bounds):
            template[a:b] = np.frombuffer(bytes(w), dtype=np.uint8)
        self.template = template
        float_at = np.concatenate(floats) if floats else np.zeros(0, dtype=np.intp)
        stamp_at = np.array(stamps, dtype=np.intp)
        assert not (float_at - 4).size or np.all((float_at - 4) % 8 == 0), "float64 not 8-aligned after the header"
        assert np.all(stamp_at % 4 == 0), "stamp not 4-aligned"
        self.float_index = (float_at - 4) // 8  # into the float64 view from byte 4
        self.sec_index = stamp_at // 4  # into the uint32 view: seconds, then nanoseconds
        self.bounds = bounds
        self.contiguous = all(b == a2 for (_, b), (a2, _) in zip(bounds, bounds[1:]))
        self.n_stamps = len(stamps)
        self.n_floats = self.float_index.size
        self._f64_count = (size - 4) // 8
        self._u32_count = size // 4

    def fill(self, t_ns: int, values: np.ndarray) -> list[bytes]:
        """The messages with every stamp t_ns and the float64 values (n_floats,) in the order
        the writers wrote them."""
        buf = self.template.copy()
        if self.n_stamps:
            sec, nsec = divmod(int(t_ns), NS_PER_S)
            u32 = buf[: 4 * self._u32_count].view("<u4")
            u32[self.sec_index] = sec & 0xFFFFFFFF  # int32 seconds, two's complement
            u32[self.sec_index + 1] = nsec
        buf[4: 4 + 8 * self._f64_count].view("<f8")[self.float_index] = np.asarray(values, dtype=np.float64).reshape(-1)
        data = buf.tobytes()
        if len(self.bounds) == 1:
            return [data[: self.bounds[0][1]]]
        return [data[a:b] for a, b in self.bounds]
