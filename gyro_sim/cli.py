"""`gyro-sim`: command-line tools over the core (run, bench)."""
from __future__ import annotations

import os

# The chain's matrices are small (N < 1000): a multi-threaded BLAS only adds synchronisation,
# and on 2 cores it fights the step loop (measured: n = 50 solve 5x slower). Must precede numpy.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import sys
import time
from pathlib import Path
from typing import Callable


# light on purpose: main's first statement sets what a signal does, and everything heavy
# (numpy, numba, the subcommands' modules) is imported after it
from gyro_sim.safe_paths import end_after_interrupt, exit_on_signals, interrupt_behind
from gyro_sim.progress import Progress  # cmd_run, cmd_bench_scaling


def cmd_run(args) -> int:
    from gyro_sim.scene.load import SceneError, load_scene
    from gyro_sim.scene.commands import model_options
    from gyro_sim.paths import find_scene

    try:
        scene = load_scene(find_scene(args.scene), **model_options(args))
    except (SceneError, FileNotFoundError) as exc:
        print(f"gyro-sim run: {exc}", file=sys.stderr)
        return 2
    log = None
    if args.record:  # no silent overwrite, never the scene file itself; published when closed
        from gyro_sim.safe_paths import AtomicOutput, OutputError

        try:
            log = AtomicOutput(args.record, inputs=[scene.path], force=args.force, what="--record")
        except OutputError as exc:
            print(f"gyro-sim run: {exc}", file=sys.stderr)
            return 2
    try:
        return _run(args, scene, log)
    finally:
        if log is not None:
            log.discard()  # nothing if published; the temporary file if the run ended otherwise


