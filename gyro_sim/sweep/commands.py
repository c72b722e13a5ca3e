"""`gyro-sim sweep SWEEP.yaml`: many runs of one scene on Dask (gyro_sim.sweep)."""
from __future__ import annotations

import argparse
import contextlib
import logging
import signal
import sys
from pathlib import Path

SWEEP_EXAMPLES = """examples:
  gyro-sim sweep config/sweeps/kapitza.yaml --quick --out out/sweep/kapitza
  gyro-sim sweep config/sweeps/sleeping_top.yaml --workers 2 --out out/sweep/top
  gyro-sim sweep my_sweep.yaml --scheduler tcp://10.0.0.5:8786 --out results/ --resume

A shipped sweep is also taken by name (kapitza, sleeping_top, sleeping_top_linear, fixed_step).
Results: DIR/results.parquet (one row per point), DIR/summary.md, DIR/map.png; finished batches
in DIR/parts/ as they come."""


def register(sub, bench) -> None:
    p = sub.add_parser("sweep", help="many runs of one scene with varied parameters, on Dask",
                       epilog=SWEEP_EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("sweep", metavar="SWEEP.yaml", help="sweep file, or the name of a shipped sweep (config/sweeps/)")
    p.add_argument("--out", metavar="DIR", help="results directory (default out/sweep/<sweep file name>)")
    p.add_argument("--quick", action="store_true", help="the file's coarse version (its quick: entries)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--workers", type=int, metavar="N",
                   help="local Dask workers (processes, one thread each); default: the cores; "
                        "0: serially, without Dask")
    g.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask scheduler (tcp://host:8786)")
    h = p.add_mutually_exclusive_group()
    h.add_argument("--resume", action="store_true", help="continue the sweep in DIR: skip the points already done")
    h.add_argument("--force", action="store_true", help="delete the results of DIR first and start over")
    p.set_defaults(fn=cmd_sweep)


def find_sweep(name: str) -> Path:
    """A sweep file by path, or a shipped one by bare name (config/sweeps/<name>.yaml)."""
    from gyro_sim.paths import config_dirs

    p = Path(name).expanduser()
    if p.is_file() or Path(name).name != name:
        return p
    stem = name if name.endswith((".yaml", ".yml")) else name + ".yaml"
    for d in config_dirs():
        if (d / "sweeps" / stem).is_file():
            return d / "sweeps" / stem
    return p


#: optional modules the sweep needs, all in the `sweep` extra
SWEEP_MODULES = ("dask", "distributed", "pyarrow", "matplotlib")


def cmd_sweep(args) -> int:
    try:
        return _cmd_sweep(args)
    except ModuleNotFoundError as exc:
        top = (exc.name or "").split(".")[0]
        if top not in SWEEP_MODULES:
            raise
        print(f"gyro-sim sweep: needs {top}, not installed; install it with: pip install 'gyro_sim[sweep]'",
              file=sys.stderr)
        return 2


@contextlib.contextmanager
def _stop_on_signals():
    """SIGINT and SIGTERM end the sweep at once: the local cluster's worker processes are
    killed (`execute.stop_local_workers`) and Dask's logging, which would report their loss, is
    silenced; then Interrupted unwinds the driver, which keeps the finished parts."""
    from gyro_sim.safe_paths import Interrupted, raise_on_signals
    from gyro_sim.sweep.execute import stop_local_workers

    def handler(signum, frame):
        logging.disable(logging.CRITICAL)  # the command ends now: one line, from cmd_sweep
        stop_local_workers()
        raise Interrupted(signum)

    with raise_on_signals():  # restores the previous handlers on the way out
        old = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            yield
        finally:
            for s, h in old.items():
                signal.signal(s, h)


def _cmd_sweep(args) -> int:
    from gyro_sim.safe_paths import OutputError, check_output
    from gyro_sim.progress import Progress
    from gyro_sim.sweep import results as res
    from gyro_sim.sweep.execute import ClusterError, run
    from gyro_sim.sweep.spec import SweepError, load_sweep

    prog = "gyro-sim sweep"
    if args.workers is not None and args.workers < 0:
        print(f"{prog}: --workers must be >= 0", file=sys.stderr)
        return 2
    path = find_sweep(args.sweep)
    try:
        sweep = load_sweep(path, quick=args.quick)
    except SweepError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 2
    out = Path(args.out) if args.out else Path("out/sweep") / (path.stem + ("_quick" if args.quick else ""))
    # no silent overwrite: results there are continued (--resume) or replaced (--force), never mixed
    try:
        if out.exists() and not out.is_dir():
            raise OutputError(f"--out: {out}: exists and is not a directory")
        old = res.read_manifest(out) if out.is_dir() else None
        has_parts = out.is_dir() and any((out / res.PARTS).glob("points-*.parquet"))
        if (old is not None or has_parts) and not (args.resume or args.force):
            raise OutputError(f"--out: {out}: holds sweep results; refused to overwrite them (--resume to "
                              "continue that sweep, --force to start over, or another --out)")
        if args.resume and old is not None and old.get("digest") != sweep.digest():
            raise OutputError(f"--out: {out}: holds another sweep ({old.get('sweep', {}).get('name')!r}"
                              f"{', quick' if old.get('sweep', {}).get('quick') else ''}); --resume continues "
                              "only the same sweep file and options (--force to start over)")
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise OutputError(f"--out: {out}: cannot make the directory ({exc.strerror or exc})") from None
        inputs = [path, sweep.scene_path]
        for name in res.OWNED:
            check_output(out / name, inputs=inputs, force=args.force or args.resume, what="--out")
        if args.force:
            res.clear(out)
        res.write_manifest(out, sweep)  # the first file written: a directory refusing it is said now
    except OutputError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 2
    where = f"scheduler {args.scheduler}" if args.scheduler else \
        ("serially" if args.workers == 0 else f"{args.workers or 'default'} local workers")
    print(f"{prog}: {sweep.name}: {len(sweep.points)} points ({where}) -> {out}", file=sys.stderr)
    bar = Progress(f"sweep {path.stem}")
    try:
        with _stop_on_signals():
            stats = run(sweep, out, workers=args.workers, scheduler=args.scheduler,
                        progress=lambda done, total, extra: bar(done, total, extra), stream=sys.stderr)
    except ClusterError as exc:
        print(f"\n{prog}: {exc}; finished points are kept in {out / res.PARTS} (--resume)", file=sys.stderr)
        return 1
    rows = res.read_parts(out)
    if stats["interrupted"] and len(rows) < len(sweep.points):
        print(f"\n{prog}: interrupted: {len(rows)} of {len(sweep.points)} points done, kept in "
              f"{out / res.PARTS}; continue with --resume", file=sys.stderr)
        from gyro_sim.safe_paths import end_after_interrupt

        end_after_interrupt()
        return 1
    if len(rows) < len(sweep.points):
        print(f"{prog}: only {len(rows)} of {len(sweep.points)} points done; run again with --resume",
              file=sys.stderr)
        return 1
    try:
        done = res.finish(sweep, out, rows, stats)
    except ModuleNotFoundError:
        raise
    except OSError as exc:
        print(f"{prog}: writing the results in {out}: {exc}", file=sys.stderr)
        return 1
    print(done["summary"])
    print(f"{prog}: {out / res.RESULTS}, {out / res.SUMMARY}, {out / res.MAP}", file=sys.stderr)
    return 0
