"""The first start: compiling the numba kernels of :mod:`gyro_sim.dynamics`, said out loud, in two
processes.

The kernels (the dynamics of fast.py, the outputs, and each integrator's compiled loop) are
compiled once per installation (and after any edit of their files) and then loaded from
numba's disk cache. The loops call the dynamics through its compiled C function
(`gyro_sim.dynamics.kernel.rhs_call`), so none of them compiles the dynamics again, and each can be
compiled without it. A cold start (:func:`precompile`) therefore splits the work:

- this process compiles the dynamics kernel (its C function: the longest piece), then the
  entry of one evaluation (it reuses the kernel's stages compiled here);
- a helper process (``python -m gyro_sim.warmup --fill INTEGRATOR``, started here) compiles at
  the same time what else the first step needs, on a kernel that only zeroes y' (`fast.null_kernel_address`:
  the loops and outputs do not depend on which kernel they call): the rk4 loop, the publication
  kernel and the integrator's first loop; it says so on its stdout, which this process waits
  for; then, at a lower priority (niced: it leaves the CPU to this process and to anything
  else), everything else a run with that integrator may switch to ("fixed": gauss4s and the
  dop853 rescue; "auto": radau), a Lagrange chain's integrals and the heavy-subtree path,
  into the same cache.

Later starts load it all (~2 s); where the cache still lacks something they may switch to, the
helper starts at the lowest priority from the beginning (``--background``). What the helper
has not yet written when a run first needs it is compiled by that run itself, outside the
node's physics thread (the node loads it in a thread of its own once the fill has ended,
`warm_when_filled`): the same code either way, so the results do not depend on it.

**The cache fills once per install.** The helper's background part outlives the process that
started it: it runs in a session of its own (a Ctrl-C of the start does not reach it), at the
lowest CPU priority (SCHED_IDLE where Linux has it, and nice 19: it takes only what nothing
else wants), under a file lock (one helper at a time fills a cache: a second one waits for the
lock and then compiles only what the first left out), and ends when the fill is done. So
short runs one after another do not each begin the fill again.

**The node does not wait for it.** On a cold cache the node (backend "auto") starts the helper
with ``--whole`` (`start_deferred`): at the lowest priority from the start, it compiles the
whole first step, the dynamics kernel and its entry included, says READY, then fills the rest.
Meanwhile the node steps on the numpy reference, which compiles nothing, where a physics step
of its scene fits there (gyro_sim.ros.node: NUMPY_STEP_SHARE; otherwise it says so in one line
and compiles first, as before); a thread of the node waits for READY, loads the kernels into
the process (`load_when_compiled`) and the physics thread switches to them at a step boundary,
recorded in the log so that re-simulation switches at the same step (gyro_sim.log.resim:
DYNAMICS_EVENT).

The fill is the same with or without a terminal (a launch file, systemd and a container start
as a shell does). It is off where it would take the cores from other work
(`background_fill_allowed`): with GYRO_SIM_BACKGROUND_FILL=0 (the test suite sets it; tests
of the fill opt in with 1 and a private NUMBA_CACHE_DIR) and under CI (the CI variable). There
the helper compiles only the first step's share beside the start and ends with it (it checks
every PARENT_POLL s), the node compiles the rest before it goes real-time, and ``gyro-sim
warmup`` fills the whole cache in the foreground, with progress.
"""
from __future__ import annotations

import os
import select
import subprocess
import sys
import time
from pathlib import Path

#: measured cold compile (CPU s) of what the first step of a run with each integrator needs,
#: NUMBA_CACHE_DIR pointing at an empty directory, on the project's 2-core machine: the longer
#: of this process's share (the dynamics kernel and its entry: 14 s; 13.5 s with trees, slides
#: and geared motors, 2026-11-29) and the helper's (the rk4 loop, the outputs: 7.5 s, and the
#: integrator's first loop), which run at the same time; wall time is longer on a busy machine
COMPILE_SECONDS = {"fixed": 15, "rk4": 15, "lie4": 15, "auto": 16, "dop853": 16, "radau": 24, "gauss4": 31,
                   "gauss4s": 48}
