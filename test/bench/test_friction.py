"""`gyro-sim bench friction`: the report is written and counts what it says; bad input is one line."""
import json
from pathlib import Path

import pytest

pytest.importorskip("mujoco", reason="the models are MJCF: MuJoCo is the optional extra [models]")

from gyro_sim.cli import main

XARM7 = Path(__file__).parents[1] / "scene" / "models" / "robosuite" / "xarm7.xml"


def test_bench_friction_counts_each_run(tmp_path, capsys):
    args = ["bench", "friction", "--models", str(XARM7), "--integrators", "rk4", "--durations", "0.05",
            "--regularised", "--regularised-duration", "0.01", "--out", str(tmp_path)]
    assert main(args) == 0
    rows = json.loads((tmp_path / "friction.json").read_text())["offline"]
    assert [(r["law"], r["integrator"]) for r in rows] == [("exact", "rk4"), ("regularised", "rk4")]
    exact = rows[0]
    # rk4: 4 evaluations a step; every step solves impulses here (joints stuck): 1 + 7 more
    assert exact["simulated_s"] == pytest.approx(0.05) and exact["evaluations_per_s"] == pytest.approx(12_000)
    assert exact["cpu_per_s"] > 0 and exact["friction_work_J"] < 0 and exact["failed"] is None
    assert "| xarm7.xml | exact | rk4 |" in (tmp_path / "friction.md").read_text()
    assert main(args) == 2  # no silent overwrite
    assert "friction" in capsys.readouterr().err


def test_bench_friction_refuses_a_model_it_cannot_read(tmp_path, capsys):
    missing = tmp_path / "missing.xml"
    assert main(["bench", "friction", "--models", str(missing), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("gyro-sim bench friction:") and "missing.xml" in err[0]
