"""The first start: compiling the numba kernels of :mod:`gyro_sim.dynamics`, said out loud.

The kernels (the dynamics of fast.py, the outputs, and each integrator's compiled loop) are
compiled once per installation (and after any edit of their files) and then loaded from
numba's disk cache; a start compiles only what its integrator runs. Compiling takes about ``COMPILE_SECONDS`` on the project's
2-core machine, during which nothing else is printed; :func:`precompile` says so first and
prints a line per kernel compiled, then later starts find the cache warm and print nothing.
"""
from __future__ import annotations

import sys
import time

#: measured cold compile (CPU s) of what a run with each integrator needs, NUMBA_CACHE_DIR pointing
#: at an empty directory, on the project's 2-core machine (README; wall time is longer on a busy
#: machine): every loop compiles the dynamics kernel into itself again, which is most of it
COMPILE_SECONDS = {"fixed": 130, "gauss4s": 120, "gauss4": 80, "lie4": 70, "dop853": 75, "rk4": 65, "auto": 105, "radau": 95}
#: the scene compiled for: one signature serves every scene (fast.py), any small one will do
WARM_UP_SCENE = "hinge_chain"


#: the modules holding numba kernels (dispatchers)
KERNEL_MODULES = ("gyro_sim.dynamics.kernel", "gyro_sim.dynamics.entry", "gyro_sim.integrators.rk4.kernels", "gyro_sim.integrators.rk4.loop", "gyro_sim.dynamics.outputs", "gyro_sim.analytic.lagrange", "gyro_sim.integrators.gauss4.kernels", "gyro_sim.integrators.gauss4.loop",
                  "gyro_sim.dynamics.canonical_kernel", "gyro_sim.integrators.dop853.kernels", "gyro_sim.integrators.dop853.loop", "gyro_sim.integrators.lie4.kernels", "gyro_sim.integrators.lie4.loop", "gyro_sim.integrators.radau.kernels", "gyro_sim.integrators.radau.loop")
#: the compiled loops each integrator runs on the numba backend, (module, name), besides the
#: kernels every run needs (fast.py's, the entry of one evaluation from Python, the outputs, a
#: Lagrange chain's integrals); the cache counts as cold for an integrator when any of its
#: kernels has no entry
COMMON_KERNELS = (("gyro_sim.dynamics.entry", "rhs_entry"), ("gyro_sim.dynamics.outputs", "outputs_kernel"), ("gyro_sim.dynamics.outputs", "publication_kernel"), ("gyro_sim.analytic.lagrange", "_sums_82"),
                  ("gyro_sim.analytic.lagrange", "_sums_85"))
LOOPS = {
    "rk4": (("gyro_sim.integrators.rk4.loop", "erk_march"),),
    "lie4": (("gyro_sim.integrators.lie4.loop", "lie_march"),),
    "gauss4": (("gyro_sim.integrators.gauss4.loop", "gauss_march"),),
    # gauss4s: gauss4's march over the canonical field (a second specialization of the march)
    "gauss4s": (("gyro_sim.integrators.gauss4.loop", "gauss_march"), ("gyro_sim.dynamics.canonical_kernel", "canonical_kernel"),
                ("gyro_sim.dynamics.canonical_kernel", "state_kernel")),
    # fixed: rk4, gauss4s on a stiff scene, and its rescue (dop853) through the Python driver on
    # the kernels
    "fixed": (("gyro_sim.integrators.rk4.loop", "erk_march"), ("gyro_sim.integrators.gauss4.loop", "gauss_march"), ("gyro_sim.dynamics.canonical_kernel", "canonical_kernel"),
              ("gyro_sim.dynamics.canonical_kernel", "state_kernel"), ("gyro_sim.integrators.dop853.kernels", "dop_update")),
    "dop853": (("gyro_sim.integrators.dop853.loop", "dop853_advance"),),
    # auto: dop853's and radau's compiled loops in their detection modes (both built with the
    # integrator: radau's is loaded, or compiled, before the first switch to it)
    "auto": (("gyro_sim.integrators.dop853.loop", "dop853_advance"), ("gyro_sim.integrators.radau.loop", "radau_advance")),
    "radau": (("gyro_sim.integrators.radau.loop", "radau_advance"),),
}
#: the node's default
DEFAULT_INTEGRATOR = "fixed"


