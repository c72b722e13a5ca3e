"""Output paths checked before anything runs, and files published whole or not at all.

Every file the package writes goes through :func:`check_output` first::

    check_output("run.mcap", inputs=[scene_path], force=args.force)

It refuses, each with one line naming the path:

- an output that already exists, unless ``force=True`` (CLI ``--force``, node ``overwrite:=true``);
- an output that *is* one of the inputs, by identity (``os.path.samefile``: the same file
  through a hard link or a symlink counts, a mere equal name is not needed), even with force;
- a directory, an output whose directory is missing, or a directory that is not writable.

Every file a ``gyro-sim`` command writes is then written through :func:`atomic_output`: to a
temporary file in the same directory (``.<stem>.<random>.partial<suffix>``, created at once,
so a directory where nothing can be created is refused before any work), published under its
final name only when complete. Publication is atomic and safe against a second writer of the
same output: without force the temporary file is hard-linked to the final name (``os.link``
fails if that name exists, whoever created it since the check; the loser gets an
:class:`OutputError`), with force it replaces it (``os.replace``). On an exception (SIGINT,
SIGTERM, a fault) the temporary file is removed, so no partial file is ever left under a final
name; only SIGKILL or a power loss can leave a ``.partial`` file behind, never the final one::

    with atomic_output("out.mcap", inputs=[src], force=False) as out:
        write_everything(out.tmp)          # published as out.mcap when the block ends normally

:func:`raise_on_signals` turns SIGTERM (and SIGINT) into :class:`Interrupted`, a
KeyboardInterrupt, so that a command unwinds the same way for both.

No ROS and no third-party imports here: the node's parameter validation uses it too.
"""
from __future__ import annotations

import atexit
import contextlib
import errno
import gc
import os
import secrets
import signal
import threading
from pathlib import Path
from typing import Callable, Iterable, Iterator

from gyro_sim.errors import GyroSimError

__all__ = ["OutputError", "check_output", "check_outputs", "AtomicOutput", "atomic_output", "write_atomic",
           "Interrupted", "raise_on_signals", "PARTIAL"]

#: the marker in a temporary output's name: ``.<stem>.<random>.partial<suffix>``
PARTIAL = ".partial"
#: random hex digits in a temporary output's name
TEMP_TOKEN_BYTES = 4
#: errors of ``os.link`` that mean "this file system has no hard links" (then a reserved name
#: is replaced instead, still refused if another writer created the output first)
NO_HARD_LINKS = frozenset({errno.EPERM, errno.EOPNOTSUPP, errno.ENOTSUP, errno.EXDEV, errno.EMLINK, errno.ENOSYS})


class OutputError(GyroSimError, ValueError):
    """An output path is refused (bad input: console scripts exit with status 2)."""


