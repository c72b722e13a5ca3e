"""Where a cold compile of the numba kernels goes: per compiled function, numba's own work
(bytecode analysis, type inference, lowering to LLVM IR) against LLVM's (optimisation and
machine code), in CPU and wall seconds.

    NUMBA_CACHE_DIR=$(mktemp -d) python -m gyro_sim.bench.compile_profile [WORKLOAD] [--json OUT]

WORKLOAD: "node" (a Simulator with the node's integrator "fixed" on the default scene, a
snapshot and a first advance; then its warm-up of the methods it may switch to; then a
Lagrange chain), or an integrator's name (a Simulator with it, a snapshot, an advance, its
warm-up). Run it with an empty NUMBA_CACHE_DIR: what is in the cache is loaded, not compiled.

Every compile of a numba dispatcher fires numba's "numba:compile" event (numba.core.event);
a callee compiled while its caller is typed nests inside the caller's event, so each
function's own time is its event's span minus its callees'. LLVM's share is the time spent
holding LLVM's lock ("numba:llvm_lock", every call into llvmlite's C++ library) while that
function is the innermost compiling. numba.cfunc compiles fire no event: they are timed here
the same way under the C function's name.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from collections import defaultdict
from dataclasses import asdict, dataclass, field

#: the scene every workload compiles on (one signature serves every scene)
SCENE = "hinge_chain"
#: a Lagrange chain (its integrals are compiled for its snapshots)
LAGRANGE_SCENE = "heavy_top"
#: simulated seconds of the first advance
FIRST_ADVANCE = 0.002
#: functions below this many CPU seconds are summed in one line of the table
SMALL = 0.3


@dataclass
class Compile:
    """One compile of one function: its own CPU and wall seconds (callees excluded), of which
    LLVM's; the phase it happened in; the outermost compile it happened for."""

    phase: str
    name: str
    cpu: float = 0.0
    wall: float = 0.0
    llvm_cpu: float = 0.0
    llvm_wall: float = 0.0
    root: str = ""


@dataclass
class _Frame:
    name: str
    cpu0: float
    wall0: float
    llvm_cpu: float = 0.0
    llvm_wall: float = 0.0
    child_cpu: float = 0.0
    child_wall: float = 0.0


