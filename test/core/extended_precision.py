"""The compiled kernel's equations evaluated in 80-digit decimal arithmetic (a test oracle).

`NUMBA_DISABLE_JIT=1` makes gyro_sim.core.fast plain Python; its kernels are then run on object
arrays of :class:`X` (an 80-digit `decimal.Decimal` that mixes with Python floats), with the
module's `np.empty` / `np.zeros` and `math.sqrt` replaced by 80-digit twins. The inputs (model
arrays, state) are the float64 ones, converted exactly, so the result is the exact
accelerations of those inputs to ~1e-75: whatever elimination the kernel uses, in exact
arithmetic it solves the same closure rows (eqs 44, 51, 54). Hinges need sin/cos, which stay
float64: use it on spherical chains with a fixed base.

Run as a script (the JIT switch must be set before numba imports):

    NUMBA_DISABLE_JIT=1 python test/core/extended_precision.py RATIO...

prints, per mass ratio of `gyro_sim.bench.extreme.mass_ratio_chain`, the ratio and u' (N,)
as a JSON line.
"""
from __future__ import annotations

import decimal
import json
import math
import os
import subprocess
import sys
import types
from pathlib import Path

import numpy as np

#: significant digits of the evaluation
DIGITS = 80
_CTX = decimal.Context(prec=DIGITS)
_D = decimal.Decimal


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


def accelerations(model, y: np.ndarray, t: float = 0.0) -> np.ndarray:
    """u' (N,) of `model` at (t, y) in 80 digits (inputs held at zero); needs NUMBA_DISABLE_JIT."""
    from gyro_sim.core import fast

    if fast.numba is not None and not getattr(fast.numba.config, "DISABLE_JIT", False):
        raise RuntimeError("set NUMBA_DISABLE_JIT=1 before importing numba")
    fast.np, fast.math = _NumpyShim("numpy"), _MathShim("math")
    try:
        args = [*fast.model_arguments(model), *fast.input_arguments(model, t, None, None, None)]
        args = [_xarray(a) if isinstance(a, np.ndarray) else a for a in args]
        work = fast.np.zeros(fast.workspace(model).shape)
        ydot = fast.np.zeros(y.shape)
        fast.rhs_kernel(X(t), _xarray(y), ydot, work, *args)
    finally:
        fast.np, fast.math = np, math
    return np.array([float(v) for v in ydot[model.i_vel]])


def mass_ratio_accelerations(ratios) -> dict[float, np.ndarray]:
    """{ratio: u' in 80 digits} for `mass_ratio_chain(ratio)` at its initial state, computed
    in a subprocess (the JIT switch)."""
    env = {**os.environ, "NUMBA_DISABLE_JIT": "1"}
    proc = subprocess.run([sys.executable, str(Path(__file__).resolve()), *map(repr, ratios)],
                          env=env, capture_output=True, text=True, check=True)
    rows = [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("[")]
    return {r: np.array(u) for r, u in rows}


def main(argv: list[str]) -> None:
    from gyro_sim.bench.extreme import mass_ratio_chain
    from gyro_sim.core.model import compile_model, initial_state
    from gyro_sim.core.scene_load import load_scene

    for r in map(float, argv):
        model = compile_model(load_scene(mass_ratio_chain(r)))
        print(json.dumps([r, accelerations(model, initial_state(model)).tolist()]))


if __name__ == "__main__":
    main(sys.argv[1:])
