"""No silent overwrite: every output path is checked before anything runs."""
from __future__ import annotations

import os
import signal
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from gyro_sim import load_scene
from gyro_sim.log.mcap_log import LogWriter, read_info
from gyro_sim.safe_paths import OutputError, check_output

from test.conftest import ROOT, SCENE, gyro_sim

def _bytes(path):
    return path.read_bytes()


# --- the check itself -----------------------------------------------------------------------------
def test_a_new_file_in_a_writable_directory_passes(tmp_path):
    assert check_output(tmp_path / "new.mcap") == tmp_path / "new.mcap"


def test_an_existing_file_is_refused_unless_forced(tmp_path):
    out = tmp_path / "old.mcap"
    out.write_bytes(b"previous")
    with pytest.raises(OutputError, match=r"old\.mcap: exists; refused"):
        check_output(out)
    check_output(out, force=True)
    assert _bytes(out) == b"previous"  # checking writes nothing


@pytest.mark.parametrize("link", ["hard", "sym"])
def test_an_output_that_is_the_input_by_identity_is_refused_even_forced(tmp_path, link):
    src = tmp_path / "in.mcap"
    src.write_bytes(b"input")
    alias = tmp_path / "other_name.mcap"
    (os.link if link == "hard" else os.symlink)(src, alias)
    for force in (False, True):
        with pytest.raises(OutputError, match="is the input"):
            check_output(alias, inputs=[src], force=force)


@pytest.mark.parametrize("make, match", [
    (lambda p: p.mkdir(), "is a directory"),
    (lambda p: None, "does not exist"),
    (lambda p: os.symlink(p.parent / "nowhere", p), "broken symbolic link"),
])
def test_directories_missing_parents_and_dangling_links_are_refused(tmp_path, make, match):
    out = tmp_path / "x" / "out.mcap" if match == "does not exist" else tmp_path / "out.mcap"
    make(out)
    with pytest.raises(OutputError, match=match):
        check_output(out, force=True)


#: the unwritable-directory check as a user without privileges (root passes every permission
#: check): imports first, then the user dropped, then the check on a writable and a read-only
#: directory of that user; prints what each check said
UNPRIVILEGED_CHECK = """
import os, sys
from pathlib import Path
from gyro_sim.safe_paths import OutputError, check_output
os.setgroups([])
os.setgid(NOBODY)
os.setuid(NOBODY)
for name in ("rw", "ro"):
    try:
        check_output(Path(sys.argv[1]) / name / "out.mcap")
        print(name, "accepted")
    except OutputError as exc:
        print(name, exc)
"""
NOBODY = 65534