#: measured cold compile (CPU s) of the first step whole in one process (the dynamics kernel, its
#: entry, the rk4 loop and the outputs: what the background helper of `start_deferred` compiles
#: before the switch), the same empty cache and machine: 19.9 + 2.2 s (2026-11-29, `time python -c
#: "from gyro_sim import warmup; warmup.precompile(integrator='fixed', helper=False)"`); the
#: integrators whose first loop is another have no figure
WHOLE_COMPILE_SECONDS = {"fixed": 22, "rk4": 22}
#: the scene compiled for: one signature serves every scene (fast.py), any small one will do
WARM_UP_SCENE = "hinge_chain"
#: a Lagrange chain (its integrals, eqs 82 and 85, are compiled for its snapshots)
LAGRANGE_SCENE = "heavy_top"
#: the helper's niceness once the first step's kernels are in the cache (the lowest priority;
#: SCHED_IDLE as well where the system has it)
HELPER_NICE = 19
#: "0" in the environment: no background fill; "1": a fill even under CI
BACKGROUND_VARIABLE = "GYRO_SIM_BACKGROUND_FILL"
#: the longest wait (s) for the helper's share of the first step (it is there in ~15 s)
HELPER_WAIT = 600.0
#: the line the helper prints when the first step's kernels are in the cache
READY = "ready"
#: how often (s) the helper checks that its parent still runs
PARENT_POLL = 0.2
#: the environment variable that gives the helper its parent's pid (it may have ended already
#: when the helper starts watching it)
PARENT_VARIABLE = "GYRO_SIM_WARMUP_PARENT"

#: the modules holding numba kernels (dispatchers)
KERNEL_MODULES = ("gyro_sim.dynamics.kernel", "gyro_sim.dynamics.entry",
                  "gyro_sim.integrators.rk4.kernels", "gyro_sim.integrators.rk4.loop",
                  "gyro_sim.dynamics.outputs", "gyro_sim.analytic.lagrange",
                  "gyro_sim.integrators.gauss4.kernels", "gyro_sim.integrators.gauss4.loop",
                  "gyro_sim.dynamics.canonical_kernel",
                  "gyro_sim.integrators.dop853.kernels", "gyro_sim.integrators.dop853.loop",
                  "gyro_sim.integrators.lie4.kernels", "gyro_sim.integrators.lie4.loop",
                  "gyro_sim.integrators.radau.kernels", "gyro_sim.integrators.radau.loop",
                  "gyro_sim.integrators.coulomb.kernels")
#: the kernels compiled as C functions (numba.cfunc: no dispatcher), (module, function): the
#: dynamics, the canonical field, the heavy-subtree path
C_KERNEL, C_CANONICAL, C_HEAVY = (("gyro_sim.dynamics.kernel", "_kernel_entry"),
                                  ("gyro_sim.dynamics.canonical_kernel", "_canonical_entry"),
                                  ("gyro_sim.dynamics.kernel", "_heavy_entry"))
#: what every run's first step needs on the numba backend besides its integrator's first loop,
#: (module, name): the entry of one evaluation from Python, the rk4 loop and the outputs
#: (FastChainODE.warm_up), the publication kernel (snapshots)
COMMON_KERNELS = (("gyro_sim.dynamics.entry", "rhs_entry"), ("gyro_sim.integrators.rk4.loop", "erk_march"),
                  ("gyro_sim.dynamics.outputs", "publication_kernel"),
                  C_KERNEL)
#: the compiled loop the first step of each integrator runs ("fixed": rk4 on a soft scene, "auto": dop853)
#: (gauss4s: its march, the state's map and the canonical field's C function, which has the field
#: compiled in: `canonical_kernel`, the field's entry from Python, is not on its path)
GAUSS4S = (("gyro_sim.integrators.gauss4.loop", "gauss_march"),
           ("gyro_sim.dynamics.canonical_kernel", "state_kernel"),
           C_CANONICAL)
