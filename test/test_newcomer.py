"""What a new user trips over: one test (or a few) per item, each able to fail.

Command-line checks run the real entry points in subprocesses with the whole environment
passed on (the ROS wheels need it); "a module is missing" is simulated by putting None in
sys.modules before gyro_sim runs, which makes `import` raise ModuleNotFoundError.
"""
from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
#: longest a console script may take to answer without starting anything (slow shared machine)
QUICK_EXIT_TIMEOUT = 60


def env(**extra) -> dict:
    e = dict(os.environ)
    e["PYTHONPATH"] = os.pathsep.join([str(ROOT), e.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    e.update(extra)
    return e


def python(code: str, cwd=ROOT, **extra_env) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, env=env(**extra_env), capture_output=True,
                          text=True, timeout=QUICK_EXIT_TIMEOUT)


def with_missing(module: str, call: str) -> str:
    """Python code running `call` (an expression giving an exit code) as if `module` were not installed."""
    return f"import sys\nsys.modules[{module!r}] = None\n{call_prefix(call)}"


def call_prefix(call: str) -> str:
    return f"code = {call}\nsys.exit(code)\n"


def node(*args: str, **extra_env) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gyro_sim.ros.node", *args], cwd=ROOT, env=env(**extra_env),
                          capture_output=True, text=True, timeout=QUICK_EXIT_TIMEOUT)


def readme_command(prefix: str) -> str:
    """The README's indented command line that starts with `prefix`."""
    for line in README.splitlines():
        if line.startswith("    " + prefix):
            return line.strip()
    raise AssertionError(f"no README command starting with {prefix!r}")


# --- 1. the Run command installs what the node's hint needs; optional imports give a hint ----------
def test_run_command_installs_the_viewer_its_hint_names():
    run = readme_command("python3 -m venv")
    extras = re.search(r'pip install "\.\[([a-z,]+)\]"', run)
    assert extras, run
    assert {"ros", "viz"} <= set(extras.group(1).split(",")), run
    setup = (ROOT / "setup.py").read_text()
    assert re.search(r'VIZ = \["rerun-sdk', setup) and '"viz": VIZ' in setup
    # the hint the node prints names exactly these two commands (rerun: rerun-sdk's binary)
    hint = (ROOT / "gyro_sim" / "ros" / "node.py").read_text()
    assert "rerun {" in hint and "gyro-sim view {" in hint


@pytest.mark.parametrize("module, argv, extra", [
    ("rerun", ["view", "LOG"], "viz"),
    ("rerun", ["view", "LOG", "--save", "OUT.rrd"], "viz"),
    ("rclpy", ["replay", "LOG"], "ros"),
    ("rclpy", ["cmd", "constant", "0.0"], "ros"),
])
@pytest.mark.slow
def test_missing_optional_module_gives_one_line_hint(tmp_path, module, argv, extra):
    log = tmp_path / "some.mcap"
    log.write_bytes(b"not read: the missing module is found first")
    argv = [str(log) if a == "LOG" else str(tmp_path / a) if a == "OUT.rrd" else a for a in argv]
    r = python(with_missing(module, f"__import__('gyro_sim.cli').cli.main({argv!r})"))
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr, r.stderr
    assert f"pip install 'gyro_sim[{extra}]'" in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr


@pytest.mark.parametrize("module, extra", [("matplotlib", "bench"), ("mujoco", "bench"), ("pinocchio", "bench"),
                                           ("rerun", "viz"), ("rclpy", "ros"), ("std_msgs.msg", "ros")])
def test_any_command_missing_an_extra_says_which(monkeypatch, capsys, module, extra):
    from gyro_sim import cli

    def needs(args):
        raise ModuleNotFoundError(f"No module named {module!r}", name=module)

    monkeypatch.setattr(cli, "cmd_bench_scaling", needs)
    assert cli.main(["bench", "scaling", "--quick"]) == 2
    err = capsys.readouterr().err
    assert f"pip install 'gyro_sim[{extra}]'" in err and module.split(".")[0] in err, err
    assert len(err.strip().splitlines()) == 1, err


