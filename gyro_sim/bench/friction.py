"""`gyro-sim bench friction`: robots with dry joint friction (MJCF `frictionloss`, URDF
`<dynamics friction>`), as published: evaluations of y' and CPU seconds per simulated second,
models x integrators x durations, for the exact Coulomb friction of
:mod:`gyro_sim.integrators.coulomb.driver` and, with `--regularised`, for the same friction written as
the regularised law (`stick_speed` 1e-4 rad/s, linear below it: the stiff ODE).

With `--node`, each model also runs in the node (`gyro_sim_node`, its default integrator "fixed",
physics 1 kHz, publish 100 Hz, real-time factor 1, `--node-seconds` of simulated time, in a
process and ROS domain of its own): its achieved real-time factor and step time p50 / p99, from
its `stats_file`.

Each run: a Simulator of the model at its initial state (no command: the arm falls under
gravity, its joints sticking and slipping; with `--push`, a moment on every axis over the first
PUSH_SECONDS, then none), one step taken first (compiles or loads the kernels:
not counted), then `Simulator.advance(STEP)` called until the duration, as the node calls it.
Evaluations are counted by the system (`nfev`, the friction's impulse steps included) and do
not depend on the machine; CPU is the process's time. The regularised law is run for
`--regularised-duration` only (it costs minutes per simulated second) and its figures are per
simulated second of that run.
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
import warnings
from pathlib import Path

#: the node's physics step, and the step of the friction's stick/slip stepping
STEP = 1e-3
INTEGRATORS = ("auto", "fixed")
DURATIONS = (1.0,)
QUICK_DURATIONS = (0.2,)
REGULARISED_DURATION = 0.01
NODE_SECONDS = 10.0
#: `--push`: how long the moment is held (simulated s)
PUSH_SECONDS = 0.1
#: the vendored public models, where the package runs from its repository (test/scene/models)
MODELS = ("robosuite/xarm7.xml", "robosuite/jaco.xml", "example_robot_data/z1.urdf")

BENCH_FRICTION_EXAMPLES = """examples:
  gyro-sim bench friction
  gyro-sim bench friction --quick
  gyro-sim bench friction --models my_arm.xml --integrators auto fixed rk4 --durations 1 5
  gyro-sim bench friction --regularised --out out/bench --force"""


def default_models() -> list[Path]:
    """The vendored public models of the repository's tests, those present."""
    root = Path(__file__).resolve().parents[2] / "test" / "scene" / "models"
    return [root / m for m in MODELS if (root / m).is_file()]


def register(sub, bench) -> None:
    p = bench.add_parser("friction", help="robots with dry joint friction: evaluations and CPU per simulated second",
                         epilog=BENCH_FRICTION_EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--models", nargs="+", metavar="FILE",
                   help="MJCF or URDF models (default: the repository's vendored xarm7, jaco, Z1)")
    p.add_argument("--integrators", nargs="+", default=list(INTEGRATORS), metavar="NAME",
                   help=f"integrators (default {' '.join(INTEGRATORS)})")
    p.add_argument("--durations", nargs="+", type=float, metavar="S", help="simulated seconds (default 1)")
    p.add_argument("--quick", action="store_true", help=f"{QUICK_DURATIONS[0]:g} s only")
    p.add_argument("--regularised", action="store_true",
                   help="also the friction as the regularised law (stick_speed 1e-4), over --regularised-duration")
    p.add_argument("--regularised-duration", type=float, default=REGULARISED_DURATION, metavar="S",
                   help=f"simulated seconds of a regularised run (default {REGULARISED_DURATION:g})")
    p.add_argument("--push", type=float, default=0.0, metavar="NM",
                   help=f"a moment on every axis over the first {PUSH_SECONDS:g} s, then none (default 0: "
                        "the arm as it starts)")
    p.add_argument("--node", action="store_true",
                   help="also each model in the node (fixed, 1 kHz): its real-time factor")
    p.add_argument("--node-seconds", type=float, default=NODE_SECONDS, metavar="S",
                   help=f"simulated seconds of a node run (default {NODE_SECONDS:g})")
    p.add_argument("--out", default="out/bench", help="directory for friction.md and .json")
    p.add_argument("--force", action="store_true", help="replace existing report files in --out")
    p.set_defaults(fn=cmd_bench_friction)


def regularised(scene):
    """The scene with every exact Coulomb friction written as the regularised law
    (stick_speed = DEFAULT_STICK_SPEED)."""
    from gyro_sim.scene.records import DEFAULT_STICK_SPEED

    def law(limits):
        if limits is None or limits.friction is None or not limits.friction.exact:
            return limits
        return dataclasses.replace(limits, friction=dataclasses.replace(limits.friction,
                                                                        stick_speed=DEFAULT_STICK_SPEED))

    bodies = tuple(dataclasses.replace(b, joint=dataclasses.replace(b.joint, limits=law(b.joint.limits)),
                                       rotors=tuple(dataclasses.replace(r, limits=law(r.limits)) for r in b.rotors))
                   for b in scene.bodies)
    return dataclasses.replace(scene, bodies=bodies)


