"""Live recording in a separate process, so that writing takes none of the physics thread's time.

Every record is (topic, type, log time, CDR bytes), the bytes exactly as published or received
(built by :mod:`gyro_sim.msgs.messages`; /tf too, which the node records even where tf2_msgs is
not installed to publish it). Log time = node time. No rclpy here.

Shape (issue 11, item 4: a writer *thread* shared the interpreter, and so the GIL, with the
physics thread; then a sender thread pickling ~n records per publication still held the GIL
~200 us per publication at n = 100):

- the physics thread hands over a publication with one call, :meth:`LiveRecorder.raw_batch`
  (one queue put); commands and events, from other threads one at a time with their own
  times, come through :meth:`LiveRecorder.raw` (one put each);
- a sender thread in the node wakes every `SEND_PERIOD` (it is not woken by the puts), takes
  what is queued and writes it to a pipe with one ``os.writev`` (which releases the GIL while
  the kernel copies). A publication cut from one
  :class:`gyro_sim.msgs.messages.Frame` goes as that frame's bytes block, unpickled, behind a
  12-byte head (layout id, log time); the frame's layout (topic, type, start, stop of each
  message) goes once, pickled, the first time it is seen. Lone records (commands, events, the
  diagnostics that ride with a publication, a publication not cut from a frame) go as one
  pickled list per wake-up (so what SIGKILL can lose grows by at most `SEND_PERIOD`);
- a child process (``python -c``, not fork: the node has DDS threads) owns the
  :class:`~gyro_sim.log.mcap_log.LogWriter`: it opens the log (an error, e.g. an existing file, is
  raised by the constructor here), cuts each block by its layout and writes the records in the
  order they were handed over, flushes every `flush_period` as before, and on end of input
  (close here, or the node killed, even by SIGKILL) writes the summary, reports its counts and
  exits. It ignores SIGINT/SIGTERM/SIGHUP: the end of its input is its only stop.

Pipe frames: a head (kind: 1 byte, payload length: uint32) and the payload. Node to child:
``S`` start (pickled path, scene, params, writer options), ``L`` layout (pickled id, layout),
``B`` block (layout id uint32, log time int64, the block), ``R`` records (pickled list of
(topic, type, log time, bytes)). Child to node: ``P`` (a pickled reply).
"""
from __future__ import annotations

import fcntl
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

#: period of the sender thread (s): it sleeps, then sends everything queued in one write. It
#: is not woken by the puts: a put that wakes a waiting thread costs the putting thread ~10 us
#: (futex wake, the woken thread asking for the GIL), a put nobody waits on ~0.2 us
SEND_PERIOD = 0.02
#: capacity asked for the pipe to the child (bytes; Linux, best effort): many publications'
#: blocks at n = 100 (~30 kB each) fit in it while the child writes
PIPE_SIZE = 1 << 20
#: longest wait for the child to open the log (s)
START_TIMEOUT = 60.0
#: niceness the writer process adds to its own: writing is background work whose latency does
#: not matter (the pipe and the queue absorb it), while the physics thread, woken at its
#: deadline on a core the writer occupies, must get it at once. At n = 100 the writer takes
#: ~12 % of a core in bursts every SEND_PERIOD; at equal priority the scheduler may let it
#: finish its slice first
WRITER_NICE = 10

_HEAD = struct.Struct("<cI")  # kind, payload length
_BLOCK = struct.Struct("<Iq")  # layout id, log time (ns): the start of a block's payload
_BLOCK_HEAD = struct.Struct("<cIIq")  # _HEAD then _BLOCK, packed at once
_IOV_MAX = os.sysconf("SC_IOV_MAX") if hasattr(os, "sysconf") else 16


def _pickled(kind: bytes, obj) -> tuple[bytes, bytes]:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    return _HEAD.pack(kind, len(data)), data


def _write_all(fd: int, bufs: list) -> None:
    """Write every buffer of `bufs` to `fd`, in order (os.writev, again after a partial write)."""
    i = 0
    while i < len(bufs):
        n = os.writev(fd, bufs[i:i + _IOV_MAX])
        while i < len(bufs):
            size = len(bufs[i])
            if n < size:
                bufs[i] = memoryview(bufs[i])[n:]
                break
            n -= size
            i += 1


def _read_exact(f, n: int) -> bytes | None:
    data = f.read(n)
    return data if data is not None and len(data) == n else None


