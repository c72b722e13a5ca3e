"""`gyro-sim bench publication`: the physics thread's cost of one publication, part by part.

The node (gyro_sim.ros.loop) prepares one publication every 10 ms of simulated time (publish
100 Hz, physics 1 kHz): `Outputs.prepare_state` (the compiled outputs, the snapshot, the
message bytes) and, at its deadline, `Outputs.send` (one `Publisher.publish(bytes)` per message,
one publisher per joint wrench topic as docs/ros-interface.md gives, and the same bytes handed to the
recorder). This bench runs exactly that code on the physics thread of this process, with a real
rclpy node, real publishers and a real recorder (gyro_sim.ros.recorder.LiveRecorder writing an
MCAP file from its child process), on spherical chains of gyro_sim.bench.scenes with a rotor on
every body (in space: no gravity, as bench realtime), RK4 at 1 ms, with wrenches, poses and /tf
on (what a recording node publishes), and /diagnostics every 10th publication as the node sends them.

Parts (wall time on the calling thread, medians and p99 over the publications). Each
publication runs what the node runs right after the physics steps, timed (prepare, publish,
record: the total), then the parts of prepare again on their own on the same state (kernel,
snapshot, bytes: the caches warm from prepare, so their sum may be below prepare):

- kernel: the compiled outputs call alone (`gyro_sim.dynamics.backends.CompiledOutputs.outputs`);
- snapshot: what prepare_state asks of the Simulator, minus the kernel: `Simulator.write_outputs`
  (the numbers into the frame and their finite check, no Snapshot) without diagnostics,
  `Simulator.snapshot` with them;
- bytes: the frame's messages (`Frame.messages`: the stamps and one block), and the
  diagnostics' bytes when they go;
- prepare: `Outputs.prepare_state` as a whole (what the node times as output_time);
- publish: `Outputs.publish`, the rclpy `publish(bytes)` calls of the batch (optional topics only
  where someone subscribes), without a subscriber and with one (a separate process subscribing
  to every topic, raw);
- record: the recorder hand-off, as `Outputs.send` makes it;
- total: prepare + publish + record, what the physics thread pays per publication.

It also measures one `publish(bytes)` alone, the binding's own `publish_raw` under it, and
whether the rcl publish releases the interpreter lock (:func:`gil_released_by_publish`).

`--recorder` (:func:`recorder_costs`, no rclpy) measures the recorder's share alone, paced as
the node: the hand-off, the CPU of the sender thread (which holds the interpreter lock the
physics thread needs) and of the writer process, per publication.

The machine may be shared: the report says the load.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

import numpy as np

DEFAULT_SIZES = (10, 50, 100)
QUICK_SIZES = (10,)
DEFAULT_PUBLICATIONS = 400
QUICK_PUBLICATIONS = 60
PHYSICS_STEP = 1e-3
PUBLISH_PERIOD = 0.01
#: the node sends /diagnostics with every DIAG_EVERY-th publication (10 Hz at 100 Hz)
DIAG_EVERY = 10
#: ROS domain of the bench: Fast DDS accepts 0..232; the tests use 50..199, bench realtime and
#: soak 200..229, test_newcomer 230..232 briefly: the bench takes 231 with localhost discovery
DOMAIN = 231
PARTS = ("kernel", "snapshot", "bytes", "prepare", "publish", "record", "total")

_SUBSCRIBER = r"""
import sys, rclpy, importlib
from rclpy.node import Node
rclpy.init()
node = Node("gyro_sim_bench_sub")
subs = []
for line in sys.stdin:
    line = line.strip()
    if not line:
        break
    topic, msgtype = line.split()
    pkg, _, name = msgtype.split("/")
    cls = getattr(importlib.import_module(pkg + ".msg"), name)
    subs.append(node.create_subscription(cls, topic, lambda m: None, 10, raw=True))
