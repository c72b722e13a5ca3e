"""One evaluation of the compiled dynamics called from Python at a small fixed cost.

numba unboxes every argument of a compiled function at each call from Python (each array
allocates a meminfo for its view: ~30 ns an array through the compiled entry point,
`gyro_sim.jit.Direct`, more through the dispatcher, which also types every
argument): the 24 arguments of :func:`gyro_sim.dynamics.kernel.rhs_kernel` cost ~2-3 us a call,
more than the kernel's own work on a short chain. Here the kernel's arrays live in one float64
buffer built once (`pack`: a header of sizes and offsets, the floats, the ints as int64 bit
patterns, is_hinge as bytes), and :func:`rhs_entry` takes four arguments, `(t, y, ydot, buf)`:
it cuts the buffer into the kernel's arrays (`gyro_sim.jit.block1/2/3`, the views the kernel cuts its
workspace with: C-ordered, of the same types as every other caller passes, so the kernel's one
specialisation serves it) and calls the
kernel. The results are those of the kernel called with the separate arrays, bit for bit.

    buf = pack(work, model_args, inputs)   # fast.workspace, fast.model_arguments,
                                           # fast.input_arguments
    set_inputs(buf, inputs)                # after a new hold, in place
    kernel_arguments(buf)                  # the kernel's 21 arguments as views of buf
    rhs_entry(t, y, ydot, buf)             # compiled: y' into ydot, counted in the header
    buf.view(np.int64)[H_NFEV]             # the evaluations counted

Cached as :func:`gyro_sim.jit.njit_with_dependencies` caches: rhs_entry compiles the kernel into
itself, so its cache is keyed on fast.py's files and this one.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from gyro_sim import jit
from gyro_sim.dynamics import kernel as fast
from gyro_sim.jit import block1, block2, block3, numba

#: the files whose kernels rhs_entry compiles in (the key of its cache directory)
DEPENDENCIES = (*fast.DEPENDENCIES, Path(__file__))
_njit = jit.njit_with_dependencies(*DEPENDENCIES)

# the header, the buffer's first HEADER words read as int64: the sizes, then the word where
# each block starts (floats, ints as int64, is_hinge as bytes)
H_N, H_NCOL, H_NT = 0, 1, 2
(H_WORK, H_HINGE_AXIS, H_S, H_MASS, H_FIRST_MOMENT, H_INERTIA, H_LAM_SPEED, H_TORQUE_AXIS,
 H_TORQUE_A, H_BASE, H_T0, H_P0, H_PDOT, H_L, H_TAU) = range(3, 18)
H_QROW, H_OWN_COL, H_COL_START, H_TORQUE_BODY, H_FLAGS, H_IS_HINGE = range(18, 24)
#: a counter (int64) of the evaluations rhs_entry ran on this buffer (FastChainODE.nfev); the
#: buffer's length in words
H_NFEV, H_WORDS = 24, 25
HEADER = 26
#: the float arrays of model_arguments as they sit in the buffer, by their header entries
_MODEL_FLOATS = ((4, H_HINGE_AXIS), (5, H_S), (6, H_MASS), (7, H_FIRST_MOMENT), (8, H_INERTIA),
                 (9, H_LAM_SPEED), (11, H_TORQUE_AXIS), (12, H_TORQUE_A), (14, H_BASE))
_MODEL_INTS = ((1, H_QROW), (2, H_OWN_COL), (3, H_COL_START), (10, H_TORQUE_BODY), (13, H_FLAGS))
_INPUTS = ((1, H_P0), (2, H_PDOT), (3, H_L), (4, H_TAU))
#: where the held t0 (a float) sits in `kernel_arguments`
T0_ARGUMENT = 16
_WORD = 8  # bytes of a float64 and an int64


def pack(work: np.ndarray, model_args: tuple, inputs: tuple) -> np.ndarray:
    """The workspace (fast.workspace), the model's arrays (fast.model_arguments) and the held
    inputs (fast.input_arguments) in one float64 buffer: a header, the floats, the ints (their
    int64 bit patterns) and is_hinge (bytes)."""
    n, N, nt = len(model_args[0]), len(inputs[4]), len(model_args[10])
    floats = [(H_WORK, work)] + [(h, model_args[i]) for i, h in _MODEL_FLOATS]
    floats += [(H_T0, np.array([inputs[0]]))] + [(h, inputs[i]) for i, h in _INPUTS]
    ints = [(h, model_args[i]) for i, h in _MODEL_INTS]
    header = np.zeros(HEADER, dtype=np.int64)
    header[[H_N, H_NCOL, H_NT]] = n, N, nt
    o = HEADER
    for h, a in floats + ints:
        header[h] = o
        o += a.size
    header[H_IS_HINGE] = o
    header[H_WORDS] = o + -(-n // _WORD)
    buf = np.zeros(header[H_WORDS])
    words = buf.view(np.int64)
    words[:HEADER] = header
    for h, a in floats:
        buf[header[h]:header[h] + a.size] = np.ravel(a)
    for h, a in ints:
        words[header[h]:header[h] + a.size] = np.ravel(a)
    buf.view(np.bool_)[_WORD * o:_WORD * o + n] = model_args[0]
    return buf


def set_inputs(buf: np.ndarray, inputs: tuple) -> None:
    """Write held inputs (fast.input_arguments) into the buffer in place."""
    header = buf.view(np.int64)
    buf[header[H_T0]] = inputs[0]
    for i, h in _INPUTS:
        a = inputs[i]
        buf[header[h]:header[h] + a.size] = a


def kernel_arguments(buf: np.ndarray) -> tuple:
    """The arguments of fast.rhs_kernel after (t, y, ydot) as rhs_entry passes them: numpy
    views of the buffer (t0 a float, read now)."""
    words = buf.view(np.int64)
    n, N, nt = (int(x) for x in words[[H_N, H_NCOL, H_NT]])

    def f(h, *shape):
        o = words[h]
        return buf[o:o + int(np.prod(shape))].reshape(shape)

    def i(h, size):
        o = words[h]
        return words[o:o + size]

    o = _WORD * int(words[H_IS_HINGE])
    return (f(H_WORK, words[H_HINGE_AXIS] - words[H_WORK]), buf.view(np.bool_)[o:o + n],
            i(H_QROW, n), i(H_OWN_COL, n), i(H_COL_START, n + 1), f(H_HINGE_AXIS, n, 3),
            f(H_S, n, 3), f(H_MASS, n), f(H_FIRST_MOMENT, n, 3), f(H_INERTIA, n, 3, 3),
            f(H_LAM_SPEED, n, 3), i(H_TORQUE_BODY, nt), f(H_TORQUE_AXIS, nt, 3), f(H_TORQUE_A, nt),
            i(H_FLAGS, fast.FLAGS_SIZE), f(H_BASE, 7), float(buf[words[H_T0]]), f(H_P0, nt), f(H_PDOT, nt),
            f(H_L, nt), f(H_TAU, N))


def _buffer(buf):
    """The buffer of `pack`, given as itself or (compiled code only) as its address
    (`buf.ctypes.data`, an int: no array for the entry point to unbox, ~0.03 us a call)."""
    return buf


if jit.compiling():
    from numba.core import types
    from numba.extending import overload

    from gyro_sim.jit import vector_at

    @overload(_buffer)
    def _buffer_overload(buf):
        if isinstance(buf, types.Array):
            return lambda buf: buf
        if isinstance(buf, types.Integer):  # its address: its length in its header
            return lambda buf: vector_at(buf, vector_at(buf, HEADER, np.float64).view(np.int64)[H_WORDS],
                                         np.float64)
        return None


@_njit
def rhs_entry(t, y, ydot, buf):
    """y' (size,) at (t, y) into ydot: fast.rhs_kernel on the arrays packed in buf (`pack`;
    or its address, an int, which the caller keeps alive).
    Raises ValueError unless y is contiguous and of ydot's length (the kernel does not check
    its indices; a few ns here, ~0.1 us as numpy attribute reads before the call). Counts the
    evaluation in the header's word H_NFEV (a few ns here, ~0.05 us as `self.nfev += 1`)."""
    if y.shape[0] != ydot.shape[0] or y.strides[0] != y.itemsize:
        raise ValueError("y must be a contiguous vector of the state's size")
    buf = _buffer(buf)
    h = buf.view(np.int64)
    h[H_NFEV] += 1
    n, N, nt = h[H_N], h[H_NCOL], h[H_NT]
    w0, ha = h[H_WORK], h[H_HINGE_AXIS]
    # the views fast.rhs_kernel cuts its workspace with: C-ordered, uncounted
    is_hinge = block1(buf.view(np.bool_), _WORD * h[H_IS_HINGE], n)
    b1, b2, b3 = block1, block2, block3
    fast.rhs_call(
        t, y, ydot, b1(buf, w0, ha - w0), is_hinge, b1(h, h[H_QROW], n), b1(h, h[H_OWN_COL], n),
        b1(h, h[H_COL_START], n + 1), b2(buf, ha, n, 3), b2(buf, h[H_S], n, 3), b1(buf, h[H_MASS], n),
        b2(buf, h[H_FIRST_MOMENT], n, 3), b3(buf, h[H_INERTIA], n, 3, 3), b2(buf, h[H_LAM_SPEED], n, 3),
        b1(h, h[H_TORQUE_BODY], nt), b2(buf, h[H_TORQUE_AXIS], nt, 3), b1(buf, h[H_TORQUE_A], nt),
        b1(h, h[H_FLAGS], fast.FLAGS_SIZE), b1(buf, h[H_BASE], 7), buf[h[H_T0]], b1(buf, h[H_P0], nt),
        b1(buf, h[H_PDOT], nt), b1(buf, h[H_L], nt), b1(buf, h[H_TAU], N))


def entry_point():
    """rhs_entry's compiled entry point for (a float, two float64 C-contiguous vectors, the
    buffer's address as an int64: `entry(t, y, ydot, buf.ctypes.data)`), compiled or loaded
    from the disk cache now: it converts its arguments to these types without checking them
    (as gyro_sim.jit.Direct). Without numba, the plain function (which takes the buffer itself)."""
    if numba is None:
        return rhs_entry
    signature = (numba.float64, numba.float64[::1], numba.float64[::1], numba.int64)
    rhs_entry.compile(signature)
    return rhs_entry.overloads[signature].entry_point
