"""Live recording in a separate process, so that writing takes none of the physics thread's time.

Every record is (topic, type, log time, CDR bytes), the bytes exactly as published or received
(built by :mod:`gyro_sim.msgs.messages`; /tf too, which the node records even where tf2_msgs is
not installed to publish it). Log time = node time. No rclpy here.

Shape (a writer *thread* shared the interpreter, and so the GIL, with the physics thread; a
sender thread pickling ~n records per publication still held the GIL ~200 us per publication
at n = 100):

- the physics thread hands over a publication with one call, :meth:`LiveRecorder.raw_batch`
  (one queue put); commands and events, one at a time with their own times, come through
  :meth:`LiveRecorder.raw`, and the commands a physics step took in through
  :meth:`LiveRecorder.raw_many` (one put each);
- a sender thread in the node wakes every `SEND_PERIOD` (it is not woken by the puts), takes
  what is queued and writes it to a pipe with ``os.writev`` (which releases the GIL while the
  kernel copies). A publication cut from one :class:`gyro_sim.msgs.messages.Frame` goes as that
  frame's bytes block, unpickled, behind a 12-byte head (layout id, log time); the frame's
  layout (topic, type, start, stop of each message) goes once, pickled, the first time it is
  seen. Lone records (commands, events, the diagnostics that ride with a publication, a
  publication not cut from a frame) go as one pickled list per wake-up (so what SIGKILL can
  lose grows by at most `SEND_PERIOD`);
- a child process (``python -c``, not fork: the node has DDS threads) owns the
  :class:`~gyro_sim.log.mcap_log.LogWriter`: it cuts each block by its layout and writes the
  records in the order they were handed over, flushes every `flush_period`, and on end of
  input (close here, or the node killed, even by SIGKILL) writes the summary, reports its
  counts and exits. It ignores SIGINT/SIGTERM/SIGHUP: the end of its input is its only stop.

The file
--------
The node creates the log file itself (:func:`create_log_file`) before the writer process
starts, and hands the open descriptor over:

- without `overwrite`, the record path itself, with ``O_CREAT | O_EXCL``: the check that it does
  not exist and its creation are one atomic step, so of two nodes started on one path one gets
  it and the other is refused at once (OutputError, nothing written);
- with `overwrite`, a file of its own beside it, ``<name>.<random hex>.partial`` (also
  ``O_EXCL``), which the writer process renames onto the record path once the log is complete
  (summary written): until then the path keeps what it held, and of two nodes overwriting one
  path the last to finish wins, so the file left there is always one whole, readable log.

What is left where
------------------
- a run that ends (duration, signal): a complete log at the record path;
- the node killed, even by SIGKILL, its writer not: the writer sees the end of its input,
  writes what it had been handed, the summary and index, renames the ``.partial`` file
  (overwrite) and exits: a complete log at the record path, a moment after the node is gone;
  missing is only what the node had not yet handed over (at most `SEND_PERIOD` of records
  while the writer keeps up; the backlog waiting in the node too when it was behind);
- node and writer both killed by SIGKILL (the whole process group, say): the file being
  written (the record path, or the ``.partial`` file with overwrite) stops without summary or
  index; everything flushed before (every ``flush_period``, 0.2 s by default) is read back by
  ``gyro-sim recover FILE -o fixed.mcap``;
- the writer dies, or a write fails (no space left on the device, a file-size limit), while the
  node runs: it is seen at once (`failure`, the writer's report or the end of its output); the
  node stops its run and exits 1 (gyro_sim.ros.node), naming the file that holds the part
  written (`file`), which ``gyro-sim recover`` reads back; the writer, when it is the one that
  failed, closes what it can (no further write, the file closed);
- the writer stopped (SIGSTOP) when the node ends: `close` waits for it at most
  CLOSE_TIMEOUT to take the last records and as long again to finish, then says the log is not
  finished (`error`; the node exits 1); resumed, the writer finishes it on its own;
- a start given up (a signal during start-up, the writer failing to start):
  :meth:`LiveRecorder.abandon` stops the writer and removes the file created for it (nothing
  was recorded), so nothing half-written is left behind.

Falling behind
--------------
The sender never blocks on the pipe (its end is non-blocking): what the pipe cannot take waits
in the node, at most `max_backlog_bytes` (the records' bytes plus ITEM_OVERHEAD each: measured,
the node's resident memory then grows by about 1.2 times the bound). While the pipe is full and
more waits than that, the *oldest* publications waiting are dropped, each whole, counted in
`dropped_records` and `dropped_publications`; commands and events (`raw`, `raw_many`) are never
dropped (nor bounded: a flood of commands into a stopped writer grows the node's memory). A
writer stopped for good (SIGSTOP) thus costs the node a bounded amount of memory, and once it
runs again the log is complete and readable, with the publications dropped missing from it.

Pipe frames: a head (kind: 1 byte, payload length: uint32) and the payload. Node to child:
``S`` start (pickled descriptor, file, rename target, scene, params, writer options), ``L``
layout (pickled id, layout), ``B`` block (layout id uint32, log time int64, the block), ``R``
records (pickled list of (topic, type, log time, bytes)). Child to node: ``P`` (a pickled
reply: ``ok`` once open, ``failed`` when a write fails, ``closed`` with its counts at the end).
"""
from __future__ import annotations