def test_node_without_rclpy_gives_one_line_hint():
    r = python(with_missing("rclpy", "__import__('gyro_sim.ros.node').ros.node.main(['x', '--ros-args', "
                                     "'-p', 'backend:=numpy'])"))
    assert r.returncode in (1, 2), r.stderr
    assert "pip install 'gyro_sim[ros]'" in r.stderr and "Traceback" not in r.stderr, r.stderr


# --- 2. gyro_sim_node --help ---------------------------------------------------------------------
@pytest.mark.parametrize("flag", ["--help", "-h"])
def test_node_help_lists_parameters_and_exits(flag):
    from gyro_sim.ros.params import PARAMETERS

    r = node(flag)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert lines[0].startswith("usage: gyro_sim_node")
    for p in PARAMETERS:
        line = next((x for x in lines if x.split()[:1] == [p.name]), None)
        assert line is not None, (p.name, r.stdout)
        kind = {float: "double", str: "string", bool: "bool"}[p.kind]
        assert line.split()[1] == kind, line
        assert p.description in line, line
        if p.kind is float:
            assert repr(float(p.default)) in line and f"[{p.low:g}, {p.high:g}]" in line, line


def test_node_help_does_not_start_rclpy():
    r = python(with_missing("rclpy", "__import__('gyro_sim.ros.node').ros.node.main(['gyro_sim_node', '--help'])"))
    assert r.returncode == 0, r.stderr
    assert "physics_rate" in r.stdout


# --- 3. misspelt parameters ------------------------------------------------------------------------
MISSPELT = "gyro_sim_node: unknown parameter 'physics_rat' (did you mean 'physics_rate'?)"


def test_misspelt_parameter_stops_the_node():
    r = node("--ros-args", "-p", "physics_rat:=500.0")
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert r.stderr.strip() == MISSPELT


def test_misspelt_parameter_in_params_file_stops_the_node(tmp_path):
    f = tmp_path / "params.yaml"
    f.write_text("gyro_sim:\n  ros__parameters:\n    physics_rat: 500.0\n    duration: 1.0\n")
    r = node("--ros-args", "--params-file", str(f))
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert r.stderr.strip() == MISSPELT


def test_missing_params_file_is_one_line():
    r = node("--ros-args", "--params-file", "/no/such/params.yaml")
    assert r.returncode == 2 and r.stderr.strip() == "gyro_sim_node: --params-file /no/such/params.yaml: no such file"


def test_argv_is_read_as_rcl_reads_it(tmp_path):
    from gyro_sim.ros.params import parse_ros_argv, unknown_parameters

    f = tmp_path / "p.yaml"
    f.write_text("/**:\n  ros__parameters:\n    duration: 2\n    use_sim_time: false\n"
                 "other_node:\n  ros__parameters:\n    whatever: 1\n"
                 "/gyro_sim:\n  ros__parameters:\n    physics_rate: 500\n    qos_overrides:\n"
                 "      /clock:\n        publisher:\n          depth: 5\n")
    help_asked, values = parse_ros_argv(["--ros-args", "-p", "duration:=1.0", "--params-file", str(f),
                                         "-r", "__ns:=/x", "-p", "gyro_sim:backend:=numpy",
                                         "-p", "other:integratr:=x", "--", "--help"])
    assert help_asked
    assert values["duration"] == 2 and values["physics_rate"] == 500 and values["backend"] == "numpy"
    assert "whatever" not in values and "integratr" not in values
    assert unknown_parameters(values) == []
    assert unknown_parameters({"rtool": 1.0, "zzz": 1}) == [
        "unknown parameter 'rtool' (did you mean 'rtol'?)",
        "unknown parameter 'zzz' (parameters: " + ", ".join(p.name for p in __import__(
            "gyro_sim.ros.params").ros.params.PARAMETERS) + ")"]


# --- 4. the first start says it compiles ------------------------------------------------------------
def test_readme_states_the_measured_compile_time():
    from gyro_sim.warmup import DEFAULT_INTEGRATOR, WHOLE_COMPILE_SECONDS

    seconds = WHOLE_COMPILE_SECONDS[DEFAULT_INTEGRATOR]  # the node's first start: its background helper's
    assert "about 10 s" not in README
    assert f"about {seconds} s" in README, "README and gyro_sim.warmup.WHOLE_COMPILE_SECONDS disagree"
    assert "measured" in README[README.index(f"about {seconds} s") - 300:][:600].lower()