print("ready", flush=True)
import threading
from rclpy.executors import SingleThreadedExecutor
ex = SingleThreadedExecutor()
ex.add_node(node)
threading.Thread(target=ex.spin, daemon=True).start()
sys.stdin.read()  # until the bench closes our input: then leave the graph cleanly
ex.shutdown()
node.destroy_node()
rclpy.shutdown()
"""


@dataclass
class Row:
    """One chain length: per part, the samples (seconds) of every publication."""

    n: int
    subscriber: bool
    samples: dict[str, list[float]] = field(default_factory=dict)
    diag: list[bool] = field(default_factory=list)
    sender_cpu: float = float("nan")  # CPU seconds of the recorder's sender thread per publication

    def stat(self, part: str, q: float = 50.0, diag: bool | None = None) -> float:
        """Percentile q of `part` in microseconds (diag: only publications with/without diagnostics)."""
        s = np.asarray(self.samples.get(part, []))
        if diag is not None and s.size:
            s = s[np.asarray(self.diag) == diag]
        return float(np.percentile(s, q) * 1e6) if s.size else float("nan")


def _env(workdir: Path) -> dict:
    env = dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               ROS_LOG_DIR=str(workdir / "ros_log"))
    root = str(Path(__file__).resolve().parents[2])
    env["PYTHONPATH"] = os.pathsep.join([root, env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return env


class _NullNode:
    """The node as gyro_sim.ros.outputs.Outputs uses it, with stand-in publishers that are
    listened to and send nothing (no rclpy)."""

    def get_fully_qualified_name(self):
        from gyro_sim.msgs import messages as M

        return M.NAMESPACE

    def create_publisher(self, cls, topic, qos, **kwargs):
        return SimpleNamespace(get_subscription_count=lambda: 1, publish=lambda data: None)


def _simulator(n: int):
    from gyro_sim.simulator import Simulator
    from gyro_sim.bench.scenes import spherical_chain

    sim = Simulator(spherical_chain(n, gravity=False, rotors=True), integrator="rk4", step=PHYSICS_STEP,
                    backend="numba")
    sim.advance(PUBLISH_PERIOD)  # compiles, and leaves the reset state
    return sim


def _frame(out):
    """The node's publication buffer (gyro_sim.msgs.messages.Frame) once prepare_state made it."""
    frames = getattr(out, "_frames", None)
    return next(iter(frames.values()), None) if frames else None


def _kernel(sim, out, diag: bool) -> None:
    """The compiled outputs call of a publication alone, as prepare_state asks for it."""
    from gyro_sim.dynamics import outputs as fo

    want = (getattr(fo, "WANT_BODIES", 0) | getattr(fo, "WANT_WRENCHES", 0)
            | (getattr(fo, "WANT_INVARIANTS", 0) if diag else 0))
    frame = _frame(out)
    try:
        sim._outputs.outputs(want, None if frame is None else frame.scatter, fresh=False)
    except TypeError:  # before the publication kernel: one call computed everything
        sim._outputs.outputs()


def _bytes(sim, out, snap, t_ns: int, run) -> None:
    """The messages' bytes of a snapshot, as prepare_state makes them."""
    from gyro_sim.msgs import messages as M

    frame = _frame(out)
    if frame is None:
        out.publication.messages(snap, t_ns, poses=True, tf=True, diagnostics_run=run)
        return
    frame.messages(t_ns)
    if run is not False:
        M.diagnostics(snap, t_ns, out.publication.hardware_id, run)


