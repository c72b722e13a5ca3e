"""Recording faults, measured from outside the node as a user would meet them: the writer
process killed, stopped, or out of space; two nodes on one path; a path where nothing can be
created; SIGKILL of the node alone and of node and writer; the record counts printed.

Every log is read back by an independent reader (mcap's, or rosbags'); a log cut short by
gyro_sim.log.recover.
"""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("rclpy", reason="the ROS 2 node needs rclpy (pip install '.[ros]')")

from diagnostic_msgs.msg import DiagnosticArray

from .helpers import (
    DISCOVERY_TIMEOUT, ROOT, Client, NodeProcess, children, diag_values, new_domain_id, node_command, ros_env,
    rss_mb, running, wait_for, writer_of,
)

#: the light configuration of the other node tests
LIGHT = ("scene:=hinge_chain", "physics_rate:=250.0", "publish_rate:=50.0")
#: how soon a fault must be acted on (s): generous against a loaded machine, far below what
#: "never" would take (wall time on purpose: the node reacts to a real process's death)
PROMPT = 10.0
#: "at once" for a signal during the start-up (s). Wall time on purpose: what is checked is that
#: the process does not wait for what it was doing (a numba compile of minutes, a writer that
#: never answers), which only a real process and a real clock show; 2 s is far from both
AT_ONCE = 2.0
#: the stall of the writer (s), and when the node's memory is first sampled in it (s)
STALL = 60.0
STALL_SETTLED = 10.0
#: the bound on the node's resident memory growth over the stall once settled (MB)
STALL_GROWTH_MB = 8.0
LOG_WRITTEN = re.compile(r"log written: (\S+) \((\d+) records(?:; (\d+) records of (\d+) publications dropped)?")


def summary_count(path) -> int | None:
    """Message count from the log's summary (mcap's reader); None without a summary."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        try:
            summary = make_reader(f).get_summary()
        except Exception:  # noqa: BLE001 - cut short: no summary
            return None
    return None if summary is None else summary.statistics.message_count


def read_all(path) -> list[tuple[str, int, bytes]]:
    """(topic, log time, bytes) of every message, in file order (mcap's reader, CRCs checked)."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return [(ch.topic, m.log_time, bytes(m.data))
                for _, ch, m in make_reader(f, validate_crcs=True).iter_messages(log_time_order=False)]


def started(node: NodeProcess, log: Path | str) -> Path:
    """Wait until the run is on and records reach the file (it grows past its start); `log` may
    be a glob pattern (the .partial file of overwrite). Returns the file."""
    wait_for(lambda: "physics thread:" in node.stderr or not node.alive(), 120.0, "the physics thread")
    assert node.alive(), node.stderr[-3000:]
    if isinstance(log, str):
        log = next(Path("/").glob(log.lstrip("/")))
    size = log.stat().st_size
    wait_for(lambda: log.stat().st_size > size or not node.alive(), 30.0, "records in the file")
    assert node.alive(), node.stderr[-3000:]
    return log


def incomplete_line(node: NodeProcess, path: Path) -> str:
    """The node's one line about an incomplete log (and nothing saying it was written)."""
    lines = [line for line in node.stderr.splitlines() if "log incomplete:" in line]
    assert len(lines) == 1, node.stderr[-3000:]
    assert f"log incomplete: {path}" in lines[0] and f"gyro-sim recover {path}" in lines[0]
    assert "log written" not in node.stdout and "Traceback" not in node.stderr, (node.stdout, node.stderr)
    return lines[0]


def recovered(path: Path, tmp: Path) -> int:
    """Messages gyro-sim recover gets back from a log cut short."""
    from gyro_sim.log.recover import recover

    return recover(path, tmp / "fixed.mcap", overwrite=True).messages