def measure(scene, integrator: str, duration: float, push: float = 0.0) -> dict:
    """One run (see the module): evaluations and CPU seconds per simulated second; `push` N m on
    every axis over the first PUSH_SECONDS."""
    from gyro_sim.simulator import SimulationError, Simulator

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # auto's switches: the figures say what they cost
        sim = Simulator(scene, integrator=integrator, step=STEP)
        sim.set_axis_moments([push] * len(sim.axis_names))
        sim.advance(STEP)
        nfev, cpu = sim.system.nfev, time.process_time()
        failed = None
        for _ in range(round(duration / STEP)):
            if push and sim.time >= PUSH_SECONDS and sim.axis_moments.any():
                sim.set_axis_moments([0.0] * len(sim.axis_names))
            try:
                sim.advance(STEP)
            except SimulationError as exc:  # a method unstable on the scene: said, not counted
                failed = str(exc)
                break
        cpu = time.process_time() - cpu
    span = sim.time - STEP
    return {"evaluations_per_s": (sim.system.nfev - nfev) / span if span > 0 else float("nan"),
            "cpu_per_s": cpu / span if span > 0 else float("nan"), "simulated_s": span,
            "friction_work_J": sim.friction_work, "failed": failed}


def run_node(path: Path, seconds: float, workdir: Path, index: int) -> dict:
    """The node on the model at `path` (module docstring): its statistics (stats_file)."""
    import json
    import os
    import subprocess

    from gyro_sim.bench.realtime import NODE_COMMAND, PHYSICS_RATE, PUBLISH_RATE

    stats = workdir / f"stats_{index}.json"
    params = [f"scene:={path.resolve()}", f"physics_rate:={PHYSICS_RATE}", f"publish_rate:={PUBLISH_RATE}",
              "real_time_factor:=1.0", f"duration:={seconds}", f"stats_file:={stats}"]
    cmd = [*NODE_COMMAND, "--ros-args", *[a for p in params for a in ("-p", p)]]
    env = dict(os.environ, ROS_DOMAIN_ID=str(200 + (os.getpid() * 17 + index) % 30),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               ROS_LOG_DIR=str(workdir / "ros_log"), OPENBLAS_NUM_THREADS="1")
    root = str(Path(__file__).resolve().parents[2])
    env["PYTHONPATH"] = os.pathsep.join([root, env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=3 * seconds + 120)
    if done.returncode != 0 or not stats.exists():
        said = (done.stdout + done.stderr)[-2000:]
        raise RuntimeError(f"gyro_sim_node failed on {path.name} (exit {done.returncode}):\n{said}")
    return json.loads(stats.read_text())


def node_table(runs: dict) -> str:
    head = ("| model | integrator | simulated s | real-time factor | step p50 (us) | step p99 (us) "
            "| deadline misses |\n"
            "|---|---|---:|---:|---:|---:|---:|\n")
    return head + "\n".join(
        f"| {name} | fixed | {st['node_time_s']:.3g} | {st['real_time_factor_achieved']:.3f} | "
        f"{st['step_time_p50_us']:.0f} | {st['step_time_p99_us']:.0f} | {st['deadline_misses']} |"
        for name, st in runs.items())


def cmd_bench_friction(args) -> int:
    from gyro_sim.bench.report import refused, write_report
    from gyro_sim.scene.load import SceneError, load_scene

    if refused(args, "friction"):
        return 2
    paths = [Path(p) for p in args.models] if args.models else default_models()
    if not paths:
        print("gyro-sim bench friction: no model: pass --models FILE (MJCF or URDF)", file=sys.stderr)
        return 2
    try:
        scenes = {p.name: load_scene(p) for p in paths}
    except SceneError as exc:
        print(f"gyro-sim bench friction: {exc}", file=sys.stderr)
        return 2
    durations = args.durations or (QUICK_DURATIONS if args.quick else DURATIONS)
    rows = []
    for name, scene in scenes.items():
        for integrator in args.integrators:
            for duration in durations:
                rows.append({"model": name, "law": "exact", "integrator": integrator,
                             **measure(scene, integrator, duration, args.push)})
                print(_row(rows[-1]), flush=True)
            if args.regularised:
                rows.append({"model": name, "law": "regularised", "integrator": integrator,
                             **measure(regularised(scene), integrator, args.regularised_duration, args.push)})
                print(_row(rows[-1]), flush=True)
    md = ("# Robots with dry joint friction\n\n"
          f"{time.strftime('%Y-%m-%d')}, `gyro-sim bench friction` "
          f"(durations {' '.join(f'{d:g}' for d in durations)} s"
          + (f", {args.push:g} N m on every axis for the first {PUSH_SECONDS:g} s" if args.push else "") + "): "
          "evaluations of y' and CPU seconds of the process per simulated second, `Simulator.advance"
          f"({STEP:g})` as the node calls it.\n\n" + table(rows) + "\n")
    runs = {}
    if args.node:
        import tempfile

        with tempfile.TemporaryDirectory(prefix="gyro_sim_friction_") as tmp:
            for i, path in enumerate(paths):
                runs[path.name] = run_node(path, args.node_seconds, Path(tmp), i)
        md += "\n### In the node (fixed, physics 1 kHz, publish 100 Hz)\n\n" + node_table(runs) + "\n"
    print(md)
    write_report(args.out, "friction", md, {"offline": rows, "node": runs}, lambda path: None, force=args.force)
    return 0


def _row(r: dict) -> str:
    if r["failed"]:
        why = "a non-finite state" if "not finite" in r["failed"] else "a simulation error"
        return f"| {r['model']} | {r['law']} | {r['integrator']} | {r['simulated_s']:.3g} | stopped by {why} | |"
    return (f"| {r['model']} | {r['law']} | {r['integrator']} | {r['simulated_s']:.3g} | "
            f"{r['evaluations_per_s']:.3g} | {r['cpu_per_s']:.3g} |")


def table(rows: list[dict]) -> str:
    head = ("| model | friction | integrator | simulated s | evaluations per simulated s | CPU s per simulated s |\n"
            "|---|---|---|---:|---:|---:|\n")
    return head + "\n".join(_row(r) for r in rows)