def test_warm_cache_is_detected():
    from gyro_sim.warmup import cache_is_cold, precompile, warm_everything

    for integrator in ("fixed", "dop853"):
        warm_everything(integrator)  # compiles or loads: the cache is warm after
        assert not cache_is_cold(integrator)
        assert precompile(integrator=integrator) is False


def test_empty_cache_is_detected(tmp_path):
    r = python("from gyro_sim.warmup import cache_is_cold, kernels\n"
               "assert len(kernels()) >= 10, kernels()\nprint(cache_is_cold())\n", NUMBA_CACHE_DIR=str(tmp_path))
    assert r.returncode == 0 and r.stdout.strip() == "True", (r.stdout, r.stderr)


@pytest.mark.slow
def test_cold_cache_is_announced_with_progress_then_silent(tmp_path):
    """An empty NUMBA_CACHE_DIR is a first start: compiles (about COMPILE_SECONDS of CPU)."""
    code = ("import sys\nfrom gyro_sim.warmup import cache_is_cold, precompile\n"
            "cold = cache_is_cold('rk4')\nprint('cold' if cold else 'warm')\nprecompile(integrator='rk4')\n")
    cache = tmp_path / "numba_cache"
    cache.mkdir()
    first = subprocess.run([sys.executable, "-c", code], cwd=ROOT,
                           env=env(NUMBA_CACHE_DIR=str(cache), GYRO_SIM_VERBOSE="1"),
                           capture_output=True, text=True, timeout=600)
    assert first.returncode == 0, first.stderr
    assert first.stdout.strip() == "cold"
    lines = first.stderr.splitlines()
    assert re.fullmatch(r"gyro_sim: compiling the dynamics once, about \d+ s( \(.*\))?; later starts load "
                        r"it from the cache", lines[0]), first.stderr
    compiled = [x for x in lines if x.startswith("  compiled ")]
    assert any("kernel._rhs " in x for x in compiled) and len(compiled) >= 10, first.stderr
    assert list(cache.rglob("*.nbi")), "nothing was cached"
    second = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env(NUMBA_CACHE_DIR=str(cache)),
                            capture_output=True, text=True, timeout=600)
    assert second.returncode == 0 and second.stdout.strip() == "warm" and second.stderr == "", second.stderr


# --- 6. gyro-sim alone -------------------------------------------------------------------------------
def test_gyro_sim_alone_lists_the_commands():
    from gyro_sim.cli import build_parser

    exe = Path(sys.executable).with_name("gyro-sim")
    cmd = [str(exe)] if exe.is_file() else [sys.executable, "-m", "gyro_sim.cli"]
    r = subprocess.run(cmd, cwd=ROOT, env=env(), capture_output=True, text=True, timeout=QUICK_EXIT_TIMEOUT)
    assert r.returncode == 2
    assert r.stderr.startswith("usage: gyro-sim"), r.stderr
    assert "required" not in r.stderr
    text = " ".join(r.stderr.split())
    sub = next(a for a in build_parser()._subparsers._group_actions)
    for choice in sub._choices_actions:
        assert f"{choice.dest} {' '.join(choice.help.split())}" in text, (choice.dest, r.stderr)