def measure_size(n: int, publications: int, node, workdir: Path, *, subscriber_env: dict | None,
                 progress=None) -> list[Row]:
    """Rows without and (subscriber_env given) with a subscriber process for chain length n."""
    from gyro_sim.ros.outputs import Outputs
    from gyro_sim.ros.recorder import LiveRecorder

    sim = _simulator(n)
    log = workdir / f"pub_{n}.mcap"
    recorder = LiveRecorder(str(log), scene=sim.scene, params={"bench": "publication"}, overwrite=True)
    config = SimpleNamespace(publish_wrenches=True, publish_poses=True)
    out = Outputs(node, sim, config, recorder=recorder)
    rows = []
    sub = None
    try:
        for with_sub in (False, True) if subscriber_env is not None else (False,):
            if with_sub:
                sub = _start_subscriber(out, subscriber_env, workdir)
                if hasattr(out, "listeners"):  # at once, not over the next WANT_PERIOD
                    out.listeners.ask_all()
            rows.append(_run(sim, out, recorder, n, publications, with_sub, progress))
    finally:
        if sub is not None:  # a clean exit: a killed reader stays matched (and slows writers) until its lease ends
            sub.stdin.close()
            try:
                sub.wait(10)
            except subprocess.TimeoutExpired:
                sub.kill()
                sub.wait()
        recorder.close()
        for r in rows:
            r.sender_cpu = recorder.sender_cpu / max(1, sum(len(x.diag) for x in rows))
        for pub in out.pubs.values():
            node.destroy_publisher(pub)
        log.unlink(missing_ok=True)
    return rows


def _start_subscriber(out, env: dict, workdir: Path, timeout: float = 20.0):
    from gyro_sim.msgs import messages as M

    proc = subprocess.Popen([sys.executable, "-c", _SUBSCRIBER], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=open(workdir / "subscriber.err", "w"), env=env, text=True)
    types = {M.JOINT_STATES: M.JOINT_STATE_TYPE, M.CLOCK: M.CLOCK_TYPE, M.DIAGNOSTICS: M.DIAGNOSTICS_TYPE,
             out.publication.poses_topic: M.POSE_ARRAY_TYPE}
    types.update({t: M.WRENCH_TYPE for t in out.wrench_topics})
    proc.stdin.write("".join(f"{t} {types[t]}\n" for t in out.pubs) + "\n")
    proc.stdin.flush()
    proc.stdout.readline()
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if all(p.get_subscription_count() > 0 for p in out.pubs.values()):
            time.sleep(0.5)  # let the matching settle
            return proc
        time.sleep(0.05)
    proc.kill()
    raise RuntimeError(f"the subscriber process did not match every publisher in {timeout:g} s")


def _run(sim, out, recorder, n: int, publications: int, with_sub: bool, progress) -> Row:
    from gyro_sim.msgs import messages as M

    row = Row(n, with_sub, {p: [] for p in PARTS})
    clock = time.perf_counter
    run = M.Status("gyro_sim: run", {"real_time_factor": 1.0})
    for i in range(publications):
        sim.advance(PUBLISH_PERIOD)
        diag = i % DIAG_EVERY == 0
        t_ns = M.time_ns(sim.time)
        # what the physics thread runs right after the physics steps (as the node): prepare, then
        # send (split into its two halves)
        t0 = clock()
        batch = out.prepare_state(t_ns, sim, run if diag else False)
        t1 = clock()
        _publish(out, batch)
        t2 = clock()
        _hand_off(recorder, t_ns, batch)
        t3 = clock()
        # then the parts, each on its own on the same state (the calls prepare_state makes; their
        # data is in the caches prepare_state left)
        t4 = clock()
        _kernel(sim, out, diag)
        t5 = clock()
        frame = _frame(out)
        snap = None
        if frame is None:
            snap = sim.snapshot(bodies=True, wrenches=True, invariants=diag)
        elif diag or not hasattr(sim, "write_outputs"):
            snap = sim.snapshot(bodies=True, wrenches=True, invariants=diag, into=frame.scatter)
        else:
            sim.write_outputs(frame.scatter, bodies=True, wrenches=True)
        t6 = clock()
        _bytes(sim, out, snap, t_ns, run if diag else False)
        t7 = clock()
        s = row.samples
        s["prepare"].append(t1 - t0)
        s["publish"].append(t2 - t1)
        s["record"].append(t3 - t2)
        s["total"].append(t3 - t0)
        s["kernel"].append(t5 - t4)
        s["snapshot"].append(t6 - t5 - (t5 - t4))
        s["bytes"].append(t7 - t6)
        row.diag.append(diag)
        if progress is not None and i % 50 == 0:
            progress(i, publications, f"n = {n}{' (subscriber)' if with_sub else ''}")
    return row