FIRST_LOOPS = {
    "rk4": (("gyro_sim.integrators.rk4.loop", "erk_march"),),
    "lie4": (("gyro_sim.integrators.lie4.loop", "lie_march"),),
    "gauss4": (("gyro_sim.integrators.gauss4.loop", "gauss_march"),),
    "gauss4s": GAUSS4S,
    "fixed": (("gyro_sim.integrators.rk4.loop", "erk_march"),),
    "dop853": (("gyro_sim.integrators.dop853.loop", "dop853_advance"),),
    "auto": (("gyro_sim.integrators.dop853.loop", "dop853_advance"),),
    "radau": (("gyro_sim.integrators.radau.loop", "radau_advance"),),
}
#: every compiled loop each integrator may run ("fixed": rk4, gauss4s on a stiff scene, and the
#: rescue, dop853's Python driver on the kernels; "auto": dop853's and radau's loops)
LOOPS = {
    **FIRST_LOOPS,
    "fixed": (("gyro_sim.integrators.rk4.loop", "erk_march"), *GAUSS4S,
              ("gyro_sim.integrators.dop853.kernels", "dop_update")),
    "auto": (("gyro_sim.integrators.dop853.loop", "dop853_advance"),
             ("gyro_sim.integrators.radau.loop", "radau_advance")),
}
#: what any run may need beyond its integrator's loops: a Lagrange chain's integrals, the
#: heavy-subtree path (a chain with a subtree STABLE_ABA_RATIO times heavier than its carrier)
EXTRA_KERNELS = (("gyro_sim.analytic.lagrange", "_sums_82"), ("gyro_sim.analytic.lagrange", "_sums_85"), C_HEAVY)
#: the node's default
DEFAULT_INTEGRATOR = "fixed"

#: the helper this process started (None: none, or it has ended)
_helper: subprocess.Popen | None = None


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


def _c_function_index(module: str, name: str) -> dict:
    """The disk cache index of a kernel compiled as a C function (C_KERNEL...), keyed as
    `gyro_sim.jit.cfunc_with_dependencies` keys it (its module's DEPENDENCIES); {} when it has
    no valid entry."""
    import importlib

    import numba
    from numba.core.caching import FunctionCache

    from gyro_sim import jit

    m = importlib.import_module(module)
    saved = numba.config.CACHE_DIR
    numba.config.CACHE_DIR = str(jit.cache_directory(m.DEPENDENCIES))
    try:
        return FunctionCache(getattr(m, name))._cache_file._load_index()
    finally:
        numba.config.CACHE_DIR = saved


def _cold(names) -> bool:
    """True if one of these kernels, (module, name), has no valid entry in numba's cache index
    (checked against its file's timestamp and size: an index written for another version of the
    file reads as empty; the loops' and the C functions' indexes sit in directories keyed on
    every file they compile in)."""
    ks = kernels()
    try:
        for module, name in names:
            if (module, name) in (C_KERNEL, C_CANONICAL, C_HEAVY):
                if not _c_function_index(module, name):
                    return True
            elif f"{module}.{name}" in ks and not ks[f"{module}.{name}"]._cache._cache_file._load_index():
                return True
        return False
    except (AttributeError, OSError, ImportError):  # another numba layout: cannot tell, say nothing
        return False


def cache_is_cold(integrator: str = DEFAULT_INTEGRATOR) -> bool:
    """True if a kernel the first step of a run with `integrator` needs has no valid entry in
    numba's disk cache (none written yet, or its file changed since): the next start compiles
    before its first step. Checked: the dynamics kernel's C function (it compiles every kernel
    of fast.py it runs: one signature serves every scene), the entry, the rk4 loop, the
    outputs and the integrator's first loop."""
    return _cold(COMMON_KERNELS + FIRST_LOOPS.get(integrator, ()))


def everything_cached(integrator: str = DEFAULT_INTEGRATOR) -> bool:
    """True when every kernel a run with `integrator` may ever call is in the cache: its first
    step's, every method it may switch to, a Lagrange chain's integrals, the heavy path."""
    return not _cold(COMMON_KERNELS + LOOPS.get(integrator, ()) + EXTRA_KERNELS)