# --- the writer dies --------------------------------------------------------------------------------
@pytest.mark.slow
def test_a_killed_writer_stops_the_run_at_once_and_says_so(tmp_path):
    log = tmp_path / "live.mcap"
    domain = new_domain_id()
    client = Client(domain)
    diags = client.subscribe("/diagnostics", DiagnosticArray, depth=1000)
    node = NodeProcess(tmp_path, domain, *LIGHT, f"record:={log}")
    try:
        started(node, log)
        wait_for(lambda: diags, DISCOVERY_TIMEOUT, "a first /diagnostics")
        writer = writer_of(node)
        os.kill(writer, signal.SIGKILL)
        t0 = time.monotonic()
        rc = node.proc.wait(PROMPT)  # the run stops by itself
        took = time.monotonic() - t0
        wait_for(lambda: any(diag_values(m).get("record", "").startswith("failed:") for _, m in client.messages(
            "/diagnostics")), 5.0, "the record key saying the failure")
    finally:
        client.close()
        node.stop(signal.SIGKILL)
    assert rc == 1 and took < PROMPT, (rc, took, node.stderr[-3000:])
    said = [line for line in node.stderr.splitlines() if "recording failed:" in line]
    assert len(said) == 1 and "killed by SIGKILL" in said[0], node.stderr[-3000:]
    incomplete_line(node, log)
    assert summary_count(log) is None  # not finished: no summary ...
    assert recovered(log, tmp_path) > 0  # ... and what was written is read back


# --- the writer stops (SIGSTOP) ---------------------------------------------------------------------
@pytest.mark.slow
def test_a_stalled_writer_costs_bounded_memory_and_the_drops_are_counted(tmp_path):
    """The writer stopped for 60 s while the node publishes 1000 times a second: the node's
    resident memory stays bounded (the oldest publications dropped beyond record_queue_mb);
    resumed, the log is complete and readable, and exactly the publications counted as dropped
    are missing from it (gaps in the 1 ms sequence of /joint_states)."""
    log, stats = tmp_path / "stall.mcap", tmp_path / "stats.json"
    node = NodeProcess(tmp_path, new_domain_id(), "scene:=hinge_chain", "physics_rate:=1000.0",
                       "publish_rate:=1000.0", "record_queue_mb:=1.0", f"record:={log}", f"stats_file:={stats}")
    try:
        started(node, log)
        writer = writer_of(node)
        os.kill(writer, signal.SIGSTOP)
        t0 = time.monotonic()
        samples = []  # (s since the stop, MB)
        while time.monotonic() - t0 < STALL:
            assert node.alive(), node.stderr[-3000:]
            samples.append((time.monotonic() - t0, rss_mb(node.proc.pid)))
            time.sleep(1.0)  # a sampling period, not a wait for an event
        os.kill(writer, signal.SIGCONT)
        wait_for(lambda: "log writer caught up" in node.stderr or not node.alive(), 60.0, "the writer catching up")
        rc = node.stop(signal.SIGINT, timeout=60.0)
    finally:
        node.stop(signal.SIGKILL)
    assert rc == 0, node.stderr[-3000:]
    settled = [mb for t, mb in samples if t >= STALL_SETTLED]
    assert max(settled) - settled[0] < STALL_GROWTH_MB, samples
    st = json.loads(stats.read_text())
    m = LOG_WRITTEN.search(node.stdout)
    assert m and m.group(1) == str(log), node.stdout
    count, dropped_records, dropped_pubs = int(m.group(2)), int(m.group(3)), int(m.group(4))
    # what the stall would have cost without the bound: the publications dropped, at the size they have in the log
    msgs = read_all(log)
    js = sorted(t for topic, t, _ in msgs if topic == "/joint_states")
    per_publication = sum(len(d) for topic, _, d in msgs if topic != "/robot_description") / len(js)
    assert dropped_pubs * per_publication > 5 * STALL_GROWTH_MB * 2**20, (dropped_pubs, per_publication)
    # printed = read back = the summary's; handed over = written + dropped
    assert count == len(msgs) == summary_count(log) == st["records_in_file"]
    assert st["records_dropped"] == dropped_records and st["publications_dropped"] == dropped_pubs
    assert st["records_handed"] == count - 1 + dropped_records  # the writer's own /robot_description
    # exactly the publications dropped are missing: one /joint_states every 1 ms from 0 to the last
    step = 1_000_000
    assert js[0] == 0 and all((t - js[0]) % step == 0 for t in js)
    expected = (js[-1] - js[0]) // step + 1
    assert expected - len(js) == dropped_pubs == st["publications"] - len(js)
    # the log says where the dropping started and stopped, and its last diagnostics count them
    events = [d for topic, _, d in msgs if topic == "/gyro_sim/events"]
    assert any(b"log writer behind" in e for e in events) and any(b"log writer caught up" in e for e in events)
    from rosbags.highlevel import AnyReader

    with AnyReader([log]) as reader:
        conns = [c for c in reader.connections if c.topic == "/diagnostics"]
        last = None
        for conn, _, raw in reader.messages(connections=conns):
            last = reader.deserialize(raw, conn.msgtype)
    values = {kv.key: kv.value for s in last.status for kv in s.values}
    assert int(values["records_dropped"]) == dropped_records
    # resumed, the writer catches up (the event above); at 1000 publications a second into a 1 MB
    # queue it may fall behind again before the end on a busy machine: either state, never failed
    assert values["record"] == "recording" or values["record"].startswith("behind"), values["record"]


