"""`gyro-sim bench realtime`: the node at physics 1 kHz / publish 100 Hz, real-time factor 1.

For each chain length n (spherical chains of gyro_sim.bench.scenes without gravity, RK4) the
node runs in its
own process and ROS domain, without and with recording, for a bounded simulated time, and
writes its timing statistics (`stats_file`). Reported per run:

- step time p50 / p99: wall time of one physics step (RK4, 4 dynamics evaluations);
- publication jitter p50 / p99: |interval between two publications - 10 ms|, publisher side;
- CPU share: CPU seconds of the node process (all threads) per wall second (1.0 = one core);
- achieved real-time factor (simulated / wall time) and deadline misses;
- with recording: records written, the writer process's CPU and the node's sender thread's;
- how many misses came after the physics thread had waited, ready to run, more than a physics
  period for a CPU (the OS gave the CPUs to other threads or processes), its whole wait for a
  CPU over the run (Linux schedstat), and the CPU time the hypervisor took from this virtual
  machine meanwhile (steal, all CPUs; 10 ms ticks);
- the physics thread's scheduling: SCHED_FIFO at the node's `thread_priority` where the
  system allows it, else 0 (normal); `--thread-priority 0 50` runs both, for the comparison;
- the floor: a thread of the bench process (`pacing.Floor`) that only sleeps to the same
  wake-up deadlines (2 ms, a miss beyond 1 ms, the same scheduling) while the node runs,
  its misses scaled to the node's wall time: what the machine itself misses (host steal,
  timer latency), without the node's work or interpreter lock;
- the longest garbage-collector pause (any thread: it holds the interpreter lock) and the
  machine's 1-minute load average at the start and end of the run (other processes included).

Nobody subscribes in these runs, so without recording the node computes joint states only;
with recording it also computes wrenches and poses (everything published is recorded).

`--violent` adds the violent step, `--violent-family` the violent family instead: step moments
of `gyro_sim.bench.extreme.abrupt_commands` (1e2, 1e3 and 1e4 x each axis's gravity torque) on
the hinge chain and free_chain_rotors, held for 0.5 s or 1.5 s of simulated time (one command,
ended by the node's command_timeout in simulated time, so every run puts in the same energy) or
sent again every publication period for 1.5 s, as a controller gone wrong would send it (the
violent step: 1e3 x on the hinge chain held for 0.5 s). For each case:

- counted, deterministically (:func:`violent_counts`, no node): the right-hand-side evaluations
  and substeps per simulated second that "fixed" spends, during the push and after it, against
  its real-time budget (`gyro_sim.integrators.fixed.EVAL_BUDGET` a physics step), the most in
  one call, the energy put in, the energy balance, and the drift it reported over budget;
- measured (:func:`run_violent_node`): the node with "fixed" on the case's scene, given the
  command by this process, which counts the /joint_states it receives from then on (their rate
  and longest gap, wall time), with the node's achieved real-time factor and step times.
"""
from __future__ import annotations

import itertools
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from gyro_sim.ros.pacing import Floor, chunk_steps

DEFAULT_SIZES = (2, 10, 20, 50, 100)
QUICK_SIZES = (2,)
PHYSICS_RATE = 1000.0
PUBLISH_RATE = 100.0
DEFAULT_SECONDS = 10.0
QUICK_SECONDS = 2.0
#: achieved real-time factor that counts as holding real time
HOLDS = 0.99
#: the chains swing free in space (started turning, as spherical_chain): under gravity the
#: 100-link chain falls, whips, and RK4 at the node's 1 ms diverges at t = 5.2 s; in space it
#: stays regular for 60 s and more (energy drift 7e-6 J in 60 s). The cost per step is the same.
GRAVITY = False
#: the physics thread's SCHED_FIFO priority asked for (the node's default thread_priority)
DEFAULT_PRIORITY = 50


@dataclass
class Run:
    n: int
    record: bool
    stats: dict
    priority: int = DEFAULT_PRIORITY

    def get(self, key: str, default=float("nan")):
        v = self.stats.get(key)
        return default if v is None else v

    @property
    def holds(self) -> bool:
        return self.get("real_time_factor_achieved", 0.0) >= HOLDS