def _read_frame(f) -> tuple[bytes, bytes] | None:
    """The next (kind, payload), or None at end of input (or a truncated frame)."""
    head = _read_exact(f, _HEAD.size)
    if head is None:
        return None
    kind, size = _HEAD.unpack(head)
    data = _read_exact(f, size)
    return None if data is None else (kind, data)


def _read_reply(f):
    frame = _read_frame(f)
    return None if frame is None else pickle.loads(frame[1])


class _Packer:
    """The sender thread's Python work: queued items -> the buffers of one pipe write (the only
    time the sender holds the interpreter lock, besides waking up: gyro-sim bench publication
    --recorder times it alone).

    An item is a record (topic, type, log time, bytes) from `raw` or a publication (log time,
    batch) from `raw_batch`. Blocks and records keep the order they were handed over in."""

    def __init__(self) -> None:
        self.layouts: dict[int, tuple[tuple, int]] = {}  # id(layout) -> (layout, its id in the child); kept: no id reused
        self.error: str | None = None

    def pack(self, items: list) -> tuple[list, int]:
        """The buffers to write and the number of records in them."""
        bufs: list = []
        records: list = []  # lone records since the last block, in order
        count = 0
        for item in items:
            if len(item) == 4:
                records.append(item)
                count += 1
                continue
            t_ns, batch = item
            count += len(batch)
            layout = getattr(batch, "layout", None)
            if layout is None:
                records += [(topic, msgtype, t_ns, data) for topic, msgtype, data in batch]
                continue
            known = self.layouts.get(id(layout))
            lid = len(self.layouts) if known is None else known[1]
            try:
                head = _BLOCK_HEAD.pack(b"B", _BLOCK.size + len(batch.block), lid, t_ns)
            except struct.error as exc:  # a log time out of range: the writer would refuse it too
                self.error = self.error or f"recorder: log time {t_ns!r}: {exc}"
                continue
            if records:
                bufs += _pickled(b"R", records)
                records = []
            if known is None:
                self.layouts[id(layout)] = (layout, lid)
                bufs += _pickled(b"L", (lid, layout))
            bufs += (head, batch.block)
            if len(batch) > len(layout):  # the diagnostics that go with it
                records += [(topic, msgtype, t_ns, data) for topic, msgtype, data in batch[len(layout):]]
        if records:
            bufs += _pickled(b"R", records)
        return bufs, count


