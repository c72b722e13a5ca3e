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
    code = "from gyro_sim import warmup\nprint(warmup.precompile(integrator='fixed'))\n"
    first = subprocess.run([sys.executable, "-c", code], cwd=ROOT,
                           env=env(NUMBA_CACHE_DIR=str(cache), GYRO_SIM_VERBOSE="1"),
                           capture_output=True, text=True, timeout=COLD_TIMEOUT)
    assert first.returncode == 0 and first.stdout.strip() == "True", first.stderr
    compiled = [x for x in first.stderr.splitlines() if x.startswith("  compiled ")]
    assert any("dynamics.kernel.rhs_kernel" in x for x in compiled), first.stderr
    # the helper's share: compiled there, loaded here
    assert not any("publication_kernel" in x for x in compiled), first.stderr
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


def test_a_second_helper_leaves_at_once(tmp_path):
    """One helper at a time per cache: with the lock taken, `--fill` returns and compiles nothing."""
    cache = tmp_path / "numba_cache"
    cache.mkdir()
    with open(cache / "gyro_sim_warmup.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        r = subprocess.run([sys.executable, "-m", "gyro_sim.warmup", "--fill", "rk4"], cwd=ROOT,
                           env=env(NUMBA_CACHE_DIR=str(cache)), capture_output=True, text=True, timeout=600)
    assert r.returncode == 0 and r.stdout == "", (r.stdout, r.stderr)
    assert not list(cache.rglob("*.nbi")), "the second helper compiled"


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