def _domain(i: int) -> int:
    """200..229: apart from the tests' domains (50..199), so a bench and the tests can share a machine."""
    return 200 + (os.getpid() * 13 + i) % 30


#: how the node is started (another command, e.g. an installed `gyro_sim_node`, can be given)
NODE_COMMAND = (sys.executable, "-m", "gyro_sim.ros.node")


def run_node(n: int, record: bool, seconds: float, workdir: Path, index: int = 0, node_command=NODE_COMMAND,
             backend: str = "auto", priority: int = DEFAULT_PRIORITY, branching: int = 1) -> Run:
    """One node run on spherical_chain(n), hung as a tree of `branching` children a body
    (`gyro_sim.bench.scenes.tree_of_links`; 1: the chain); its statistics."""
    import yaml

    from gyro_sim.bench.scenes import tree_of_links

    scene = workdir / (f"chain_{n}.yaml" if branching == 1 else f"tree_{n}_{branching}.yaml")
    scene.write_text(yaml.safe_dump(tree_of_links(n, branching, gravity=GRAVITY), sort_keys=False))
    stats = workdir / f"stats_{n}_{int(record)}_{priority}.json"
    params = [f"scene:={scene}", f"physics_rate:={PHYSICS_RATE}", f"publish_rate:={PUBLISH_RATE}",
              "real_time_factor:=1.0", "integrator:=rk4", f"backend:={backend}", f"duration:={seconds}",
              f"stats_file:={stats}", f"thread_priority:={priority}"]
    if record:
        params.append(f"record:={workdir / f'chain_{n}_{priority}.mcap'}")
    cmd = [*node_command, "--ros-args"]
    for p in params:
        cmd += ["-p", p]
    env = dict(os.environ, ROS_DOMAIN_ID=str(_domain(index)), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               ROS_LOG_DIR=str(workdir / "ros_log"), OPENBLAS_NUM_THREADS="1")
    root = str(Path(__file__).resolve().parents[2])
    env["PYTHONPATH"] = os.pathsep.join([root, env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    load0 = os.getloadavg()[0]
    floor = Floor(2.0 / PHYSICS_RATE, 1.0 / PHYSICS_RATE, priority).start()  # the machine's own misses
    floor_t0 = time.monotonic()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        out, err = proc.communicate(timeout=3 * seconds + 20)  # an overloaded run is cut short
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
    finally:
        floor_misses, floor_wall = floor.stop(), time.monotonic() - floor_t0
    if proc.returncode != 0 or not stats.exists():
        raise RuntimeError(f"gyro_sim_node failed (n = {n}, record = {record}, exit {proc.returncode}):\n{err[-2000:]}")
    # the machine's 1-minute load average when the run started and ended (the node included)
    st = json.loads(stats.read_text())
    # the floor ran from before the node's start-up to its exit: its misses scaled to the run's wall time
    st.update(load_start=load0, load_end=os.getloadavg()[0], floor_misses=floor_misses, floor_wall_s=floor_wall,
              floor_priority=floor.got_priority,
              floor_misses_scaled=floor_misses * st.get("wall_s", 0.0) / floor_wall if floor_wall > 0 else float("nan"))
    return Run(n, record, st, priority)


# --- the violent family ----------------------------------------------------------------------
#: a violent command starts at this simulated time, after one publication period at rest
VIOLENT_AT = 0.01
#: the family: step moments of these multiples of each axis's gravity torque
#: (`gyro_sim.bench.extreme.abrupt_commands`) ...
VIOLENT_FACTORS = (1e2, 1e3, 1e4)
#: ... held for these simulated seconds (one command, ended by the node's command_timeout in
#: simulated time, so every run puts in the same energy) ...
VIOLENT_PUSHES = (0.5, 1.5)
#: ... and, as a controller gone wrong sends it, the same command again every publication
#: period for this long (the node's command_timeout then ends it REPEAT_TIMEOUT after the last)
VIOLENT_REPEATED = 1.5
REPEAT_TIMEOUT = 0.05
#: the scenes: every shipped chain whose actuated axes no max_torque saturates
VIOLENT_SCENES = ("hinge_chain", "free_chain_rotors")
#: the push of the single violent step (`--violent` without the family: 1e3 x for VIOLENT_PUSH)
VIOLENT_PUSH = 0.5
#: simulated seconds counted after the push
VIOLENT_AFTER = 1.0
#: the publication period (s): a repeated command comes again this often
VIOLENT_PERIOD = 1.0 / PUBLISH_RATE
#: the node's calls (s): as many physics steps as it takes a wake-up (`pacing.chunk_steps`: 2 ms)
VIOLENT_CALL = chunk_steps(round(PHYSICS_RATE / PUBLISH_RATE), 1.0 / PHYSICS_RATE, 1.0) / PHYSICS_RATE
#: simulated seconds of a node run with a violent command
VIOLENT_SECONDS = 5.0
#: the command is sent again when the node's diagnostics (every 0.1 s simulated) still say it has
#: taken none this many wall seconds after it was sent
RESEND_AFTER = 0.3


@dataclass(frozen=True)
class ViolentCase:
    """One case of the family: a scene, the step moments' multiple of its gravity torques, how
    long (simulated s) they last, and whether they come as one command or again every
    publication period."""

    scene: str = "hinge_chain"
    factor: float = 1e3
    push: float = VIOLENT_PUSH
    repeated: bool = False

    @property
    def label(self) -> str:
        how = f"sent at {PUBLISH_RATE:g} Hz for" if self.repeated else "held"
        return f"{self.scene}, {self.factor:.0e} x gravity torque {how} {self.push:g} s"


def violent_family(scenes=VIOLENT_SCENES, factors=VIOLENT_FACTORS) -> list[ViolentCase]:
    """Every case: per scene and factor, the command held for each of VIOLENT_PUSHES, then sent
    at the publish rate for VIOLENT_REPEATED."""
    return [ViolentCase(sc, f, p, r) for sc in scenes for f in factors
            for p, r in [*((p, False) for p in VIOLENT_PUSHES), (VIOLENT_REPEATED, True)]]


def violent_counts(case: ViolentCase | None = None, after: float = VIOLENT_AFTER) -> dict:
    """A violent case offline, as the node steps it ("fixed" advanced 1 / PHYSICS_RATE at a
    time, VIOLENT_CALL's worth a wake-up, the command set at the wake-up it takes effect,
    again at every wake-up when repeated): the counts per simulated second of the whole run, of the push and
    after it, deterministic: they depend on the simulated states only. A simulation error ends
    the run and is reported (`error`)."""
    import numpy as np

    from gyro_sim.bench import extreme as ex
    from gyro_sim.integrators import fixed
    from gyro_sim.simulator import Simulator, SimulationError

    case = case or ViolentCase()
    scene, moments = ex.abrupt_commands(case.factor, case.scene)
    sim = Simulator(scene, integrator="fixed", step=1.0 / PHYSICS_RATE)
    g = sim.integrator
    e0 = sim.invariants()["energy"]
    dt = 1.0 / PHYSICS_RATE
    steps = round(VIOLENT_CALL / dt)
    n_calls = round((VIOLENT_AT + case.push + after) / VIOLENT_CALL)
    on, off = round(VIOLENT_AT / VIOLENT_CALL), round((VIOLENT_AT + case.push) / VIOLENT_CALL)
    marks, methods, worst, error = {}, set(), 0, None
    for i in range(n_calls):
        if i == on or (case.repeated and on < i < off):
            sim.set_axis_moments(moments)
        elif i == off:
            sim.set_axis_moments(np.zeros(len(moments)))
        if i in (on, off):
            marks[i] = (g.nfev, g.nsteps)
        before = g.nfev
        try:
            for _ in range(steps):  # the node's physics steps of one wake-up (gyro_sim.ros.loop.SimLoop._chunk)
                sim.advance(dt)
        except SimulationError as exc:
            error = str(exc)
            break
        worst = max(worst, g.nfev - before)
        if i >= off:
            methods.add(g._label())
    span = sim.time - VIOLENT_AT
    marks.setdefault(off, (g.nfev, g.nsteps))
    end = (g.nfev, g.nsteps)
    snap = sim.snapshot(bodies=False, wrenches=False)
    inv = sim.invariants()
    balance = None if snap.energy_balance is None else snap.energy_balance / inv["energy"]
    return {
        "case": case.label, "scene": case.scene, "factor": case.factor, "push_s": case.push,
        "repeated": case.repeated, "after_s": after, "moments_Nm": [float(m) for m in moments],
        "budget_per_s": fixed.EVAL_BUDGET * PHYSICS_RATE,
        "evaluations_per_s": (end[0] - marks[on][0]) / span, "substeps_per_s": (end[1] - marks[on][1]) / span,
        "evaluations_per_s_push": (marks[off][0] - marks[on][0]) / case.push,
        "evaluations_per_s_after": (end[0] - marks[off][0]) / after,
        "substeps_per_s_push": (marks[off][1] - marks[on][1]) / case.push,
        "substeps_per_s_after": (end[1] - marks[off][1]) / after,
        "most_evaluations_in_a_call": worst, "simulated_s": sim.time,
        "energy_put_in_J": snap.work, "energy_J": inv["energy"], "energy_start_J": e0,
        "energy_balance_relative": balance,
        "over_budget_calls": g.budget_calls, "over_budget_energy_error": g.budget_energy_error,
        "methods_after": sorted(methods), "finite": bool(np.isfinite(sim.state).all()), "error": error,
    }


def _g(x, fmt: str = ".2g") -> str:
    return "-" if x is None else format(x, fmt)


def violent_table(counts: list[dict], nodes: list[dict | None] | None = None) -> str:
    """The counts of :func:`violent_counts` (and the node's runs, where measured) as Markdown."""
    nodes = nodes or [None] * len(counts)
    lines = [
        f"The violent family: step moments of a multiple of each axis's gravity torque, from t = {VIOLENT_AT:g} s, "
        f"held (one command) or sent again every {1e3 * VIOLENT_PERIOD:g} ms; \"fixed\" at {PHYSICS_RATE:g} Hz, "
        f"a call a step and {1e3 * VIOLENT_CALL:g} ms a wake-up, counted over the push and {VIOLENT_AFTER:g} s "
        f"after it; budget {counts[0]['budget_per_s']:,.0f} rhs evaluations per simulated s.",
        "",
        "| case | rhs evaluations / simulated s (push; after) | substeps / simulated s | most in a wake-up "
        "| energy put in (J) | (E - E0 - W) / E | calls kept over budget (their energy error) | methods after "
        "| /joint_states | RTF | step p50 / p99 (us) | longest gap (ms) |",
        "|---|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|",
    ]
    for c, v in zip(counts, nodes):
        if c["error"]:
            row = f"| {c['case']} | simulation error at t = {c['simulated_s']:.2f} s: {c['error'][:80]} | | | | | | "
        else:
            row = (f"| {c['case']} | {c['evaluations_per_s']:,.0f} ({c['evaluations_per_s_push']:,.0f}; "
                   f"{c['evaluations_per_s_after']:,.0f}) | {c['substeps_per_s']:,.0f} "
                   f"| {c['most_evaluations_in_a_call']:,} | {c['energy_put_in_J']:.3g} "
                   f"| {_g(c['energy_balance_relative'])} | {c['over_budget_calls']} "
                   f"({c['over_budget_energy_error']:.2g}) | {', '.join(c['methods_after'])} ")
        if v is None:
            row += "| | | | |"
        elif "failed" in v:
            row += f"| node failed: {v['failed'][:80]} | | | |"
        else:
            row += (f"| {v['rate_Hz']:.1f} Hz | {v.get('real_time_factor_achieved', float('nan')):.3f} "
                    f"| {v.get('step_time_p50_us', float('nan')):.0f} / {v.get('step_time_p99_us', float('nan')):.0f} "
                    f"| {1e3 * v['longest_gap_s']:.0f} |")
        lines.append(row)
    return "\n".join(lines)


def run_violent_node(workdir: Path, seconds: float = VIOLENT_SECONDS, case: ViolentCase | None = None, index: int = 0,
                     node_command=NODE_COMMAND, priority: int = DEFAULT_PRIORITY, record: Path | None = None) -> dict:
    """The node on the case's scene with "fixed", given the case's command by this process as
    soon as its first /joint_states arrives: held, once (command_timeout = the push: the node
    ends it after the push in simulated time), or repeated at the publish rate (wall time)
    until the node has published the push's worth of /joint_states (command_timeout
    REPEAT_TIMEOUT). The /joint_states received from the command on: count, rate, longest gap
    (wall time), with the node's own statistics. `record`: the node's log there."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from gyro_sim.bench import extreme as ex
    from gyro_sim.msgs.messages import DIAGNOSTICS, JOINT_STATES, RUN_STATUS
    from gyro_sim.ros.commands import command_topic
    from gyro_sim.ros.discovery import announce_often

    case = case or ViolentCase()
    _, moments = ex.abrupt_commands(case.factor, case.scene)
    stats = workdir / f"stats_violent_{index}.json"
    domain = _domain(index)
    timeout = REPEAT_TIMEOUT if case.repeated else case.push
    params = [f"scene:={case.scene}", f"physics_rate:={PHYSICS_RATE}", f"publish_rate:={PUBLISH_RATE}",
              "real_time_factor:=1.0", "integrator:=fixed", f"duration:={seconds}", f"command_timeout:={timeout}",
              f"stats_file:={stats}", f"thread_priority:={priority}",
              # the node's time starts with the command: a command lost before the subscription
              # matched, and sent again, finds the scene where the case starts, however loaded
              "hold:=until_command"]
    if record is not None:
        params.append(f"record:={record}")
    cmd = [*node_command, "--ros-args"]
    for p in params:
        cmd += ["-p", p]
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               ROS_LOG_DIR=str(workdir / "ros_log"), OPENBLAS_NUM_THREADS="1")
    root = str(Path(__file__).resolve().parents[2])
    env["PYTHONPATH"] = os.pathsep.join([root, env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    arrivals: list[float] = []
    sent: list[float] = []
    accepted: list[tuple[float, int]] = []  # (arrival, the node's count of accepted commands) from /diagnostics
    pushes = round(case.push / VIOLENT_PERIOD)  # publications while a repeated command lasts

    def on_diagnostics(msg) -> None:
        for status in msg.status:
            if status.name.endswith(RUN_STATUS):
                accepted.extend((time.monotonic(), int(float(kv.value))) for kv in status.values
                                if kv.key == "commands_accepted")

    announce_often()
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
    proc = None
    log = workdir / f"violent_{index}.log"  # a file, not a pipe nobody reads while the node runs
    try:
        node = rclpy.create_node("gyro_sim_bench_violent", context=context)
        pub = node.create_publisher(Float64MultiArray, command_topic("/"), 10)
        node.create_subscription(JointState, JOINT_STATES, lambda msg: arrivals.append(time.monotonic()), 100)
        node.create_subscription(DiagnosticArray, DIAGNOSTICS, on_diagnostics, 10)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        with open(log, "w") as out:
            proc = subprocess.Popen(cmd, env=env, stdout=out, stderr=subprocess.STDOUT)
        end = time.monotonic() + 3 * seconds + 60
        while proc.poll() is None and time.monotonic() < end:
            executor.spin_once(timeout_sec=0.002 if case.repeated else 0.005)
            # once it publishes and its command subscription has matched this publisher; again
            # while its diagnostics say it has taken none (a command sent before the node's
            # side of the match is lost: the topic keeps nothing for late subscribers); a
            # repeated command every publication period while the push lasts
            now = time.monotonic()
            since = [n for t, n in accepted if t > sent[-1] + RESEND_AFTER] if sent else []
            again = bool(since) and not any(n for _, n in accepted)  # reports long after it: none taken
            due = (case.repeated and sent and now >= sent[-1] + VIOLENT_PERIOD
                   and sum(t >= sent[0] for t in arrivals) < pushes)
            if arrivals and pub.get_subscription_count() > 0 and (not sent or again or due):
                pub.publish(Float64MultiArray(data=list(moments)))
                sent.append(now)
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
        proc.wait(timeout=30)
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    if proc.returncode != 0 or not stats.exists():
        raise RuntimeError(f"gyro_sim_node failed ({case.label}, exit {proc.returncode}):\n"
                           f"{log.read_text(errors='replace')[-2000:]}")
    st = json.loads(stats.read_text())
    if not case.repeated and st.get("commands_accepted") != 1:
        raise RuntimeError(f"the node took {st.get('commands_accepted')} commands, not the violent step's one")
    after = [t for t in arrivals if sent and t >= sent[0]]
    gaps = [b - a for a, b in itertools.pairwise(after)]
    span = after[-1] - after[0] if len(after) > 1 else float("nan")
    return {"received": len(after), "rate_Hz": (len(after) - 1) / span if len(after) > 1 else 0.0,
            "longest_gap_s": max(gaps, default=float("nan")), "wall_s": span, "sent": len(sent), **st}


def measure(sizes=DEFAULT_SIZES, seconds: float = DEFAULT_SECONDS, progress=None, node_command=NODE_COMMAND,
            backend: str = "auto", priorities=(DEFAULT_PRIORITY,), branching: int = 1) -> list[Run]:
    runs = []
    with tempfile.TemporaryDirectory(prefix="gyro_sim_realtime_") as tmp:
        cases = [(n, rec, p) for n in sizes for rec in (False, True) for p in priorities]
        for i, (n, rec, p) in enumerate(cases):
            runs.append(run_node(n, rec, seconds, Path(tmp), i, node_command, backend, p, branching))
            if progress:
                progress(i + 1, len(cases), f"n = {n}{' recording' if rec else ''}, thread_priority {p}")
    return runs


def table(runs: list[Run]) -> str:
    lines = [
        "| n | recording | FIFO priority (asked / got) | step p50 (us) | step p99 (us) "
        "| publish jitter p50 (us) | publish jitter p99 (us) "
        "| CPU share | achieved RTF | deadline misses | of which after waiting for a CPU "
        "| physics thread waiting for a CPU (ms) | host steal (ms) | floor: misses of a bare paced thread beside it "
        "| longest GC pause (us) | load (start / end) |",
        "|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in runs:
        lines.append(
            f"| {r.n} | {'yes' if r.record else 'no'} | {r.priority} / {int(r.get('physics_thread_priority', 0))} "
            f"| {r.get('step_time_p50_us'):.0f} | {r.get('step_time_p99_us'):.0f} "
            f"| {r.get('publish_jitter_p50_us'):.0f} | {r.get('publish_jitter_p99_us'):.0f} "
            f"| {100 * r.get('cpu_share'):.0f} % | {r.get('real_time_factor_achieved'):.3f} "
            f"| {int(r.get('deadline_misses', 0))} | {int(r.get('cpu_wait_misses', 0))} "
            f"| {1e3 * r.get('physics_cpu_wait_s'):.0f} | {1e3 * r.get('host_steal_s'):.0f} "
            f"| {r.get('floor_misses_scaled'):.0f} | {r.get('gc_pause_max_us'):.0f} "
            f"| {r.get('load_start'):.2f} / {r.get('load_end'):.2f} |"
        )
    held = [r.n for r in runs if r.holds and not r.record]
    held_rec = [r.n for r in runs if r.holds and r.record]
    lines.append("")
    lines.append(
        "Largest n holding real time (achieved RTF >= " + f"{HOLDS:g}): "
        + (f"{max(held)}" if held else f"none of n = {sorted({r.n for r in runs})}")
        + " without recording, " + (f"{max(held_rec)}" if held_rec else "none") + " with recording."
    )
    rec = [r for r in runs if r.record]
    if rec:
        lines.append("Recording: " + "; ".join(
            f"n = {r.n}: {int(r.get('records_written', 0))} records, "
            f"writer process {r.get('recorder_thread_cpu_s'):.2f} s CPU, "
            f"the node's sender thread {r.get('recorder_sender_cpu_s', float('nan')):.2f} s, "
            f"in {r.get('wall_s'):.1f} s" for r in rec) + ".")
    if any(r.priority and not r.get("physics_thread_priority", 0) for r in runs):
        lines.append("SCHED_FIFO was refused here: every run used the normal scheduler (an rtprio limit allows it).")
    return "\n".join(lines)


def plot(runs: list[Run], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, (a1, a2, a3) = plt.subplots(1, 3, figsize=(15, 4.4))
    priorities = sorted({r.priority for r in runs})
    for (rec, style), prio in ((c, p) for c in ((False, "o-"), (True, "s--")) for p in priorities):
        rs = [r for r in runs if r.record == rec and r.priority == prio]
        if not rs:
            continue
        n = [r.n for r in rs]
        label = ("recording" if rec else "no recording") + (f", priority {prio}" if len(priorities) > 1 else "")
        a1.plot(n, [r.get("step_time_p50_us") for r in rs], style, label=f"p50, {label}")
        a1.plot(n, [r.get("step_time_p99_us") for r in rs], style, alpha=0.5, label=f"p99, {label}")
        a2.plot(n, [r.get("real_time_factor_achieved") for r in rs], style, label=f"achieved RTF, {label}")
        a2.plot(n, [r.get("cpu_share") for r in rs], style, alpha=0.5, label=f"CPU share, {label}")
    sizes = sorted({r.n for r in runs})
    for ax in (a1, a2):
        ax.set_xticks(sizes)
    a1.axhline(1e6 / PHYSICS_RATE, color="k", lw=0.8, ls=":", label="physics period")
    a1.set_xlabel("chain length n")
    a1.set_ylabel("step time (us)")
    a1.legend(fontsize=8)
    a1.grid(alpha=0.3)
    a2.axhline(1.0, color="k", lw=0.8, ls=":")
    a2.set_xlabel("chain length n")
    a2.set_ylabel("real-time factor / CPU share (1 = one core)")
    a2.legend(fontsize=8)
    a2.grid(alpha=0.3)
    # the misses of each run beside the machine's floor and the host's steal
    x = np.arange(len(runs))
    a3.bar(x - 0.2, [r.get("deadline_misses", 0) for r in runs], 0.4, label="node: deadline misses")
    a3.bar(x + 0.2, [r.get("floor_misses_scaled", np.nan) for r in runs], 0.4,
           label="floor: a bare thread sleeping to the same deadlines")
    a3.bar(x - 0.2, [r.get("cpu_wait_misses", 0) for r in runs], 0.4, fill=False, hatch="//",
           label="of the node's: after waiting for a CPU")
    for i, r in enumerate(runs):
        a3.annotate(f"{1e3 * r.get('host_steal_s'):.0f}", (i, 0), xytext=(0, 3),
                    textcoords="offset points", ha="center", fontsize=7)
    a3.set_xticks(x, [f"{r.n}{'R' if r.record else ''}\nP{r.priority}" for r in runs], fontsize=7)
    a3.set_xlabel("run: n (R: recording), P: FIFO priority asked", fontsize=8)
    a3.set_ylabel(f"misses in {max(r.get('node_time_s', 0) for r in runs):.0f} s (numbers: host steal, ms)")
    a3.legend(fontsize=7)
    a3.grid(alpha=0.3, axis="y")
    backends = ", ".join(sorted({str(r.stats.get("backend")) for r in runs}))
    fig.suptitle(f"gyro_sim_node, physics {PHYSICS_RATE:g} Hz, publish {PUBLISH_RATE:g} Hz, RK4, {backends} dynamics")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def cmd_bench_realtime(args) -> int:
    from gyro_sim.progress import Progress
    from gyro_sim.bench.report import refused, write_report

    if refused(args, "realtime"):
        return 2
    if args.branching < 1:
        print(f"gyro-sim bench realtime: --branching must be >= 1, got {args.branching}", file=sys.stderr)
        return 2
    sizes = QUICK_SIZES if args.quick else tuple(args.sizes or DEFAULT_SIZES)
    seconds = QUICK_SECONDS if args.quick else args.seconds
    t0 = time.perf_counter()
    load0 = os.getloadavg()[0]
    try:
        runs = measure(sizes, seconds, progress=Progress("realtime"), backend=args.backend,
                       priorities=tuple(args.thread_priority), branching=args.branching)
    except RuntimeError as exc:
        print(f"gyro-sim bench realtime: {exc}", file=sys.stderr)
        return 1
    backends = ", ".join(sorted({str(r.stats.get("backend")) for r in runs}))
    shape = ("chains" if args.branching == 1 else
             f"trees (body k hangs from body (k - 1) // {args.branching}: `tree_of_links`)")
    text = (f"### Real time: the node at physics {PHYSICS_RATE:g} Hz, publish {PUBLISH_RATE:g} Hz, RK4 "
            f"({backends} dynamics), {seconds:g} s simulated per run, spherical {shape}\n\n" + table(runs)
            + f"\nMachine load (1-minute average, {os.cpu_count()} cores): {load0:.2f} at the start, "
            f"{os.getloadavg()[0]:.2f} at the end.")
    rows = [{"n": r.n, "record": r.record, **r.stats} for r in runs]
    if args.violent or args.violent_family:
        cases = violent_family(tuple(args.violent_scenes)) if args.violent_family else [ViolentCase()]
        counts, nodes = [], []
        with tempfile.TemporaryDirectory(prefix="gyro_sim_violent_") as tmp:
            for i, case in enumerate(cases):
                counts.append(violent_counts(case))
                try:
                    nodes.append(run_violent_node(Path(tmp), case=case, index=i, priority=args.thread_priority[0]))
                except RuntimeError as exc:  # said in the table: a case the node did not get through
                    nodes.append({"failed": " ".join(str(exc).split())})
        text += ("\n\n" + violent_table(counts, nodes) + "\n\nThe node given each (warm cache, "
                 f"{os.cpu_count()} cores, {VIOLENT_SECONDS:g} s runs): the /joint_states received from the "
                 "command on, their rate and longest gap in wall time; the node's achieved RTF and step times.")
        rows.append({"violent_counts": counts, "violent_node": nodes})
    print(text)
    write_report(args.out, "realtime", text + "\n", rows,
                 lambda png: plot(runs, png), force=args.force, json_default=str)
    print(f"in {time.perf_counter() - t0:.0f} s")
    return 0


def register(sub, bench) -> None:
    """Add `gyro-sim bench realtime`."""
    r = bench.add_parser("realtime", help="the node's step time, jitter, CPU share and real-time factor (needs rclpy)")
    r.add_argument("--sizes", type=int, nargs="+", help=f"chain lengths (default {' '.join(map(str, DEFAULT_SIZES))})")
    r.add_argument("--seconds", type=float, default=DEFAULT_SECONDS, help="simulated seconds per run")
    r.add_argument("--branching", type=int, default=1, metavar="K",
                   help="hang the n links as a tree: body k from body (k - 1) // K (default 1: a chain; 2: a "
                   "binary tree; n: a hub carrying the others)")
    r.add_argument("--quick", action="store_true", help=f"n = 2 only, {QUICK_SECONDS:g} s runs (CI)")
    r.add_argument("--backend", default="auto", help="dynamics of the node: auto | numba | numpy")
    r.add_argument("--thread-priority", type=int, nargs="+", default=[DEFAULT_PRIORITY], choices=range(100),
                   metavar="P", help=f"the node's thread_priority, 0-99 (0: normal scheduler); several: a run each "
                   f"(default {DEFAULT_PRIORITY}, the node's)")
    r.add_argument("--violent", action="store_true",
                   help=f"add the violent step (1e3 x gravity torque for {VIOLENT_PUSH:g} s on the hinge chain): its "
                   f"counts, and the node given it ({VIOLENT_SECONDS:g} s run)")
    r.add_argument("--violent-family", action="store_true",
                   help="add the violent family instead: 1e2, 1e3, 1e4 x gravity torque held 0.5 s and 1.5 s, and "
                   f"sent at {PUBLISH_RATE:g} Hz for {VIOLENT_REPEATED:g} s, on each of --violent-scenes")
    r.add_argument("--violent-scenes", nargs="+", default=list(VIOLENT_SCENES), choices=VIOLENT_SCENES,
                   help=f"the family's scenes (default {' '.join(VIOLENT_SCENES)})")
    r.add_argument("--out", default="out/bench", help="directory for realtime.md, realtime.json, realtime.png")
    r.add_argument("--force", action="store_true", help="replace existing report files in --out")
    r.set_defaults(fn=cmd_bench_realtime)
