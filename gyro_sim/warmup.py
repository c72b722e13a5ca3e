"""The first start: compiling the numba kernels of :mod:`gyro_sim.core.fast`, said out loud.

The kernels are compiled once per installation (and after any edit of fast.py) and then
loaded from numba's disk cache. Compiling takes about ``COMPILE_SECONDS`` on the project's
2-core machine, during which nothing else is printed; :func:`precompile` says so first and
prints a line per kernel compiled, then later starts find the cache warm and print nothing.
"""
from __future__ import annotations

import sys
import time

#: measured cold compile of every kernel (s), NUMBA_CACHE_DIR pointing at an empty directory:
#: 10.3-11.3 s on the project's 2-core machine while idle, 20.5-26.5 s while four jobs shared it (README)
COMPILE_SECONDS = 12
#: the scene compiled for: one signature serves every scene (fast.py), any small one will do
WARM_UP_SCENE = "hinge_chain"


def kernels() -> dict:
    """The numba dispatchers of gyro_sim.core.fast by name ({} without numba)."""
    try:
        from numba.core.dispatcher import Dispatcher

        from .core import fast
    except ImportError:
        return {}
    return {name: d for name, d in vars(fast).items() if isinstance(d, Dispatcher)}


def cache_is_cold() -> bool:
    """True if a kernel has no valid entry in numba's disk cache (none written yet, or fast.py
    changed since): the next Simulator with the numba backend compiles. Every kernel of
    fast.py is compiled by any scene (one signature), so after one start none is missing."""
    try:
        # numba's cache index of each kernel, checked against fast.py's timestamp and size
        # (an index written for another version of the file reads as empty)
        return any(not d._cache._cache_file._load_index() for d in kernels().values())
    except (AttributeError, OSError):  # another numba layout: cannot tell, say nothing
        return False


def precompile(stream=sys.stderr, prog: str = "gyro_sim") -> bool:
    """If the cache is cold, say so, compile every kernel with a line per kernel, and return
    True; otherwise (or without numba) return False at once. Compile errors are left to the
    backend selection of the Simulator, which falls back to numpy when it may."""
    ks = kernels()
    if not ks or not cache_is_cold():
        return False
    from numba.core import event

    stream.write(f"{prog}: compiling the dynamics once, about {COMPILE_SECONDS} s (more on a busy machine); "
                 f"later starts load it from the cache\n")
    stream.flush()
    done: set[str] = set()
    t0 = time.perf_counter()

    class _Listener(event.Listener):
        def on_start(self, ev):
            pass

        def on_end(self, ev):
            name = ev.data["dispatcher"].py_func.__name__
            if name in ks and name not in done:
                done.add(name)
                stream.write(f"  compiled {name} ({len(done)}/{len(ks)}, {time.perf_counter() - t0:.1f} s)\n")
                stream.flush()

    listener = _Listener()
    event.register("numba:compile", listener)
    try:
        from .core.simulator import Simulator

        try:  # building a Simulator on the numba backend compiles (or loads) every kernel
            Simulator(WARM_UP_SCENE, integrator="rk4", backend="numba")
        except Exception as exc:  # noqa: BLE001 - the real run reports (or falls back) itself
            stream.write(f"{prog}: compiling failed ({type(exc).__name__}: {exc}); the run itself will say more\n")
            return True
    finally:
        event.unregister("numba:compile", listener)
    stream.write(f"{prog}: compiled in {time.perf_counter() - t0:.1f} s\n")
    stream.flush()
    return True
