"""Live recording in a separate process, so that writing takes none of the physics thread's time.

Every record is (topic, type, log time, CDR bytes), the bytes exactly as published or received
(built by :mod:`gyro_sim.io.messages`; /tf too, which the node records even where tf2_msgs is
not installed to publish it). Log time = node time. No rclpy here.

Shape (issue 11, item 4: a writer *thread* shared the interpreter, and so the GIL, with the
physics thread):

- the physics and executor threads call :meth:`LiveRecorder.raw`: one put on a queue;
- a sender thread in the node takes what is queued (a publication's ~n records at once, after a
  short gathering pause) and hands it as one pickled batch to a pipe;
- a child process (``python -c``, not fork: the node has DDS threads) owns the
  :class:`~gyro_sim.io.mcap_log.LogWriter`: it opens the log (an error, e.g. an existing file, is
  raised by the constructor here), writes each batch, flushes every `flush_period` as before, and
  on end of input (close here, or the node killed, even by SIGKILL) writes the summary, reports
  its counts and exits. It ignores SIGINT/SIGTERM/SIGHUP: the end of its input is its only stop.
"""
from __future__ import annotations

import os
import pickle
import queue
import select
import signal
import struct
import subprocess
import sys
import threading
import time
from types import SimpleNamespace

#: pause of the sender thread after the first record of a batch (s): lets the publication's
#: other records join it (one pipe write per publication, not per record)
BATCH_GATHER = 0.002
#: longest wait for the child to open the log (s)
START_TIMEOUT = 60.0

_HEADER = struct.Struct("<I")


def _write_frame(f, obj) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    f.write(_HEADER.pack(len(data)) + data)
    f.flush()


def _read_exact(f, n: int) -> bytes | None:
    data = f.read(n)
    return data if data is not None and len(data) == n else None


def _read_frame(f):
    """The next object, or None at end of input (or a truncated frame)."""
    head = _read_exact(f, _HEADER.size)
    if head is None:
        return None
    data = _read_exact(f, _HEADER.unpack(head)[0])
    return None if data is None else pickle.loads(data)