def _same(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (or cannot be stat'ed): not the same file
        return False


def check_output(path: str | os.PathLike, *, inputs: Iterable[str | os.PathLike | None] = (),
                 force: bool = False, what: str = "output") -> Path:
    """The output `path`, checked (module docstring); raise OutputError otherwise.

    Parameters
    ----------
    path : the file about to be written
    inputs : files the command reads (None entries ignored); the output may never be one of them
    force : allow replacing an existing regular file that is not an input
    what : how the message names the path ("output", "--record", "record", ...)
    """
    if path is None or not str(path).strip():
        raise OutputError(f"{what}: empty path")
    p = Path(path).expanduser()
    for src in inputs:
        if src is not None and str(src) and _same(p, Path(src).expanduser()):
            raise OutputError(f"{what}: {p}: is the input {src} (the same file): refused, "
                              "it would destroy the input; give another path")
    if p.is_dir():
        raise OutputError(f"{what}: {p}: is a directory; give a file path")
    if os.path.lexists(p):
        if not p.exists():  # a dangling symlink: writing would create its target somewhere else
            raise OutputError(f"{what}: {p}: is a broken symbolic link; refused")
        if not p.is_file():
            raise OutputError(f"{what}: {p}: exists and is not a regular file; refused")
        if not force:
            raise OutputError(f"{what}: {p}: exists; refused to overwrite it (use --force, or "
                              "overwrite:=true for the node)")
        if not os.access(p, os.W_OK):
            raise OutputError(f"{what}: {p}: exists and is not writable")
    parent = p.resolve().parent
    if not parent.is_dir():
        raise OutputError(f"{what}: directory {parent} does not exist (for {p.name})")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"{what}: directory {parent} is not writable (for {p.name})")
    return p


def check_outputs(paths: Iterable[str | os.PathLike], **kw) -> list[Path]:
    """:func:`check_output` on each path (all checked before any is written)."""
    return [check_output(p, **kw) for p in paths]


# =========================================================================================
# Publication: a temporary file in the same directory, renamed when complete
# =========================================================================================
def _fsync_dir(directory: Path) -> None:
    """Make a rename in `directory` durable where the system allows it (not on Windows)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


#: temporary outputs created and neither published nor removed yet (this process's)
_UNPUBLISHED: set[Path] = set()


@atexit.register
def _remove_unpublished() -> None:
    """At exit, the temporary files of outputs never published: an interrupt that landed
    between a temporary file's creation and its ``with`` block leaves nothing behind."""
    for tmp in list(_UNPUBLISHED):
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        _UNPUBLISHED.discard(tmp)


class AtomicOutput(contextlib.AbstractContextManager):
    """One output written under a temporary name and published when complete (module docstring).

    Parameters
    ----------
    path : the final name (checked with :func:`check_output`)
    inputs, force, what : as for :func:`check_output`

    Attributes
    ----------
    path : the final name
    tmp : the temporary file to write (created empty, mode 0666 less the umask)
    """

    def __init__(self, path: str | os.PathLike, *, inputs: Iterable[str | os.PathLike | None] = (),
                 force: bool = False, what: str = "output"):
        self.inputs = [i for i in inputs if i is not None]
        self.force = force
        self.what = what
        self.path = check_output(path, inputs=self.inputs, force=force, what=what)
        self.published = False
        self.tmp = self._reserve()

    def _reserve(self) -> Path:
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)
        while True:
            tmp = self.path.with_name(f".{self.path.stem}.{secrets.token_hex(TEMP_TOKEN_BYTES)}{PARTIAL}"
                                      f"{self.path.suffix}")
            # registered before it exists: a signal landing anywhere from here to the `with`
            # block's exit still finds it (_remove_unpublished, at exit)
            _UNPUBLISHED.add(tmp)
            try:
                os.close(os.open(tmp, flags, 0o666))
                return tmp
            except FileExistsError:
                _UNPUBLISHED.discard(tmp)
                continue
            except OSError as exc:
                _UNPUBLISHED.discard(tmp)
                raise OutputError(f"{self.what}: {self.path}: cannot create a file in {self.path.parent} "
                                  f"({exc.strerror or exc})") from None

    def publish(self) -> Path:
        """Give the complete temporary file its final name; return it. OutputError if the name
        was taken meanwhile (without force) or is now an input; the temporary file is removed
        in every case."""
        if self.published:
            return self.path
        try:
            fd = os.open(self.tmp, os.O_RDONLY)
            try:
                os.fsync(fd)  # the data is on disk before the name points at it
            finally:
                os.close(fd)
            if self.force:
                for src in self.inputs:
                    if _same(self.path, Path(src).expanduser()):
                        raise OutputError(f"{self.what}: {self.path}: is now the input {src}: refused")
                try:
                    os.replace(self.tmp, self.path)
                except IsADirectoryError:
                    raise OutputError(f"{self.what}: {self.path}: is a directory; give a file path") from None
            else:
                self._link_no_overwrite()
        except OSError as exc:
            raise OutputError(f"{self.what}: {self.path}: cannot publish ({exc.strerror or exc})") from None
        finally:
            self._remove_tmp()
        self.published = True
        _fsync_dir(self.path.parent)
        return self.path

    def _link_no_overwrite(self) -> None:
        taken = OutputError(f"{self.what}: {self.path}: was created by another writer while this one "
                            "worked; refused to overwrite it (use --force)")
        try:
            os.link(self.tmp, self.path)
            return
        except FileExistsError:
            raise taken from None
        except OSError as exc:
            if exc.errno not in NO_HARD_LINKS:
                raise
        try:  # no hard links here: reserve the name exclusively, then replace it
            os.close(os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
        except FileExistsError:
            raise taken from None
        os.replace(self.tmp, self.path)

    def _remove_tmp(self) -> None:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.tmp)
        _UNPUBLISHED.discard(self.tmp)

    def discard(self) -> None:
        """Remove the temporary file (nothing is published)."""
        if not self.published:
            self._remove_tmp()

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.publish()
        else:
            self.discard()


def atomic_output(path: str | os.PathLike, *, inputs: Iterable[str | os.PathLike | None] = (),
                  force: bool = False, what: str = "output") -> AtomicOutput:
    """An :class:`AtomicOutput`, a context manager: write ``.tmp`` inside the block; it is
    published when the block ends normally and removed when it ends by an exception."""
    return AtomicOutput(path, inputs=inputs, force=force, what=what)


