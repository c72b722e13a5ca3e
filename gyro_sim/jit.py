"""numba in one place: the options of every compiled kernel of gyro_sim, where their cache lives,
and the plumbing by which compiled code calls a C function at an address.

Options. Every kernel compiles in nopython mode, cached on disk, with IEEE arithmetic (no
fastmath: results equal the numpy reference to round-off) and numpy's error model (x / 0 ->
inf rather than an exception: non-finite states are caught by the integrators and the
Simulator). Without numba a function stays plain Python (correct, slow).

- :func:`njit`: a kernel that compiles in only functions of its own file (numba's usual cache,
  beside the file, keyed on that file).
- :func:`njit_with_dependencies`, :func:`cfunc_with_dependencies`: a kernel that compiles in
  functions of other files. numba's disk cache keys a kernel on its own file only (numba docs,
  "Cache limitations"): cached the usual way, it would survive an edit of a file it inlines
  and run stale code. So its cache lives in a directory named after a digest of every file it
  compiles in, this one included (:func:`cache_directory`): an edit of any starts an empty one.
  Options such as `_nrt` (numba's reference counting) and `forceinline` pass through.
- :func:`inline_ir`: inlined by numba itself into its callers (not cached on its own).

Calls at a small fixed cost. :class:`Direct` calls a kernel's compiled entry point without
numba's per-call type dispatch; :func:`c_address` compiles (or loads) a function as a C
function once per process and gives its address; compiled code calls such an address with
:func:`call_address`, passing arrays as :func:`address_of` their data and rebuilding them on
the other side with :func:`vector_at`; :func:`block1`/:func:`block2`/:func:`block3` cut C-ordered,
uncounted views out of a contiguous vector. A kernel called through an address is compiled once,
not into every loop that calls it.
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

try:
    import numba
    from numba.core.errors import NumbaError
except ImportError:  # pragma: no cover - exercised only where numba is missing
    numba = None

    class NumbaError(Exception):
        """Stands in for numba's error type where numba is missing (never raised)."""

#: numba's options shared by every kernel (see the module's docstring)
OPTIONS = {"cache": True, "error_model": "numpy"}


def available() -> bool:
    """True if numba imports."""
    return numba is not None


def compiling() -> bool:
    """True when decorated functions are compiled: numba imports and NUMBA_DISABLE_JIT is not
    set (with it, the intrinsics below stand for plain-Python twins and no C function exists)."""
    return numba is not None and not numba.config.DISABLE_JIT


def njit(fn):
    """`fn` compiled in nopython mode and cached on disk beside its file (plain Python without
    numba): for a kernel that compiles in no function of another file."""
    if numba is None:
        return fn
    return numba.njit(**OPTIONS)(fn)


def inline_ir(fn):
    """`fn` inlined by numba into its compiled callers (`inline="always"`: at numba's IR level,
    so it takes the callers' cache), plain Python without numba."""
    if numba is None:
        return fn
    return numba.njit(inline="always", error_model="numpy")(fn)


def cache_directory(files) -> Path:
    """Where kernels compiled from `files` (paths) are cached: `fast_loop-<digest of the files and
    of this module>` under NUMBA_CACHE_DIR when set, else under this package's __pycache__ (if
    writable), else under ~/.cache/gyro_sim. This module is part of the key: its options and
    intrinsics are compiled into every such kernel."""
    paths = [*files, Path(__file__)]
    digest = hashlib.sha256(b"".join(Path(p).read_bytes() for p in paths)).hexdigest()[:16]
    if numba is not None and numba.config.CACHE_DIR:
        base = Path(numba.config.CACHE_DIR)
    else:
        base = Path(__file__).parent / "__pycache__"
        if not os.access(base if base.exists() else base.parent, os.W_OK):
            base = user_cache_root()
    return base / f"fast_loop-{digest}"


def user_cache_root() -> Path:
    """Where site-packages is read-only: a cache per user, one directory per version of gyro_sim
    and of numba and per CPU (two installs of other versions, or a home shared by two machines,
    do not overwrite each other's entries)."""
    import platform
    from importlib import metadata

    try:  # the installed distribution's version (the package itself is above this module)
        __version__ = metadata.version("gyro_sim")
    except metadata.PackageNotFoundError:
        __version__ = "source"
    cpu = platform.machine() or "cpu"
    if numba is not None:
        try:
            import llvmlite.binding as llvm

            cpu = f"{cpu}-{llvm.get_host_cpu_name()}"
        except (ImportError, RuntimeError):
            pass
        key = f"gyro_sim-{__version__}-numba-{numba.__version__}-{cpu}"
    else:
        key = f"gyro_sim-{__version__}-{cpu}"
    return Path.home() / ".cache" / "gyro_sim" / key


