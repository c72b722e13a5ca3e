"""The compiled kernel's equations evaluated in 80-digit decimal arithmetic (a test oracle).

The oracle lives in the package (:mod:`gyro_sim.bench.heavy_tips`, which the stability report
runs from an installed package): `NUMBA_DISABLE_JIT=1` makes gyro_sim.dynamics.kernel plain Python,
and its kernels run on 80-digit numbers from the float64 inputs converted exactly, so the
result is the exact accelerations of those inputs to ~1e-75, whatever elimination the kernel
uses. Hinges' sin/cos stay float64: use it on spherical chains with a fixed base.

    accelerations(model, y)            # needs NUMBA_DISABLE_JIT=1 set before numba imports
    mass_ratio_accelerations(ratios)   # {ratio: u'} of mass_ratio_chain(ratio), in a subprocess
"""
from gyro_sim.bench.heavy_tips import accelerations_80 as accelerations
from gyro_sim.bench.heavy_tips import oracle as mass_ratio_accelerations

__all__ = ["accelerations", "mass_ratio_accelerations"]