def _dispatchers(module_names) -> dict:
    try:
        import importlib

        from numba.core.dispatcher import Dispatcher
    except ImportError:
        return {}
    out = {}
    for mod in module_names:
        try:
            m = importlib.import_module(mod)
        except ImportError:
            continue
        out.update({f"{mod}.{name}": d for name, d in vars(m).items() if isinstance(d, Dispatcher)})
    return out


def kernels() -> dict:
    """The numba dispatchers of gyro_sim.dynamics's compiled modules by "module.name" ({} without numba)."""
    return _dispatchers(KERNEL_MODULES)


def _needed(integrator: str) -> list:
    ks = kernels()
    names = [name for name in ks if name.startswith("gyro_sim.dynamics.kernel.")]
    names += [f"{m}.{n}" for m, n in COMMON_KERNELS + LOOPS.get(integrator, ())]
    return [ks[n] for n in names if n in ks]


def cache_is_cold(integrator: str = DEFAULT_INTEGRATOR) -> bool:
    """True if a kernel a run with `integrator` needs has no valid entry in numba's disk cache
    (none written yet, or its file changed since): the next start compiles. Checked: every
    kernel of fast.py (any scene compiles all of them: one signature), the outputs, the
    Lagrange integrals and the integrator's compiled loop (LOOPS: their cache index is keyed on
    every file they inline)."""
    try:
        # numba's cache index of each kernel, checked against its file's timestamp and size
        # (an index written for another version of the file reads as empty)
        return any(not d._cache._cache_file._load_index() for d in _needed(integrator))
    except (AttributeError, OSError):  # another numba layout: cannot tell, say nothing
        return False


def warm_everything(integrator: str = DEFAULT_INTEGRATOR) -> None:
    """Compile (or load) every kernel a run with `integrator` may call on the numba backend:
    the dynamics, the outputs, a Lagrange chain's integrals, and the integrator's loop ("fixed":
    both of its methods)."""
    from gyro_sim.simulator import Simulator

    for scene in (WARM_UP_SCENE, "heavy_top"):  # heavy_top: a Lagrange chain (eqs 82, 85)
        sim = Simulator(scene, integrator=integrator if integrator in LOOPS else "rk4", backend="numba")
        sim.snapshot()
        warm = getattr(sim.integrator, "warm_up", None)
        if warm is not None:
            warm(sim.time, sim.state)
        sim.advance(0.002)


def precompile(stream=sys.stderr, prog: str = "gyro_sim", integrator: str = DEFAULT_INTEGRATOR) -> bool:
    """If the cache is cold for a run with `integrator`, say so, compile its kernels with a
    line per kernel, and return True; otherwise (or without numba) return False at once.
    Compile errors are left to the backend selection of the Simulator, which falls back to
    numpy when it may."""
    ks = kernels()
    if not ks or not cache_is_cold(integrator):
        return False
    from numba.core import event

    seconds = COMPILE_SECONDS.get(integrator, max(COMPILE_SECONDS.values()))
    stream.write(f"{prog}: compiling the dynamics once, about {seconds} s (more on a busy machine); "
                 f"later starts load it from the cache\n")
    stream.flush()
    done: set[str] = set()
    t0 = time.perf_counter()

    class _Listener(event.Listener):
        def on_start(self, ev):
            pass

        def on_end(self, ev):
            d = ev.data["dispatcher"]
            name = f"{d.py_func.__module__}.{d.py_func.__name__}"
            if name in ks and name not in done:
                done.add(name)
                stream.write(f"  compiled {name} ({len(done)} kernels, {time.perf_counter() - t0:.1f} s)\n")
                stream.flush()

    listener = _Listener()
    event.register("numba:compile", listener)
    try:
        try:  # compiles (or loads) every kernel a run may call
            warm_everything(integrator)
        except Exception as exc:  # noqa: BLE001 - the real run reports (or falls back) itself
            stream.write(f"{prog}: compiling failed ({type(exc).__name__}: {exc}); the run itself will say more\n")
            return True
    finally:
        event.unregister("numba:compile", listener)
    stream.write(f"{prog}: compiled in {time.perf_counter() - t0:.1f} s\n")
    stream.flush()
    return True