# --- 7. scenes by name, from anywhere; paths stay paths ----------------------------------------------
def test_load_scene_takes_shipped_names_from_elsewhere(tmp_path):
    r = python("from gyro_sim import load_scene\n"
               "print(load_scene('hinge_chain').name)\nprint(load_scene('chain_4.yaml').name)\n", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines() == ["hinge chain with commanded moments, r = 2", "four-body spherical chain, chaotic"]


def test_find_scene_refuses_missing_paths_and_takes_bare_names(tmp_path, monkeypatch):
    from gyro_sim.scene.load import SceneError, load_scene
    from gyro_sim.paths import find_scene

    monkeypatch.chdir(tmp_path)
    assert find_scene("chain_4").name == find_scene("chain_4.yaml").name == "chain_4.yaml"
    for path in ("/no/such/dir/chain_4.yaml", "./chain_4.yaml", "sub/chain_4"):
        with pytest.raises(FileNotFoundError, match="no such file"):
            find_scene(path)
    with pytest.raises(FileNotFoundError, match="not found .shipped scenes: .*hinge_chain"):
        find_scene("chain_5")
    with pytest.raises(SceneError, match="file not found"):
        load_scene("/no/such/dir/chain_4.yaml")
    with pytest.raises(SceneError, match="shipped scenes"):
        load_scene("chain_5")
    own = tmp_path / "chain_4.yaml"  # a file of that name here wins over the shipped one
    shutil.copy(find_scene("heavy_top"), own)
    assert find_scene("chain_4.yaml") == Path("chain_4.yaml")
    assert load_scene("chain_4.yaml").name == load_scene("heavy_top").name


# --- 8. everything a reader needs is in the repository ------------------------------------------------
def test_readme_links_stay_inside_the_repository():
    links = re.findall(r"\]\(([^)#]+)\)", README)
    assert "docs/theory.md" in links
    for link in links:
        if "://" in link:
            continue
        target = (ROOT / link).resolve()
        assert target.is_relative_to(ROOT) and target.exists(), link


def test_theory_digest_is_in_docs_with_equation_numbers():
    theory = (ROOT / "docs" / "theory.md").read_text()
    for eq in ("(18)-(19)", "(22)", "(29)", "(30)", "(31)", "(33)", "(40)", "(44)", "(48)", "(51)", "(52)-(54)",
               "(79)", "(82)", "(85)", "(88)"):
        assert eq in theory, eq
    # the sections the code's docstrings cite ("docs/theory.md section 5") exist under those numbers
    for n in range(1, 8):
        assert re.search(rf"^## {n}\. ", theory, re.M), n
    errata = theory[theory.index("## 7. Transcription errors"):]
    assert "-2 mu_k cos theta_k" in errata and "eps_{kl}" in errata


def test_docs_are_not_ignored():
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    for doc in ("docs/theory.md", "docs/scene-format.md"):
        r = subprocess.run(["git", "check-ignore", "--no-index", "-q", doc], cwd=ROOT)
        assert r.returncode == 1, f"{doc} is matched by .gitignore"


# --- 9. small things -------------------------------------------------------------------------------
def test_counts_are_singular_for_one():
    from gyro_sim.log.resim import Resimulation
    from gyro_sim.progress import plural

    assert plural(1, "command") == "1 command" and plural(0, "command") == "0 commands"
    text = Resimulation(commands=1, resets=1, steps=1, compared=1).report()
    assert "1 command," in text and "1 reset)" in text and "1 step " in text and "1 joint-state message" in text
    assert not re.search(r"\b1 \w+s\b", text), text


@pytest.mark.slow
def test_cmd_says_at_once_that_it_waits_for_the_node(tmp_path):
    pytest.importorskip("rclpy")
    domain = str(230 + os.getpid() % 3)  # 230..232: no test or bench node runs there
    out = tmp_path / "cmd.out"
    with open(out, "w") as f:
        p = subprocess.Popen([sys.executable, "-m", "gyro_sim.cli", "cmd", "--seconds", "1", "constant", "0"],
                             cwd=ROOT, stdout=f, stderr=subprocess.STDOUT,
                             env=env(ROS_DOMAIN_ID=domain, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                                     ROS_LOG_DIR=str(tmp_path / "ros_log")))
    try:
        t0 = time.monotonic()
        from gyro_sim.ros.commands import DISCOVERY_TIMEOUT

        # "at once": long before the discovery timeout (rclpy's import and init take 1-3 s)
        while "waiting" not in out.read_text() and p.poll() is None and time.monotonic() - t0 < DISCOVERY_TIMEOUT:
            time.sleep(0.05)
        assert f"waiting for the gyro_sim node (ROS_DOMAIN_ID={domain}" in out.read_text(), out.read_text()
    finally:
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
            try:
                p.wait(20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(5)


# --- Progress lives in its own module -----------------------------------------------------------------
def test_bench_does_not_import_the_cli():
    for path in (ROOT / "gyro_sim" / "bench").glob("*.py"):
        assert "from ..cli" not in path.read_text() and "gyro_sim.cli" not in path.read_text(), path
    from gyro_sim.cli import Progress as P1
    from gyro_sim.progress import Progress as P2

    assert P1 is P2