# --- no space left ----------------------------------------------------------------------------------
@pytest.fixture
def small_tmpfs(tmp_path):
    """A 300 kB tmpfs: a recording fills it in seconds."""
    mnt = tmp_path / "small"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=300k", "tmpfs", str(mnt)], capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"a tmpfs cannot be mounted here (root and mount rights needed): {r.stderr.strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


def _stops_with_one_line(node: NodeProcess, log: Path, tmp: Path, cause: str) -> None:
    rc = node.proc.wait(120.0)  # the run (duration 120 s) stops long before: the device fills in seconds
    assert rc == 1, (rc, node.stderr[-3000:])
    said = [line for line in node.stderr.splitlines() if "recording failed:" in line]
    assert len(said) == 1 and cause in said[0].lower(), node.stderr[-3000:]
    incomplete_line(node, log)
    assert recovered(log, tmp) > 0


@pytest.mark.slow
def test_a_full_device_stops_the_run_with_one_line_and_a_recoverable_log(tmp_path, small_tmpfs):
    log = small_tmpfs / "full.mcap"
    node = NodeProcess(tmp_path, new_domain_id(), *LIGHT, "duration:=120.0", f"record:={log}")
    try:
        _stops_with_one_line(node, log, tmp_path, "no space left")
    finally:
        node.stop(signal.SIGKILL)


@pytest.mark.slow
def test_a_file_size_limit_of_the_writer_is_the_same_fault(tmp_path):
    import resource

    log = tmp_path / "limited.mcap"
    node = NodeProcess(tmp_path, new_domain_id(), *LIGHT, "duration:=120.0", f"record:={log}")
    try:
        started(node, log)
        limit = log.stat().st_size + 100_000
        resource.prlimit(writer_of(node), resource.RLIMIT_FSIZE, (limit, limit))
        _stops_with_one_line(node, log, tmp_path, "file too large")
    finally:
        node.stop(signal.SIGKILL)


# --- paths ------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_two_nodes_on_one_path_one_runs_the_other_is_refused_in_one_line(tmp_path):
    log = tmp_path / "shared.mcap"
    procs = [subprocess.Popen(node_command(*LIGHT, "duration:=1.0", f"record:={log}"), cwd=ROOT,
                              env=ros_env(new_domain_id(), tmp_path), text=True, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE) for _ in range(2)]
    results = [(p.wait(120), *p.communicate()) for p in procs]
    codes = sorted(r[0] for r in results)
    assert codes == [0, 2], results
    _, out, _ = next(r for r in results if r[0] == 0)
    _, _, err = next(r for r in results if r[0] == 2)
    said = [line for line in err.splitlines() if line.startswith("gyro_sim_node:")]
    assert len(said) == 1 and f"record: {log}: exists" in said[0] and "Traceback" not in err, err
    assert int(LOG_WRITTEN.search(out).group(2)) == summary_count(log) == len(read_all(log))


@pytest.mark.slow
def test_two_nodes_overwriting_one_path_leave_one_complete_log(tmp_path):
    log = tmp_path / "shared.mcap"
    log.write_bytes(b"an older file")
    procs = [subprocess.Popen(node_command(*LIGHT, f"duration:={d}", f"record:={log}", "overwrite:=true"), cwd=ROOT,
                              env=ros_env(new_domain_id(), tmp_path), text=True, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE) for d in (1.0, 1.5)]
    results = [(p.wait(120), *p.communicate()) for p in procs]
    assert [r[0] for r in results] == [0, 0], results
    printed = {int(LOG_WRITTEN.search(out).group(2)) for _, out, _ in results}
    assert len(printed) == 2  # two runs of different lengths
    assert summary_count(log) == len(read_all(log)) in printed  # one whole log, the last renamed
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("shared")) == ["shared.mcap"]