class LiveRecorder:
    """Record to `path` (gyro_sim.io.mcap_log.LogWriter) from a child process.

    Parameters
    ----------
    path : the MCAP file.
    scene : the Scene (embedded in the log).
    params : the node's parameters (embedded as metadata).
    writer_options : passed on to LogWriter (flush_period, overwrite ...).

    Attributes after `close`: `written` (records written by the child), `max_backlog` (most
    records waiting in the node's queue at one hand-over), `thread_cpu` (CPU seconds of the
    writer process), `sender_cpu` (CPU seconds of the sender thread here), `error`.
    `writer.flush_period`: the writer's flush period, as the child reports it.
    """

    def __init__(self, path: str, *, scene, params: dict, **writer_options):
        self.path = path
        self.queue: queue.SimpleQueue = queue.SimpleQueue()
        self.written = 0
        self.max_backlog = 0
        self.thread_cpu = 0.0  # CPU seconds spent by the writer process
        self.sender_cpu = 0.0  # CPU seconds spent by the sender thread in this process
        self.error: str | None = None
        self._closed = False
        self._lock = threading.Lock()
        env = dict(os.environ)
        root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        self._proc = subprocess.Popen(
            [sys.executable, "-c", "from gyro_sim.ros.recorder import _child_main; _child_main()"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env, close_fds=True,
        )
        try:
            _write_frame(self._proc.stdin, (path, scene, params, writer_options))
            if not select.select([self._proc.stdout], [], [], START_TIMEOUT)[0]:
                raise RuntimeError(f"log {path}: the recorder process did not start in {START_TIMEOUT:g} s")
            reply = _read_frame(self._proc.stdout)
            if reply is None:
                raise RuntimeError(f"log {path}: the recorder process exited (code {self._proc.wait(5)})")
            if reply[0] == "error":
                raise reply[1]
        except BaseException:
            self._abandon()
            raise
        self.writer = SimpleNamespace(flush_period=reply[1])
        self._thread = threading.Thread(target=self._send_loop, name="gyro_sim-recorder", daemon=True)
        self._thread.start()

    def _abandon(self) -> None:
        try:
            self._proc.stdin.close()
        except OSError:
            pass
        try:
            self._proc.wait(10.0)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()

    # --- from the physics and executor threads (cheap: one queue put) ------------------------------
    def raw(self, topic: str, msgtype: str, t_ns: int, data: bytes) -> None:
        self.queue.put((topic, msgtype, t_ns, data))

    # --- the sender thread --------------------------------------------------------------------------
    def _send_loop(self) -> None:
        cpu0 = time.thread_time()
        q, out = self.queue, self._proc.stdin
        broken = False
        stop = False
        while not stop:
            item = q.get()
            if item is not None and BATCH_GATHER > 0:
                time.sleep(BATCH_GATHER)
            batch = []
            while True:
                if item is None:
                    stop = True
                    break
                batch.append(item)
                try:
                    item = q.get_nowait()
                except queue.Empty:
                    break
            if len(batch) > self.max_backlog:
                self.max_backlog = len(batch)
            if batch and not broken:
                try:
                    _write_frame(out, batch)
                except (OSError, ValueError) as exc:  # the child is gone: keep draining, report it
                    broken = True
                    self.error = f"recorder process: {type(exc).__name__}: {exc}"
        self.sender_cpu = time.thread_time() - cpu0

    def close(self, timeout: float = 10.0) -> None:
        """Hand over what is queued; the child writes it and the MCAP summary. Idempotent."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        if self._thread.is_alive():
            self.queue.put(None)
            self._thread.join(timeout)
        try:
            out, _ = self._proc.communicate(timeout=timeout)  # closes the child's input: it finishes
        except subprocess.TimeoutExpired:  # left running: it finishes the log on its own
            self.error = self.error or f"recorder process still writing after {timeout:g} s"
            return
        except (OSError, ValueError) as exc:
            self.error = self.error or f"recorder process: {type(exc).__name__}: {exc}"
            return
        try:
            reply = pickle.loads(out[_HEADER.size:]) if len(out) > _HEADER.size else None
        except Exception:  # noqa: BLE001
            reply = None
        if reply is None or reply[0] != "closed":
            self.error = self.error or f"recorder process exited (code {self._proc.returncode}) without a report"
            return
        _, self.written, self.thread_cpu, child_error = reply
        self.error = self.error or child_error


# --- the child process ---------------------------------------------------------------------------
def _child_main() -> None:
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):  # stop only at the end of input
        signal.signal(sig, signal.SIG_IGN)
    inp = sys.stdin.buffer
    reply_fd = os.dup(1)
    os.dup2(2, 1)  # stray prints go to stderr, not into the replies
    reply = os.fdopen(reply_fd, "wb")
    cpu0 = time.process_time()
    start = _read_frame(inp)
    if start is None:
        return
    path, scene, params, writer_options = start
    try:
        from gyro_sim.io.mcap_log import LogWriter

        w = LogWriter(path, scene=scene, params=params, **writer_options)
    except BaseException as exc:  # noqa: BLE001 - raised in the node instead
        try:
            pickle.dumps(exc)
        except Exception:  # noqa: BLE001
            exc = RuntimeError(f"{type(exc).__name__}: {exc}")
        _write_frame(reply, ("error", exc))
        return
    _write_frame(reply, ("ok", w.flush_period))
    channels: dict[str, int] = {}
    written = 0
    error = None
    try:
        while True:
            batch = _read_frame(inp)
            if batch is None:
                break
            for topic, msgtype, t_ns, data in batch:
                try:
                    ch = channels.get(topic)
                    if ch is None:
                        ch = channels[topic] = w.add_channel(topic, msgtype)
                    w.write_raw(ch, t_ns, data)
                    written += 1
                except Exception as exc:  # noqa: BLE001 - a bad record must not stop the recording
                    error = f"{type(exc).__name__}: {exc}"
    finally:
        w.close()
    try:
        _write_frame(reply, ("closed", written, time.process_time() - cpu0, error))
    except OSError:  # the node is gone (killed): nobody to tell
        pass
