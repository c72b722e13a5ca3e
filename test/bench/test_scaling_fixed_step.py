"""`gyro-sim bench scaling`: the fixed-step rows beside MuJoCo (tiny run)."""
import pytest

from gyro_sim.bench import scaling
from gyro_sim.core import fast

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