def warm_everything(integrator: str = DEFAULT_INTEGRATOR) -> None:
    """Compile (or load) every kernel a run with `integrator` may call on the numba backend:
    the dynamics, the outputs, a Lagrange chain's integrals, and the integrator's loops ("fixed":
    all of its methods)."""
    from gyro_sim.simulator import Simulator

    # heavy_top: a Lagrange chain (eqs 82, 85); a hinge with exact Coulomb friction: its responses
    for scene in (WARM_UP_SCENE, LAGRANGE_SCENE, _with_exact_friction(WARM_UP_SCENE)):
        sim = Simulator(scene, integrator=integrator if integrator in LOOPS else "rk4", backend="numba")
        sim.snapshot(bodies=False, wrenches=False)
        warm = getattr(sim.integrator, "warm_up", None)
        if warm is not None:
            warm(sim.time, sim.state)
        sim.advance(0.002)


def _with_exact_friction(name: str):
    """The shipped scene `name` with exact Coulomb friction on its first hinge (a mapping for
    load_scene): what compiles gyro_sim.integrators.coulomb's kernels."""
    import copy

    from gyro_sim.scene.load import load_scene

    source = copy.deepcopy(load_scene(name).source)
    hinge = next(b for b in source["bodies"] if b.get("joint", {}).get("type") == "hinge")
    hinge["joint"]["friction"] = {"coulomb": 1e-3}
    return source


#: how often (s) the node's loader thread looks whether the cache fill has ended
LOAD_POLL = 1.0


def warm_when_filled(sim, poll: float = LOAD_POLL):
    """Off the physics thread, what `sim`'s integrator may switch to (for a guarded "fixed",
    gyro_sim.integrators.fixed: `guard`, WARM): a daemon thread waits until no helper fills the
    cache (`filling`), then runs the warm-up of a second Simulator of the same scene, integrator
    and step, which loads (or, if the fill left it out, compiles) every method into this
    process; the guard then lets them step. The second Simulator shares nothing with `sim` but
    the compiled code. Returns the thread."""
    import threading

    scene, step, integrator = sim.scene, sim.integrator.step, sim.integrator_name

    def load():
        while filling():
            time.sleep(poll)
        try:
            from gyro_sim.simulator import Simulator

            twin = Simulator(scene, integrator=integrator, step=step, backend="numba")
            twin.integrator.warm_up(twin.time, twin.state)
        except Exception:  # noqa: BLE001 - the guard keeps the rung back: the run goes on without it
            pass

    thread = threading.Thread(target=load, name="gyro_sim-load-rungs", daemon=True)
    thread.start()
    return thread


def filling() -> bool:
    """True while a helper compiles into this cache (the one this process started, or another
    start's: it holds the lock): a start then leaves the methods it may switch to for later
    (the helper compiles them)."""
    import fcntl

    global _helper
    if _helper is not None and _helper.poll() is not None:
        _helper = None
    if _helper is not None:
        return True
    try:
        with open(_lock_path(), "w") as lock:
            try:
                fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)  # released when closed
            except BlockingIOError:
                return True
    except OSError:  # no lock file can be made there: no helper can run there either
        return False
    return False


def _lock_path() -> Path:
    """The helper's lock: beside the loops' cache directories (NUMBA_CACHE_DIR, or the package's
    __pycache__, or ~/.cache/gyro_sim)."""
    from gyro_sim import jit

    base = jit.cache_directory(()).parent
    base.mkdir(parents=True, exist_ok=True)
    return base / "gyro_sim_warmup.lock"


def background_fill_allowed() -> bool:
    """May a start leave a helper compiling into the cache beside it and after it (see the
    module's docstring)? GYRO_SIM_BACKGROUND_FILL decides when set ("0" or "1"); else yes, but
    not under CI. The same with or without a terminal: a launch file, systemd or a container
    start as a shell does."""
    chosen = os.environ.get(BACKGROUND_VARIABLE, "").strip()
    if chosen in ("0", "1"):
        return chosen == "1"
    return os.environ.get("CI", "").strip().lower() in ("", "0", "false", "no")


def _lowest_priority() -> None:
    """This process at the lowest CPU priority: SCHED_IDLE where Linux has it, and nice 19."""
    try:
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    except (AttributeError, OSError):
        pass
    try:
        os.nice(HELPER_NICE - os.nice(0))
    except OSError:
        pass


