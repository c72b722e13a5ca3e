"""`gyro-sim bench scaling --memory`: every integrator runs a long chain in memory that grows
O(n). At n = 300 (2,100 states) a dense Jacobian with radau's two LU factors
would take 8 * 2100^2 * 4 bytes = 141 MB on top of the model; the run must add far less."""
from __future__ import annotations

import pytest

from gyro_sim.bench import scaling


@pytest.mark.slow
def test_radau_and_rk4_on_a_long_chain_add_no_n_squared_memory():
    rows = scaling.memory((300,), ("rk4", "radau"))
    assert [r.integrator for r in rows] == ["rk4", "radau"] and not any(r.failed for r in rows), rows
    for r in rows:
        dense = 8 * r.size**2 * 4 / 2**20  # MB: J, the real LU and the complex one (twice)
        assert r.steps > 0 and r.peak_mb - r.built_mb < 0.1 * dense, (r, dense)
    assert "| 300 (2100) | radau |" in scaling.memory_table(rows)