def write_atomic(path: str | os.PathLike, data: str | bytes, *, force: bool = False,
                 inputs: Iterable[str | os.PathLike | None] = (), what: str = "output") -> Path:
    """Write `data` (text as UTF-8) to `path` through :func:`atomic_output`; return the path."""
    with atomic_output(path, inputs=inputs, force=force, what=what) as out:
        out.tmp.write_bytes(data.encode() if isinstance(data, str) else data)
    return out.path


# =========================================================================================
# Signals
# =========================================================================================
class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM arrived while :func:`raise_on_signals` was in force."""

    def __init__(self, signum: int):
        self.signum = signum
        super().__init__(signal.Signals(signum).name)

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name


def exit_on_signals(line: Callable[[str], str], code: int,
                    signums: Iterable[int] = (signal.SIGINT, signal.SIGTERM)) -> None:
    """From now until a later handler replaces it, each of `signums` ends the process at once
    with ``line(name)`` (name: "SIGINT"...) on stderr and exit status `code`: for a console
    script's first statement, before its imports, when nothing has been created yet that an
    exit could leave behind. os._exit: an import cut half-way has nothing to unwind, and no
    KeyboardInterrupt can surface from inside it as a traceback. Main thread only (elsewhere
    nothing is done)."""
    if threading.current_thread() is not threading.main_thread():
        return

    def handler(signum, frame):
        try:
            os.write(2, (line(signal.Signals(signum).name) + "\n").encode())
        finally:
            os._exit(code)

    for s in signums:
        signal.signal(s, handler)


#: seconds after which a signal whose exception a finalizer swallowed is delivered again
REDELIVER_DELAY = 0.01


@contextlib.contextmanager
def raise_on_signals(signums: Iterable[int] = (signal.SIGINT, signal.SIGTERM)) -> Iterator[None]:
    """Inside the block, each of `signums` raises :class:`Interrupted` in the main thread (the
    previous handlers are restored after). Elsewhere than in the main thread it does nothing.

    Python runs a signal's handler wherever the main thread is, and that may be inside a
    finalizer (a `__del__`, a weakref callback, run by the garbage collector at any
    allocation: numba's and llvmlite's objects have them), which cannot raise: the interpreter
    reports the exception as unraisable and goes on, and the signal would be lost. Here such an
    interrupt is not reported: the same signal is delivered again, to the main thread, an
    instant later (`_thread.interrupt_main`), where it raises."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    import _thread
    import sys

    def handler(signum, frame):
        raise Interrupted(signum)

    previous_hook = sys.unraisablehook

    def unraisable(u):
        if isinstance(u.exc_value, Interrupted):  # ours, swallowed by a finalizer: again
            threading.Timer(REDELIVER_DELAY, _thread.interrupt_main, (u.exc_value.signum,)).start()
            return
        previous_hook(u)

    old = {}
    try:
        sys.unraisablehook = unraisable
        for s in signums:
            old[s] = signal.signal(s, handler)
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        sys.unraisablehook = previous_hook


def interrupt_behind(exc: BaseException) -> KeyboardInterrupt | None:
    """The KeyboardInterrupt (SIGINT, or SIGTERM under `raise_on_signals`) that
    `exc` comes from, if any (its causes and contexts followed), else None.

    A signal's exception is raised wherever the main thread is when the signal comes, and
    Python 3.11 wraps one raised while a class is created (a signal during the import of a
    module that defines a dataclass: mcap's records are imported when a log is first opened)
    in a RuntimeError: a handler that turns every Exception into "damaged log" (LogError) must
    let the interrupt through instead (:func:`raise_interrupt_behind`).
    """
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


def raise_interrupt_behind(exc: BaseException) -> None:
    """Raise the KeyboardInterrupt that `exc` comes from (:func:`interrupt_behind`), if any."""
    interrupt = interrupt_behind(exc)
    if interrupt is not None:
        raise interrupt from None


def end_after_interrupt() -> None:
    """Make the exit that follows an interrupt prompt: the objects alive now are left out of
    the interpreter's last garbage collections.

    At exit Python tears the imported modules down with full collections over every object
    still alive (numba's and scipy's: about 1e5 after a heavy-top run), and that is most of the
    CPU a command spends between SIGINT / SIGTERM and its end (measured: 0.2 s of 0.25 s after
    `gyro-sim run`, 0.04 s without them). Call it once the command has said its line and its
    outputs are closed (published or removed): atexit handlers, the standard streams' flush and
    the reference-counted teardown still run; only objects in reference cycles are left
    unfinalized, and the process ends right after.
    """
    gc.freeze()
