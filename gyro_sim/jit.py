"""numba's options for the cached kernels of gyro_sim, in one place.

:func:`njit`: nopython mode, cached on disk, IEEE arithmetic (no fastmath: results equal the
numpy reference to round-off) and numpy's error model (x / 0 -> inf rather than an exception:
non-finite states are caught by the integrators and the Simulator). Without numba a function
stays plain Python (correct, slow). The dynamics kernel (:mod:`gyro_sim.dynamics.kernel`) and
the compiled loops (:mod:`gyro_sim.integrators.rk4.loop`) add options of their own to these.
"""
from __future__ import annotations

try:
    import numba
except ImportError:  # pragma: no cover - exercised only where numba is missing
    numba = None


def njit(fn):
    """`fn` compiled in nopython mode and cached on disk (plain Python without numba)."""
    if numba is None:
        return fn
    return numba.njit(cache=True, error_model="numpy")(fn)