@dataclass
class Profile:
    """Records every compile while installed (`install`)."""

    phase: str = ""
    compiles: list[Compile] = field(default_factory=list)
    outside_llvm_cpu: float = 0.0  # LLVM work outside any compile (loading cached code)
    _stack: list[_Frame] = field(default_factory=list)
    _llvm_depth: int = 0
    _llvm0: tuple[float, float] = (0.0, 0.0)

    def start(self, name: str) -> None:
        self._stack.append(_Frame(name, time.process_time(), time.perf_counter()))

    def end(self) -> None:
        f = self._stack.pop()
        cpu, wall = time.process_time() - f.cpu0, time.perf_counter() - f.wall0
        root = self._stack[0].name if self._stack else f.name
        self.compiles.append(Compile(self.phase, f.name, cpu - f.child_cpu, wall - f.child_wall, f.llvm_cpu,
                                     f.llvm_wall, root))
        if self._stack:
            self._stack[-1].child_cpu += cpu
            self._stack[-1].child_wall += wall

    def llvm_start(self) -> None:
        if self._llvm_depth == 0:
            self._llvm0 = (time.process_time(), time.perf_counter())
        self._llvm_depth += 1

    def llvm_end(self) -> None:
        self._llvm_depth -= 1
        if self._llvm_depth == 0:
            cpu, wall = time.process_time() - self._llvm0[0], time.perf_counter() - self._llvm0[1]
            if self._stack:
                self._stack[-1].llvm_cpu += cpu
                self._stack[-1].llvm_wall += wall
            else:
                self.outside_llvm_cpu += cpu

    def install(self) -> None:
        """Listen to numba's compile and LLVM-lock events, and time numba.cfunc compiles."""
        from numba.core import ccallback, event

        profile = self

        def name_of(fn) -> str:
            return f"{fn.__module__.removeprefix('gyro_sim.')}.{fn.__name__}"

        class Compiles(event.Listener):
            def on_start(self, ev):
                profile.start(name_of(ev.data["dispatcher"].py_func))

            def on_end(self, ev):
                profile.end()

        class Llvm(event.Listener):
            def on_start(self, ev):
                profile.llvm_start()

            def on_end(self, ev):
                profile.llvm_end()

        event.register("numba:compile", Compiles())
        event.register("numba:llvm_lock", Llvm())
        compile_cfunc = ccallback.CFunc.compile

        def timed(cfunc):
            profile.start(name_of(cfunc._pyfunc) + " (C function)")
            try:
                return compile_cfunc(cfunc)
            finally:
                profile.end()

        ccallback.CFunc.compile = timed

    def table(self) -> str:
        """Per phase: every function above SMALL CPU seconds, the rest summed; then per
        outermost compile; then the totals."""
        lines = []
        phases = list(dict.fromkeys(c.phase for c in self.compiles))
        for phase in phases:
            rows = sorted((c for c in self.compiles if c.phase == phase), key=lambda c: -c.cpu)
            cpu, llvm = sum(c.cpu for c in rows), sum(c.llvm_cpu for c in rows)
            lines.append(f"{phase}: {len(rows)} compiles, CPU {cpu:.1f} s (numba {cpu - llvm:.1f}, LLVM {llvm:.1f}), "
                         f"wall {sum(c.wall for c in rows):.1f} s")
            for c in rows:
                if c.cpu >= SMALL:
                    lines.append(f"  {c.name:44s} CPU {c.cpu:6.2f} (numba {c.cpu - c.llvm_cpu:5.2f}, "
                                 f"LLVM {c.llvm_cpu:5.2f})  wall {c.wall:6.2f}")
            small = [c for c in rows if c.cpu < SMALL]
            if small:
                lines.append(f"  {len(small)} more below {SMALL} s: CPU {sum(c.cpu for c in small):.2f}")
        roots: dict[tuple[str, str], list[float]] = defaultdict(lambda: [0.0, 0.0, 0.0])
        for c in self.compiles:
            r = roots[c.phase, c.root]
            r[0] += c.cpu
            r[1] += c.llvm_cpu
            r[2] += 1
        lines.append("by outermost compile (everything compiled for it):")
        for (phase, root), (cpu, llvm, n) in roots.items():
            lines.append(f"  [{phase}] {root:44s} CPU {cpu:6.1f} (LLVM {llvm:5.1f}), {int(n)} compiles")
        cpu, llvm = sum(c.cpu for c in self.compiles), sum(c.llvm_cpu for c in self.compiles)
        lines.append(f"total: CPU {cpu:.1f} s (numba {cpu - llvm:.1f}, LLVM {llvm:.1f}); "
                     f"LLVM outside compiles (loading) {self.outside_llvm_cpu:.2f} s")
        return "\n".join(lines)


def run(workload: str, profile: Profile) -> None:
    """Compile what `workload` (module docstring) needs, phase by phase."""
    from gyro_sim.simulator import Simulator

    integrator = "fixed" if workload == "node" else workload
    profile.phase = f"{integrator}: first step"
    sim = Simulator(SCENE, integrator=integrator, backend="numba")
    sim.snapshot()
    sim.advance(FIRST_ADVANCE)
    warm = getattr(sim.integrator, "warm_up", None)
    if warm is not None:
        profile.phase = f"{integrator}: warm-up of the other methods"
        warm(sim.time, sim.state)
    if workload == "node":
        profile.phase = "a Lagrange chain"
        Simulator(LAGRANGE_SCENE, integrator=integrator, backend="numba").snapshot()


def main(argv=None) -> int:
    from gyro_sim.integrators import INTEGRATORS

    ap = argparse.ArgumentParser(prog="python -m gyro_sim.bench.compile_profile", description=__doc__.splitlines()[0])
    ap.add_argument("workload", nargs="?", default="node", choices=["node", *INTEGRATORS])
    ap.add_argument("--json", help="also write every compile to this JSON file")
    args = ap.parse_args(argv)
    profile = Profile()
    profile.install()
    run(args.workload, profile)
    print(profile.table())
    if args.json:
        with open(args.json, "w") as f:
            json.dump([asdict(c) for c in profile.compiles], f, indent=0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