class LiveRecorder:
    """Record to `path` (gyro_sim.log.mcap_log.LogWriter) from a child process.

    Parameters
    ----------
    path : the MCAP file.
    scene : the Scene (embedded in the log).
    params : the node's parameters (embedded as metadata).
    writer_options : passed on to LogWriter (flush_period, overwrite ...).

    Attributes after `close`: `written` (records written by the child), `max_backlog` (most
    records waiting in the node's queue at one hand-over), `thread_cpu` (CPU seconds of the
    writer process, of which `open_cpu` to start and open the log), `sender_cpu` (CPU seconds
    of the sender thread here, wake-ups and pipe writes included), `error`.
    `writer.flush_period`: the writer's flush period, as the child reports it; `writer.nice`:
    the writer process's niceness (WRITER_NICE above the node's where the system allows).
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
            fcntl.fcntl(self._proc.stdin.fileno(), fcntl.F_SETPIPE_SZ, PIPE_SIZE)
        except (AttributeError, OSError):  # not Linux, or above /proc/sys/fs/pipe-max-size: the default
            pass
        try:
            _write_all(self._proc.stdin.fileno(), list(_pickled(b"S", (path, scene, params, writer_options))))
            if not select.select([self._proc.stdout], [], [], START_TIMEOUT)[0]:
                raise RuntimeError(f"log {path}: the recorder process did not start in {START_TIMEOUT:g} s")
            reply = _read_reply(self._proc.stdout)
            if reply is None:
                raise RuntimeError(f"log {path}: the recorder process exited (code {self._proc.wait(5)})")
            if reply[0] == "error":
                raise reply[1]
        except BaseException:
            self._abandon()
            raise
        self.writer = SimpleNamespace(flush_period=reply[1], nice=reply[3])
        self.open_cpu = reply[2]  # CPU seconds of the writer process to start and open the log
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
        """One record (a command, an event) with its own log time."""
        self.queue.put((topic, msgtype, t_ns, data))

    def raw_batch(self, t_ns: int, batch: list) -> None:
        """A publication: [(topic, type, bytes)], all at log time t_ns, kept as handed over (not
        copied: neither the list nor its bytes may change after). A
        :class:`gyro_sim.msgs.messages.FrameBatch` goes to the writer as its block."""
        self.queue.put((t_ns, batch))

    # --- the sender thread --------------------------------------------------------------------------
    def _send_loop(self) -> None:
        cpu0 = time.thread_time()
        q, fd, packer = self.queue, self._proc.stdin.fileno(), _Packer()
        broken = False
        stop = False
        while not stop:
            time.sleep(SEND_PERIOD)  # not woken by each put: a put that wakes a waiting thread costs ~10 us
            items = []
            while True:
                try:
                    items.append(q.get_nowait())
                except queue.Empty:
                    break
            if None in items:  # close(): what came before it is the last to send
                stop = True
                items = items[:items.index(None)]
            try:
                bufs, count = packer.pack(items)
            except Exception as exc:  # noqa: BLE001 - a bad item must not stop the recording
                bufs, count = [], len(items)
                self.error = self.error or f"recorder: {type(exc).__name__}: {exc}"
            self.error = self.error or packer.error
            if count > self.max_backlog:
                self.max_backlog = count
            if bufs and not broken:
                try:
                    _write_all(fd, bufs)
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
            reply = pickle.loads(out[_HEAD.size:]) if len(out) > _HEAD.size else None
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
    cpu0 = time.process_time()
    try:
        nice = os.nice(WRITER_NICE)
    except OSError:  # not allowed here: as the node
        nice = os.nice(0)

    def send(obj) -> None:
        _write_all(reply_fd, list(_pickled(b"P", obj)))

    start = _read_frame(inp)
    if start is None or start[0] != b"S":
        return
    path, scene, params, writer_options = pickle.loads(start[1])
    try:
        from gyro_sim.log.mcap_log import LogWriter

        w = LogWriter(path, scene=scene, params=params, **writer_options)
    except BaseException as exc:  # noqa: BLE001 - raised in the node instead
        try:
            pickle.dumps(exc)
        except Exception:  # noqa: BLE001
            exc = RuntimeError(f"{type(exc).__name__}: {exc}")
        send(("error", exc))
        return
    send(("ok", w.flush_period, time.process_time() - cpu0, nice))
    channels: dict[str, int] = {}
    layouts: dict[int, list[tuple[int | None, int, int]]] = {}  # layout id -> (channel, start, stop) per message
    written = 0
    error = None

    def channel(topic: str, msgtype: str) -> int:
        ch = channels.get(topic)
        if ch is None:
            ch = channels[topic] = w.add_channel(topic, msgtype)
        return ch

    try:
        while True:
            frame = _read_frame(inp)
            if frame is None:
                break
            kind, payload = frame
            try:
                if kind == b"B":  # a publication's block: its records, cut by the layout
                    lid, t_ns = _BLOCK.unpack_from(payload)
                    view, at = memoryview(payload), _BLOCK.size
                    for ch, a, b in layouts[lid]:
                        if ch is not None:
                            try:
                                w.write_raw(ch, t_ns, view[at + a:at + b])
                                written += 1
                            except Exception as exc:  # noqa: BLE001 - a bad record must not stop the recording
                                error = f"{type(exc).__name__}: {exc}"
                elif kind == b"R":
                    for topic, msgtype, t_ns, data in pickle.loads(payload):
                        try:
                            w.write_raw(channel(topic, msgtype), t_ns, data)
                            written += 1
                        except Exception as exc:  # noqa: BLE001
                            error = f"{type(exc).__name__}: {exc}"
                elif kind == b"L":
                    lid, layout = pickle.loads(payload)
                    cut = []
                    for topic, msgtype, a, b in layout:
                        try:
                            ch = channel(topic, msgtype)
                        except Exception as exc:  # noqa: BLE001 - its records are left out, the others written
                            error, ch = f"{type(exc).__name__}: {exc}", None
                        cut.append((ch, a, b))
                    layouts[lid] = cut
                else:
                    error = f"recorder process: unknown frame {kind!r}"
            except Exception as exc:  # noqa: BLE001 - a bad frame must not stop the recording
                error = f"{type(exc).__name__}: {exc}"
    finally:
        w.close()
    try:
        send(("closed", written, time.process_time() - cpu0, error))
    except OSError:  # the node is gone (killed): nobody to tell
        pass