import collections
import fcntl
import itertools
import os
import pickle
import queue
import secrets
import select
import signal
import struct
import subprocess
import sys
import threading
import time
import weakref
from dataclasses import dataclass
from types import SimpleNamespace

from gyro_sim.log.mcap_log import LogError
from gyro_sim.safe_paths import OutputError

#: period of the sender thread (s): it sleeps, then sends everything queued in one write. It
#: is not woken by the puts: a put that wakes a waiting thread costs the putting thread ~10 us
#: (futex wake, the woken thread asking for the GIL), a put nobody waits on ~0.2 us
SEND_PERIOD = 0.02
#: capacity asked for the pipe to the child (bytes; Linux, best effort): many publications'
#: blocks at n = 100 (~30 kB each) fit in it while the child writes
PIPE_SIZE = 1 << 20
#: longest wait for the child to open the log (s); the wait ends at once if the child dies
START_TIMEOUT = 60.0
#: longest wait (s) in `close` for the writer to take the last records, then to finish the log
CLOSE_TIMEOUT = 10.0
#: longest wait (s) for a writer process killed by `abandon`, or for the exit status of a
#: writer whose output ended
EXIT_TIMEOUT = 2.0
#: niceness the writer process adds to its own: writing is background work whose latency does
#: not matter (the pipe and the queue absorb it), while the physics thread, woken at its
#: deadline on a core the writer occupies, must get it at once. At n = 100 the writer takes
#: ~12 % of a core in bursts every SEND_PERIOD; at equal priority the scheduler may let it
#: finish its slice first
WRITER_NICE = 10
#: default bound (bytes) of what waits in the node for the writer (see "Falling behind")
DEFAULT_MAX_BACKLOG_BYTES = 64 << 20
#: bytes counted per record waiting, besides its CDR bytes (the Python objects holding it)
ITEM_OVERHEAD = 100
#: suffix of the file written with `overwrite` until it is complete
PARTIAL_SUFFIX = ".partial"
#: random hex digits in the name of that file
PARTIAL_TOKEN_BYTES = 4

_HEAD = struct.Struct("<cI")  # kind, payload length
_BLOCK = struct.Struct("<Iq")  # layout id, log time (ns): the start of a block's payload
_BLOCK_HEAD = struct.Struct("<cIIq")  # _HEAD then _BLOCK, packed at once
_IOV_MAX = os.sysconf("SC_IOV_MAX") if hasattr(os, "sysconf") else 16
#: the last field of a queue item holding several records of one topic (`raw_many`)
_MANY = "many"

#: log files created and recorders started and not yet closed (`abandon_all`)
_OPEN: weakref.WeakSet = weakref.WeakSet()
#: held while a log file is created and registered, and by `abandon_all`: a file is either
#: registered before `abandon_all` looks, or never created after it
_REGISTRY_LOCK = threading.RLock()
_given_up = False


class RecordingError(LogError):
    """The log writer process could not start (it died, did not answer, or refused to open)."""


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


def _write_some(fd: int, bufs: collections.deque) -> int:
    """Write from the front of `bufs` to the non-blocking `fd` until it would block; what was
    written is taken off `bufs`. Returns the number of bytes written."""
    total = 0
    while bufs:
        try:
            n = os.writev(fd, list(itertools.islice(bufs, _IOV_MAX)))
        except BlockingIOError:
            break
        total += n
        while bufs and n >= len(bufs[0]):
            n -= len(bufs[0])
            bufs.popleft()
        if n:  # a partial write: the rest of that buffer waits
            bufs[0] = memoryview(bufs[0])[n:]
    return total


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


