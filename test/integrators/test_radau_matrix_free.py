"""Radau above DENSE_MAX states: no Jacobian formed, GMRES on Jacobian-vector products
(memory O(n)). Checked against the dense path on the same problems (the
same accepted steps, the same states to far below the tolerance) and by what it allocates."""
from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from gyro_sim.bench.scenes import spherical_chain
from gyro_sim.integrators.radau import driver as R
from gyro_sim.simulator import Simulator


@pytest.mark.parametrize("scene", ["hinge_chain", "heavy_top", "stiff_fast_rotor"])
@pytest.mark.slow
def test_matrix_free_takes_the_dense_steps(scene, monkeypatch):
    runs = {}
    for free in (False, True):
        monkeypatch.setattr(R, "DENSE_MAX", -1 if free else 10**9)
        sim = Simulator(scene, integrator="radau", rtol=1e-8, atol=1e-10)
        sim.advance(0.3)
        i = sim.integrator
        assert i.matrix_free is free
        assert (i.jacobian is None) is free
        runs[free] = (sim.state.copy(), i.nsteps, i.nrejected, i.njev)
    (y_dense, *counts_dense), (y_free, *counts_free) = runs[False], runs[True]
    assert counts_free == counts_dense
    assert np.abs(y_free - y_dense).max() <= 1e-9 * max(1.0, np.abs(y_dense).max())


def test_auto_switches_to_matrix_free_radau_on_a_stiff_scene(monkeypatch):
    """auto's return test needs rho(J): from Krylov on the kept Jacobian point when none is formed."""
    monkeypatch.setattr(R, "DENSE_MAX", -1)
    sim = Simulator("stiff_fast_rotor", integrator="auto", rtol=1e-8, atol=1e-10)
    sim.advance(0.5)
    imp = sim.integrator.implicit
    assert imp.matrix_free and imp.nsteps > 0 and imp.jacobian_point is not None


@pytest.mark.slow
def test_a_step_of_a_long_chain_allocates_O_n():
    """n = 400 bodies (2,800 states, above DENSE_MAX): a dense Jacobian alone would be 63 MB
    (real) plus its two LU factors (63 MB + 125 MB); the matrix-free steps stay far below."""
    sim = Simulator(spherical_chain(400), integrator="radau", rtol=1e-6, atol=1e-8)
    size = sim.integrator.n
    assert size > R.DENSE_MAX and sim.integrator.matrix_free
    tracemalloc.start()
    sim.advance(0.002)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert sim.integrator.nsteps > 0
    assert peak < 0.1 * 8 * size * size, (peak, 8 * size * size)
