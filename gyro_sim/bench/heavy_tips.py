"""Heavy and light tips: the compiled accelerations against the numpy reference and 80 digits.

For `extreme.mass_ratio_chain(ratio)` (a three-body spherical chain whose tip is `ratio` x its
neighbour) at ratios RATIOS and their inverses, at its initial state: the accelerations u'
from the compiled (numba) kernel and from the numpy reference (a dense solve of the
composite-inertia matrix), and the same equations evaluated in 80-digit decimal arithmetic
(the oracle the tests use too, test/core/extended_precision.py; here so the report runs
from the installed package): the compiled kernel run as plain Python (NUMBA_DISABLE_JIT=1, in a
subprocess) on 80-digit numbers. Its inputs are the float64 ones, converted exactly, so it
gives the exact accelerations of those inputs to ~1e-75, whatever elimination the kernel uses.
Every difference is relative to the largest 80-digit acceleration.

Run as a script with NUMBA_DISABLE_JIT=1 (``python -m gyro_sim.bench.heavy_tips RATIO...``):
one JSON line [ratio, u'] per ratio.
"""
from __future__ import annotations

import decimal
import json
import math
import os
import subprocess
import sys
import types
from dataclasses import asdict, dataclass

import numpy as np

#: tip / neighbour mass ratios (and their inverses: light tips)
RATIOS = (1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8)
DIGITS = 80
_CTX = decimal.Context(prec=DIGITS)
_D = decimal.Decimal


# ------------------------------------------------------------------ the 80-digit oracle
def _cv(o):
    if isinstance(o, X):
        return o.v
    if isinstance(o, (bool, int, np.integer)):
        return _D(int(o))
    return _D(float(o))  # exact: every float is a finite decimal


class X:
    """An 80-digit decimal number that mixes with floats (converted exactly)."""

    __slots__ = ("v",)

    def __init__(self, v):
        self.v = v if isinstance(v, _D) else _cv(v)

    def __add__(self, o):
        return X(_CTX.add(self.v, _cv(o)))

    __radd__ = __add__

    def __sub__(self, o):
        return X(_CTX.subtract(self.v, _cv(o)))

    def __rsub__(self, o):
        return X(_CTX.subtract(_cv(o), self.v))

    def __mul__(self, o):
        return X(_CTX.multiply(self.v, _cv(o)))

    __rmul__ = __mul__

    def __truediv__(self, o):
        return X(_CTX.divide(self.v, _cv(o)))

    def __rtruediv__(self, o):
        return X(_CTX.divide(_cv(o), self.v))

    def __neg__(self):
        return X(-self.v)

    def __abs__(self):
        return X(abs(self.v))

    def __float__(self):
        return float(self.v)

    def __lt__(self, o):
        return self.v < _cv(o)

    def __le__(self, o):
        return self.v <= _cv(o)

    def __gt__(self, o):
        return self.v > _cv(o)

    def __ge__(self, o):
        return self.v >= _cv(o)

    def __eq__(self, o):
        return self.v == _cv(o)

    def __ne__(self, o):
        return self.v != _cv(o)

    __hash__ = None


def _xarray(a):
    a = np.asarray(a)
    if a.dtype.kind != "f":
        return a
    out = np.empty(a.shape, dtype=object)
    for i, v in np.ndenumerate(a):
        out[i] = X(float(v))
    return out


class _NumpyShim(types.ModuleType):
    """numpy, with float arrays made of X."""

    def __getattr__(self, name):
        return getattr(np, name)

    def zeros(self, shape, dtype=float):
        if dtype is not float:
            return np.zeros(shape, dtype)
        a = np.empty(shape, dtype=object)
        for i in np.ndindex(a.shape):
            a[i] = X(0)
        return a

    empty = zeros


class _MathShim(types.ModuleType):
    def __getattr__(self, name):
        return getattr(math, name)

    @staticmethod
    def sqrt(x):
        return X(_CTX.sqrt(_cv(x)))


