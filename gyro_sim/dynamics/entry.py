"""One evaluation of the compiled dynamics called from Python at a small fixed cost.

numba unboxes every argument of a compiled function at each call from Python (each array
allocates a meminfo for its view: ~30 ns an array through the compiled entry point,
`gyro_sim.jit.Direct`, more through the dispatcher, which also types every argument): the
kernel's three records, 21 arrays, would cost ~1 us a call, as much as the kernel's own work on
a short chain. :func:`rhs_entry` takes four arguments instead, `(t, y, ydot, descriptor)`: the
descriptor of a workspace (`gyro_sim.dynamics.kernel.describe`, or its address as an int),
through which the kernel's C function finds the model, the workspace and the held inputs. The
results are those of the kernel called with the records, bit for bit.

    model, data, inputs = fast.records(m)                   # bound together
    entry = entry_point()                                   # compiled or loaded now
    entry(t, y, ydot, data.descriptor.ctypes.data)          # y' into ydot, counted
    data.descriptor[fast.D_NFEV]                            # the evaluations counted

Cached as :func:`gyro_sim.jit.njit_with_dependencies` caches: keyed on fast.py's files and this one.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from gyro_sim import jit
from gyro_sim.dynamics import kernel as fast
from gyro_sim.jit import numba

#: the files whose kernels rhs_entry compiles in (the key of its cache directory)
DEPENDENCIES = (*fast.DEPENDENCIES, Path(__file__))
_njit = jit.njit_with_dependencies(*DEPENDENCIES)


def _descriptor(d):
    """A workspace's descriptor, given as itself or (compiled code only) as its address (an
    int: no array for the entry point to unbox, ~0.03 us a call)."""
    return d


if jit.compiling():
    from numba.core import types
    from numba.extending import overload

    from gyro_sim.jit import address_of, call_address, vector_at

    @overload(_descriptor)
    def _descriptor_overload(d):
        if isinstance(d, types.Array):
            return lambda d: d
        if isinstance(d, types.Integer):
            return lambda d: vector_at(d, fast.DESCRIPTOR_SIZE, np.int64)
        return None

    @_njit
    def rhs_entry(t, y, ydot, descriptor):
        """y' (size,) at (t, y) into ydot: fast.rhs_kernel on the records `descriptor` (a
        workspace's, or its address, an int, which the caller keeps alive) describes, through
        the kernel's C function. Raises ValueError unless y is contiguous and of ydot's length
        (the kernel does not check its indices; a few ns here, ~0.1 us as numpy attribute reads
        before the call). Counts the evaluation in the descriptor's word D_NFEV (a few ns here,
        ~0.05 us as `self.nfev += 1`)."""
        if y.shape[0] != ydot.shape[0] or y.strides[0] != y.itemsize:
            raise ValueError("y must be a contiguous vector of the state's size")
        d = _descriptor(descriptor)
        d[fast.D_NFEV] += 1
        flags = vector_at(d[fast.D_MODEL + fast.MODEL_FLAGS], fast.FLAGS_SIZE, np.int64)
        call_address(flags[fast.FLAG_KERNEL], (t, address_of(y), address_of(ydot), y.shape[0], address_of(d)))


def entry_point():
    """rhs_entry's compiled entry point for (a float, two float64 C-contiguous vectors, a
    descriptor's address as an int64: `entry(t, y, ydot, data.descriptor.ctypes.data)`), compiled
    or loaded from the disk cache now: it converts its arguments to these types without checking
    them (as gyro_sim.jit.Direct). None where nothing compiles (`gyro_sim.jit.compiling`)."""
    if not jit.compiling():
        return None
    signature = (numba.float64, numba.float64[::1], numba.float64[::1], numba.int64)
    rhs_entry.compile(signature)
    return rhs_entry.overloads[signature].entry_point
