"""gyro_sim.dynamics.kernel.rhs_kernel allocates nothing per evaluation on the classic elimination:
everything lives in the workspace `fast.records(model)` gives (numba's own allocation
counters, NUMBA_NRT_STATS, in a subprocess: the switch must be set before numba imports).
Counted inside one compiled call, so that the boxing of the arguments at the Python boundary
is not."""
import json
import os
import subprocess
import sys

import pytest

from gyro_sim.dynamics import kernel as fast

pytestmark = pytest.mark.skipif(not fast.available(), reason="numba is not installed")

PROBE = r"""
import json
import numba
import numpy as np
from numba.core.runtime import rtsys
from gyro_sim import load_scene
from gyro_sim.bench.scenes import spherical_chain
from gyro_sim.dynamics import kernel as fast
from gyro_sim.dynamics.model import compile_model, initial_state
from test.dynamics.chains import random_chain
from test.dynamics.test_geared_motor import motor_chain

@numba.njit
def repeat(m, t, y, ydot, args):
    for i in range(m):
        fast.rhs_kernel(t + 0.001 * i, y, ydot, *args)


moving = random_chain(4, n=4)
moving["base"] = {"type": "moving", "position": [0.0, 0.0, 0.0],
                  "motion": {"type": "sine", "amplitude": [0.0, 0.0, 0.01], "frequency": 20.0}}
out = {}
for name, scene in (("spherical, rotors, gravity", spherical_chain(5, rotors=True)),
                    ("hinges, free base", random_chain(3, base="free", n=5)),
                    ("hinges, moving base", moving),
                    ("geared motors, free base", motor_chain(1, "free"))):
    model = compile_model(load_scene(scene))
    y = initial_state(model)
    args = fast.records(model)
    ydot = np.empty(model.size)
    repeat(1, 0.0, y, ydot, args)  # compiled or loaded (and numba's runtime started)
    counts = []
    for m in (1, 1, 11):  # once (twice, the first as a check) and eleven times in one call
        before = rtsys.get_allocation_stats().alloc
        repeat(m, 0.0, y, ydot, args)
        counts.append(rtsys.get_allocation_stats().alloc - before)
    out[name] = counts[2] - counts[1]  # the arguments' own (unboxing) counted once in each
print(json.dumps(out))
"""


@pytest.mark.slow
def test_classic_path_allocates_nothing():
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    env = {**os.environ, "NUMBA_NRT_STATS": "1"}
    proc = subprocess.run([sys.executable, "-c", PROBE], env=env, cwd=root, capture_output=True,
                          text=True)
    assert proc.returncode == 0, proc.stderr
    allocations = json.loads(proc.stdout.strip().splitlines()[-1])
    assert allocations and all(v == 0 for v in allocations.values()), allocations
