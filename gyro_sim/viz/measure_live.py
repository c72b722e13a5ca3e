"""What attaching `gyro-sim view --live` costs the node, and how far behind the view is.

    python -m gyro_sim.viz.measure_live [--sizes 10 100] [--seconds 10]

For each chain size n (a spherical chain with a rotor on every body, gyro_sim.bench.scenes),
the node runs `seconds` of simulated time twice at real_time_factor 1 (the node's CPU share
and achieved real-time factor from its stats_file) and twice as fast as it can
(real_time_factor 0: the achieved factor is its throughput), each time without and with a
live viewer saving to a temporary .rrd (its CPU share while the node runs, messages drawn,
its lag line). Linux only (/proc). Each
run uses its own ROS_DOMAIN_ID. Prints a Markdown table.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: wall seconds a node may take to start (a cold numba cache compiles) and to end
START_TIMEOUT = 300.0
#: the viewer's start-up (imports, DDS discovery) before the node is started (s)
VIEWER_START = 60.0


def _env(domain: int, tmp: Path) -> dict:
    root = Path(__file__).resolve().parents[2]
    env = dict(os.environ)
    env.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_LOG_DIR=str(tmp / "ros_log"),
               PYTHONPATH=os.pathsep.join([str(root), env.get("PYTHONPATH", "")]).rstrip(os.pathsep))
    return env


def _scene(n: int, tmp: Path) -> Path:
    import yaml

    from gyro_sim.bench.scenes import spherical_chain

    path = tmp / f"chain_{n}.yaml"
    path.write_text(yaml.safe_dump(spherical_chain(n)))
    return path


def _wait_line(path: Path, text: str, proc, timeout: float) -> None:
    end = time.monotonic() + timeout
    while text not in path.read_text():
        if proc.poll() is not None or time.monotonic() > end:
            raise RuntimeError(f"no '{text}' from the viewer:\n{path.read_text()[-2000:]}")
        time.sleep(0.05)


def _cpu(pid: int) -> float:
    """CPU seconds (user + system) of a running process so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def run_once(n: int, seconds: float, rtf: float, viewer: bool, domain: int) -> dict:
    """One node run; its stats and, with a viewer, the viewer's CPU and lag."""
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        (tmp / "ros_log").mkdir()
        env = _env(domain, tmp)
        scene = _scene(n, tmp)
        stats = tmp / "stats.json"
        live = None
        if viewer:  # the node publishes its description: the viewer waits for it
            err = tmp / "live.err"
            live = subprocess.Popen([sys.executable, "-m", "gyro_sim.cli", "view", "--live",
                                     "--save", str(tmp / "l.rrd")],
                                    env=env, stdout=subprocess.DEVNULL, stderr=open(err, "w"))
            _wait_line(err, "waiting for", live, VIEWER_START)
        cpu0, t0 = (_cpu(live.pid), time.monotonic()) if live is not None else (0.0, 0.0)
        node = subprocess.Popen([sys.executable, "-m", "gyro_sim.ros.node", "--ros-args", "-p", f"scene:={scene}",
                                 "-p", f"duration:={seconds}", "-p", f"real_time_factor:={rtf}",
                                 "-p", f"stats_file:={stats}"], env=env,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            node.wait(START_TIMEOUT + 20 * seconds)
        finally:
            if node.poll() is None:
                node.kill()
        share = (_cpu(live.pid) - cpu0) / (time.monotonic() - t0) if live is not None else None
        out = json.loads(stats.read_text())
        row = {"n": n, "rtf_target": rtf, "viewer": viewer, "rtf": out["real_time_factor_achieved"],
               "node_cpu_share": out["cpu_share"]}
        if live is not None:
            live.send_signal(signal.SIGINT)
            live.wait(60)
            text = err.read_text()
            m = re.search(r"(\d+) messages drawn .*?; (lag: .*)", text)
            row.update(viewer_cpu_share=share, viewer_exit=live.returncode,
                       drawn=int(m.group(1)) if m else None, lag=m.group(2) if m else text[-300:])
        return row




def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m gyro_sim.viz.measure_live", description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10, 100])
    ap.add_argument("--seconds", type=float, default=10.0, help="simulated seconds per run")
    ap.add_argument("--rtf", type=float, nargs="+", default=[1.0, 0.0],
                    help="the node's real_time_factor values (0: as fast as possible)")
    args = ap.parse_args(argv)
    domain = 150 + os.getpid() % 40
    print("| n | real_time_factor | viewer | achieved RTF | node CPU share | viewer CPU share | drawn | lag |")
    print("|---|---|---|---|---|---|---|---|")
    for n in args.sizes:
        for rtf in args.rtf:
            for viewer in (False, True):
                r = run_once(n, args.seconds, rtf, viewer, domain)
                viewer_cpu = f"{r['viewer_cpu_share']:.2f}" if viewer else ""
                print(f"| {n} | {'max' if rtf == 0 else f'{rtf:g}'} | {'yes' if viewer else 'no'} | {r['rtf']:.2f} | "
                      f"{r['node_cpu_share']:.2f} | {viewer_cpu} | {r.get('drawn', '')} | {r.get('lag', '')} |",
                      flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
