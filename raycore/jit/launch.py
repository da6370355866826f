"""Worker kernels started on numba's own (OpenMP) threads by a parallel loop
that calls them through their machine-code address: the fastest start and
the cheapest compile.

A driver's work is one worker kernel per thread, each pulling tiles from
the shared tile queue. Started from Python threads (thread_pool.on_threads)
the workers compile once, but run 3-5 % slower than on OpenMP's threads
(hand's sweep 36.6 against 34.9 ms, toys' 45.1 against 43.9, alternating
calls on one frame). Called directly from a `prange` loop, numba links the
worker and everything it calls into the parallel kernel and optimises it
all twice more (the sweep compiled in 36 s that way, 22 s alone). Here the
loop calls the worker through its address (`native_entry`, an int64 argument
at run time, so that the cached loop stays valid in every process): nothing
is linked in, and the loop compiles in about a second.

The call uses numba's own calling convention (status, exception slot, the
arguments flattened as numba passes them); the address comes from the
worker's overload for exactly the argument types the loop is called with,
so the two cannot disagree. Workers started this way return nothing; one
that raises (numba's MemoryError) cannot pass its exception through the
parallel loop, so each thread's call reports success in a flag and the
caller raises (check_workers) instead of writing a frame with holes.
"""
import numba
import numpy as np
from numba.core import types
from numba.extending import intrinsic


@intrinsic
def call_native(typingctx, entry, args):
    """worker(*args) for the worker kernel whose native entry point is
    `entry` (native_entry: compiled for exactly args' types). Returns False
    when the worker raised (its exception cannot cross the parallel loop:
    the caller raises instead, check_workers)."""
    arg_types = tuple(args.types)

    def codegen(context, builder, signature, llargs):
        address, packed = llargs
        values = [builder.extract_value(packed, i) for i in range(len(arg_types))]
        fnty = context.call_conv.get_function_type(types.none, arg_types)
        fn = builder.inttoptr(address, fnty.as_pointer())
        status, _ = context.call_conv.call_function(builder, fn, types.none, arg_types, values)
        return builder.not_(status.is_error)

    return types.boolean(entry, args), codegen


def on_omp_threads(loop, worker, n_workers, *args, per_worker=None):
    """worker(*args) on n_workers of numba's threads: `loop` is the
    worker's parallel loop, loop(entry, ok, *args[, per_worker]), which
    calls it through call_native on each thread (with per_worker[w] as the
    last argument when given); raises if a worker failed."""
    ok = np.zeros(n_workers, np.bool_)
    if per_worker is None:
        loop(native_entry(worker, *args), ok, *args)
    else:
        loop(native_entry(worker, *args, per_worker[0]), ok, *args, per_worker)
    check_workers(worker, ok)


def check_workers(worker, ok):
    """Raise if a worker started through call_native failed (ok: one flag a worker)."""
    if not ok.all():
        raise RuntimeError(f"{worker.py_func.__name__} failed on {int((~ok).sum())} of {ok.shape[0]} threads "
                           "(out of memory?); the frame is not written")


_ENTRIES = {}          # (worker, argument types) -> address
_BY_KIND = {}          # (worker, the arguments' value_kind) -> address


def value_kind(a):
    """What numba types a value by, found cheaply: an array's dtype,
    dimensions, layout, writability and alignment; a scalar's class; a
    tuple's class and items. None where unsure (numba.typeof then decides).
    numba.typeof over a driver's ~30 arguments took 0.36 ms, once a pass."""
    t = type(a)
    if t is np.ndarray:
        f = a.flags
        layout = "C" if f.c_contiguous else ("F" if f.f_contiguous else "A")        # as numba picks it
        return (a.dtype.str, a.ndim, layout, f.writeable, f.aligned)
    if t is bool or t is float or isinstance(a, (np.bool_, np.number)):
        return t
    if t is int:
        return (int, -2 ** 63 <= a < 2 ** 63)          # beyond int64 numba takes uint64
    if isinstance(a, tuple):
        items = tuple(value_kind(x) for x in a)
        return None if None in items else (t, items)
    return None


def native_entry(worker, *args) -> int:
    """The machine-code address of `worker` compiled (or loaded from the
    cache) for these arguments' types."""
    kinds = tuple(value_kind(a) for a in args)
    fast = None if None in kinds else (worker, kinds)
    address = _BY_KIND.get(fast) if fast is not None else None
    if address is not None:
        return address
    arg_types = tuple(numba.typeof(a) for a in args)
    key = (worker, arg_types)
    address = _ENTRIES.get(key)
    if address is None:
        worker.compile(arg_types)
        cres = worker.overloads[arg_types]
        if cres.signature.return_type != types.none:
            raise TypeError(f"{worker.py_func.__name__}: a worker started by jit/launch.py returns nothing")
        address = _ENTRIES[key] = cres.library.get_pointer_to_function(cres.fndesc.llvm_func_name)
    if fast is not None:
        _BY_KIND[fast] = address
    return address