def _publish(out, batch) -> None:
    """The rclpy half of `Outputs.send` (`Outputs.publish` where it has one)."""
    publish = getattr(out, "publish", None)
    if publish is not None:
        publish(batch)
        return
    publisher = getattr(out, "_publisher", None)  # the call Outputs.send makes
    listeners = getattr(out, "listeners", None)  # an optional topic nobody subscribes to is not published
    listened = (lambda topic: True) if listeners is None else (lambda topic: listeners.listened.get(topic, True))
    for topic, _, data in batch:
        if publisher is not None:
            fn = publisher(topic)
            if fn is not None and listened(topic):
                fn(data)
        else:
            pub = out.pubs.get(topic)
            if pub is not None:
                pub.publish(data)


def isolated(n: int, repeats: int = 300) -> dict[str, float]:
    """Microseconds (median of `repeats` back-to-back calls on one state, no rclpy, no recorder,
    no other thread): the kernel (joint states only, and with wrenches and poses), a snapshot
    as the recording node asks for it, the bytes, and prepare_state with and without the
    diagnostics, through Outputs with stand-in publishers."""
    from gyro_sim.dynamics import outputs as fo
    from gyro_sim.msgs import messages as M
    from gyro_sim.ros.outputs import Outputs

    sim = _simulator(n)
    out = Outputs(_NullNode(), sim, SimpleNamespace(publish_wrenches=True, publish_poses=True))
    out.prepare_state(0, sim)
    out.prepare_state(0, sim)
    frame = _frame(out)
    run = M.Status("gyro_sim: run", {"real_time_factor": 1.0})

    def med(fn) -> float:
        ts = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            fn()
            ts.append(time.perf_counter() - t0)
        return float(np.median(ts) * 1e6)

    res = {}
    scatter = None if frame is None else frame.scatter
    if hasattr(fo, "WANT_BODIES"):
        res["kernel, joint states"] = med(lambda: sim._outputs.outputs(0, None, fresh=False))
        res["kernel, + wrenches, poses"] = med(lambda: sim._outputs.outputs(
            fo.WANT_BODIES | fo.WANT_WRENCHES, scatter, fresh=False))
        res["snapshot"] = med(lambda: sim.snapshot(invariants=False, into=scatter))
        if hasattr(sim, "write_outputs"):
            res["write_outputs"] = med(lambda: sim.write_outputs(scatter))
        res["bytes"] = med(lambda: frame.messages(1))
    else:
        res["kernel, + wrenches, poses"] = med(lambda: sim._outputs.outputs())
        res["snapshot"] = med(lambda: sim.snapshot(invariants=False))
        snap = sim.snapshot(invariants=False)
        res["bytes"] = med(lambda: out.publication.messages(snap, 1))
    res["prepare"] = med(lambda: out.prepare_state(1, sim))
    res["prepare, with diagnostics"] = med(lambda: out.prepare_state(1, sim, run))
    return res


def _hand_off(recorder, t_ns: int, batch: list) -> None:
    """What `Outputs.send` hands the recorder for one publication (one call where the recorder
    takes a publication at once, else one call per record)."""
    raw_batch = getattr(recorder, "raw_batch", None)
    if raw_batch is not None:
        raw_batch(t_ns, batch)
        return
    raw = recorder.raw
    for topic, msgtype, data in batch:
        raw(topic, msgtype, t_ns, data)