def _in_cache_of(files, make):
    """make() with numba's CACHE_DIR set to :func:`cache_directory` of `files` (numba reads it
    when a dispatcher or a C function's cache is made)."""
    saved = numba.config.CACHE_DIR
    numba.config.CACHE_DIR = str(cache_directory(files))
    try:
        return make()
    finally:
        numba.config.CACHE_DIR = saved


def njit_with_dependencies(*files, **options):
    """A decorator: compiled in nopython mode (:data:`OPTIONS`, and numba's `options`), cached
    on disk in :func:`cache_directory` of `files`, the files of every kernel the function
    compiles in (its own included): an edit of any starts afresh."""

    def decorate(fn):
        if numba is None:
            return fn
        return _in_cache_of(files, lambda: numba.njit(**OPTIONS, **options)(fn))

    return decorate


def cfunc_with_dependencies(signature, *files, **options):
    """A decorator: compiled as a C function of `signature` (numba.cfunc: its `address` is what
    compiled code calls, :func:`call_address`), with :data:`OPTIONS` and numba's `options`,
    cached on disk in :func:`cache_directory` of `files` (as :func:`njit_with_dependencies`).
    Compiles (or loads) when applied: apply it when the function is first needed."""

    def decorate(fn):
        return _in_cache_of(files, lambda: numba.cfunc(signature, **OPTIONS, **options)(fn))

    return decorate


#: the C functions compiled in this process, by the Python function
_C_FUNCTIONS: dict = {}


def c_address(fn, signature, files, **options) -> int:
    """The address of `fn` compiled as a C function of `signature()` (a callable: numba's types
    exist only with numba) by :func:`cfunc_with_dependencies` of `files`, compiled or loaded
    from the disk cache on the first call in this process; 0 where nothing compiles
    (:func:`compiling`), whose callers call the plain function instead."""
    if not compiling():
        return 0
    compiled = _C_FUNCTIONS.get(fn)
    if compiled is None:
        compiled = _C_FUNCTIONS[fn] = cfunc_with_dependencies(signature(), *files, **options)(fn)
    return compiled.address


class Direct:
    """A compiled kernel called without numba's per-call type dispatch: the first call goes
    through the dispatcher (compiling or loading), later calls straight to the compiled
    entry point of that first call's signature (numba resolves the types of every argument on
    every call otherwise: ~0.3 us an argument, 5-10 us for the kernels here).

    The caller guarantees that every later call passes arguments of the first call's types
    (dtype, dimensions, C-contiguous arrays; float and int scalars): the entry point converts,
    it does not check. Without numba, the plain function is called.
    """

    def __init__(self, kernel):
        self.kernel = kernel
        self.entry = None

    def __call__(self, *args):
        if self.entry is not None:
            return self.entry(*args)
        out = self.kernel(*args)
        if numba is not None:
            signature = tuple(numba.typeof(a) for a in args)
            self.entry = self.kernel.overloads[signature].entry_point
        return out


def type_key(a) -> tuple:
    """What numba's type of an argument depends on: dtype, dimensions, layout (as numba.typeof
    reads it: C if C-contiguous, else F if Fortran-contiguous, else A), writeability of an
    array; the same of every item of a tuple (a record); the Python type of a scalar. Equal keys:
    one compiled specialisation serves both (the key of a cache of `Direct` entries)."""
    if isinstance(a, tuple):
        return (type(a), *(type_key(x) for x in a))
    if hasattr(a, "dtype") and hasattr(a, "flags"):
        layout = "C" if a.flags.c_contiguous else ("F" if a.flags.f_contiguous else "A")
        return (a.dtype.str, a.ndim, layout, a.flags.writeable)
    return (type(a),)


# --- views and addresses in compiled code -----------------------------------------------------
def _view_codegen(context, builder, sig, args):
    """Lowering of `block1/2/3`: the array value of a C-ordered view of work[o:] of the given
    shape (its fields filled through numba's data model), borrowed: no meminfo, so nothing is
    counted; valid while `work` is, i.e. during the call that made it."""
    from numba.core import cgutils
    from numba.core import types as nbt

    source = context.data_model_manager[sig.args[0]]
    view = context.data_model_manager[sig.return_type]
    o, *dims = (context.cast(builder, v, t, nbt.intp) for v, t in zip(args[1:], sig.args[1:]))
    itemsize = builder.extract_value(args[0], source.get_field_position("itemsize"))
    data = builder.extract_value(args[0], source.get_field_position("data"))
    strides = [itemsize]
    nitems = dims[-1]
    for d in reversed(dims[1:]):
        strides.insert(0, builder.mul(strides[0], d))
    for d in dims[:-1]:
        nitems = builder.mul(nitems, d)
    value = cgutils.get_null_value(context.get_value_type(sig.return_type))  # meminfo, parent: null
    for name, v in (("nitems", nitems), ("itemsize", itemsize), ("data", builder.gep(data, [o])),
                    ("shape", cgutils.pack_array(builder, dims)),
                    ("strides", cgutils.pack_array(builder, strides))):
        value = builder.insert_value(value, v, view.get_field_position(name))
    return value