@pytest.mark.slow
def test_a_record_path_where_no_file_can_be_created_is_refused_before_the_run(tmp_path):
    r = subprocess.run(node_command(*LIGHT, "duration:=1.0", "record:=/proc/x.mcap"), cwd=ROOT,
                       env=ros_env(new_domain_id(), tmp_path), text=True, capture_output=True, timeout=120)
    said = [line for line in r.stderr.splitlines() if line.startswith("gyro_sim_node:")]
    assert r.returncode == 2 and len(said) == 1 and "record: /proc/x.mcap: cannot create it" in said[0], r.stderr
    assert "Traceback" not in r.stderr and "scene '" not in r.stderr and "simulated" not in r.stdout


# --- SIGKILL ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("overwrite", [False, True], ids=["new", "overwrite"])
@pytest.mark.slow
def test_sigkill_of_the_node_alone_leaves_a_complete_log(tmp_path, overwrite):
    """The writer outlives the node: it sees the end of its input, finishes the log (summary and
    index) and, with overwrite, renames it onto the record path."""
    log = tmp_path / "killed.mcap"
    if overwrite:
        log.write_bytes(b"an older file")
    node = NodeProcess(tmp_path, new_domain_id(), *LIGHT, f"record:={log}", f"overwrite:={str(overwrite).lower()}")
    try:
        written = started(node, log if not overwrite else f"{tmp_path}/killed.mcap.*.partial")
        assert written.name.endswith(".partial") == overwrite
        writer = writer_of(node)
        node.proc.send_signal(signal.SIGKILL)
        node.proc.wait(PROMPT)
        wait_for(lambda: not running(writer), 60.0, "the writer to finish")
    finally:
        node.stop(signal.SIGKILL)
    n = summary_count(log)
    assert n is not None and n == len(read_all(log)) and n > 1, n
    assert not list(tmp_path.glob("killed.mcap.*"))


@pytest.mark.slow
def test_sigkill_of_node_and_writer_leaves_a_file_without_summary_that_recover_reads(tmp_path):
    log = tmp_path / "both.mcap"
    node = NodeProcess(tmp_path, new_domain_id(), *LIGHT, f"record:={log}", new_session=True)
    try:
        started(node, log)
        writer_of(node)
        os.killpg(node.proc.pid, signal.SIGKILL)  # the node and its writer at once
        node.proc.wait(PROMPT)
    finally:
        node.stop(signal.SIGKILL)
    assert summary_count(log) is None
    assert recovered(log, tmp_path) > 0


# --- start-up ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("signals", [(signal.SIGTERM,), (signal.SIGINT,), (signal.SIGTERM, signal.SIGTERM)],
                         ids=["SIGTERM", "SIGINT", "two SIGTERMs"])
@pytest.mark.slow
def test_a_signal_during_the_first_compile_ends_the_start_at_once(tmp_path, signals):
    """The numba compile (an empty cache: NUMBA_CACHE_DIR) takes minutes: a signal during it ends
    the process within 2 s, exit 0, one line, nothing left behind."""
    log = tmp_path / "never.mcap"
    cache = tmp_path / "numba_cache"
    cache.mkdir()
    node = NodeProcess(tmp_path, new_domain_id(), *LIGHT, f"record:={log}",
                       env={"NUMBA_CACHE_DIR": str(cache), "GYRO_SIM_VERBOSE": "1"})
    try:
        wait_for(lambda: "  compiled " in node.stderr or not node.alive(), 120.0, "the compile under way")
        assert node.alive(), node.stderr
        t0 = time.monotonic()
        for i, sig in enumerate(signals):
            if i:
                time.sleep(0.01)
            try:
                node.proc.send_signal(sig)
            except ProcessLookupError:  # already gone
                pass
        rc = node.proc.wait(PROMPT)
        took = time.monotonic() - t0
    finally:
        node.stop(signal.SIGKILL)
    assert rc == 0 and took < AT_ONCE, (rc, took, node.stderr[-2000:])
    said = [line for line in node.stderr.splitlines() if "during start-up" in line]
    assert said == [f"gyro_sim_node: {signals[0].name} during start-up: not started (nothing recorded)"], node.stderr
    assert "Traceback" not in node.stderr and not log.exists()