def recorder_costs(n: int, publications: int = 300, workdir: str | None = None) -> dict[str, float]:
    """The recorder's share of a publication at chain length n (no rclpy): the node's physics loop
    paced at 100 Hz of wall time (advance 10 ms of simulated time, `Outputs.prepare_state` with
    wrenches, poses, /tf and every 10th time /diagnostics, then the hand-off), recording to an
    MCAP file through gyro_sim.ros.recorder.LiveRecorder.

    Returns microseconds per publication: `hand_off` (median and p99: the physics thread's time
    in the recorder calls), `sender_cpu` (CPU of the recorder's sender thread in this process,
    `time.thread_time` there, its wake-ups and pipe writes included: ~50 us a wake-up on this
    virtual machine, without the interpreter lock), `pack` (the sender's Python work for one
    publication timed alone, :func:`_sender_python`: what it holds the interpreter lock for),
    `writer_cpu` (CPU of the writer process, without its start where the recorder tells it),
    `advance` (median wall time of the 10 physics
    steps between two publications, the physics thread's own work with the recorder beside it),
    and `records`, `written` (records handed over and written)."""
    from gyro_sim.msgs import messages as M
    from gyro_sim.ros.outputs import Outputs
    from gyro_sim.ros.recorder import LiveRecorder

    sim = _simulator(n)
    run = M.Status("gyro_sim: run", {"real_time_factor": 1.0})
    with tempfile.TemporaryDirectory(prefix="gyro_sim_rec_", dir=workdir) as tmp:
        recorder = LiveRecorder(str(Path(tmp) / "rec.mcap"), scene=sim.scene, params={"bench": "recorder"})
        out = Outputs(_NullNode(), sim, SimpleNamespace(publish_wrenches=True, publish_poses=True), recorder=recorder)
        hand, adv, records = [], [], 0
        try:
            out.prepare_state(0, sim)  # the first call learns the joint names, the second makes the frame
            clock = time.perf_counter
            deadline = clock()
            for i in range(publications):
                t0 = clock()
                sim.advance(PUBLISH_PERIOD)
                t1 = clock()
                t_ns = M.time_ns(sim.time)
                batch = out.prepare_state(t_ns, sim, run if i % DIAG_EVERY == 0 else False)
                t2 = clock()
                _hand_off(recorder, t_ns, batch)
                t3 = clock()
                adv.append(t1 - t0)
                hand.append(t3 - t2)
                records += len(batch)
                deadline += PUBLISH_PERIOD
                pause = deadline - clock()
                if pause > 0:
                    time.sleep(pause)
                else:  # behind: start again from now (as the node's pacer after a miss)
                    deadline = clock()
        finally:
            recorder.close()
    us = 1e6
    return {"hand_off": float(np.median(hand) * us), "hand_off_p99": float(np.percentile(hand, 99) * us),
            "sender_cpu": recorder.sender_cpu / publications * us,
            "pack": _sender_python(batch, t_ns) * us,
            "writer_cpu": (recorder.thread_cpu - getattr(recorder, "open_cpu", 0.0)) / publications * us,
            "advance": float(np.median(adv) * us), "records": records, "written": recorder.written,
            "publications": publications,
            "error": recorder.error}


def _sender_python(batch: list, t_ns: int, repeats: int = 200) -> float:
    """Seconds (median, back-to-back, no other thread) of the sender thread's Python work for one
    publication: the recorder's `_Packer.pack` where it has one, else (the recorder before it)
    pickling the records into one frame as its sender did."""
    import pickle

    from gyro_sim.ros import recorder as R

    packer = getattr(R, "_Packer", None)
    if packer is not None:
        p = packer()
        p.pack([(t_ns, batch)])  # the layout goes once

        def work():
            p.pack([(t_ns, batch)])
    else:
        def work():
            data = pickle.dumps([(topic, msgtype, t_ns, b) for topic, msgtype, b in batch],
                                protocol=pickle.HIGHEST_PROTOCOL)
            return len(data).to_bytes(4, "little") + data

    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        work()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def recorder_table(costs: dict[int, dict]) -> str:
    """Markdown: one line per chain length of :func:`recorder_costs`."""
    text = ("| n | records / publication | hand-off p50 / p99 (us) | sender thread CPU (us) "
            "| sender's Python work (us) | writer process CPU (us) | 10 physics steps (us) |\n"
            "|---:|---:|---:|---:|---:|---:|---:|\n")
    for n, c in costs.items():
        text += (f"| {n} | {c['records'] / c['publications']:.1f} | {c['hand_off']:.1f} / {c['hand_off_p99']:.1f} "
                 f"| {c['sender_cpu']:.1f} | {c['pack']:.1f} | {c['writer_cpu']:.0f} | {c['advance']:.0f} |\n")
    text += ("\nPer publication (physics 1 kHz, publish 100 Hz paced on the wall clock, wrenches, poses, /tf, "
             "/diagnostics every 10th): the physics thread's hand-off to the recorder, the CPU of the recorder's "
             "sender thread (wake-ups and pipe writes included), its Python work for one publication timed alone "
             "(what it holds the interpreter lock the physics thread needs for), of the writer process, and "
             f"the physics thread's own 10 steps. Machine load {os.getloadavg()[0]:.2f} "
             f"({os.cpu_count()} cores, shared).\n")
    return text


