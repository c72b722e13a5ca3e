"""examples/geared_vs_armature.py: the geared motor against the armature on a turntable. Without
the turntable's spin the fork turns about an axis normal to the motor's, and the two models are
the same motion; with it they part, by less the higher the gear at the same J G^2."""
import importlib.util
from pathlib import Path

import pytest

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "geared_vs_armature.py"


@pytest.fixture(scope="module")
def example():
    spec = importlib.util.spec_from_file_location("geared_vs_armature", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_models_agree_without_spin_and_part_with_it(example):
    rows = example.table([5.0, 20.0, 100.0], [0.0, 10.0], 0.5)
    still = [r for r in rows if r["spin"] == 0.0]
    spun = [r for r in rows if r["spin"] == 10.0]
    for r in still:  # a . w_fork = 0 at all times: exactly the armature
        assert abs(r["arm"] - r["arm_armature"]) <= 1e-12 and r["tilt"] == r["tilt_armature"] == 0.0
    gaps = [abs(r["arm"] - r["arm_armature"]) for r in spun]
    assert gaps[0] > 1e-3 and gaps[0] > gaps[1] > gaps[2] > 0.0  # the coupling J G = J G^2 / G


def test_main_prints_the_table(example, capsys):
    assert example.main(["--seconds", "0.1", "--gears", "10", "--spins", "0", "5"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[1].startswith("| turntable (rad/s) | gear |") and len(lines) == 5