_NEVER_ANSWERS = r"""
import subprocess, sys, types
from gyro_sim import load_scene
from gyro_sim.ros import node, recorder

shutdown = node.Shutdown()
real = subprocess.Popen
recorder.subprocess = types.SimpleNamespace(  # a writer that never answers: the start waits on it
    Popen=lambda args, **kw: real(["sleep", "1000"], **kw), PIPE=subprocess.PIPE,
    TimeoutExpired=subprocess.TimeoutExpired)
print("starting", flush=True)
recorder.LiveRecorder(sys.argv[1], scene=load_scene("hinge_chain"), params={})
print("not given up", flush=True)
"""


def test_a_signal_while_the_writer_starts_kills_it_and_removes_the_file(tmp_path):
    """gyro_sim.ros.node's start-up signal handling with a writer that never answers: the
    signal ends the process at once, the writer killed and the file created for it removed."""
    log = tmp_path / "starting.mcap"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.Popen([sys.executable, "-c", _NEVER_ANSWERS, str(log)], env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        assert proc.stdout.readline() == "starting\n"
        wait_for(lambda: log.exists(), 30.0, "the log file")
        writer = wait_for(lambda: next(iter(children(proc.pid)), None), 30.0, "the writer")
        t0 = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=PROMPT)
        took = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0 and took < AT_ONCE, (proc.returncode, took, err)
    assert err.strip() == "gyro_sim_node: SIGTERM during start-up: not started (nothing recorded)" and not out
    assert not log.exists() and not running(writer)


def test_scipy_lapack_under_a_tight_address_space_limit_is_refused_not_a_hang(tmp_path):
    """Loading scipy's LAPACK with ~48 MB of address space left spun forever in OpenBLAS (the
    node hung under prlimit --as): refused with MemoryError at once instead."""
    script = ("import resource, sys\n"
              "from gyro_sim.ros import node\n"
              "size = next(int(l.split()[1]) * 1024 for l in open('/proc/self/status') if l.startswith('VmSize:'))\n"
              "resource.setrlimit(resource.RLIMIT_AS, (size + (48 << 20), resource.RLIM_INFINITY))\n"
              "try:\n"
              "    node.load_lapack()\n"
              "except MemoryError as exc:\n"
              "    print('refused:', exc)\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    r = subprocess.run([sys.executable, "-c", script], env=env, text=True, capture_output=True, timeout=PROMPT)
    assert r.stdout.startswith("refused:") and "scipy's LAPACK needs" in r.stdout, (r.stdout, r.stderr)


@pytest.mark.slow
def test_the_node_under_a_tight_address_space_limit_ends_in_one_line(tmp_path):
    """prlimit --as just above what the node's imports take: it ends at once with one line and
    exit 1 (it died with a traceback, or an abort, or hung in Fast DDS or OpenBLAS)."""
    import resource

    env = ros_env(new_domain_id(), tmp_path)
    probe = ("import gyro_sim.ros.node\n"
             "print(next(int(l.split()[1]) * 1024 for l in open('/proc/self/status') if l.startswith('VmSize:')))")
    size = int(subprocess.run([sys.executable, "-c", probe], cwd=ROOT, env=env, text=True, capture_output=True,
                              timeout=120, check=True).stdout)
    limit = size + (64 << 20)  # room for a thread or two, not for scipy's LAPACK

    def limited():
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))

    log = tmp_path / "limited.mcap"
    r = subprocess.run(node_command(*LIGHT, "duration:=1.0", f"record:={log}"), cwd=ROOT, env=env, text=True,
                       capture_output=True, timeout=120, preexec_fn=limited)
    said = [line for line in r.stderr.splitlines() if line.startswith("gyro_sim_node:")]
    assert r.returncode == 1 and len(said) == 1 and "out of memory" in said[0], r.stderr[-3000:]
    assert "Traceback" not in r.stderr and not log.exists()
