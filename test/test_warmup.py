"""A cold start (gyro_sim.warmup): the kernel compiled here, the rest by a helper process into
the same cache; what the helper compiled runs as if compiled here (same results bit for bit)."""
import fcntl
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from gyro_sim.bench.procs import running
from gyro_sim import warmup
from gyro_sim.dynamics import kernel as fast

pytestmark = pytest.mark.skipif(not fast.available(), reason="needs numba")

ROOT = Path(__file__).resolve().parents[1]
#: generous bounds for a cold compile on a shared 2-core machine (s)
COLD_TIMEOUT = 1800
HELPER_TIMEOUT = 1800
#: what the second start runs: each integrator, this long (s)
RUNS = (("fixed", 0.02), ("gauss4s", 0.005))

RUN_CODE = """
import sys
import numpy as np
from numba.core import event
from gyro_sim.simulator import Simulator

compiled = []

class Count(event.Listener):
    def on_start(self, ev):
        compiled.append(ev.data["dispatcher"].py_func.__qualname__)

    def on_end(self, ev):
        pass

event.register("numba:compile", Count())
for integrator, seconds in {runs!r}:
    sim = Simulator("hinge_chain", integrator=integrator, backend="numba")
    sim.set_axis_moments([0.3] * len(sim.axis_names))
    sim.advance(seconds)
    np.save(sys.argv[1] + "/" + integrator + ".npy", sim.state)
print(len(compiled), compiled)
"""


def env(**extra) -> dict:
    e = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "NUMBA_DISABLE_JIT")}
    e["PYTHONPATH"] = os.pathsep.join(filter(None, (str(ROOT), os.environ.get("PYTHONPATH"))))
    e.update(extra)
    return e


