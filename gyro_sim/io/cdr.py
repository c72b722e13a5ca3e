"""A small CDR writer: ROS 2 messages as the exact bytes DDS carries, without rclpy.

ROS 2 serialises with OMG CDR (XCDR1), little endian: a 4-byte encapsulation header
(``00 01 00 00``), then the fields in order, each primitive aligned to its own size counted
from the end of the header; strings are a uint32 length (NUL included), the bytes and a NUL;
a sequence is a uint32 count, then its elements. Padding bytes are zero and nothing follows the
last field, so every reader (rclpy, rosbags, mcap-ros2-support) accepts the bytes, and the
node publishes and records the very same ones (tests compare them with all three).

Only what gyro_sim's messages need; their layouts are in :mod:`gyro_sim.io.messages`.
"""
from __future__ import annotations

import struct

import numpy as np

HEADER = b"\x00\x01\x00\x00"  # CDR, little endian, no options
_U32 = struct.Struct("<I")
_TIME = struct.Struct("<iI")
_F64 = {k: struct.Struct(f"<{k}d") for k in (1, 3, 4, 6, 7)}
NS_PER_S = 1_000_000_000


class CdrWriter:
    """Append fields to one message's bytes (`bytes()` when done)."""

    __slots__ = ("buf",)

    def __init__(self) -> None:
        self.buf = bytearray(HEADER)

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

    def f64(self, *values: float) -> None:
        """Fixed-size float64 fields (a Vector3, a Pose ...): aligned to 8."""
        self.align(8)
        self.buf += _F64[len(values)].pack(*values)

    def f64_block(self, values: np.ndarray) -> None:
        """Consecutive float64 fields from an array (e.g. Vector3 + Quaternion = 7)."""
        self.align(8)
        self.buf += np.ascontiguousarray(values, dtype="<f8").tobytes()

    def f64_seq(self, values) -> None:
        """sequence<float64>: the count, then (aligned to 8 when there are any) the values."""
        a = np.ascontiguousarray(values, dtype="<f8")
        self.u32(a.size)
        if a.size:
            self.align(8)
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
