"""Live recording: a writer thread fed by a queue, so that the physics loop only enqueues.

Every record is (topic, type, log time, CDR bytes), the bytes exactly as published or received
(built by :mod:`gyro_sim.io.messages`; /tf too, which the node records even where tf2_msgs is
not installed to publish it). Log time = node time. No rclpy here.
"""
from __future__ import annotations

import queue
import threading
import time


class LiveRecorder:
    """Record to `path` (gyro_sim.io.mcap_log.LogWriter) from a background thread.

    Parameters
    ----------
    path : the MCAP file.
    scene : the Scene (embedded in the log).
    params : the node's parameters (embedded as metadata).
    writer_options : passed on to LogWriter (flush_period, overwrite ...).
    """

    def __init__(self, path: str, *, scene, params: dict, **writer_options):
        from ..io.mcap_log import LogWriter

        self.path = path
        self.writer = LogWriter(path, scene=scene, params=params, **writer_options)
        self.queue: queue.SimpleQueue = queue.SimpleQueue()
        self.channels: dict[str, int] = {}
        self.written = 0
        self.max_backlog = 0
        self.thread_cpu = 0.0  # CPU seconds spent by the writer thread
        self.error: str | None = None
        self._thread = threading.Thread(target=self._run, name="gyro_sim-recorder", daemon=True)
        self._thread.start()

    # --- from the physics and executor threads (cheap: one queue put) ------------------------------
    def raw(self, topic: str, msgtype: str, t_ns: int, data: bytes) -> None:
        self.queue.put((topic, msgtype, t_ns, data))

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
            topic, msgtype, t_ns, data = item
            try:
                ch = self.channels.get(topic)
                if ch is None:
                    ch = self.channels[topic] = w.add_channel(topic, msgtype)
                w.write_raw(ch, t_ns, data)
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
