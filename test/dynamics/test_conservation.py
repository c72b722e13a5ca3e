"""Every shipped conservative scene keeps its first integrals to 1e-9 (relative) over 10 s
with the adaptive method at tight tolerance (the integrals are computed from the state alone)."""
from pathlib import Path

import numpy as np
import pytest

from gyro_sim import Simulator, load_scene
from gyro_sim.dynamics.invariants import conserved
from gyro_sim.paths import NOT_SCENES

CONFIG = Path(__file__).resolve().parents[2] / "config"
SCENES = sorted(p.name for p in CONFIG.glob("*.yaml") if p.name not in NOT_SCENES)
HORIZON = 10.0
TOLERANCE = 1e-9


@pytest.mark.slow
@pytest.mark.parametrize("name", SCENES)
def test_shipped_scene_conserves(name):
    scene = load_scene(CONFIG / name)
    sim = Simulator(scene, integrator="dop853", rtol=1e-12, atol=1e-14)
    names = conserved(sim.model)
    if not names:
        pytest.skip(f"{name}: nothing is conserved (a moving base, or friction on a hinge at the base)")
    i0 = sim.invariants()
    worst = {k: 0.0 for k in names}
    for _ in range(20):
        sim.advance(HORIZON / 20)
        i1 = sim.invariants()
        for k in names:
            a, b = np.asarray(i0[k]), np.asarray(i1[k])
            # relative to the size of the quantity; a quantity that starts at zero is
            # measured against the chain's angular momentum scale instead
            scale = max(np.max(np.abs(a)), 1e-2 * max(abs(i0["vertical_momentum"]), 1e-3))
            worst[k] = max(worst[k], float(np.max(np.abs(b - a)) / scale))
    assert all(v < TOLERANCE for v in worst.values()), worst
