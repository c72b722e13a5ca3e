"""`gyro-sim bench scaling`: the fixed-step rows beside MuJoCo (tiny run)."""
import pytest

from gyro_sim.bench import scaling
from gyro_sim.dynamics import kernel as fast

pytestmark = pytest.mark.skipif(not fast.available(), reason="numba is not installed")


def test_fixed_step_rows_and_table():
    rows = scaling.fixed_step((2,), seconds=0.01, repeats=1)
    (r,) = rows
    assert r.n == 2 and r.one_call_s > 0 and r.per_step_s > 0
    text = scaling.fixed_step_table(rows)
    assert text.splitlines()[0].startswith("| n (rotors on every body)")
    if r.mujoco_s is not None:
        assert r.ratio(r.one_call_s) == pytest.approx(r.one_call_s / r.mujoco_s)
        assert "x |" in text.splitlines()[2]


def test_growth_exponents_are_log_log_slopes():
    """Costs c n^p per simulated second give slope p; rows missing n = 100 or 1000 give none."""
    def row(n, p):
        return scaling.FixedStepRow(n, 2e-4 * n, 3e-4 * n ** 1.5, None,
                                    others={"lie4": 1e-5 * n ** 2, "gauss4": 0.7 * n ** p})
    rows = [row(n, 1.25) for n in (100, 200, 1000)]
    got = scaling.growth_exponents(rows)
    assert got == pytest.approx({"rk4 one advance": 1.0, "rk4 per step": 1.5, "lie4": 2.0,
                                 "gauss4": 1.25})
    assert "gauss4 1.25" in scaling.fixed_step_table(rows)
    assert scaling.growth_exponents(rows[:2]) == {}
