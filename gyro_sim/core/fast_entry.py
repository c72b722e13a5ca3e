"""One evaluation of the compiled dynamics called from Python at a small fixed cost.

numba unboxes every argument of a compiled function at each call from Python (~0.1 us an
array even through the compiled entry point, `gyro_sim.core.fast_loop.Direct`): the 24
arguments of :func:`gyro_sim.core.fast.rhs_kernel` cost ~3 us a call, several times the
kernel's own work on a short chain. Here the kernel's arrays live in two buffers built once,
one float64 (`fbuf`) and one int64 (`ibuf`, a header of offsets first), and
:func:`rhs_entry` takes six arguments, `(t, y, ydot, fbuf, ibuf, is_hinge)`: it cuts the
buffers into the kernel's arrays (`_view`: C-ordered views of the same types as every other
caller passes, so the kernel's one specialisation serves it) and calls the kernel. The results are those of the kernel called with the separate arrays, bit for bit.

`is_hinge` (bool) stays an argument of its own: a bool view of an integer buffer would be
another array type for the kernel, i.e. one more specialisation to compile.

    fbuf, ibuf = pack(work, model_args, inputs)   # fast.workspace, fast.model_arguments,
                                                  # fast.input_arguments
    set_inputs(fbuf, ibuf, inputs)                # after a new hold, in place
    kernel_arguments(fbuf, ibuf, is_hinge)        # the kernel's 21 arguments as views of both
    rhs_entry(t, y, ydot, fbuf, ibuf, is_hinge)   # compiled: y' into ydot

Caching as :mod:`gyro_sim.core.fast_loop` (`njit_with_dependencies`): rhs_entry compiles the
kernel into itself, so its cache is keyed on fast.py and this file.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from . import fast
from .fast_loop import njit_with_dependencies

try:
    import numba
    from numba.core import cgutils, types
    from numba.core.imputils import impl_ret_borrowed
    from numba.extending import intrinsic
except ImportError:  # pragma: no cover - exercised only where numba is missing
    numba = None

#: the files whose kernels rhs_entry compiles in (the key of its cache directory)
DEPENDENCIES = (Path(fast.__file__), Path(__file__))
_njit = njit_with_dependencies(*DEPENDENCIES)

# ibuf header: the sizes, then where each array starts (in fbuf for floats, ibuf for ints)
H_N, H_NCOL, H_NT = 0, 1, 2
(H_WORK, H_HINGE_AXIS, H_S, H_MASS, H_FIRST_MOMENT, H_INERTIA, H_LAM_SPEED, H_TORQUE_AXIS,
 H_TORQUE_A, H_BASE, H_T0, H_P0, H_PDOT, H_L, H_TAU, H_FEND) = range(3, 19)
H_QROW, H_OWN_COL, H_COL_START, H_TORQUE_BODY, H_FLAGS, H_IEND = range(19, 25)
HEADER = 25
#: the float arrays of model_arguments (after is_hinge) as they sit in fbuf, and their headers
_MODEL_FLOATS = ((4, H_HINGE_AXIS), (5, H_S), (6, H_MASS), (7, H_FIRST_MOMENT), (8, H_INERTIA),
                 (9, H_LAM_SPEED), (11, H_TORQUE_AXIS), (12, H_TORQUE_A), (14, H_BASE))
_MODEL_INTS = ((1, H_QROW), (2, H_OWN_COL), (3, H_COL_START), (10, H_TORQUE_BODY), (13, H_FLAGS))
_INPUTS = ((1, H_P0), (2, H_PDOT), (3, H_L), (4, H_TAU))
#: where the held t0 (a float) sits in `kernel_arguments`
T0_ARGUMENT = 16


def pack(work: np.ndarray, model_args: tuple, inputs: tuple) -> tuple[np.ndarray, np.ndarray]:
    """(fbuf, ibuf): the workspace, the model's arrays (fast.model_arguments, is_hinge left out)
    and the held inputs (fast.input_arguments) in one float64 and one int64 buffer."""
    n, N, nt = len(model_args[0]), len(inputs[4]), len(model_args[10])
    header = np.zeros(HEADER, dtype=np.int64)
    header[[H_N, H_NCOL, H_NT]] = n, N, nt
    floats = [(H_WORK, work)] + [(h, model_args[i]) for i, h in _MODEL_FLOATS]
    floats += [(H_T0, np.array([inputs[0]]))] + [(h, inputs[i]) for i, h in _INPUTS]
    ints = [(h, model_args[i]) for i, h in _MODEL_INTS]
    o = 0
    for h, a in floats:
        header[h] = o
        o += a.size
    header[H_FEND] = o
    fbuf = np.concatenate([np.asarray(a, dtype=np.float64).ravel() for _, a in floats])
    o = HEADER
    for h, a in ints:
        header[h] = o
        o += a.size
    header[H_IEND] = o
    ibuf = np.concatenate([header] + [np.asarray(a, dtype=np.int64).ravel() for _, a in ints])
    return fbuf, ibuf


def set_inputs(fbuf: np.ndarray, ibuf: np.ndarray, inputs: tuple) -> None:
    """Write held inputs (fast.input_arguments) into fbuf in place."""
    fbuf[ibuf[H_T0]] = inputs[0]
    for i, h in _INPUTS:
        a = inputs[i]
        fbuf[ibuf[h]:ibuf[h] + a.size] = a


def kernel_arguments(fbuf: np.ndarray, ibuf: np.ndarray, is_hinge: np.ndarray) -> tuple:
    """The arguments of fast.rhs_kernel after (t, y, ydot): numpy views of the buffers (t0 a
    float, read now), what rhs_entry passes."""
    n, N, nt = (int(x) for x in ibuf[[H_N, H_NCOL, H_NT]])

    def f(h, *shape):
        o = ibuf[h]
        return fbuf[o:o + int(np.prod(shape))].reshape(shape)

    def i(h, size):
        o = ibuf[h]
        return ibuf[o:o + size]

    return (f(H_WORK, ibuf[H_HINGE_AXIS]), is_hinge, i(H_QROW, n), i(H_OWN_COL, n),
            i(H_COL_START, n + 1), f(H_HINGE_AXIS, n, 3), f(H_S, n, 3), f(H_MASS, n),
            f(H_FIRST_MOMENT, n, 3), f(H_INERTIA, n, 3, 3), f(H_LAM_SPEED, n, 3),
            i(H_TORQUE_BODY, nt), f(H_TORQUE_AXIS, nt, 3), f(H_TORQUE_A, nt), i(H_FLAGS, 7),
            f(H_BASE, 7), float(fbuf[ibuf[H_T0]]), f(H_P0, nt), f(H_PDOT, nt), f(H_L, nt),
            f(H_TAU, N))


if numba is not None:
    @intrinsic
    def _view(typingctx, buf, start, shape):
        """buf[start : start + prod(shape)] as a C-ordered array of `shape` (a tuple of ints),
        sharing buf's memory (and keeping it alive), for buf a C-contiguous vector. Unchecked:
        the header of `pack` keeps every block inside its buffer. numba's reshape of a slice
        gives the same array but calls a C helper (~50 ns, six times an evaluation); this
        only fills the array's fields."""
        if not (isinstance(buf, types.Array) and buf.ndim == 1 and buf.layout == "C"
                and isinstance(start, types.Integer) and isinstance(shape, types.UniTuple)
                and isinstance(shape.dtype, types.Integer)):
            return None
        nd = shape.count
        view_type = buf.copy(ndim=nd, layout="C")

        def codegen(context, builder, sig, args):
            source, view = (context.data_model_manager[ty] for ty in (sig.args[0], view_type))

            def field(name):
                return builder.extract_value(args[0], source.get_field_position(name))

            dims = [context.cast(builder, d, shape.dtype, types.intp)
                    for d in cgutils.unpack_tuple(builder, args[2], nd)]
            itemsize = field("itemsize")
            strides = [itemsize] * nd  # C order: the last axis varies fastest
            for i in range(nd - 2, -1, -1):
                strides[i] = builder.mul(strides[i + 1], dims[i + 1])
            nitems = dims[0]
            for d in dims[1:]:
                nitems = builder.mul(nitems, d)
            offset = context.cast(builder, args[1], sig.args[1], types.intp)
            value = cgutils.get_null_value(context.get_value_type(view_type))
            for name, v in (("meminfo", field("meminfo")), ("parent", field("parent")),
                            ("nitems", nitems), ("itemsize", itemsize),
                            ("data", builder.gep(field("data"), [offset])),
                            ("shape", cgutils.pack_array(builder, dims)),
                            ("strides", cgutils.pack_array(builder, strides))):
                value = builder.insert_value(value, v, view.get_field_position(name))
            return impl_ret_borrowed(context, builder, view_type, value)

        return view_type(buf, start, shape), codegen