def publish_costs(node, repeats: int = 3000) -> dict[str, float]:
    """Microseconds (median) of one `publish(bytes)` of a WrenchStamped without a subscriber, and
    of the binding's `publish_raw` under it (rclpy's Python layer is the difference)."""
    from geometry_msgs.msg import WrenchStamped

    from gyro_sim.msgs import messages as M

    pub = node.create_publisher(WrenchStamped, "/gyro_sim_bench/wrench_probe", 10)
    data = M.wrench_stamped(1, "probe", np.ones(3), np.ones(3))
    raw = pub._Publisher__publisher.publish_raw  # rclpy keeps the C publisher private
    out = {}
    for name, fn in (("publish", pub.publish), ("publish_raw", raw)):
        ts = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            fn(data)
            ts.append(time.perf_counter() - t0)
        out[name] = float(np.median(ts) * 1e6)
    node.destroy_publisher(pub)
    return out


def gil_released_by_publish(node, seconds: float = 0.5) -> dict[str, float]:
    """Whether rcl's publish releases the interpreter lock: publish calls per second on one thread
    while another thread runs Python, against the same with a call that does release it
    (time.sleep(0)). A call that releases the lock must win it back on return, which waits for the
    other thread's switch interval: such a loop manages only ~1/switch-interval calls per second."""
    from geometry_msgs.msg import WrenchStamped

    from gyro_sim.msgs import messages as M

    pub = node.create_publisher(WrenchStamped, "/gyro_sim_bench/gil_probe", 10)
    data = M.wrench_stamped(1, "probe", np.ones(3), np.ones(3))

    def rate(fn) -> float:
        stop = False

        def spin():
            while not stop:
                pass

        th = threading.Thread(target=spin, daemon=True)
        th.start()
        t0, calls = time.perf_counter(), 0
        while time.perf_counter() - t0 < seconds:
            fn()
            calls += 1
        stop = True
        th.join()
        return calls / seconds

    out = {"publish_calls_per_s": rate(lambda: pub.publish(data)), "sleep0_calls_per_s": rate(lambda: time.sleep(0)),
           "switch_interval_s": sys.getswitchinterval()}
    out["released"] = float(out["publish_calls_per_s"] < 10 * out["sleep0_calls_per_s"])
    node.destroy_publisher(pub)
    return out