def accelerations_80(model, y: np.ndarray, t: float = 0.0) -> np.ndarray:
    """u' (N,) of `model` at (t, y) in 80 digits (inputs held at zero); needs NUMBA_DISABLE_JIT
    (spherical chains on a fixed base: hinges' sin/cos stay float64)."""
    from gyro_sim.dynamics import kernel as fast

    if fast.numba is not None and not getattr(fast.numba.config, "DISABLE_JIT", False):
        raise RuntimeError("set NUMBA_DISABLE_JIT=1 before importing numba")
    fast.np, fast.math = _NumpyShim("numpy"), _MathShim("math")
    try:
        chain, data, inputs = fast.records(model)
        fast.hold(inputs, model, t, None, None, None)
        chain, inputs = (type(r)(*(_xarray(a) for a in r)) for r in (chain, inputs))
        data = data._replace(work=fast.np.zeros(data.work.shape))
        ydot = fast.np.zeros(y.shape)
        fast.rhs_kernel(X(t), _xarray(y), ydot, chain, data, inputs)
    finally:
        fast.np, fast.math = np, math
    return np.array([float(v) for v in ydot[model.i_vel]])


def oracle(ratios) -> dict[float, np.ndarray]:
    """{ratio: u' in 80 digits} of `mass_ratio_chain(ratio)` at its initial state (subprocess:
    the JIT switch must be set before numba imports)."""
    env = {**os.environ, "NUMBA_DISABLE_JIT": "1"}
    proc = subprocess.run([sys.executable, "-m", "gyro_sim.bench.heavy_tips", *map(repr, ratios)],
                          env=env, capture_output=True, text=True, check=True)
    rows = [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("[")]
    return {r: np.array(u) for r, u in rows}


# -------------------------------------------------------------------------------- table
@dataclass
class TipRow:
    ratio: float  # tip / neighbour
    kind: str  # heavy | light
    numba_numpy: float | None  # |numba - numpy| / max |u'|
    numba_oracle: float | None  # |numba - 80 digits| / max |u'|
    numpy_oracle: float  # |numpy - 80 digits| / max |u'|


def rows(ratios=RATIOS) -> list[TipRow]:
    from gyro_sim.bench.extreme import mass_ratio_chain
    from gyro_sim.dynamics import kernel as fast
    from gyro_sim.dynamics.model import compile_model, initial_state
    from gyro_sim.scene.load import load_scene
    from gyro_sim.dynamics.system import ChainODE, FastChainODE

    all_ratios = [*ratios, *(1.0 / r for r in ratios)]
    exact = oracle(all_ratios)
    out = []
    for r in all_ratios:
        model = compile_model(load_scene(mass_ratio_chain(r)))
        y = initial_state(model)
        ref = ChainODE(model).rhs(0.0, y)[model.i_vel]
        ex = exact[r]
        scale = float(np.abs(ex).max())
        comp = FastChainODE(model).rhs(0.0, y)[model.i_vel] if fast.available() else None
        out.append(TipRow(r, "heavy" if r > 1 else "light",
                          None if comp is None else float(np.abs(comp - ref).max() / scale),
                          None if comp is None else float(np.abs(comp - ex).max() / scale),
                          float(np.abs(ref - ex).max() / scale)))
    return out


def table(tip_rows: list[TipRow]) -> str:
    def g(x):
        return "n/a (no numba)" if x is None else f"{x:.1e}"

    lines = ["| tip | mass ratio (tip / neighbour) | \\|numba - numpy\\| | \\|numba - 80 digits\\| |"
             " \\|numpy - 80 digits\\| |", "|---|---:|---:|---:|---:|"]
    for kind in ("heavy", "light"):
        for r in (x for x in tip_rows if x.kind == kind):
            lines.append(f"| {kind} | {r.ratio:.0e} | {g(r.numba_numpy)} | {g(r.numba_oracle)} | "
                         f"{r.numpy_oracle:.1e} |")
    return "\n".join(lines)


def to_json(tip_rows: list[TipRow]) -> list[dict]:
    return [asdict(r) for r in tip_rows]


def main(argv: list[str]) -> None:
    from gyro_sim.bench.extreme import mass_ratio_chain
    from gyro_sim.dynamics.model import compile_model, initial_state
    from gyro_sim.scene.load import load_scene

    for r in map(float, argv):
        model = compile_model(load_scene(mass_ratio_chain(r)))
        print(json.dumps([r, accelerations_80(model, initial_state(model)).tolist()]))


if __name__ == "__main__":
    main(sys.argv[1:])