def _run(args, scene, log) -> int:
    """`gyro-sim run` once the scene is loaded and the log's temporary file (`log`) created."""
    from gyro_sim.simulator import SimulationError, Simulator
    from gyro_sim.log.mcap_log import LogError
    from gyro_sim.msgs.messages import NonFiniteError
    from gyro_sim.safe_paths import OutputError

    if log is not None and scene.imus:  # the log samples the IMUs at its publications
        from gyro_sim.dynamics.imu import check_rates

        problem = check_rates(scene, args.publish_rate)
        if problem is not None:
            print(f"gyro-sim run: {problem}", file=sys.stderr)
            return 2
    from gyro_sim.dynamics.actuators import ActuatorError

    try:
        sim = Simulator(scene, integrator=args.integrator, rtol=args.rtol, atol=args.atol, step=args.step)
    except ActuatorError as exc:  # the scene's actuators and the method asked for do not go together
        print(f"gyro-sim run: {exc}", file=sys.stderr)
        return 2
    inv0 = sim.reference_invariants()
    schedule = []
    if args.commands:
        from gyro_sim.log.record import read_schedule

        try:
            schedule = read_schedule(args.commands, sim.axis_names)
        except (ValueError, OSError, LogError) as exc:
            print(f"gyro-sim run: --commands {args.commands}: {exc}", file=sys.stderr)
            return 2
    chunk = min(args.chunk, args.duration)
    steps = max(1, int(round(args.duration / chunk)))
    bar = Progress(f"{scene.name}")
    wall0, cpu0 = time.perf_counter(), time.process_time()
    record = None
    try:
        if log is not None:
            import signal

            from gyro_sim.log.record import record_run

            # SIGINT / SIGTERM end the run at the next step and the log is closed cleanly: a
            # complete, well-formed log of the simulated span, published under its name
            stop = []
            handler = lambda signum, frame: stop.append(signum)  # noqa: E731
            old = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}
            try:
                record = record_run(sim, log.tmp, duration=args.duration, chunk=chunk, schedule=schedule,
                                    publish_rate=args.publish_rate, flush_period=args.flush_period,
                                    overwrite=True,
                                    progress=lambda t, total: bar(t, total, f"t = {t:.3f} s"),
                                    stop=lambda: bool(stop))
            finally:
                for sig, h in old.items():
                    signal.signal(sig, h)
            record.path = str(log.publish())
            if record.interrupted:
                print(f"\ngyro-sim run: interrupted at t = {sim.time:.3f} s of {args.duration:g}: the log up to "
                      f"there is closed and complete in {log.path}", file=sys.stderr)
                end_after_interrupt()
                return 1
        else:
            pending = list(schedule)
            for i in range(steps):
                while pending and pending[0][0] <= sim.time + 1e-9 * chunk:
                    sim.set_axis_moments(pending.pop(0)[1])
                sim.advance(args.duration / steps)
                bar(i + 1, steps, f"t = {sim.time:.3f} s")
    except SimulationError as exc:
        if log is None:
            print(f"gyro-sim run: stopped: {exc}", file=sys.stderr)
            return 1
        try:  # the log was closed when the error left record_run: it shows the run up to the error
            log.publish()
        except OutputError as err:
            print(f"gyro-sim run: stopped: {exc}; {err}", file=sys.stderr)
            return 1
        print(f"gyro-sim run: stopped: {exc}; the log up to t = {sim.time:.6g} s is in {log.path}", file=sys.stderr)
        return 1
    except OutputError as exc:  # another writer published the log's name meanwhile
        print(f"\ngyro-sim run: {exc}", file=sys.stderr)
        return 2
    except (LogError, NonFiniteError, OSError) as exc:
        print(f"gyro-sim run: log {args.record}: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as exc:
        print(f"\ngyro-sim run: interrupted ({getattr(exc, 'name', 'SIGINT')}) at t = {sim.time:.3f} s of "
              f"{args.duration:g}", file=sys.stderr)
        end_after_interrupt()
        return 1
    try:  # the work is done (and the log published): a signal now does not change that
        _report(args, scene, sim, inv0, record, wall0, cpu0)
    except KeyboardInterrupt:
        pass
    return 0


def _report(args, scene, sim, inv0, record, wall0, cpu0) -> None:
    """The summary `gyro-sim run` prints at the end."""
    from gyro_sim.dynamics.invariants import conserved

    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    snap = sim.snapshot(bodies=False, wrenches=False)
    inv1 = snap.invariants
    integ = sim.integrator
    print(f"scene:                     {scene.name} ({len(scene.bodies)} bodies, {sim.model.N} velocities)")
    print(f"integrator:                {args.integrator} (rtol {args.rtol:g}, atol {args.atol:g}, "
          f"step {args.step:g} s)")
    print(f"simulated:                 {sim.time:.6g} s in {cpu:.3f} s CPU, {wall:.3f} s wall: "
          f"real-time factor {sim.time / max(wall, 1e-9):.1f}")
    print(f"work:                      {integ.nsteps} steps, {integ.nrejected} rejected, "
          f"{sim.system.nfev} dynamics evaluations")
    for name, drift in snap.drift.items():
        print(f"{name + ' drift:':<26}{drift:.3e} (relative, conserved in this scene without commands)")
    if snap.work:
        print(f"{'work of the commands:':<26}{snap.work:.6g} J; energy balance E - E0 - W: "
              f"{snap.energy_balance / snap.energy_scale:.3e} (relative)" if snap.energy_balance is not None
              else f"{'work of the commands:':<26}{snap.work:.6g} J")
    for name in ("energy", "vertical_momentum"):
        if name not in conserved(sim.model):
            print(f"{name + ':':<26}{inv0[name]:.6g} -> {inv1[name]:.6g} (not conserved in this scene)")
    if record is not None:
        from gyro_sim.log.record import print_record

        print_record(record)


def cmd_bench_scaling(args) -> int:
    import dataclasses

    from gyro_sim.bench import scaling
    from gyro_sim.bench.report import refused, write_report

    if refused(args, "scaling"):
        return 2
    sizes = scaling.QUICK_SIZES if args.quick else tuple(args.sizes or scaling.DEFAULT_SIZES)
    rows = scaling.measure(sizes, min_time=0.05 if args.quick else 0.3, progress=Progress("scaling"))
    text = "### Scaling: cost against chain length\n\n" + scaling.table(rows)
    feat = scaling.features(quick=args.quick)
    text += "\n\n### Leaving out what a scene does not have\n\n" + scaling.features_table(feat)
    fixed = scaling.fixed_step(scaling.QUICK_FIXED_STEP_SIZES if args.quick else scaling.FIXED_STEP_SIZES,
                               seconds=0.2 if args.quick else 1.0,
                               repeats=1 if args.quick else scaling.FIXED_STEP_REPEATS)
    text += ("\n\n### One simulated second, RK4 at 1 kHz, beside MuJoCo (CPU, median of runs)\n\n"
             + scaling.fixed_step_table(fixed))
    tree_rows = scaling.trees(scaling.QUICK_TREE_SIZES if args.quick else scaling.TREE_SIZES,
                              min_time=0.05 if args.quick else 0.3)
    text += ("\n\n### Trees: one evaluation, the compiled kernel's own time, n links as a chain and as "
             "trees\n\n" + scaling.trees_table(tree_rows))
    mem = []
    if args.memory:
        mem = scaling.memory(scaling.QUICK_MEMORY_SIZES if args.quick else scaling.MEMORY_SIZES,
                             scaling.QUICK_MEMORY_INTEGRATORS if args.quick else scaling.MEMORY_INTEGRATORS,
                             progress=Progress("memory"))
        text += (f"\n\n### Memory: {scaling.MEMORY_SECONDS:g} s of a long chain, every integrator "
                 "(peak resident memory of a process of its own)\n\n" + scaling.memory_table(mem))
    print(text)
    data = {"rows": [dataclasses.asdict(r) if dataclasses.is_dataclass(r) else r for r in rows],
            "fixed_step": [dataclasses.asdict(r) for r in fixed], "memory": [dataclasses.asdict(r) for r in mem],
            "trees": tree_rows}
    write_report(args.out, "scaling", text + "\n", data, lambda png: scaling.plot(rows, png), force=args.force,
                 json_default=str)
    return 0


#: `gyro-sim --help`, after the list of commands (every line that starts with gyro-sim is run or
#: parsed by test/test_examples.py)
EXAMPLES = """examples:
  gyro-sim run --scene double_gyro_plus --duration 10
  gyro-sim run --scene hinge_chain --duration 10 --record run.mcap
  gyro-sim view run.mcap --save run.rrd
  gyro-sim replay --resimulate run.mcap
  gyro-sim recover broken.mcap -o fixed.mcap
  gyro-sim cmd --scene hinge_chain --seconds 15 sine --amplitude 0.002 0.05 0.03 --frequency 0.5
  gyro-sim bench scaling --quick

Each command lists its options with --help after it. Shipped scenes (config/) are taken by
name from anywhere; the node is gyro_sim_node (gyro_sim_node --help)."""

BENCH_EXAMPLES = """examples:
  gyro-sim bench scaling --quick
  gyro-sim bench accuracy --quick --out out/bench
  gyro-sim bench stability --quick
  gyro-sim bench realtime --quick
  gyro-sim bench loop --rates 100 1000

Each writes <report>.md and <report>.png to --out (default out/bench)."""


# Modules that add their own subcommands: each has `register(sub, bench)` (sub: the top-level
# subparsers, bench: the `gyro-sim bench` subparsers) and imports heavy dependencies lazily.
PLUGINS = (
    "gyro_sim.log.commands",  # recover
    "gyro_sim.viz.commands",  # view (a log, or --live)
    "gyro_sim.ros.commands",  # cmd (publish axis moments)
    "gyro_sim.bench.accuracy",
    "gyro_sim.bench.stability",
    "gyro_sim.bench.realtime",
    "gyro_sim.bench.loop",  # bench loop (a controller over DDS)
    "gyro_sim.bench.publication",
    "gyro_sim.sweep.commands",  # sweep (many runs on Dask)
    "gyro_sim.scene.commands",  # import (an MJCF or URDF model as a scene)
    "gyro_sim.bench.soak",
    "gyro_sim.bench.startup",
    "gyro_sim.linear.commands",  # linearize (the linear model at a state)
    "gyro_sim.bench.linearize",  # bench linearize (its cost against pinocchio)
    "gyro_sim.bench.friction",  # bench friction (robots with dry joint friction)
    "gyro_sim.bench.steps",  # bench steps (CPU per physics step, beside another source tree)
    "gyro_sim.warmup",  # warmup (the kernel cache filled in the foreground)
)


# --- replay ------------------------------------------------------------------------------------------
def cmd_replay(args) -> int:
    """`gyro-sim replay`: a log's topics published on ROS 2, or the log re-simulated."""
    import signal

    from gyro_sim.log.commands import input_file
    from gyro_sim.log.mcap_log import LogError

    if not input_file("replay", args.log):
        return 2
    if args.resimulate:
        from gyro_sim.simulator import SimulationError
        from gyro_sim.log.resim import resimulate

        try:
            res = resimulate(args.log, integrator=args.integrator, rtol=args.rtol, atol=args.atol)
        except SimulationError as exc:
            _err_replay(exc)
            return 1
        except (LogError, ValueError, OSError) as exc:  # damaged or crafted log, bad option: bad input
            _err_replay(exc)
            return 2
        print(res.report())
        return 0 if (res.max_deviation <= args.tolerance and res.compared) else 1
    try:
        import rclpy  # noqa: F401
    except ImportError as exc:
        _err_replay(f"needs rclpy ({exc}): pip install 'gyro_sim[ros]', or source a ROS 2 Jazzy install")
        return 2
    from gyro_sim.ros.replay import replay

    stop = []
    old = signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    try:
        stats = replay(args.log, rate=args.rate, loop=args.loop, topics=args.topics,
                       wait_for_subscribers=args.wait_for_subscribers, should_stop=lambda: bool(stop))
    except (LogError, OSError) as exc:
        _err_replay(exc)
        return 2
    except KeyboardInterrupt:
        return 0
    finally:
        signal.signal(signal.SIGTERM, old)
    print(stats.report())
    return 0


def _err_replay(msg) -> None:
    print(f"gyro-sim replay: {msg}", file=sys.stderr)


def _register_replay(sub) -> None:
    """Add replay to the `gyro-sim` subparsers."""
    r = sub.add_parser("replay", help="publish a log's topics on ROS 2 at recorded pace, or re-simulate it")
    r.add_argument("log", help="an MCAP log")
    r.add_argument("--rate", type=float, default=1.0, help="speed factor (2: twice as fast as recorded)")
    r.add_argument("--loop", action="store_true", help="start again at the end, until Ctrl-C")
    r.add_argument("--topics", nargs="+", metavar="TOPIC", help="only these topics")
    r.add_argument("--wait-for-subscribers", type=float, default=0.0, metavar="S",
                   help="wait up to S seconds for a subscriber on every topic before starting")
    r.add_argument("--resimulate", action="store_true",
                   help="no ROS: re-run the embedded scene with the recorded commands and report the "
                        "largest deviation from the logged joint states (0 expected)")
    r.add_argument("--integrator", help="re-simulate with another integrator than the recorded one")
    r.add_argument("--rtol", type=float, help="re-simulate with another rtol")
    r.add_argument("--atol", type=float, help="re-simulate with another atol")
    r.add_argument("--tolerance", type=float, default=0.0,
                   help="exit status 1 when the deviation exceeds this (default 0: bit for bit)")
    r.set_defaults(fn=cmd_replay)


def build_parser() -> argparse.ArgumentParser:
    import importlib

    from gyro_sim.log.mcap_log import DEFAULT_FLUSH_PERIOD

    ap = argparse.ArgumentParser(prog="gyro-sim", description="Chains of gyrostats: offline runs, logs and reports.",
                                 epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", title="commands", metavar="COMMAND")
    r = sub.add_parser("run", help="simulate a scene offline, as fast as possible")
    r.add_argument("--scene", required=True,
                   help="scene file, an MJCF or URDF model (docs/models.md), or the name of a shipped scene (config/)")
    r.add_argument("--keyframe", metavar="NAME",
                   help="models only: the keyframe of the initial state and of the servos' controls "
                   "(default: the model's first; none: rest)")
    from gyro_sim.scene.commands import add_model_options

    add_model_options(r)
    r.add_argument("--duration", type=float, required=True, help="simulated seconds")
    r.add_argument("--integrator", default="auto",
                   help="auto (dop853, switching to radau when stiff) | dop853 | radau | rk4 | lie4 | gauss4 | fixed")
    r.add_argument("--rtol", type=float, default=1e-10)
    r.add_argument("--atol", type=float, default=1e-12)
    r.add_argument("--step", type=float, default=1e-3, help="step of fixed-step methods (s)")
    r.add_argument("--chunk", type=float, default=0.01, help="simulated seconds per advance() call")
    r.add_argument("--commands", metavar="FILE",
                   help="axis moments to apply: a YAML list of [t, [one value per axis]], or a gyro_sim log "
                        "(.mcap) whose /gyro_sim/axis_moments are replayed at their log times")
    r.add_argument("--record", metavar="OUT.mcap",
                   help="record an MCAP log (ROS 2 messages; view with gyro-sim view). It is written as "
                        ".OUT.<random>.partial.mcap beside OUT.mcap and renamed when closed (also on Ctrl-C "
                        "or SIGTERM); after SIGKILL, `gyro-sim recover` reads the .partial file")
    r.add_argument("--publish-rate", type=float, default=100.0, help="messages per simulated second in the log (Hz)")
    r.add_argument("--flush-period", type=float, default=DEFAULT_FLUSH_PERIOD,
                   help="wall-clock seconds between flushes of the log (what a crash can lose)")
    r.add_argument("--force", action="store_true", help="replace an existing --record file (never the scene)")
    r.set_defaults(fn=cmd_run)
    b = sub.add_parser("bench", help="benchmarks and reports", epilog=BENCH_EXAMPLES,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    bsub = b.add_subparsers(dest="bench", title="reports", metavar="REPORT")
    b.set_defaults(fn=None, help_of=b)
    s = bsub.add_parser("scaling", help="cost per evaluation and per simulated second against chain length")
    s.add_argument("--sizes", type=int, nargs="+")
    s.add_argument("--quick", action="store_true", help="small sizes, short timings (CI)")
    s.add_argument("--memory", action="store_true",
                   help="also the peak memory of 0.1 s at n = 1000 and 5000 with every integrator "
                        "(minutes; quick: n = 300)")
    s.add_argument("--out", default="out/bench", help="directory for scaling.md, .json and .png")
    s.add_argument("--force", action="store_true", help="replace existing report files in --out")
    s.set_defaults(fn=cmd_bench_scaling)
    _register_replay(sub)
    for name in PLUGINS:
        try:
            mod = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name and name.startswith(exc.name):  # not built yet
                continue
            raise
        mod.register(sub, bsub)
    ap.set_defaults(fn=None, help_of=ap)
    return ap


#: the extra that installs an optional module (by its top-level import name)
EXTRAS = {"rerun": "viz", "rclpy": "ros", "rpyutils": "ros", "matplotlib": "bench", "mujoco": "bench",
          "pinocchio": "bench"}


def extra_for(module: str | None) -> str | None:
    """The gyro_sim extra that provides `module` (ROS message packages: "ros"), else None."""
    top = (module or "").split(".")[0]
    if top.endswith(("_msgs", "_srvs", "_interfaces")) or top.startswith("rosidl"):
        return "ros"
    return EXTRAS.get(top)


def _quiet(unraisable) -> None:
    """An unraisable-exception hook that says nothing (after an interrupt was reported)."""


def _compile_first(args) -> None:
    """`run` and `replay --resimulate` build a Simulator: on a cold numba cache, say that the
    first one compiles (gyro_sim.warmup) instead of staying silent for seconds."""
    if args.cmd == "run":
        from gyro_sim.scene.load import SceneError, load_scene
        from gyro_sim.scene.commands import model_options
        from gyro_sim.paths import find_scene

        try:
            load_scene(find_scene(args.scene), **model_options(args))
        except (SceneError, FileNotFoundError):
            return  # cmd_run reports it, with nothing compiled
    elif args.cmd == "replay" and getattr(args, "resimulate", False) and Path(args.log).is_file():
        from gyro_sim.log.mcap_log import LogError
        from gyro_sim.log.resim import prepare

        try:  # a damaged or crafted log is refused before anything is compiled
            prepare(args.log, integrator=args.integrator)
        except (LogError, OSError):
            return  # cmd_replay reports it
    else:
        return
    from gyro_sim.warmup import precompile

    precompile(sys.stderr, prog=f"gyro-sim {args.cmd}", integrator=getattr(args, "integrator", None) or "auto")


def _interrupted(args, exc: KeyboardInterrupt) -> int:
    """Say that the command was interrupted (by `exc`, SIGINT or SIGTERM) and end it: exit 1."""
    print(f"\ngyro-sim {args.cmd}: interrupted ({getattr(exc, 'name', 'SIGINT')}) before finishing; "
          "no output is left half-written under its name", file=sys.stderr)
    # what the interrupt cut half-way (a library object whose constructor it stopped) may
    # fail again when collected at exit: that is not news after the line above
    sys.unraisablehook = _quiet
    end_after_interrupt()
    return 1


def _interrupted_line(argv) -> Callable[[str], str]:
    """The line of an interrupt before the command runs (`_interrupted`'s, its name guessed
    from the command line: the first word that is not an option)."""
    words = sys.argv[1:] if argv is None else list(argv)
    cmd = next((" " + w for w in words if not w.startswith("-")), "")
    return lambda name: (f"gyro-sim{cmd}: interrupted ({name}) before finishing; no output is left half-written "
                         "under its name")


def _warnings_in_one_line(prog: str):
    """A warning this command prints (an integrator's switch, a library's) in one line, its
    kind and message, without the source line Python quotes by default. Returns the previous
    format, for `main` to put back when it returns (a caller in the same process keeps its own)."""
    import warnings

    previous = warnings.formatwarning
    warnings.formatwarning = lambda message, category, *_, **__: f"{prog}: {category.__name__}: {message}\n"
    return previous


class _ReaderMayLeave:
    """Standard output (or error) whose reader may close it early (`gyro-sim import m.xml |
    head -1`): the first write that finds the pipe closed sends this and every later write to
    the null device (the descriptor itself, so that the interpreter's last flush finds nothing
    to complain about), and the command goes on to its end and its own exit status: what it
    writes to files is written, what it prints after that is dropped."""

    def __init__(self, stream):
        self._stream = stream

    def _guarded(self, call, *args):
        try:
            return call(*args)
        except BrokenPipeError:
            null = os.open(os.devnull, os.O_WRONLY)
            try:
                os.dup2(null, self._stream.fileno())
            finally:
                os.close(null)
            return None

    def write(self, text):
        self._guarded(self._stream.write, text)
        return len(text)

    def flush(self):
        self._guarded(self._stream.flush)

    def __getattr__(self, name):
        return getattr(self._stream, name)


def main(argv=None) -> int:
    """`gyro-sim`: the command `argv` names (sys.argv's by default); its exit status."""
    streams = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = (s if s is None or isinstance(s, _ReaderMayLeave) else _ReaderMayLeave(s)
                              for s in streams)
    try:
        return _main(argv)
    finally:
        sys.stdout, sys.stderr = streams


def _main(argv) -> int:
    # a signal during the imports and the parser's construction: one line and exit 1, as later
    exit_on_signals(_interrupted_line(argv), 1)
    ap = build_parser()
    args = ap.parse_args(argv)
    if args.fn is None:  # `gyro-sim` or `gyro-sim bench` alone: what there is to choose from
        args.help_of.print_help(sys.stderr)
        return 2
    if getattr(args, "duration", None) is not None and args.duration <= 0:
        ap.error("--duration must be > 0")
    import warnings

    previous_format = _warnings_in_one_line(f"gyro-sim {args.cmd}")
    from gyro_sim.safe_paths import OutputError, raise_on_signals

    try:
        with raise_on_signals():  # SIGTERM unwinds like Ctrl-C: temporary outputs are removed
            _compile_first(args)
            return args.fn(args)
    except KeyboardInterrupt as exc:  # SIGINT or SIGTERM where the command does not handle it
        return _interrupted(args, exc)
    except OutputError as exc:  # an output taken by another writer while this one worked
        print(f"gyro-sim {args.cmd}: {exc}", file=sys.stderr)
        return 2
    except ModuleNotFoundError as exc:
        extra = extra_for(exc.name)
        if extra is None:
            raise
        print(f"gyro-sim {args.cmd}: needs {exc.name.split('.')[0]}, not installed; "
              f"install it with: pip install 'gyro_sim[{extra}]'", file=sys.stderr)
        return 2
    except Exception as exc:  # only to find a signal Python wrapped (interrupt_behind)
        interrupt = interrupt_behind(exc)
        if interrupt is None:
            raise
        return _interrupted(args, interrupt)
    finally:
        warnings.formatwarning = previous_format


if __name__ == "__main__":
    sys.exit(main())
