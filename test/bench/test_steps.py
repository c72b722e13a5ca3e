"""`gyro-sim bench steps`: each case measured in each tree, a case a tree refuses said as
refused; bad input is one line."""
import json

import pytest

from gyro_sim.cli import main


@pytest.mark.slow
def test_bench_steps_measures_this_tree_and_says_what_the_other_refuses(tmp_path, capsys):
    other = tmp_path / "other"
    (other / "gyro_sim").mkdir(parents=True)
    (other / "gyro_sim" / "__init__.py").write_text(
        "class Simulator:\n"
        "    def __init__(self, *args, **kwargs):\n"
        "        raise ValueError('this version takes no such scene')\n")
    out = tmp_path / "out"
    args = ["bench", "steps", "--quick", "--scenes", "heavy_top", "--rounds", "2", "--against", str(other),
            "--out", str(out)]
    assert main(args) == 0
    (row,) = json.loads((out / "steps.json").read_text())["rows"]
    assert row["scene"] == "heavy_top" and row["integrator"] == "rk4"
    assert len(row["this tree"]) == 2 and all(us > 0 for us in row["this tree"])
    assert row["against"].startswith("ValueError: this version takes no such scene")  # measured once, not again
    assert "| heavy_top | rk4 |" in (out / "steps.md").read_text()
    assert "refused (ValueError)" in (out / "steps.md").read_text()
    assert main(args) == 2  # no silent overwrite
    assert "steps" in capsys.readouterr().err


def test_bench_steps_refuses_a_directory_without_gyro_sim(tmp_path, capsys):
    assert main(["bench", "steps", "--against", str(tmp_path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("gyro-sim bench steps: --against") and "no gyro_sim" in err[0]
