"""Live recording: a writer thread fed by a queue, so that the physics loop only enqueues.

Every record is (topic, type, log time, payload): CDR bytes exactly as published or received
(written with `LogWriter.write_raw`), or, for the log-only `/tf` channel (tf2_msgs is not on
PyPI, so the node cannot publish it), the transforms, encoded here by `encode_tf` (the
generic dynamic encoder takes ~0.7 ms per message at n = 20, this ~20 us). Log time = node time.
"""
from __future__ import annotations

import queue
import struct
import threading
import time

TF_TOPIC = "/tf"
TF_TYPE = "tf2_msgs/msg/TFMessage"
WORLD_FRAME = "world"
#: CDR encapsulation header: plain CDR, little endian
CDR_LE = b"\x00\x01\x00\x00"


class Recorder:
    """Record to `path` (gyro_sim.io.mcap_log.LogWriter) from a background thread.

    Parameters
    ----------
    path : the MCAP file.
    scene : the Scene (embedded in the log).
    params : the node's parameters (embedded as metadata).
    """

    def __init__(self, path: str, *, scene, params: dict, flush_period: float = 1.0):
        from ..io.mcap_log import LogWriter

        self.path = path
        self.writer = LogWriter(path, scene=scene, params=params, flush_period=flush_period)
        self.queue: queue.SimpleQueue = queue.SimpleQueue()
        self.channels: dict[str, int] = {}
        self.written = 0
        self.max_backlog = 0
        self.thread_cpu = 0.0  # CPU seconds spent by the writer thread
        self.error: str | None = None
        self._thread = threading.Thread(target=self._run, name="gyro_sim-recorder", daemon=True)
        self._thread.start()

    # --- from the physics thread (cheap: one queue put) -------------------------------------------
    def raw(self, topic: str, msgtype: str, t_ns: int, data: bytes) -> None:
        self.queue.put((topic, msgtype, t_ns, data))

    def tf(self, t_ns: int, transforms: list) -> None:
        """transforms: (child frame, (x, y, z), (qx, qy, qz, qw)) of each body in the world frame."""
        self.queue.put((TF_TOPIC, TF_TYPE, t_ns, transforms))

    def event(self, t_ns: int, text: str) -> None:
        self.queue.put((None, None, t_ns, text))

    # --- the writer thread --------------------------------------------------------------------------
    def _run(self) -> None:
        cpu0 = time.thread_time()
        w = self.writer
        while True:
            item = self.queue.get()
            if item is None:
                break
            backlog = self.queue.qsize()
            if backlog > self.max_backlog:
                self.max_backlog = backlog
            topic, msgtype, t_ns, payload = item
            try:
                if topic is None:
                    w.event(t_ns, payload)
                else:
                    ch = self.channels.get(topic)
                    if ch is None:
                        ch = self.channels[topic] = w.add_channel(topic, msgtype)
                    if topic == TF_TOPIC:
                        payload = encode_tf(t_ns, WORLD_FRAME, payload)
                    w.write_raw(ch, t_ns, payload)
                self.written += 1
            except Exception as exc:  # noqa: BLE001 - a bad record must not stop the recording
                self.error = f"{type(exc).__name__}: {exc}"
        self.thread_cpu = time.thread_time() - cpu0

    def close(self, timeout: float = 10.0) -> None:
        """Write what is queued, then the MCAP summary; idempotent."""
        if self._thread.is_alive():
            self.queue.put(None)
            self._thread.join(timeout)
        self.writer.close()


def _cdr_string(buf: bytearray, text: str) -> None:
    buf.extend(b"\0" * (-(len(buf) - 4) % 4))  # align 4 (offsets count after the header)
    data = text.encode() + b"\0"
    buf.extend(struct.pack("<I", len(data)))
    buf.extend(data)


def encode_tf(t_ns: int, frame: str, transforms) -> bytes:
    """tf2_msgs/msg/TFMessage as CDR (little endian), every transform stamped `t_ns` in `frame`.

    transforms: iterable of (child_frame_id, (x, y, z), (qx, qy, qz, qw)).
    """
    sec, nsec = divmod(int(t_ns), 1_000_000_000)
    transforms = list(transforms)
    buf = bytearray(CDR_LE)
    buf.extend(struct.pack("<I", len(transforms)))
    for child, p, q in transforms:
        buf.extend(b"\0" * (-(len(buf) - 4) % 4))
        buf.extend(struct.pack("<iI", sec, nsec))  # header.stamp
        _cdr_string(buf, frame)  # header.frame_id
        _cdr_string(buf, child)  # child_frame_id
        buf.extend(b"\0" * (-(len(buf) - 4) % 8))  # align 8 for the float64 of transform
        buf.extend(struct.pack("<7d", *p, *q))
    return bytes(buf)