if compiling():
    from llvmlite import ir as _llir
    from numba.core import cgutils as _cgutils
    from numba.core import types as _nbt
    from numba.extending import intrinsic as _intrinsic

    # work[o : o + n m ...] (work contiguous) as a C-ordered (n, m, ...) view. An intrinsic:
    # numba's reshape calls a C helper (~40 ns, twenty times per evaluation) and as_strided
    # gives a layout-"A" array (every index scaled by strides loaded at run time), both counted.
    def _view_typing(work, nd, *ints):
        """(signature, codegen) of the view of a vector `work` with nd axes (None: not for
        these argument types)."""
        if not (isinstance(work, _nbt.Array) and work.ndim == 1
                and all(isinstance(i, _nbt.Integer) for i in ints)):
            return None
        return _nbt.Array(work.dtype, nd, "C")(work, *ints), _view_codegen

    @_intrinsic
    def block1(typingctx, work, o, n):
        return _view_typing(work, 1, o, n)

    @_intrinsic
    def block2(typingctx, work, o, n, m):
        return _view_typing(work, 2, o, n, m)

    @_intrinsic
    def block3(typingctx, work, o, n, m, q):
        return _view_typing(work, 3, o, n, m, q)

    @_intrinsic
    def address_of(typingctx, a):
        """The address (int64) of the first element of the C-contiguous array a (compiled code
        only; another layout does not compile: the callee reads the items consecutively)."""
        if not (isinstance(a, _nbt.Array) and a.layout == "C"):
            return None

        def codegen(context, builder, sig, args):
            data = context.make_array(sig.args[0])(context, builder, args[0]).data
            return builder.ptrtoint(data, context.get_value_type(_nbt.int64))

        return _nbt.int64(a), codegen

    @_intrinsic
    def vector_at(typingctx, address, size, dtype):
        """The C-contiguous vector of `size` items of `dtype` (a numpy scalar class) at `address`
        (int64), owned elsewhere (no meminfo, nothing counted): the caller keeps it alive."""
        if not (isinstance(address, _nbt.Integer) and isinstance(size, _nbt.Integer)
                and isinstance(dtype, _nbt.NumberClass)):
            return None
        vector = _nbt.Array(dtype.dtype, 1, "C")

        def codegen(context, builder, sig, args):
            model = context.data_model_manager[vector]
            item = context.get_constant(_nbt.intp, context.get_abi_sizeof(context.get_data_type(dtype.dtype)))
            n = context.cast(builder, args[1], sig.args[1], _nbt.intp)
            data = builder.inttoptr(args[0], context.get_value_type(_nbt.CPointer(dtype.dtype)))
            value = _cgutils.get_null_value(context.get_value_type(vector))
            for name, v in (("nitems", n), ("itemsize", item), ("data", data),
                            ("shape", _cgutils.pack_array(builder, [n])),
                            ("strides", _cgutils.pack_array(builder, [item]))):
                value = builder.insert_value(value, v, model.get_field_position(name))
            return value

        return vector(address, size, dtype), codegen

    @_intrinsic
    def call_address(typingctx, address, args):
        """Call the C function `void f(...)` at `address` with the tuple `args` (compiled code
        only), integers passed as int64, floats as double: a call the caller's compilation does
        not compile in."""
        if not (isinstance(address, _nbt.Integer) and isinstance(args, _nbt.BaseTuple)
                and all(isinstance(a, (_nbt.Integer, _nbt.Float)) for a in args)):
            return None
        kinds = [_nbt.float64 if isinstance(a, _nbt.Float) else _nbt.int64 for a in args]

        def codegen(context, builder, sig, llargs):
            fnty = _llir.FunctionType(_llir.VoidType(), [context.get_value_type(k) for k in kinds])
            fn = builder.inttoptr(llargs[0], fnty.as_pointer())
            values = [context.cast(builder, v, t, k)
                      for v, t, k in zip(_cgutils.unpack_tuple(builder, llargs[1], len(args)), args, kinds)]
            builder.call(fn, values)
            return context.get_dummy_value()

        return _nbt.void(address, args), codegen
else:  # plain Python: without numba, or NUMBA_DISABLE_JIT (the 80-digit oracle, bench.heavy_tips)
    def block1(work, o, n):
        return work[o:o + n]

    def block2(work, o, n, m):
        return work[o:o + n * m].reshape(n, m)

    def block3(work, o, n, m, q):
        return work[o:o + n * m * q].reshape(n, m, q)