def measure(sizes=DEFAULT_SIZES, publications: int = DEFAULT_PUBLICATIONS, *, subscriber: bool = True,
            progress=None) -> dict:
    """Every size's rows, the cost of one publish and the lock test; needs rclpy."""
    import rclpy
    from rclpy.node import Node

    with tempfile.TemporaryDirectory(prefix="gyro_sim_pub_") as tmp:
        workdir = Path(tmp)
        env = _env(workdir)
        os.environ.update({k: env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_LOG_DIR")})
        rclpy.init()
        try:
            node = Node("gyro_sim", namespace="/gyro_sim_bench")
            rows = []
            alone = {n: isolated(n) for n in sizes}
            for n in sizes:
                rows += measure_size(n, publications, node, workdir, subscriber_env=env if subscriber else None,
                                     progress=progress)
            one = publish_costs(node)
            gil = gil_released_by_publish(node)
            node.destroy_node()
        finally:
            rclpy.shutdown()
    return {"rows": rows, "isolated": alone, "publish": one, "gil": gil, "load": os.getloadavg()[0],
            "cores": os.cpu_count()}


def table(result: dict) -> str:
    """Markdown: one line per size and subscriber case, median / p99 of each part (us)."""
    rows = result["rows"]
    head = "| n | subscriber | " + " | ".join(PARTS) + " | total, with diagnostics | recorder's sender thread |\n"
    head += "|---:|:---:|" + "---:|" * (len(PARTS) + 2) + "\n"
    lines = []
    for r in rows:
        cells = [f"{r.stat(p):.0f} / {r.stat(p, 99):.0f}" for p in PARTS]
        lines.append(f"| {r.n} | {'yes' if r.subscriber else 'no'} | " + " | ".join(cells)
                     + f" | {r.stat('total', 50, diag=True):.0f} | {r.sender_cpu * 1e6:.0f} |")
    one, gil = result["publish"], result["gil"]
    text = head + "\n".join(lines) + "\n\n"
    text += ("Microseconds, median / p99 over the publications (every 10th with /diagnostics; the median of those in "
             "its column; the recorder's sender thread: its CPU per publication, which holds the interpreter lock "
             "the physics thread needs). prepare: `Outputs.prepare_state` right after the physics steps, as the node "
             "runs it; kernel, snapshot, bytes: its parts run again after it on the same state; "
             "total = prepare + publish + record, the physics thread's cost.\n\n")
    text += (f"One `publish(bytes)` without a subscriber: {one['publish']:.2f} us, of which the binding's "
             f"`publish_raw`: {one['publish_raw']:.2f} us. With another thread running Python, publish "
             f"manages {gil['publish_calls_per_s']:.0f} calls/s against {gil['sleep0_calls_per_s']:.0f} for "
             f"a call that releases the lock (time.sleep(0)): rcl publish "
             f"{'releases' if gil['released'] else 'does not release'} the interpreter lock.\n\n")
    alone = result.get("isolated") or {}
    if alone:
        keys = list(next(iter(alone.values())))
        text += ("Each part alone (median of back-to-back calls on one state, stand-in publishers, no recorder, "
                 "no other thread), us:\n\n| n | " + " | ".join(keys) + " |\n|---:|" + "---:|" * len(keys) + "\n")
        text += "".join(f"| {n} | " + " | ".join(f"{v[k]:.1f}" for k in keys) + " |\n" for n, v in alone.items())
        text += "\n"
    text += f"Machine load (1-minute average, {result['cores']} cores, shared): {result['load']:.2f}.\n"
    return text


def cmd_bench_publication(args) -> int:
    from gyro_sim.progress import Progress

    sizes = QUICK_SIZES if args.quick else tuple(args.sizes or DEFAULT_SIZES)
    pubs = QUICK_PUBLICATIONS if args.quick else args.publications
    if args.recorder:  # no rclpy: the recorder's share alone
        print(recorder_table({n: recorder_costs(n, pubs) for n in sizes}))
        return 0
    try:
        result = measure(sizes, pubs, subscriber=not args.no_subscriber, progress=Progress("publication"))
    except (ImportError, RuntimeError) as exc:
        print(f"gyro-sim bench publication: {exc}", file=sys.stderr)
        return 1
    print(table(result))
    return 0


def register(sub, bench) -> None:
    """Add `gyro-sim bench publication`."""
    p = bench.add_parser("publication", help="the physics thread's cost of one publication, part by part (needs rclpy)")
    p.add_argument("--sizes", type=int, nargs="+", help=f"chain lengths (default {' '.join(map(str, DEFAULT_SIZES))})")
    p.add_argument("--publications", type=int, default=DEFAULT_PUBLICATIONS, help="publications per size")
    p.add_argument("--no-subscriber", action="store_true", help="skip the runs with a subscriber process")
    p.add_argument("--quick", action="store_true", help=f"n = {QUICK_SIZES[0]}, {QUICK_PUBLICATIONS} publications")
    p.add_argument("--recorder", action="store_true",
                   help="only the recorder's share (hand-off, sender thread and writer CPU per publication; no rclpy)")
    p.set_defaults(fn=cmd_bench_publication)
