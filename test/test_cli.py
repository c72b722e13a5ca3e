"""The `gyro-sim` command line: offline run and the scaling bench (quick mode)."""
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def gyro_sim(*args, **kw):
    return subprocess.run(
        [sys.executable, "-m", "gyro_sim.cli", *args], cwd=ROOT, capture_output=True, text=True, **kw
    )


@pytest.mark.slow
def test_run_prints_summary_with_drift():
    r = gyro_sim("run", "--scene", "heavy_top", "--duration", "0.5")
    assert r.returncode == 0, r.stderr
    assert "100%" in r.stderr  # progress
    m = re.search(r"energy drift:\s+([0-9.e+-]+)", r.stdout)
    assert m and float(m.group(1)) < 1e-8, r.stdout
    assert "real-time factor" in r.stdout


@pytest.mark.slow
def test_run_refuses_bad_scene(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nbase: {type: fixed}\nbodies:\n"
                   "  - {name: a, joint: {type: spherical}, mass: -1, inertia: {axial: 1, transverse: 1}}\n")
    r = gyro_sim("run", "--scene", str(bad), "--duration", "1")
    assert r.returncode == 2
    assert "bodies[0].mass" in r.stderr
    r = gyro_sim("run", "--scene", "no_such_scene", "--duration", "1")
    assert r.returncode == 2 and "shipped scenes" in r.stderr


@pytest.mark.slow
def test_bench_scaling_quick(tmp_path):
    r = gyro_sim("bench", "scaling", "--quick", "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    text, fixed = (tmp_path / "scaling.md").read_text().split("### One simulated second")
    assert re.search(r"^\| 10 \| [\d.]+ \| [\d.]+ \|", fixed, re.M)  # RK4 beside MuJoCo
    rows = [line for line in text.splitlines() if re.match(r"\| \d+ \|", line)]
    assert [int(line.split("|")[1]) for line in rows] == [1, 2, 5]
    for line in rows:
        cells = [c.strip() for c in line.split("|")[1:-1]]
        assert float(cells[1]) > 0 and float(cells[2]) > 0
    assert "| gravity |" in text and "| rotors |" in text


def test_a_warning_is_one_line_naming_the_command(tmp_path):
    """The auto integrator's switch on a stiff scene is said in one line, its kind and message,
    without the source line Python quotes by default."""
    r = subprocess.run([sys.executable, "-m", "gyro_sim.cli", "run", "--scene", "stiff_fast_rotor",
                        "--duration", "0.2"], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    said = [line for line in r.stderr.splitlines() if "Warning" in line]
    assert said and all(line.startswith("gyro-sim run: StiffnessWarning: auto integrator:") for line in said)
    assert not any(line.startswith(" ") for line in r.stderr.splitlines()), r.stderr


def _closed_pipe():
    """The write end of a pipe whose reader has gone (`| head -1` once it has its line)."""
    import os

    r, w = os.pipe()
    os.close(r)
    return w


@pytest.mark.slow
def test_a_reader_that_leaves_early_neither_stops_the_command_nor_gets_a_traceback(tmp_path):
    import os

    model = ROOT / "test" / "scene" / "models" / "robosuite" / "jaco.xml"
    out, log = tmp_path / "jaco.yaml", tmp_path / "run.mcap"
    w = _closed_pipe()
    try:  # stdout closed (`gyro-sim import m.xml | head -0`): the scene is written, exit 0
        r = subprocess.run([sys.executable, "-m", "gyro_sim.cli", "import", str(model), "--out", str(out)],
                           cwd=tmp_path, stdout=w, stderr=subprocess.PIPE, text=True)
        # both closed (`gyro-sim run ... 2>&1 | head -1`): the run goes on to its end and its log
        both = subprocess.run([sys.executable, "-m", "gyro_sim.cli", "run", "--scene", "heavy_top", "--duration",
                               "0.2", "--record", str(log)], cwd=ROOT, stdout=w, stderr=w)
    finally:
        os.close(w)
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    assert "bodies:" in out.read_text()
    assert both.returncode == 0
    from mcap.reader import make_reader  # an independent reader: the log is whole, to its end

    with open(log, "rb") as f:
        stats = make_reader(f).get_summary().statistics
    assert stats.message_count > 0 and stats.message_end_time >= 0.2e9 - 1e6
