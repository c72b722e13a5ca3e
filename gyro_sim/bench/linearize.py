"""`gyro-sim bench linearize`: the cost of one linearisation (gyro_sim.linear) against
Pinocchio's computeABADerivatives on the same chain.

The chain is the scaling report's (`gyro_sim.bench.scenes.spherical_chain`: n identical links on
spherical joints under gravity, swinging), linearised at its initial state; Pinocchio's model is
the same chain (`gyro_sim.bench.scaling.pin_chain`). Both are timed as CPU time of the calling
thread, the best of a few calls; the evaluations of the dynamics a linearisation takes
(1 + states + inputs complex-step directions, stacked through the numpy reference in passes of
`gyro_sim.linear.linearize.BATCH_ELEMENTS` directions x bodies) are counted, which does not
depend on the machine.
"""
from __future__ import annotations

import argparse
import time

SIZES = (10, 100)
QUICK_SIZES = (10,)

BENCH_LINEARIZE_EXAMPLES = """examples:
  gyro-sim bench linearize
  gyro-sim bench linearize --sizes 10 30 100 --out out/bench"""


def register(sub, bench) -> None:
    p = bench.add_parser("linearize", help="one linearisation against pinocchio's computeABADerivatives",
                         epilog=BENCH_LINEARIZE_EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--sizes", type=int, nargs="+", help=f"chain lengths (default {' '.join(map(str, SIZES))})")
    p.add_argument("--quick", action="store_true", help=f"n = {QUICK_SIZES[0]} only")
    p.add_argument("--out", default="out/bench", help="directory for linearize.md and .json")
    p.add_argument("--force", action="store_true", help="replace existing report files in --out")
    p.set_defaults(fn=cmd_bench_linearize)


def _best_cpu(fn, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.thread_time()
        fn()
        best = min(best, time.thread_time() - t0)
    return best


def measure(n: int) -> dict:
    """One row: states, evaluations, CPU seconds of one linearisation and of one
    computeABADerivatives (None without pinocchio)."""
    from gyro_sim import Simulator, load_scene
    from gyro_sim.bench.scaling import pin_chain
    from gyro_sim.bench.scenes import spherical_chain

    scene = spherical_chain(n)
    sim = Simulator(load_scene(scene), integrator="rk4", backend="numpy")
    lin = sim.linearize()
    ours = _best_cpu(sim.linearize, 3 if n <= 30 else 1)
    pin_s = None
    try:
        import pinocchio as pin

        model, data, q, v, tau = pin_chain(scene)
        pin.computeABADerivatives(model, data, q, v, tau)
        k = 100 if n <= 30 else 20
        pin_s = _best_cpu(lambda: [pin.computeABADerivatives(model, data, q, v, tau) for _ in range(k)], 5) / k
    except ImportError:
        pass
    return {"n": n, "states": len(lin.state_names), "evaluations": lin.evaluations, "linearize_s": ours,
            "pinocchio_aba_derivatives_s": pin_s, "ratio": None if pin_s is None else ours / pin_s}


def table(rows: list[dict]) -> str:
    lines = ["| n | states | evaluations | linearize (ms) | pinocchio computeABADerivatives (us) | ratio |",
             "|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        pin_us = "-" if r["pinocchio_aba_derivatives_s"] is None else f"{r['pinocchio_aba_derivatives_s'] * 1e6:.1f}"
        ratio = "-" if r["ratio"] is None else f"{r['ratio']:.0f}"
        lines.append(f"| {r['n']} | {r['states']} | {r['evaluations']} | {r['linearize_s'] * 1e3:.1f} "
                     f"| {pin_us} | {ratio} |")
    return "\n".join(lines)


def cmd_bench_linearize(args) -> int:
    from gyro_sim.bench.report import refused, write_report

    if refused(args, "linearize"):
        return 2
    sizes = args.sizes or (QUICK_SIZES if args.quick else SIZES)
    rows = [measure(n) for n in sizes]
    md = ("# One linearisation against pinocchio's computeABADerivatives\n\n"
          f"{time.strftime('%Y-%m-%d')}, `gyro-sim bench linearize --sizes {' '.join(map(str, sizes))}`: "
          "CPU time of the calling thread, best of a few calls, on the spherical chain of the scaling report.\n\n"
          + table(rows) + "\n")
    print(md)
    write_report(args.out, "linearize", md, rows, lambda path: None, force=args.force)
    return 0