def _exit_text(code: int | None) -> str:
    """How the writer process ended, for a message."""
    if code is None:
        return "closed its output but did not exit"
    if code < 0:
        try:
            return f"was killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"was killed by signal {-code}"
    return f"exited with status {code}"


@dataclass(eq=False)
class LogFile:
    """A log file created for a writer process (:func:`create_log_file`).

    `path`: the file written; `target`: the record path it is renamed onto once complete (None:
    `path` is the record path); `fd`: its descriptor here until the writer has its own;
    `ident`: (device, inode), so that `abandon` removes this file and no other."""

    path: str
    target: str | None
    fd: int | None
    ident: tuple[int, int]

    def close_fd(self) -> None:
        if self.fd is not None:
            fd, self.fd = self.fd, None
            try:
                os.close(fd)
            except OSError:
                pass

    def abandon(self) -> None:
        """Close it here and remove it (only if the path still names this file)."""
        self.close_fd()
        try:
            st = os.stat(self.path)
            if (st.st_dev, st.st_ino) == self.ident:
                os.unlink(self.path)
        except OSError:
            pass
        _OPEN.discard(self)


def create_log_file(path: str | os.PathLike, overwrite: bool = False, what: str = "log") -> LogFile:
    """Create the file a writer process will write the log at `path` to (module docstring,
    "The file"): `path` itself with O_EXCL, or with `overwrite` a ``.partial`` file of its own
    beside it. Raises OutputError (one line naming the path) when it exists (without
    `overwrite`) or cannot be created."""
    with _REGISTRY_LOCK:
        if _given_up:
            raise OutputError(f"{what}: {path}: not created, the start was given up")
        f = _create(os.path.abspath(os.fspath(path)), overwrite, what)
        _OPEN.add(f)
        return f


def _create(final: str, overwrite: bool, what: str) -> LogFile:
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)
    if overwrite:
        folder, name = os.path.split(final)
        while True:
            tmp = os.path.join(folder, f"{name}.{secrets.token_hex(PARTIAL_TOKEN_BYTES)}{PARTIAL_SUFFIX}")
            try:
                fd = os.open(tmp, flags, 0o666)
                break
            except FileExistsError:  # another run's: draw another name
                continue
            except OSError as exc:
                raise OutputError(f"{what}: {final}: cannot create a file beside it ({exc.strerror or exc})") from None
        written, target = tmp, final
    else:
        try:
            fd = os.open(final, flags, 0o666)
        except FileExistsError:
            raise OutputError(f"{what}: {final}: exists; refused to overwrite it "
                              "(overwrite:=true to replace)") from None
        except OSError as exc:
            raise OutputError(f"{what}: {final}: cannot create it ({exc.strerror or exc})") from None
        written, target = final, None
    st = os.fstat(fd)
    return LogFile(written, target, fd, (st.st_dev, st.st_ino))


def _kill(proc: subprocess.Popen) -> None:
    """Kill a writer process and wait at most EXIT_TIMEOUT for its end."""
    if proc.poll() is None:
        try:
            proc.kill()
            proc.wait(EXIT_TIMEOUT)
        except (OSError, subprocess.TimeoutExpired):
            pass


def abandon_all() -> None:
    """`abandon` every recorder started and every log file created and not yet closed, and
    create none after (a start given up: gyro_sim.ros.node's signal handling during start-up).

    For a process about to end (its caller ends it): a recorder whose start it broke does not
    raise in its own thread, it waits for that end."""
    global _given_up
    with _REGISTRY_LOCK:
        _given_up = True
        objs = list(_OPEN)
    for obj in objs:
        try:
            obj.abandon()
        except Exception:  # noqa: BLE001 - the others must still go
            pass


def _item_size(item) -> tuple[int, int]:
    """(bytes held, records) of a queue item."""
    if len(item) == 2:  # a publication
        batch = item[1]
        block = getattr(batch, "block", None)
        if block is not None:
            extra = batch.extra
            return len(block) + sum(len(x[2]) for x in extra) + ITEM_OVERHEAD * (1 + len(extra)), len(batch)
        return sum(len(x[2]) for x in batch) + ITEM_OVERHEAD * len(batch), len(batch)
    if len(item) == 4:  # one record
        return len(item[3]) + ITEM_OVERHEAD, 1
    datas = item[3]  # several records of one topic (raw_many)
    return sum(map(len, datas)) + ITEM_OVERHEAD * len(datas), len(datas)


