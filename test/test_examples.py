"""Every example command a user is shown works.

Collected from every `--help` of `gyro-sim` (descriptions and epilogs of the top-level parser
and of every subcommand, nested ones included), from `gyro_sim_node --help`, and from the
README's code blocks (segments of a `&&` chain too). Each is parsed by the real parser (the
class of bug reported: `unrecognized arguments: --seconds 10`); the cheap ones are also run
for real, each in a fresh directory holding the logs they name: `run` (duration cut to
RUN_SECONDS), `view --save`, `replay --resimulate`, `recover`. What needs a live node, a
viewer window, Vulkan or minutes of benchmarking is parsed only.
"""
from __future__ import annotations

import argparse
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PROGRAMS = ("gyro-sim", "gyro_sim_node")
#: simulated seconds of the `run` examples when run for real
RUN_SECONDS = "0.5"
#: the logs the examples name, made once from one short recorded run
LOG_NAMES = ("run.mcap", "gyro_sim_live.mcap", "broken.mcap")


def _command(line: str) -> str | None:
    """`line` without its comment and optional-argument brackets, if it is an example command."""
    line = line.strip()
    if not line.startswith(tuple(p + " " for p in PROGRAMS)):
        return None
    line = re.sub(r"\s+#.*$", "", line)
    return re.sub(r"\[([^\[\]]*)\]", r"\1", line).strip()


def _parsers(parser: argparse.ArgumentParser):
    yield parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in dict.fromkeys(action.choices.values()):  # aliases share a parser
                yield from _parsers(sub)


def examples() -> list[tuple[str, str]]:
    """(where it is shown, command line), every one the user can read."""
    from gyro_sim.cli import build_parser
    from gyro_sim.ros.params import help_text

    found = []
    for p in _parsers(build_parser()):
        for text in (p.description, p.epilog):
            found += [(f"{p.prog} --help", c) for c in map(_command, (text or "").splitlines()) if c]
    found += [("gyro_sim_node --help", c) for c in map(_command, help_text().splitlines()) if c]
    in_block = False
    for line in (ROOT / "README.md").read_text().splitlines():
        if line.startswith("```"):
            in_block = not in_block
            continue
        if in_block or line.startswith("    "):
            for segment in line.split(" && "):
                c = _command(segment)
                if c:
                    found.append(("README.md", c))
    return list(dict.fromkeys(found))


EXAMPLES = examples()
#: each distinct command once, with every place it is shown (the same line parses and runs the
#: same wherever it is shown: running it once per place would assert the same thing again)
COMMANDS = list({c: " and ".join(w for w, c2 in EXAMPLES if c2 == c) for _, c in EXAMPLES}.items())


def test_examples_are_collected():
    sources = {s for s, _ in EXAMPLES}
    assert {"gyro-sim --help", "gyro-sim cmd --help", "gyro-sim bench --help", "gyro_sim_node --help",
            "README.md"} <= sources, sources
    commands = [c for _, c in EXAMPLES]
    for sub in ("run", "view", "replay", "recover", "cmd", "bench"):
        assert any(c.startswith(f"gyro-sim {sub} ") for c in commands), sub
    assert any(c.startswith("gyro_sim_node --ros-args") for c in commands)


def runs_for_real(argv: list[str]) -> bool:
    cmd = argv[0]
    return (cmd == "run" or (cmd == "view" and "--save" in argv and "--screenshot" not in argv)
            or (cmd == "replay" and "--resimulate" in argv) or cmd == "recover")


def env() -> dict:
    e = dict(os.environ)  # the whole environment: the ROS wheels need theirs
    e["PYTHONPATH"] = os.pathsep.join([str(ROOT), e.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return e


def gyro_sim(argv, cwd) -> subprocess.CompletedProcess:
    exe = Path(sys.executable).with_name("gyro-sim")
    cmd = [str(exe)] if exe.is_file() else [sys.executable, "-m", "gyro_sim.cli"]
    return subprocess.run(cmd + list(argv), cwd=cwd, env=env(), capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> Path:
    """A directory with the logs the examples name: one short recording, and a copy cut short."""
    d = tmp_path_factory.mktemp("example_logs")
    r = gyro_sim(["run", "--scene", "hinge_chain", "--duration", RUN_SECONDS, "--record", "run.mcap"], d)
    assert r.returncode == 0, r.stderr
    shutil.copy(d / "run.mcap", d / "gyro_sim_live.mcap")
    data = (d / "run.mcap").read_bytes()
    (d / "broken.mcap").write_bytes(data[: int(len(data) * 0.7)])  # as after SIGKILL: no index, no footer
    return d


@pytest.mark.parametrize("line, where", COMMANDS, ids=[c for c, _ in COMMANDS])
@pytest.mark.slow
def test_example(where, line, tmp_path, logs, monkeypatch):
    argv = shlex.split(line)
    program, argv = argv[0], argv[1:]
    if program == "gyro_sim_node":
        from gyro_sim.ros.params import parse_ros_argv, unknown_parameters, validate

        # the README's params file is config/params.yaml of the clone; the outputs it names are
        # checked against a fresh directory, never the user's tree (a log of an earlier run there
        # must not change the verdict)
        (tmp_path / "config").symlink_to(ROOT / "config", target_is_directory=True)
        monkeypatch.chdir(tmp_path)
        help_asked, values = parse_ros_argv(argv)
        assert not help_asked and unknown_parameters(values) == [], (where, line)
        validate(values)  # raises ParameterError naming what is wrong
        return
    from gyro_sim.cli import build_parser

    try:
        build_parser().parse_args(argv)
    except SystemExit as exc:
        pytest.fail(f"{where}: `{line}` does not parse (exit {exc.code})")
    if not runs_for_real(argv):
        return
    if "--duration" in argv:
        argv[argv.index("--duration") + 1] = RUN_SECONDS
    if argv[0] != "run":  # the inputs it names; what it writes does not exist yet
        for name in LOG_NAMES:
            shutil.copy(logs / name, tmp_path / name)
    r = gyro_sim(argv, tmp_path)
    assert r.returncode == 0, (where, line, r.stdout, r.stderr)
    assert "Traceback" not in r.stderr
    for i, a in enumerate(argv[:-1]):
        if a in ("--record", "--save", "-o", "--output"):
            assert (tmp_path / argv[i + 1]).is_file(), (line, argv[i + 1])