def _start_helper(integrator: str, background: bool = False, share_only: bool = False,
                  whole: bool = False) -> subprocess.Popen | None:
    """Start the helper that fills the cache for `integrator` (its stdout a pipe: READY when the
    first step's share is there; `background`: at the lowest priority from its start, when this
    process needs nothing from it). It runs in a session of its own and outlives this process,
    unless `share_only`: then it compiles the first step's share only and ends with this
    process. `whole`: the first step whole (the dynamics kernel and its entry too: this
    process compiles nothing, it steps on numpy meanwhile) before READY. None where it cannot
    start."""
    # the gyro_sim this process runs, also as the working directory: `-m` puts the working
    # directory first on sys.path, and a start from a source tree of another version must not
    # fill the cache for that tree's kernels
    root = str(Path(__file__).resolve().parents[1])
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, (root, os.environ.get("PYTHONPATH")))),
               **{PARENT_VARIABLE: str(os.getpid())})
    try:
        return subprocess.Popen([sys.executable, "-m", "gyro_sim.warmup", "--fill", integrator,
                                 *(["--background"] if background else []),
                                 *(["--share-only"] if share_only else []),
                                 *(["--whole"] if whole else [])], env=env, cwd=root,
                                stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                text=True, start_new_session=not share_only)
    except OSError:
        return None


def _wait_ready(helper: subprocess.Popen, timeout: float = HELPER_WAIT) -> None:
    """Wait until the helper says READY, ends, or `timeout` s pass."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        ready, _, _ = select.select([helper.stdout], [], [], max(0.0, end - time.monotonic()))
        if not ready:
            return
        line = helper.stdout.readline()
        if not line or line.strip() == READY:  # ended (EOF), or its share is in the cache
            return


def _compile_kernel() -> None:
    """This process's share of a cold first step: the dynamics kernel (its C function) and the
    entry of one evaluation (which compiles the kernel's stages into itself: they are in memory
    here)."""
    from gyro_sim.dynamics.model import compile_model, initial_state
    from gyro_sim.scene.load import load_scene
    from gyro_sim.dynamics.system import FastChainODE

    system = FastChainODE(compile_model(load_scene(WARM_UP_SCENE)))  # the kernel's C function
    system.rhs(0.0, initial_state(system.model))


def _first_step(integrator: str) -> None:
    """What the first step of a run with `integrator` compiles: a Simulator built, a snapshot,
    an advance (the methods it may switch to left out)."""
    from gyro_sim.simulator import Simulator

    sim = Simulator(WARM_UP_SCENE, integrator=integrator if integrator in LOOPS else "rk4", backend="numba")
    sim.snapshot(bodies=False, wrenches=False)
    sim.advance(0.002)


#: set (not "0") in the environment: a line per kernel compiled at a first start
VERBOSE_VARIABLE = "GYRO_SIM_VERBOSE"


def verbose() -> bool:
    """Whether the environment asks for a line per kernel (``GYRO_SIM_VERBOSE=1``)."""
    return os.environ.get(VERBOSE_VARIABLE, "") not in ("", "0")


def precompile(stream=None, prog: str = "gyro_sim", integrator: str = DEFAULT_INTEGRATOR,
               helper: bool = True) -> bool:
    """If the cache is cold for the first step of a run with `integrator`, say so in one line,
    compile its kernels (with a line per kernel where :func:`verbose`; the helper compiling
    its share at the same time), and
    return True; otherwise (or without numba) return False at once. Where something else a
    run may need is not cached and `helper`, the helper is started to compile it in the
    background (`filling`); it ends with this process. Compile errors are left to the backend
    selection of the Simulator, which falls back to numpy when it may. The helper fills the
    whole cache and outlives this process where `background_fill_allowed`; elsewhere it
    compiles only the first step's share beside it (a cold start) and ends with it."""
    stream = sys.stderr if stream is None else stream
    global _helper
    ks = kernels()
    if not ks:
        return False
    cold = cache_is_cold(integrator)
    if helper and (cold or not everything_cached(integrator)) and not filling():
        if background_fill_allowed():
            _helper = _start_helper(integrator, background=not cold)
        elif cold:
            _helper = _start_helper(integrator, share_only=True)
    if not cold:
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
                if not verbose():
                    return
                stream.write(f"  compiled {name} ({len(done)} kernels, {time.perf_counter() - t0:.1f} s)\n")
                stream.flush()

    listener = _Listener()
    event.register("numba:compile", listener)
    try:
        try:  # this process's share, then (the helper's share loaded, or compiled here) the first step
            _compile_kernel()
            if _helper is not None:
                _wait_ready(_helper)
            _first_step(integrator)
        except Exception as exc:  # noqa: BLE001 - the real run reports (or falls back) itself
            stream.write(f"{prog}: compiling failed ({type(exc).__name__}: {exc}); the run itself will say more\n")
            return True
    finally:
        event.unregister("numba:compile", listener)
    stream.write(f"{prog}: compiled in {time.perf_counter() - t0:.1f} s\n")
    stream.flush()
    return True