def wait_for_helper(lock: Path, timeout: float) -> None:
    """Until no helper holds the lock (it holds it from before READY until it ends)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        with open(lock, "w") as f:
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
                return
            except OSError:
                pass
        time.sleep(1.0)
    raise AssertionError(f"the helper still runs after {timeout} s")


@pytest.mark.slow
def test_a_cold_start_shares_the_work_and_the_helper_fills_the_cache(tmp_path):
    cache = tmp_path / "numba_cache"
    cache.mkdir()
    # the helper outlives its parent: this one waits for it
    code = "from gyro_sim import warmup\nprint(warmup.precompile(integrator='fixed'))\nwarmup._helper.wait()\n"
    first = subprocess.run([sys.executable, "-c", code], cwd=ROOT,
                           env=env(NUMBA_CACHE_DIR=str(cache), GYRO_SIM_VERBOSE="1", GYRO_SIM_BACKGROUND_FILL="1"),
                           capture_output=True, text=True, timeout=COLD_TIMEOUT)
    assert first.returncode == 0 and first.stdout.strip() == "True", first.stderr
    compiled = [x for x in first.stderr.splitlines() if x.startswith("  compiled ")]
    assert any("dynamics.kernel._rhs " in x for x in compiled), first.stderr  # the kernel, in its C function
    # the helper's share: compiled there, loaded here
    assert not any("publication_kernel" in x or "erk_march" in x for x in compiled), first.stderr
    wait_for_helper(cache / "gyro_sim_warmup.lock", HELPER_TIMEOUT)
    check = subprocess.run([sys.executable, "-c", "from gyro_sim import warmup\n"
                            "print(warmup.cache_is_cold('fixed'), warmup.everything_cached('fixed'))"],
                           cwd=ROOT, env=env(NUMBA_CACHE_DIR=str(cache)), capture_output=True, text=True, timeout=600)
    assert check.stdout.split() == ["False", "True"], (check.stdout, check.stderr)
    # a second start compiles nothing, and its steps are those of code compiled here
    out = tmp_path / "states"
    out.mkdir()
    second = subprocess.run([sys.executable, "-c", RUN_CODE.format(runs=RUNS), str(out)], cwd=ROOT,
                            env=env(NUMBA_CACHE_DIR=str(cache)), capture_output=True, text=True, timeout=600)
    assert second.returncode == 0, second.stderr
    assert second.stdout.startswith("0 "), second.stdout
    from gyro_sim.simulator import Simulator

    for integrator, seconds in RUNS:
        sim = Simulator("hinge_chain", integrator=integrator, backend="numba")
        sim.set_axis_moments([0.3] * len(sim.axis_names))
        sim.advance(seconds)
        assert np.array_equal(np.load(out / f"{integrator}.npy"), sim.state), integrator


#: a parent that starts a helper of the first step's share only on its cache, prints the
#: helper's pid, and ends when its stdin closes
PARENT_CODE = """
import sys
from gyro_sim import warmup
helper = warmup._start_helper(sys.argv[1], share_only=True)
print(helper.pid, flush=True)
print(helper.stdout.readline().strip(), flush=True)
sys.stdin.read()
"""


#: a helper ends this soon after its parent (it checks every PARENT_POLL s; filling the whole
#: cache takes minutes of CPU)
ENDS_WITHIN = 60.0


def locked(path: Path) -> bool:
    """Whether a process holds the lock at `path`."""
    if not path.exists():
        return False
    with open(path, "a") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            return True
    return False


def test_a_second_helper_of_the_share_says_ready_at_once_and_ends_with_its_parent(tmp_path):
    """With the cache's lock taken (another helper fills it), a helper of the first step's share
    (no background fill: CI, tests, no terminal) says READY at once (its parent compiles
    itself), compiles nothing, and ends when its parent ends."""
    cache = tmp_path / "numba_cache"
    cache.mkdir()
    with open(cache / "gyro_sim_warmup.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        parent = subprocess.Popen([sys.executable, "-c", PARENT_CODE, "rk4"], cwd=ROOT,
                                  env=env(NUMBA_CACHE_DIR=str(cache)), stdin=subprocess.PIPE,
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            helper = int(parent.stdout.readline())
            assert parent.stdout.readline().strip() == "ready"
            assert running(helper)
            parent.stdin.close()
            assert parent.wait(HELPER_TIMEOUT) == 0, parent.stderr.read()
            end = time.monotonic() + HELPER_TIMEOUT
            while running(helper) and time.monotonic() < end:
                time.sleep(0.05)
            assert not running(helper), "the helper outlived its parent"
        finally:
            if parent.poll() is None:
                parent.kill()
            parent.stdout.close()
            parent.stderr.close()
    assert not list(cache.rglob("*.nbi")), "the second helper compiled while the first held the lock"


def test_a_helper_of_the_share_ends_with_its_parent_while_it_compiles(tmp_path):
    """Where no background fill is allowed, the helper compiling the first step's share on a
    cold cache ends soon after the process that started it ends (it does not go on compiling on
    a machine the start has left)."""
    cache = tmp_path / "numba_cache"
    cache.mkdir()
    parent = subprocess.Popen([sys.executable, "-c", "import sys\nfrom gyro_sim import warmup\n"
                               "print(warmup._start_helper('fixed', share_only=True).pid, flush=True)\n"
                               "sys.stdin.read()\n"],
                              cwd=ROOT, env=env(NUMBA_CACHE_DIR=str(cache)), stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)
    try:
        helper = int(parent.stdout.readline())
        end = time.monotonic() + HELPER_TIMEOUT
        while not locked(cache / "gyro_sim_warmup.lock") and time.monotonic() < end:  # it has begun
            time.sleep(0.05)
        assert running(helper)
        parent.stdin.close()
        assert parent.wait(HELPER_TIMEOUT) == 0
        end = time.monotonic() + ENDS_WITHIN
        while running(helper) and time.monotonic() < end:
            time.sleep(0.05)
        assert not running(helper), f"the helper still compiles {ENDS_WITHIN} s after its parent ended"
    finally:
        if parent.poll() is None:
            parent.kill()
        parent.stdout.close()
    with open(cache / "gyro_sim_warmup.lock", "w") as lock:  # released: no helper holds it
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)


def test_the_helper_says_how_to_call_it():
    r = subprocess.run([sys.executable, "-m", "gyro_sim.warmup", "--fill", "euler"], cwd=ROOT, env=env(),
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 2 and r.stderr.startswith("usage: python -m gyro_sim.warmup --fill {"), r.stderr
    assert len(r.stderr.splitlines()) == 1


def test_filling_while_a_helper_holds_the_lock():
    """Another start's helper (it holds the cache's lock) counts: this start then leaves the
    methods it may switch to to it."""
    from gyro_sim import warmup

    assert warmup.filling() is False
    with open(warmup._lock_path(), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        assert warmup.filling() is True
    assert warmup.filling() is False


def test_the_helper_runs_the_gyro_sim_of_its_parent_wherever_it_starts(tmp_path):
    """Started from a directory holding another gyro_sim (a source tree of another version),
    the helper still runs the one its parent runs: it fills the cache for the kernels the parent
    loads."""
    other = tmp_path / "checkout" / "gyro_sim"
    other.mkdir(parents=True)
    (other / "__init__.py").write_text("")
    marker = tmp_path / "the_other_ran"
    (other / "warmup.py").write_text(f"open({str(marker)!r}, 'w').close()\nprint('ready', flush=True)\n")
    cache = tmp_path / "numba_cache"
    cache.mkdir()
    with open(cache / "gyro_sim_warmup.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # the helper waits for it: it compiles nothing here
        parent = subprocess.Popen([sys.executable, "-P", "-c", PARENT_CODE, "rk4"], cwd=other.parent,
                                  env=env(NUMBA_CACHE_DIR=str(cache)), stdin=subprocess.PIPE,
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            int(parent.stdout.readline())
            assert parent.stdout.readline().strip() == "ready"
            parent.stdin.close()
            assert parent.wait(HELPER_TIMEOUT) == 0, parent.stderr.read()
        finally:
            if parent.poll() is None:
                parent.kill()
            parent.stdout.close()
            parent.stderr.close()
    assert not marker.exists(), "the helper ran the gyro_sim of its working directory"


def test_the_node_loads_the_rungs_off_its_physics_thread_once_the_fill_ends(monkeypatch):
    """warm_when_filled: a thread waits while a helper fills the cache, then loads every rung of
    "fixed" into the process (the manifest gets them) through a Simulator of its own."""
    from gyro_sim.integrators import fixed
    from gyro_sim.simulator import Simulator

    answers = iter([True, True, False])
    monkeypatch.setattr(warmup, "filling", lambda: next(answers, False))
    monkeypatch.setattr(fixed, "WARM", set())
    sim = Simulator("hinge_chain", integrator="fixed", step=1e-3, backend="numba")
    thread = warmup.warm_when_filled(sim, poll=0.0)
    thread.join(600)
    assert not thread.is_alive() and next(answers, None) is None  # it waited through both "filling"
    assert {"gauss4s", fixed.RESCUE} <= fixed.WARM
    assert sim.time == 0.0 and sim.integrator.nfev == 0  # the node's own Simulator untouched


def test_a_background_fill_outlives_its_parent_in_a_session_of_its_own_at_the_lowest_priority(tmp_path):
    """The fill for an interactive start: once its parent has ended it still runs and holds the
    cache's lock, in a session of its own (a Ctrl-C of the start does not reach it), at
    SCHED_IDLE and nice 19. (Ended here by its pid: the whole fill takes minutes of CPU.)"""
    import signal

    cache = tmp_path / "numba_cache"
    cache.mkdir()
    parent = subprocess.Popen([sys.executable, "-c", "import sys\nfrom gyro_sim import warmup\n"
                               "h = warmup._start_helper('rk4', background=True)\nprint(h.pid, flush=True)\n"],
                              cwd=ROOT, env=env(NUMBA_CACHE_DIR=str(cache)), stdout=subprocess.PIPE, text=True)
    helper = int(parent.stdout.readline())
    try:
        assert parent.wait(HELPER_TIMEOUT) == 0
        end = time.monotonic() + HELPER_TIMEOUT
        while not locked(cache / "gyro_sim_warmup.lock") and running(helper) and time.monotonic() < end:
            time.sleep(0.05)
        assert running(helper) and locked(cache / "gyro_sim_warmup.lock"), "the fill ended with its parent"
        assert os.getsid(helper) == helper != os.getsid(0)
        assert os.sched_getscheduler(helper) == os.SCHED_IDLE
        assert int(Path(f"/proc/{helper}/stat").read_text().rsplit(")", 1)[1].split()[16]) == 19  # nice
    finally:
        if running(helper):
            os.kill(helper, signal.SIGKILL)
        parent.stdout.close()


@pytest.mark.parametrize("variables, tty, allowed", [
    ({"GYRO_SIM_BACKGROUND_FILL": "0"}, True, False),
    ({"GYRO_SIM_BACKGROUND_FILL": "1", "CI": "true"}, False, True),
    ({"CI": "true"}, True, False),
    ({}, False, True),
    ({}, True, True),
])
def test_background_fill_is_off_under_ci_and_in_tests_and_the_same_with_or_without_a_terminal(monkeypatch, variables,
                                                                                              tty, allowed):
    import io

    for name in ("GYRO_SIM_BACKGROUND_FILL", "CI"):
        monkeypatch.delenv(name, raising=False)
    for name, value in variables.items():
        monkeypatch.setenv(name, value)

    class Stream(io.StringIO):
        def isatty(self):
            return tty

    for name in ("stdin", "stdout", "stderr"):
        monkeypatch.setattr(sys, name, Stream())
    assert warmup.background_fill_allowed() is allowed


def test_warmup_fills_the_cache_in_the_foreground_with_progress(tmp_path):
    """`gyro-sim warmup` on a full cache: nothing to do, exit 0 at once; a bad integrator: exit 2,
    one usage error."""
    from gyro_sim.cli import main

    assert main(["warmup", "--integrator", "rk4"]) == 0
    with pytest.raises(SystemExit) as e:
        main(["warmup", "--integrator", "euler"])
    assert e.value.code == 2


def test_a_read_only_install_caches_per_user_keyed_on_versions_and_cpu(monkeypatch, tmp_path):
    import numba

    from gyro_sim import __version__, jit

    monkeypatch.setattr(numba.config, "CACHE_DIR", "")
    monkeypatch.setattr(jit.os, "access", lambda path, mode: False)  # site-packages read-only
    monkeypatch.setenv("HOME", str(tmp_path))
    where = jit.cache_directory(())
    key = where.parent.name
    assert where.parent.parent == tmp_path / ".cache" / "gyro_sim"
    assert key.startswith(f"gyro_sim-{__version__}-numba-{numba.__version__}-")
    assert key.split("-numba-")[1].count("-") >= 1  # the CPU after the version