class _Packer:
    """The sender thread's Python work: queued items -> the buffers of one pipe write (the only
    time the sender holds the interpreter lock, besides waking up: gyro-sim bench publication
    --recorder times it alone).

    An item is a record (topic, type, log time, bytes) from `raw` or a publication (log time,
    batch) from `raw_batch`. Blocks and records keep the order they were handed over in."""

    def __init__(self) -> None:
        # id(layout) -> (layout, its id in the child); kept: no id reused
        self.layouts: dict[int, tuple[tuple, int]] = {}
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
    """Record to `path` (gyro_sim.log.mcap_log.LogWriter) from a child process (module docstring).

    Parameters
    ----------
    path : the MCAP file (the record path).
    scene : the Scene (embedded in the log).
    params : the node's parameters (embedded as metadata).
    overwrite : replace an existing file at `path`, once the new log is complete.
    log_file : the file already created for it (:func:`create_log_file`); default: created here.
    max_backlog_bytes : most bytes waiting here for the writer before the oldest publications
        are dropped ("Falling behind").
    writer_options : passed on to LogWriter (flush_period ...).

    Raises OutputError when the file cannot be created, RecordingError when the writer cannot
    start (it died, did not answer in START_TIMEOUT, or could not write the log's start: no
    space left...); the file created is then removed.

    While it runs: `failure` (None, or why the recording cannot go on: the writer process died,
    a write failed), `dropped_records`, `dropped_publications` (left out because the writer was
    behind), `handed` (records handed over so far).

    After `close`: `complete` (True when the log was finished: summary, index, renamed onto the
    record path), `file` (the file holding the log: the record path once complete, else the
    file written, for ``gyro-sim recover``), `records_in_file` (every record of the finished
    file, the writer's own /robot_description included), `written` (records written of those
    handed over), `max_backlog` (most records waiting here at once), `max_backlog_bytes_seen`,
    `backlog_bytes` (bytes waiting here after the sender's last period), `thread_cpu` (CPU
    seconds of the writer process, of which `open_cpu` to start and open the log), `sender_cpu`
    (CPU seconds of the sender thread here), `error` (records left out, or why the log is not
    complete). `writer.flush_period`: the writer's flush period, as the child
    reports it; `writer.nice`: the writer process's niceness (WRITER_NICE above the node's
    where the system allows).
    """

    def __init__(self, path: str, *, scene, params: dict, overwrite: bool = False, log_file: LogFile | None = None,
                 max_backlog_bytes: int = DEFAULT_MAX_BACKLOG_BYTES, **writer_options):
        self.path = os.path.abspath(path)
        self.queue: queue.SimpleQueue = queue.SimpleQueue()
        self.max_backlog_bytes = int(max_backlog_bytes)
        self.written = 0
        self.records_in_file = 0
        self.handed = 0
        self.dropped_records = 0
        self.dropped_publications = 0
        self.max_backlog = 0
        self.max_backlog_bytes_seen = 0
        self.backlog_bytes = 0  # bytes waiting here for the pipe after the sender's last period
        self.thread_cpu = 0.0  # CPU seconds spent by the writer process
        self.sender_cpu = 0.0  # CPU seconds spent by the sender thread in this process
        self.open_cpu = 0.0
        self.error: str | None = None
        self.failure: str | None = None
        self.complete = False
        self._closed = False
        self._abandoned = False
        # guards `_abandoned` and `_proc` together: `abandon` (from any thread, or a signal
        # handler in this one) either sees the writer process or stops it being started
        self._lock = threading.RLock()
        self._result: tuple | None = None
        self._ended = threading.Event()  # the writer's output ended (its last reply read)
        self._sent = threading.Event()  # the sender thread is done
        self._close_deadline = float("inf")
        self._close_timeout = CLOSE_TIMEOUT
        self._proc: subprocess.Popen | None = None
        self.log_file = log_file if log_file is not None else create_log_file(path, overwrite)
        self.file = self.log_file.path
        _OPEN.add(self)
        try:
            self._start(scene, params, writer_options)
        except BaseException:
            self.abandon()
            if _given_up:  # abandon_all killed the writer: the process is ending there, quietly
                threading.Event().wait()
            raise

    def _start(self, scene, params: dict, writer_options: dict) -> None:
        env = dict(os.environ)
        root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        fd = self.log_file.fd
        with self._lock:
            if self._abandoned:
                raise RecordingError(f"log {self.path}: abandoned before the log writer process started")
            self._proc = subprocess.Popen(
                [sys.executable, "-c", "from gyro_sim.ros.recorder import _child_main; _child_main()"],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env, close_fds=True, pass_fds=(fd,),
            )
        if self._abandoned:  # by a signal handler of this thread while it started the writer
            _kill(self._proc)
            raise RecordingError(f"log {self.path}: abandoned while the log writer process started")
        self.log_file.close_fd()  # the writer has its own
        try:
            fcntl.fcntl(self._proc.stdin.fileno(), fcntl.F_SETPIPE_SZ, PIPE_SIZE)
        except (AttributeError, OSError):  # not Linux, or above /proc/sys/fs/pipe-max-size: the default
            pass
        start = (fd, self.log_file.path, self.log_file.target, scene, params, writer_options)
        _write_all(self._proc.stdin.fileno(), list(_pickled(b"S", start)))
        # select ends when the reply comes or the writer dies (end of its output)
        if not select.select([self._proc.stdout], [], [], START_TIMEOUT)[0]:
            raise RecordingError(f"log {self.path}: the log writer process did not start in {START_TIMEOUT:g} s")
        reply = _read_reply(self._proc.stdout)
        if reply is None:
            try:
                code = self._proc.wait(EXIT_TIMEOUT)
            except subprocess.TimeoutExpired:
                code = None
            raise RecordingError(f"log {self.path}: the log writer process {_exit_text(code)} before it opened the log")
        if reply[0] == "error":
            exc = reply[1]
            why = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
            raise RecordingError(f"log {self.path}: {why}") from exc
        self.writer = SimpleNamespace(flush_period=reply[1], nice=reply[3])
        self.open_cpu = reply[2]  # CPU seconds of the writer process to start and open the log
        os.set_blocking(self._proc.stdin.fileno(), False)  # the sender never waits for the writer
        self._watcher = threading.Thread(target=self._watch, name="gyro_sim-recorder-watch", daemon=True)
        self._watcher.start()
        self._thread = threading.Thread(target=self._send_loop, name="gyro_sim-recorder", daemon=True)
        self._thread.start()

    def abandon(self) -> None:
        """Give the recording up at once: the writer process killed, the file created for it
        removed (a start given up: nothing was recorded). Idempotent; no wait longer than
        EXIT_TIMEOUT."""
        with self._lock:
            if self._abandoned:
                return
            self._abandoned = self._closed = True
            proc = self._proc
        self.failure = self.failure or "abandoned"
        if proc is not None:
            _kill(proc)
        self.log_file.abandon()
        _OPEN.discard(self)

    def _fail(self, why: str) -> None:
        if self.failure is None:
            self.failure = why

    # --- from the physics and executor threads (cheap: one queue put) ------------------------------
    def raw(self, topic: str, msgtype: str, t_ns: int, data: bytes) -> None:
        """One record (a command, an event) with its own log time; never dropped."""
        if self.failure is None:  # else nobody would write it
            self.queue.put((topic, msgtype, t_ns, data))

    def raw_many(self, topic: str, msgtype: str, t_ns: int, datas: list) -> None:
        """Several records of one topic at one log time, in order (the commands a physics step
        took in); never dropped. `datas` is kept as handed over (not copied)."""
        if self.failure is None:
            self.queue.put((topic, msgtype, t_ns, datas, _MANY))

    def raw_batch(self, t_ns: int, batch: list) -> None:
        """A publication: [(topic, type, bytes)], all at log time t_ns, kept as handed over (not
        copied: neither the list nor its bytes may change after). A
        :class:`gyro_sim.msgs.messages.FrameBatch` goes to the writer as its block. Dropped whole
        when the writer is too far behind ("Falling behind")."""
        if self.failure is None:
            self.queue.put((t_ns, batch))

    # --- the watcher thread: the writer's replies and its end ----------------------------------------
    def _watch(self) -> None:
        try:
            while True:
                reply = _read_reply(self._proc.stdout)
                if reply is None:
                    break
                if reply[0] == "failed":
                    self._fail(reply[1])
                elif reply[0] == "closed":
                    self._result = reply
        except BaseException as exc:  # noqa: BLE001 - a reply that cannot be read: the writer is lost
            self._fail(f"the log writer's replies cannot be read ({type(exc).__name__}: {exc})")
        finally:
            try:
                code = self._proc.wait(EXIT_TIMEOUT)
            except subprocess.TimeoutExpired:
                code = None
            if self._result is None:
                self._fail(f"the log writer process {_exit_text(code)}")
            self._ended.set()

    # --- the sender thread --------------------------------------------------------------------------
    def _send_loop(self) -> None:
        cpu0 = time.thread_time()
        try:
            self._send_until_closed()
        except BaseException as exc:  # noqa: BLE001 - MemoryError...: the recording cannot go on, said
            self._fail(f"the recorder's sender thread stopped ({type(exc).__name__}: {exc})")
        finally:
            try:
                self._proc.stdin.close()  # the writer sees the end of its input
            except OSError:
                pass
            self.sender_cpu = time.thread_time() - cpu0
            self._sent.set()

    def _send_until_closed(self) -> None:
        q, fd, packer = self.queue, self._proc.stdin.fileno(), _Packer()
        pending: collections.deque = collections.deque()  # [item, bytes, records], not yet packed
        pending_bytes = pending_records = 0
        out: collections.deque = collections.deque()  # buffers packed, not yet in the pipe
        out_bytes = 0
        closing = False
        while True:
            if closing and out:  # finishing: wait for room in the pipe rather than a period
                select.select([], [fd], [], SEND_PERIOD)
            else:
                time.sleep(SEND_PERIOD)  # not woken by each put: a put that wakes a waiting thread costs ~10 us
            while True:
                try:
                    item = q.get_nowait()
                except queue.Empty:
                    break
                if item is None:  # close(): what came before it is the last to send
                    closing = True
                    continue
                size, n = _item_size(item)
                pending.append((item, size, n))
                pending_bytes += size
                pending_records += n
                self.handed += n
            if self.failure is not None:  # nobody to write to: what waits is lost with the log's end
                return
            if pending_records > self.max_backlog:
                self.max_backlog = pending_records
            if pending_bytes + out_bytes > self.max_backlog_bytes_seen:
                self.max_backlog_bytes_seen = pending_bytes + out_bytes
            if not out and pending:
                items = []
                for item, _, _ in pending:
                    if len(item) == 5:  # raw_many: its records, one by one
                        topic, msgtype, t_ns, datas, _ = item
                        items += [(topic, msgtype, t_ns, data) for data in datas]
                    else:
                        items.append(item)
                try:
                    bufs, _ = packer.pack(items)
                except Exception as exc:  # noqa: BLE001 - a bad item must not stop the recording
                    bufs = []
                    self.error = self.error or f"recorder: {type(exc).__name__}: {exc}"
                self.error = self.error or packer.error
                out.extend(bufs)
                out_bytes = sum(map(len, bufs))
                pending.clear()
                pending_bytes = pending_records = 0
            if out:
                try:
                    out_bytes -= _write_some(fd, out)
                except OSError as exc:  # the writer is gone (its input broke): the watcher says how
                    self._fail(f"the log writer process stopped reading ({exc.strerror or exc})")
                    return
            if out and pending_bytes + out_bytes > self.max_backlog_bytes:  # the pipe is full: behind
                pending_bytes, pending_records = self._drop_oldest(pending, pending_bytes, pending_records,
                                                                   self.max_backlog_bytes - out_bytes)
            self.backlog_bytes = pending_bytes + out_bytes
            if closing and not out and not pending:
                return
            if closing and time.monotonic() > self._close_deadline:
                self.error = self.error or (f"the log writer did not take the last {pending_records} records and "
                                            f"{out_bytes} bytes within {self._close_timeout:g} s")
                return

    def _drop_oldest(self, pending: collections.deque, size: int, records: int, room: int) -> tuple[int, int]:
        """Drop the oldest publications of `pending` until its bytes fit in `room` (commands and
        events stay, in order); returns the bytes and records left."""
        kept = []
        while size > room and pending:
            entry = pending.popleft()
            if len(entry[0]) == 2:  # a publication
                size -= entry[1]
                records -= entry[2]
                self.dropped_records += entry[2]
                self.dropped_publications += 1
            else:
                kept.append(entry)
        pending.extendleft(reversed(kept))
        return size, records

    def close(self, timeout: float = CLOSE_TIMEOUT) -> None:
        """Hand over what is queued; the child writes it and the MCAP summary. Idempotent. Every
        wait is bounded by `timeout` and ends early if the writer dies. Afterwards: `complete`,
        `file`, `failure`, `error` (class docstring)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self._close_timeout = timeout
        self._close_deadline = time.monotonic() + timeout
        self.queue.put(None)
        self._sent.wait(timeout + 2 * SEND_PERIOD)
        if not self._ended.wait(timeout):  # the writer's last reply
            self.error = self.error or (f"the log writer process (pid {self._proc.pid}) has not finished {self.file} "
                                        f"after {timeout:g} s; it goes on on its own")
            _OPEN.discard(self)
            return
        _OPEN.discard(self)
        _OPEN.discard(self.log_file)
        result = self._result
        if result is None:
            return  # the writer failed: `failure` says how; `file` is the part written
        _, self.written, self.thread_cpu, child_error, self.records_in_file, self.file = result
        self.error = self.error or child_error
        self.complete = self.failure is None


# --- the child process ---------------------------------------------------------------------------
def _io_failure(exc: BaseException, path: str) -> str:
    if isinstance(exc, OSError):
        return f"{exc.strerror or exc} (writing {path})"
    if isinstance(exc, MemoryError):
        return f"out of memory (writing {path})"
    return f"{type(exc).__name__}: {exc} (writing {path})"


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
        try:
            _write_all(reply_fd, list(_pickled(b"P", obj)))
        except OSError:  # the node is gone (killed): nobody to tell
            pass

    start = _read_frame(inp)
    if start is None or start[0] != b"S":
        return
    fd, path, target, scene, params, writer_options = pickle.loads(start[1])
    try:
        from gyro_sim.log.mcap_log import LogWriter

        w = LogWriter(path, scene=scene, params=params, file=os.fdopen(fd, "wb"), **writer_options)
    except BaseException as exc:  # noqa: BLE001 - raised in the node instead
        if isinstance(exc, OSError):
            exc = OSError(exc.errno, f"{exc.strerror or exc} (writing {path})")
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
                            except OSError:
                                raise
                            except Exception as exc:  # noqa: BLE001 - a bad record must not stop the recording
                                error = f"{type(exc).__name__}: {exc}"
                elif kind == b"R":
                    for topic, msgtype, t_ns, data in pickle.loads(payload):
                        try:
                            w.write_raw(channel(topic, msgtype), t_ns, data)
                            written += 1
                        except OSError:
                            raise
                        except Exception as exc:  # noqa: BLE001
                            error = f"{type(exc).__name__}: {exc}"
                elif kind == b"L":
                    lid, layout = pickle.loads(payload)
                    cut = []
                    for topic, msgtype, a, b in layout:
                        try:
                            ch = channel(topic, msgtype)
                        except OSError:
                            raise
                        except Exception as exc:  # noqa: BLE001 - its records are left out, the others written
                            error, ch = f"{type(exc).__name__}: {exc}", None
                        cut.append((ch, a, b))
                    layouts[lid] = cut
                else:
                    error = f"recorder process: unknown frame {kind!r}"
            except OSError:
                raise
            except Exception as exc:  # noqa: BLE001 - a bad frame must not stop the recording
                error = f"{type(exc).__name__}: {exc}"
        w.close()
        if w.failure is not None:  # the background flush failed and the summary after it
            raise w.failure
        if target is not None:
            try:
                os.replace(path, target)  # complete: now it is the record path's (the last rename wins)
            except OSError as exc:
                raise OSError(exc.errno, f"cannot rename it onto {target}: {exc.strerror or exc}") from None
    except BaseException as exc:  # noqa: BLE001 - a write failed (no space left...): no further write
        send(("failed", _io_failure(exc, path)))
        try:
            w.close()  # what can be closed; the part flushed before stays readable by recover
        except BaseException:  # noqa: BLE001
            pass
        sys.exit(1)
    send(("closed", written, time.process_time() - cpu0, error, w.message_count, target or path))