# --- a start that steps on numpy while the kernels compile -----------------------------------
#: the helper compiling the whole first step while this process steps on the numpy reference
#: (`start_deferred`); None: none
_deferred: subprocess.Popen | None = None


def start_deferred(integrator: str = DEFAULT_INTEGRATOR, stream=None, prog: str = "gyro_sim") -> bool:
    """Where the cache is cold for the first step of a run with `integrator` and a background
    fill is allowed (`background_fill_allowed`), start the helper compiling that first step
    whole, then everything else a run may switch to, at the lowest CPU priority (it takes no
    CPU the caller wants), say so in one line and return True: the caller steps on the numpy
    reference, which compiles nothing, until `wait_deferred` says the kernels are in the cache,
    then loads them off its physics thread and switches at a step boundary (the node:
    gyro_sim.ros.loop). False, with nothing started, where the cache is warm, numba is missing,
    the fill is not allowed, or no helper can start."""
    stream = sys.stderr if stream is None else stream
    global _helper, _deferred
    if not kernels() or not background_fill_allowed() or not cache_is_cold(integrator):
        return False
    helper = _start_helper(integrator, background=True, whole=True)
    if helper is None:
        return False
    _helper = _deferred = helper
    seconds = WHOLE_COMPILE_SECONDS.get(integrator)
    about = f"about {seconds} s of CPU, " if seconds is not None else ""
    stream.write(f"{prog}: compiling the dynamics in the background ({about}at the lowest "
                 f"priority); the run steps on the numpy reference until then\n")
    stream.flush()
    return True


def deferred() -> bool:
    """Whether this process started a helper that compiles its first step (`start_deferred`)."""
    return _deferred is not None


def stop_deferring() -> None:
    """This process compiles its first step itself after all (the helper goes on filling)."""
    global _deferred
    _deferred = None


def wait_deferred(integrator: str = DEFAULT_INTEGRATOR, timeout: float = HELPER_WAIT) -> bool:
    """Wait until the helper of `start_deferred` has the first step of `integrator` in the cache:
    True then (loading it compiles nothing), False if it ended (or `timeout` s passed) without."""
    helper = _deferred
    if helper is not None:
        _wait_ready(helper, timeout)
    return not cache_is_cold(integrator)


def load_when_compiled(sim, then):
    """Off the physics thread: a daemon thread waits for the helper of `start_deferred`
    (`wait_deferred`), loads the first step's kernels into this process by a twin Simulator of
    `sim`'s scene, integrator and step on numba (built, a snapshot, one step; its "fixed"
    guarded: it takes no rung the cache does not hold yet; it shares nothing with `sim` but the
    compiled code), and calls ``then("numba")``: `sim`'s owner switches at its next step
    boundary, and that step compiles nothing. Nothing is called if the helper ended without
    the kernels (the run stays on numpy). Returns the thread."""
    import threading

    scene, step, integrator = sim.scene, sim.integrator.step, sim.integrator_name

    def load():
        if not wait_deferred(integrator):
            return
        try:
            from gyro_sim.simulator import Simulator

            twin = Simulator(scene, integrator=integrator, step=step, backend="numba")
            if hasattr(twin.integrator, "guard"):
                twin.integrator.guard = True
            twin.snapshot()
            twin.advance(step)
        except Exception:  # noqa: BLE001 - the run stays on numpy
            return
        then("numba")

    thread = threading.Thread(target=load, name="gyro_sim-load-kernels", daemon=True)
    thread.start()
    return thread


