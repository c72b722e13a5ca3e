"""`gyro-sim bench steps`: the CPU time of one 1 ms step, as the node takes it, on a family of
scenes (one body to a hundred, hinges, rotors, a tree) and integrators; with `--against DIR`, the
same runs of another source tree of gyro_sim (a checkout: an earlier version, a branch)
interleaved with this one's, and their ratio.

Each measurement is a process of its own (the tree's package first on its path, no background
cache fill): a Simulator of the scene with the integrator and step STEP, `advance(WARM_UP)`
first (compiles or loads the kernels: not counted), then BLOCKS blocks of `advance(BLOCK)`; the
figure is the median over the blocks of the process's CPU time per step. With `--against`,
each round runs the two trees one after the other, in alternating order (A B, then B A): a
drift of the machine's speed over the rounds falls on both alike, and the ratio of each round's
pair is what is compared (its median over the rounds, with the smallest and largest). CPU times
on a shared or throttled machine still vary by some percent from round to round: read the
spread beside the median.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: the node's physics step (s), the untimed first advance and one timed block (simulated s)
STEP = 1e-3
WARM_UP = 0.05
BLOCK = 0.5
#: timed blocks per measurement, and rounds (quick)
BLOCKS, QUICK_BLOCKS = 7, 3
ROUNDS, QUICK_ROUNDS = 5, 2
#: the shipped scenes of the family, then the synthetic spherical chains (`scenes.spherical_chain`,
#: rotors on every link) by their lengths
SHIPPED = ("heavy_top", "chain_4", "hinge_chain", "rw_pendulum", "free_chain_rotors", "spacecraft_panels")
CHAIN_SIZES = (20, 100)
QUICK_SHIPPED = ("heavy_top", "hinge_chain")
INTEGRATORS = ("rk4", "gauss4s")
QUICK_INTEGRATORS = ("rk4",)

BENCH_STEPS_EXAMPLES = """examples:
  gyro-sim bench steps
  gyro-sim bench steps --quick
  gyro-sim bench steps --against ../gyro_sim-1.4 --rounds 8
  gyro-sim bench steps --scenes heavy_top my_arm.yaml --integrators rk4 fixed"""

#: one measurement, run by the tree's own Python: scene, integrator, blocks -> a JSON line
_MEASURE = """
import json, sys, time, warnings
warnings.simplefilter("ignore")
scene, integrator, blocks = sys.argv[1], sys.argv[2], int(sys.argv[3])
step, warm, block = float(sys.argv[4]), float(sys.argv[5]), float(sys.argv[6])
try:
    from gyro_sim import Simulator
    sim = Simulator(scene, integrator=integrator, step=step)
    sim.advance(warm)
    per_step = []
    for _ in range(blocks):
        cpu = time.process_time()
        sim.advance(block)
        per_step.append((time.process_time() - cpu) / round(block / step))
    per_step.sort()
    print(json.dumps({"us": per_step[len(per_step) // 2] * 1e6}))
except Exception as exc:
    print(json.dumps({"refused": f"{type(exc).__name__}: {str(exc).splitlines()[0][:120]}"}))
"""


def register(sub, bench) -> None:
    p = bench.add_parser("steps", help="CPU per 1 ms step on a family of scenes; --against: beside another source tree",
                         epilog=BENCH_STEPS_EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenes", nargs="+", metavar="SCENE",
                   help=f"shipped scene names or scene files (default: {' '.join(SHIPPED)}, and spherical "
                        f"chains of {' and '.join(map(str, CHAIN_SIZES))} links with rotors)")
    p.add_argument("--integrators", nargs="+", metavar="NAME", help=f"default {' '.join(INTEGRATORS)}")
    p.add_argument("--against", metavar="DIR",
                   help="a source tree of gyro_sim (the directory holding its gyro_sim package) run interleaved "
                        "with this one")
    p.add_argument("--rounds", type=int, metavar="K", help=f"measurements per case and tree (default {ROUNDS})")
    p.add_argument("--quick", action="store_true", help="two scenes, rk4, fewer blocks and rounds")
    p.add_argument("--out", default="out/bench", help="directory for steps.md and .json")
    p.add_argument("--force", action="store_true", help="replace existing report files in --out")
    p.set_defaults(fn=cmd_bench_steps)


def this_tree() -> Path:
    """The directory holding the gyro_sim package this process runs."""
    return Path(__file__).resolve().parents[2]


def measure(tree: Path, scene: str, integrator: str, blocks: int) -> dict:
    """One measurement (module docstring) in a process running `tree`'s gyro_sim: {"us": median
    CPU us per step} or {"refused": the error's line} (a scene or integrator that tree refuses)."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, (str(tree), os.environ.get("PYTHONPATH")))),
               GYRO_SIM_BACKGROUND_FILL="0", OPENBLAS_NUM_THREADS="1")
    done = subprocess.run([sys.executable, "-c", _MEASURE, scene, integrator, str(blocks), repr(STEP),
                           repr(WARM_UP), repr(BLOCK)], env=env, cwd=str(tree), capture_output=True, text=True)
    lines = done.stdout.strip().splitlines()
    try:
        return json.loads(lines[-1])
    except (IndexError, json.JSONDecodeError):
        return {"refused": f"exit {done.returncode}: {(done.stderr.strip().splitlines() or [''])[-1][:120]}"}


def run(cases, trees: dict[str, Path], rounds: int, blocks: int, progress=print) -> list[dict]:
    """Every case (label, scene, integrator) measured `rounds` times in each tree, the trees'
    order alternating from round to round; a case refused by a tree is not measured again there."""
    rows = []
    names = list(trees)
    for label, scene, integrator in cases:
        row = {"scene": label, "integrator": integrator, **{name: [] for name in names}}
        for r in range(rounds):
            for name in (names if r % 2 == 0 else names[::-1]):
                if isinstance(row[name], str):
                    continue
                got = measure(trees[name], scene, integrator, blocks)
                row[name] = got["refused"] if "refused" in got else row[name] + [got["us"]]
        rows.append(row)
        progress(_line(row, names))
    return rows


def _median(x) -> float | None:
    return statistics.median(x) if isinstance(x, list) and x else None


def _line(row: dict, names: list[str]) -> str:
    cells = [f"{row['scene']} | {row['integrator']}"]
    for name in names:
        m = _median(row[name])
        cells.append(f"{m:.3f}" if m is not None else f"refused ({row[name].split(':')[0]})")
    if len(names) == 2:
        cells.append(_ratio(row, names))
    return "| " + " | ".join(cells) + " |"


def _ratio(row: dict, names: list[str]) -> str:
    a, b = row[names[0]], row[names[1]]
    if not (isinstance(a, list) and isinstance(b, list) and a and b):
        return ""
    pairs = [x / y for x, y in zip(a, b)]
    return f"{statistics.median(pairs):.3f} ({min(pairs):.3f} to {max(pairs):.3f})"


def table(rows: list[dict], names: list[str]) -> str:
    head = "| scene | integrator | " + " | ".join(f"{n}: us per step" for n in names)
    rule = "|---|---|" + "---:|" * len(names)
    if len(names) == 2:
        head += f" | {names[0]} / {names[1]}: median of the rounds (range)"
        rule += "---:|"
    return head + " |\n" + rule + "\n" + "\n".join(_line(r, names) for r in rows)


def cases(scenes, integrators, tmp: Path) -> list[tuple[str, str, str]]:
    """(label, scene path or name, integrator) for each scene and integrator; the synthetic
    chains written as scene files in `tmp` (every tree reads a file)."""
    import yaml

    from gyro_sim.bench.scenes import spherical_chain

    named = []
    for s in scenes:
        if s.startswith("chain:"):  # a synthetic chain of that many links
            n = int(s.split(":", 1)[1])
            path = tmp / f"spherical_chain_{n}.yaml"
            path.write_text(yaml.safe_dump(spherical_chain(n, rotors=True)))
            named.append((f"spherical chain, {n} links, rotors", str(path)))
        else:
            p = Path(s)
            named.append((p.stem if p.suffix else s, str(p.resolve()) if p.suffix else s))
    return [(label, scene, integrator) for label, scene in named for integrator in integrators]


def cmd_bench_steps(args) -> int:
    from gyro_sim.bench.report import refused, write_report

    if refused(args, "steps"):
        return 2
    trees = {"this tree": this_tree()}
    if args.against:
        other = Path(args.against).resolve()
        if not (other / "gyro_sim" / "__init__.py").is_file():
            print(f"gyro-sim bench steps: --against {args.against}: no gyro_sim package in that directory",
                  file=sys.stderr)
            return 2
        trees["against"] = other
    for s in args.scenes or ():
        if Path(s).suffix and not Path(s).is_file():
            print(f"gyro-sim bench steps: --scenes {s}: no such file", file=sys.stderr)
            return 2
    scenes = args.scenes or (list(QUICK_SHIPPED) if args.quick
                             else [*SHIPPED, *(f"chain:{n}" for n in CHAIN_SIZES)])
    integrators = args.integrators or (QUICK_INTEGRATORS if args.quick else INTEGRATORS)
    rounds = args.rounds or (QUICK_ROUNDS if args.quick else ROUNDS)
    if rounds < 1:
        print("gyro-sim bench steps: --rounds must be at least 1", file=sys.stderr)
        return 2
    blocks = QUICK_BLOCKS if args.quick else BLOCKS
    names = list(trees)
    print(table([], names).rstrip())
    with tempfile.TemporaryDirectory(prefix="gyro_sim_steps_") as tmp:
        rows = run(cases(scenes, integrators, Path(tmp)), trees, rounds, blocks)
    cpu = _cpu_name()
    md = ("# CPU per physics step\n\n"
          f"{time.strftime('%Y-%m-%d')}, `gyro-sim bench steps"
          + (f" --against {args.against}" if args.against else "") + "`"
          f"; {os.cpu_count()} cores{', ' + cpu if cpu else ''}. The median CPU time of one "
          f"`advance({STEP:g})` over {blocks} blocks of {round(BLOCK / STEP)} steps, in a process of its own, "
          f"{rounds} rounds per case" + (", the two trees in alternating order" if len(names) == 2 else "")
          + ".\n\n" + table(rows, names) + "\n")
    print()
    write_report(args.out, "steps", md, {"trees": {k: str(v) for k, v in trees.items()}, "rows": rows},
                 lambda path: None, force=args.force)
    return 0


def _cpu_name() -> str:
    """The processor's model name where the system says it ('' elsewhere)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()
