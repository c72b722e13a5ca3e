"""`gyro-sim bench linearize --quick`: the report is written, and counts what it says."""
import json

from gyro_sim.cli import main


def test_bench_linearize_quick(tmp_path, capsys):
    assert main(["bench", "linearize", "--quick", "--out", str(tmp_path)]) == 0
    rows = json.loads((tmp_path / "linearize.json").read_text())
    assert [r["n"] for r in rows] == [10]
    r = rows[0]
    assert r["states"] == 6 * 10 and r["evaluations"] == 1 + r["states"]  # no inputs on this chain
    assert r["linearize_s"] > 0
    if r["pinocchio_aba_derivatives_s"] is not None:
        assert r["ratio"] == r["linearize_s"] / r["pinocchio_aba_derivatives_s"]
    assert "computeABADerivatives" in (tmp_path / "linearize.md").read_text()
    assert main(["bench", "linearize", "--quick", "--out", str(tmp_path)]) == 2  # no silent overwrite
    assert "linearize" in capsys.readouterr().err