# --- the helper ------------------------------------------------------------------------------
def fill(integrator: str, out=sys.stdout, parent: int | None = None, background: bool = False,
         share_only: bool = False, whole: bool = False) -> None:
    """The helper's work (one at a time per cache), for as long as its parent (`parent`, default
    the process that started it) lives: the first step's kernels other than the dynamics and
    the entry (the rk4 loop, the outputs, the integrator's first loop) on a null kernel, READY on
    `out`, then at a lower priority every other kernel a run with `integrator` may need
    (`warm_everything` on the null kernel, the heavy path), and last the dynamics kernel itself
    (loaded: this process's parent compiled it, or compiled here). Failures end a step, not the
    helper: what it leaves out, a run compiles itself. With `background` (the parent's first
    step is in the cache), all of it at the lower priority.

    A second helper on the same cache finds the lock taken: it says READY at once (its parent
    compiles the first step itself), waits at a lower priority for the lock, and then compiles
    only what the first one left out. numba writes each cache file under a temporary name and
    renames it: a helper ended at any moment leaves no torn entry. With `share_only` it ends
    after READY, and with its parent (`parent`, default the process that started it) before;
    otherwise it outlives its parent and ends when the fill is done. With `whole`, its first
    share is the whole first step, the dynamics kernel and its entry included (its parent
    steps on numpy until READY: `start_deferred`)."""
    import fcntl

    if share_only:
        _end_with(os.getppid() if parent is None else parent)
    if background:
        _lowest_priority()
    with open(_lock_path(), "w") as lock:
        said = False
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:  # another helper fills this cache: wait for it, then fill the rest
            said = not whole and _say_ready(out)  # (whole: READY once the first step is cached)
            if share_only:
                return
            if not background:
                _lowest_priority()
            fcntl.flock(lock, fcntl.LOCK_EX)
            if everything_cached(integrator):
                if whole:
                    _say_ready(out)
                return
        from gyro_sim.dynamics import kernel as fast
        from gyro_sim.dynamics.model import compile_model, initial_state
        from gyro_sim.scene.load import load_scene
        from gyro_sim.integrators import make_integrator
        from gyro_sim.dynamics.system import FastChainODE
        from gyro_sim.integrators.rk4.loop import ErkMarch

        real_kernel = fast.kernel_address

        def step(fn, *args):
            try:
                fn(*args)
            except Exception:  # noqa: BLE001 - what is left out, a run compiles itself
                pass

        def share():  # on a system with no warm-up: its entry is this process's parent's share
            system = FastChainODE(compile_model(load_scene(WARM_UP_SCENE)))
            y = initial_state(system.model)
            ErkMarch(system).warm_up(0.0, y)  # the rk4 loop (an RK4 on a compiled system runs it)
            if FIRST_LOOPS.get(integrator) != FIRST_LOOPS["rk4"]:
                make_integrator(integrator, system).advance(0.0, y.copy(), 0.002)  # the first loop
            system.outputs(0.0, y)  # the publication kernel

        if not said:
            if whole:  # the real kernel, then everything the first step runs
                step(_compile_kernel)
                step(_first_step, integrator)
            else:
                fast.kernel_address = fast.null_kernel_address  # chain_model reads it when a system is built
                step(share)
            _say_ready(out)
            if share_only:
                return
            if not background:
                _lowest_priority()
        fast.kernel_address = fast.null_kernel_address  # the rest on a kernel that only zeroes y'
        step(warm_everything, integrator)
        step(fast.heavy_elimination_address)
        fast.kernel_address = real_kernel
        step(fast.kernel_address)


def _say_ready(out) -> bool:
    """READY on `out` (the parent's pipe), closed after; True."""
    try:
        out.write(f"{READY}\n")
        out.close()
    except OSError:  # the parent has gone: _end_with ends this process
        pass
    return True