def test_an_unwritable_directory_is_refused(tmp_path):
    """A directory its user may not write to: refused. Run as root (as CI runs), the check runs
    in a child process that has dropped to an unprivileged user, in a directory of that user's
    under the system's temporary directory (the user cannot enter pytest's own, root's)."""
    if os.geteuid() != 0:
        d = tmp_path / "ro"
        d.mkdir()
        d.chmod(stat.S_IRUSR | stat.S_IXUSR)
        try:
            with pytest.raises(OutputError, match="is not writable"):
                check_output(d / "out.mcap")
        finally:
            d.chmod(stat.S_IRWXU)
        return
    import shutil
    import tempfile

    base = Path(tempfile.mkdtemp(prefix="gyro_sim-unwritable-"))
    try:
        os.chmod(base, 0o755)
        for name, mode in (("rw", 0o700), ("ro", 0o500)):
            (base / name).mkdir()
            os.chown(base / name, NOBODY, NOBODY)
            os.chmod(base / name, mode)
        done = subprocess.run([sys.executable, "-c", UNPRIVILEGED_CHECK.replace("NOBODY", str(NOBODY)), str(base)],
                              capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stderr
        said = dict(line.split(" ", 1) for line in done.stdout.splitlines())
        assert said["rw"] == "accepted"  # the same user may write to its own directory
        assert "is not writable" in said["ro"] and str(base / "ro") in said["ro"], said
    finally:
        shutil.rmtree(base)


# --- the LogWriter: no code path can clobber a file -------------------------------------------------
def test_log_writer_refuses_an_existing_file_and_leaves_it_alone(tmp_path):
    out = tmp_path / "old.mcap"
    out.write_bytes(b"previous log")
    scene = load_scene(SCENE)
    with pytest.raises(OutputError, match="exists"):
        LogWriter(out, scene=scene, params={})
    assert _bytes(out) == b"previous log"
    with LogWriter(out, scene=scene, params={"x": 1}, overwrite=True):
        pass
    assert read_info(out).params == {"x": 1}


# --- the commands ------------------------------------------------------------------------------------
def _one_line_no_traceback(r, *needles):
    err = r.stderr.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    for n in needles:
        assert n in err, err


@pytest.mark.slow
def test_run_record_refuses_an_existing_log_and_force_replaces_it(tmp_path):
    out = tmp_path / "old.mcap"
    out.write_bytes(b"previous log")
    r = gyro_sim("run", "--scene", SCENE, "--duration", "0.02", "--record", out)
    assert r.returncode == 2
    _one_line_no_traceback(r, str(out), "exists")
    assert _bytes(out) == b"previous log"
    r = gyro_sim("run", "--scene", SCENE, "--duration", "0.02", "--record", out, "--force")
    assert r.returncode == 0, r.stderr
    assert read_info(out).message_count > 0


@pytest.mark.slow
def test_run_record_never_writes_over_its_scene(tmp_path):
    scene = tmp_path / "scene.yaml"
    scene.write_bytes(SCENE.read_bytes())
    alias = tmp_path / "alias.mcap"
    os.link(scene, alias)
    for extra in ((), ("--force",)):
        r = gyro_sim("run", "--scene", scene, "--duration", "0.02", "--record", alias, *extra)
        assert r.returncode == 2
        _one_line_no_traceback(r, "is the input")
    assert scene.read_bytes() == SCENE.read_bytes()


@pytest.mark.slow
def test_run_record_into_a_directory_or_a_missing_one_is_bad_input(tmp_path):
    for out, needle in ((tmp_path, "is a directory"), (tmp_path / "no" / "x.mcap", "does not exist")):
        r = gyro_sim("run", "--scene", SCENE, "--duration", "0.02", "--record", out)
        assert r.returncode == 2
        _one_line_no_traceback(r, needle)


@pytest.mark.slow
def test_recover_onto_a_hard_link_of_its_input_is_refused_and_the_input_kept(recorded, tmp_path):
    log, _ = recorded
    src = tmp_path / "in.mcap"
    src.write_bytes(log.read_bytes())
    alias = tmp_path / "fixed.mcap"
    os.link(src, alias)
    before = src.read_bytes()
    for extra in ((), ("--force",)):
        r = gyro_sim("recover", src, "-o", alias, *extra)
        assert r.returncode == 2
        _one_line_no_traceback(r, "is the input")
        assert src.read_bytes() == before


@pytest.mark.slow
def test_recover_default_output_is_not_overwritten_without_force(recorded, tmp_path):
    log, _ = recorded
    src = tmp_path / "run.mcap"
    src.write_bytes(log.read_bytes())
    default = tmp_path / "run.recovered.mcap"
    default.write_bytes(b"earlier recovery")
    r = gyro_sim("recover", src)
    assert r.returncode == 2
    _one_line_no_traceback(r, str(default), "exists")
    assert default.read_bytes() == b"earlier recovery"
    r = gyro_sim("recover", src, "--force")
    assert r.returncode == 0, r.stderr
    assert read_info(default).message_count == read_info(src).message_count


@pytest.mark.slow
def test_view_save_refuses_the_log_itself_and_existing_files(recorded, tmp_path):
    log, _ = recorded
    src = tmp_path / "run.mcap"
    src.write_bytes(log.read_bytes())
    before = src.read_bytes()
    for extra in ((), ("--force",)):
        r = gyro_sim("view", src, "--save", src, *extra)
        assert r.returncode == 2
        _one_line_no_traceback(r, "is the input")
    assert src.read_bytes() == before
    old = tmp_path / "old.rrd"
    old.write_bytes(b"earlier recording")
    for opt in ("--save", "--screenshot"):
        r = gyro_sim("view", src, opt, old)
        assert r.returncode == 2
        _one_line_no_traceback(r, opt, "exists")
    assert old.read_bytes() == b"earlier recording"


def test_bench_reports_are_not_replaced_without_force(tmp_path):
    from gyro_sim.bench.report import write_report

    write_report(tmp_path, "demo", "# first\n", {"a": 1}, lambda png: None)
    with pytest.raises(OutputError, match=r"demo\.md: exists"):
        write_report(tmp_path, "demo", "# second\n", {"a": 2}, lambda png: None)
    assert (tmp_path / "demo.md").read_text() == "# first\n"
    write_report(tmp_path, "demo", "# second\n", {"a": 2}, lambda png: None, force=True)
    assert (tmp_path / "demo.md").read_text() == "# second\n"


def test_bench_command_refuses_existing_reports_before_running(tmp_path):
    (tmp_path / "realtime.json").write_text("[]")
    r = gyro_sim("bench", "realtime", "--quick", "--out", tmp_path, timeout=60)
    assert r.returncode == 2
    _one_line_no_traceback(r, "realtime.json: exists")
    assert (tmp_path / "realtime.json").read_text() == "[]"
    assert not (tmp_path / "realtime.md").exists()


# --- publication: whole files only, and two writers of one output ------------------------------------
def test_an_output_appears_only_complete(tmp_path):
    from gyro_sim.safe_paths import PARTIAL, atomic_output

    out = tmp_path / "out.bin"
    with atomic_output(out) as target:
        target.tmp.write_bytes(b"half")
        assert not out.exists() and target.tmp.parent == tmp_path and PARTIAL in target.tmp.name
        target.tmp.write_bytes(b"whole")
    assert out.read_bytes() == b"whole" and list(tmp_path.iterdir()) == [out]


def test_an_exception_leaves_nothing_under_the_name_nor_beside_it(tmp_path):
    from gyro_sim.safe_paths import atomic_output

    out = tmp_path / "out.bin"
    with pytest.raises(KeyboardInterrupt):
        with atomic_output(out) as target:
            target.tmp.write_bytes(b"half")
            raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []


def test_the_later_of_two_writers_is_refused_and_the_first_file_kept(tmp_path):
    from gyro_sim.safe_paths import AtomicOutput

    out = tmp_path / "out.bin"
    first, second = AtomicOutput(out), AtomicOutput(out)  # both checked while the name was free
    first.tmp.write_bytes(b"first")
    second.tmp.write_bytes(b"second")
    first.publish()
    with pytest.raises(OutputError, match="was created by another writer"):
        second.publish()
    assert out.read_bytes() == b"first" and list(tmp_path.iterdir()) == [out]
    forced = AtomicOutput(out, force=True)
    forced.tmp.write_bytes(b"forced")
    forced.publish()
    assert out.read_bytes() == b"forced" and list(tmp_path.iterdir()) == [out]


@pytest.mark.slow
def test_two_recover_processes_on_one_output_one_wins_and_the_other_exits_2(recorded, tmp_path):
    log, _ = recorded
    out = tmp_path / "fixed.mcap"
    cmd = [sys.executable, "-m", "gyro_sim.cli", "recover", str(log), "-o", str(out)]
    procs = [subprocess.Popen(cmd, cwd=ROOT, env=dict(os.environ), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True) for _ in range(2)]
    results = [(p.wait(timeout=120), p.stderr.read()) for p in procs]
    for p in procs:
        p.stdout.close()
        p.stderr.close()
    codes = sorted(code for code, _ in results)
    # both may also have run one after the other: then the second was refused at its check
    assert codes == [0, 2], results
    err = next(e for code, e in results if code == 2).strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err and str(out) in err, err
    assert read_info(out).message_count == read_info(log).message_count
    assert [p.name for p in tmp_path.iterdir()] == ["fixed.mcap"]


def test_a_file_system_without_hard_links_still_refuses_the_later_writer(tmp_path, monkeypatch):
    import errno

    from gyro_sim import safe_paths

    def no_links(src, dst):
        raise OSError(errno.EPERM, "Operation not permitted")

    monkeypatch.setattr(safe_paths.os, "link", no_links)
    out = tmp_path / "out.bin"
    first, second = safe_paths.AtomicOutput(out), safe_paths.AtomicOutput(out)
    first.tmp.write_bytes(b"first")
    second.tmp.write_bytes(b"second")
    first.publish()
    with pytest.raises(OutputError, match="was created by another writer"):
        second.publish()
    assert out.read_bytes() == b"first"


# --- every command: a bad output path is exit 2 and one line, before any work ---------------------
def _outputs(tmp_path, log):
    """(command args with {out} for the output path) of every command that writes a file."""
    return {
        "run": ["run", "--scene", str(SCENE), "--duration", "0.02", "--record", "{out}"],
        "view": ["view", str(log), "--save", "{out}"],
        "recover": ["recover", str(log), "-o", "{out}"],
        "bench": ["bench", "realtime", "--quick", "--out", "{out}"],
        "sweep": ["sweep", "kapitza", "--quick", "--workers", "0", "--out", "{out}"],
    }


BAD_OUTPUTS = {
    "a missing directory": ("{tmp}/no/such/dir/out.x", "does not exist"),
    "/proc": ("/proc/gyro_sim_out/out.x", ""),
    "a directory nothing can be created in": ("/sys/gyro_sim_out.x", ""),
    "the input itself": ("{input}", "is the input"),
}


#: bench and sweep write a directory of their own files (made when missing), read from no input
DIRECTORY_WRITERS = ("bench", "sweep")


@pytest.mark.parametrize("command, case", [
    (command, case) for command in ("run", "view", "recover", "bench", "sweep") for case in BAD_OUTPUTS
    if not (command in DIRECTORY_WRITERS and case in ("a missing directory", "the input itself"))])
def test_a_bad_output_path_is_exit_2_in_one_line(recorded, tmp_path, capsys, command, case):
    from gyro_sim.cli import main

    if command == "view":
        pytest.importorskip("rerun", reason="view needs rerun-sdk")
    if command == "sweep":
        pytest.importorskip("distributed", reason="sweeps need dask.distributed")
    if case == "a directory nothing can be created in" and os.access("/sys", os.W_OK) and not Path("/sys").is_dir():
        pytest.skip("no /sys on this system")
    log, _ = recorded
    src = tmp_path / "in.mcap"
    src.write_bytes(log.read_bytes())
    scene = tmp_path / "scene.yaml"
    scene.write_bytes(SCENE.read_bytes())
    args = [a.replace(str(SCENE), str(scene)) for a in _outputs(tmp_path, src)[command]]
    path, needle = BAD_OUTPUTS[case]
    the_input = scene if command == "run" else src
    out = path.format(tmp=tmp_path, input=the_input)
    before = sorted(p.name for p in tmp_path.iterdir())
    capsys.readouterr()
    code = main([a.replace("{out}", out) for a in args])
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert "Traceback" not in err and len(err.splitlines()) == 1 and err.startswith(f"gyro-sim {command}"), err
    assert needle in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing written, nothing half-made
    assert the_input.read_bytes() == (SCENE if command == "run" else log).read_bytes()


def test_view_save_and_screenshot_publish_both_whole(recorded, tmp_path, capsys, monkeypatch):
    """The screenshot (its viewer needs Vulkan, stood in for here) reads the .rrd under its
    final name, and writes the picture under a temporary one until it is complete."""
    pytest.importorskip("rerun", reason="view needs rerun-sdk")
    from gyro_sim.cli import main
    from gyro_sim.viz import commands
    from gyro_sim.viz import rerun_view

    log, _ = recorded
    rrd, png = tmp_path / "v.rrd", tmp_path / "v.png"
    seen = {}

    def fake_screenshot(exe, rrd_path, png_path, size):
        seen["rrd"], seen["png"] = Path(rrd_path), Path(png_path)
        seen["rrd size"] = Path(rrd_path).stat().st_size
        Path(png_path).write_bytes(b"\x89PNG picture")
        assert not png.exists()

    monkeypatch.setattr(commands, "rerun_binary", lambda: "rerun")
    monkeypatch.setattr(rerun_view, "screenshot", fake_screenshot)
    assert main(["view", str(log), "--save", str(rrd), "--screenshot", str(png)]) == 0, capsys.readouterr().err
    assert seen["rrd"] == rrd and seen["rrd size"] > 0 and seen["png"] != png
    assert png.read_bytes() == b"\x89PNG picture"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["v.png", "v.rrd"]


def test_an_output_reserved_but_never_entered_is_removed_at_exit(tmp_path):
    """An interrupt landing between a temporary file's creation and its `with` block (the
    constructor done, __exit__ never run) leaves nothing at exit, under either name."""
    import subprocess
    import sys

    target = tmp_path / "x.mcap"
    code = ("from gyro_sim.safe_paths import AtomicOutput\n"
            f"out = AtomicOutput({str(target)!r})\n"
            "assert out.tmp.exists()\n"
            "raise KeyboardInterrupt\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert "KeyboardInterrupt" in r.stderr and "AssertionError" not in r.stderr, r.stderr
    assert list(tmp_path.iterdir()) == []


class _SignalledWhileFinalized:
    """An object whose finalizer is running when SIGINT comes: the handler's exception is raised
    inside `__del__`, where Python reports it as unraisable and goes on."""

    def __del__(self):
        signal.raise_signal(signal.SIGINT)  # the handler runs here, in the finalizer


def test_a_signal_that_lands_in_a_finalizer_is_not_lost():
    import time

    from gyro_sim.safe_paths import Interrupted, raise_on_signals

    hook = sys.unraisablehook
    end = None
    with pytest.raises(Interrupted):
        with raise_on_signals():
            _SignalledWhileFinalized()  # dropped at once: its finalizer runs now
            end = time.monotonic() + 5.0
            while time.monotonic() < end:  # the work goes on: the interrupt must reach it
                time.sleep(0.001)
    assert time.monotonic() < end, "the interrupt swallowed by the finalizer was lost"
    assert sys.unraisablehook is hook