else:  # pragma: no cover - exercised only where numba is missing
    def _view(buf, start, shape):
        return buf[start:start + int(np.prod(shape))].reshape(shape)


@_njit
def rhs_entry(t, y, ydot, fbuf, ibuf, is_hinge):
    """y' (size,) at (t, y) into ydot: fast.rhs_kernel on the arrays packed in (fbuf, ibuf).
    Raises ValueError unless y is contiguous and of ydot's length (the kernel does not check
    its indices; a few ns here, ~0.1 us as numpy attribute reads before the call)."""
    if y.shape[0] != ydot.shape[0] or y.strides[0] != y.itemsize:
        raise ValueError("y must be a contiguous vector of the state's size")
    n, N, nt = ibuf[H_N], ibuf[H_NCOL], ibuf[H_NT]
    w0, ha, s0, m0, fm, in0 = ibuf[H_WORK], ibuf[H_HINGE_AXIS], ibuf[H_S], ibuf[H_MASS], ibuf[H_FIRST_MOMENT], ibuf[H_INERTIA]
    ls, ta, tA, b0, t0 = ibuf[H_LAM_SPEED], ibuf[H_TORQUE_AXIS], ibuf[H_TORQUE_A], ibuf[H_BASE], ibuf[H_T0]
    p0, pd, L0, tau0 = ibuf[H_P0], ibuf[H_PDOT], ibuf[H_L], ibuf[H_TAU]
    q0, oc, cs, tb, fl = ibuf[H_QROW], ibuf[H_OWN_COL], ibuf[H_COL_START], ibuf[H_TORQUE_BODY], ibuf[H_FLAGS]
    fast.rhs_kernel(t, y, ydot, _view(fbuf, w0, (ha - w0,)), is_hinge, _view(ibuf, q0, (n,)),
                    _view(ibuf, oc, (n,)), _view(ibuf, cs, (n + 1,)), _view(fbuf, ha, (n, 3)),
                    _view(fbuf, s0, (n, 3)), _view(fbuf, m0, (n,)), _view(fbuf, fm, (n, 3)),
                    _view(fbuf, in0, (n, 3, 3)), _view(fbuf, ls, (n, 3)), _view(ibuf, tb, (nt,)),
                    _view(fbuf, ta, (nt, 3)), _view(fbuf, tA, (nt,)), _view(ibuf, fl, (7,)),
                    _view(fbuf, b0, (7,)), fbuf[t0], _view(fbuf, p0, (nt,)), _view(fbuf, pd, (nt,)),
                    _view(fbuf, L0, (nt,)), _view(fbuf, tau0, (N,)))


def entry_point():
    """rhs_entry's compiled entry point for (float, then float64, float64, float64, int64 and
    bool C-contiguous vectors), compiled or loaded from the disk cache now: it converts its
    arguments to these types without checking them (fast_loop.Direct). Without numba, the
    plain function."""
    if numba is None:
        return rhs_entry
    signature = (numba.float64, numba.float64[::1], numba.float64[::1], numba.float64[::1],
                 numba.int64[::1], numba.boolean[::1])
    rhs_entry.compile(signature)
    return rhs_entry.overloads[signature].entry_point