def _end_with(parent: int) -> None:
    """End this process (at once: os._exit) when `parent` ends, checked every PARENT_POLL s
    from a daemon thread: a helper never outlives the start that needs it. On Linux the kernel
    also kills it when its parent ends (PR_SET_PDEATHSIG), which no thread of this process
    has to see: the watch needs the interpreter, and a compile may keep it from the watch."""
    import threading

    try:
        import ctypes
        import signal

        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL))  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # not Linux: the watch alone
        pass

    def watch():
        while os.getppid() == parent:
            time.sleep(PARENT_POLL)
        os._exit(0)

    threading.Thread(target=watch, name="gyro_sim-warmup-parent", daemon=True).start()


# --- gyro-sim warmup: the whole fill in the foreground -----------------------------------------
def foreground_fill(integrator: str = DEFAULT_INTEGRATOR, out=None) -> bool:
    """Every kernel a run with `integrator` may call, compiled (or loaded) into the cache now,
    with a progress line per part, under the helpers' lock (a helper filling the cache is waited
    for: what it left, this compiles). False when there was nothing to do."""
    import fcntl

    from gyro_sim.progress import Progress

    out = sys.stderr if out is None else out

    with open(_lock_path(), "w") as lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            out.write("gyro-sim warmup: a background fill holds the cache: waiting for it\n")
            out.flush()
            fcntl.flock(lock, fcntl.LOCK_EX)
        if everything_cached(integrator):
            return False
        from gyro_sim.dynamics import kernel as fast

        parts = (("the dynamics kernel", _compile_kernel), ("the first step", lambda: _first_step(integrator)),
                 (f"every method {integrator} may switch to, the outputs, the Lagrange integrals",
                  lambda: warm_everything(integrator)),
                 ("the heavy-subtree path", fast.heavy_elimination_address))
        progress = Progress("gyro-sim warmup", out)
        t0 = time.perf_counter()
        for i, (label, work) in enumerate(parts):
            progress(i, len(parts), label)
            work()
        progress(len(parts), len(parts), f"in {time.perf_counter() - t0:.0f} s")
        return True


def cmd_warmup(args) -> int:
    """`gyro-sim warmup`: exit 0 (filled, or already full), 1 (a compile failed)."""
    if not kernels():
        print("gyro-sim warmup: numba is not installed: nothing to compile (the numpy backend runs)", file=sys.stderr)
        return 0
    t0 = time.perf_counter()
    try:
        did = foreground_fill(args.integrator)
    except Exception as exc:  # noqa: BLE001 - one line, not a traceback
        print(f"gyro-sim warmup: compiling failed ({type(exc).__name__}: {exc})", file=sys.stderr)
        return 1
    print(f"gyro-sim warmup: the cache holds every kernel of {args.integrator} "
          f"({'filled' if did else 'nothing to do'}, {time.perf_counter() - t0:.1f} s)", file=sys.stderr)
    return 0


def register(sub, bench) -> None:
    """Add `gyro-sim warmup`."""
    w = sub.add_parser("warmup", help="fill the kernel cache now, in the foreground (a container build, CI)")
    w.add_argument("--integrator", default=DEFAULT_INTEGRATOR, choices=sorted(LOOPS),
                   help=f"the integrator whose kernels to compile (default {DEFAULT_INTEGRATOR}, the node's)")
    w.set_defaults(fn=cmd_warmup)


def main(argv=None) -> int:
    """``python -m gyro_sim.warmup --fill INTEGRATOR [--background] [--share-only] [--whole]``: the
    helper (`fill`)."""
    args = sys.argv[1:] if argv is None else list(argv)
    flags = args[2:]
    background, share_only, whole = "--background" in flags, "--share-only" in flags, "--whole" in flags
    if (len(args) < 2 or args[0] != "--fill" or args[1] not in LOOPS
            or len(flags) != background + share_only + whole):
        print(f"usage: python -m gyro_sim.warmup --fill {{{','.join(LOOPS)}}} [--background] [--share-only] [--whole]",
              file=sys.stderr)
        return 2
    parent = os.environ.get(PARENT_VARIABLE, "")
    fill(args[1], parent=int(parent) if parent.isdigit() else None, background=background, share_only=share_only,
         whole=whole)
    return 0


if __name__ == "__main__":
    sys.exit(main())
