"""One place for numba presets, the threading layer and the atomic tile counter.

Why these flags:
* `cache=True` so a second run loads machine code instead of compiling (~15 s -> ~0.2 s);
  jit/kernel_cache.py makes an edit to any kernel source recompile every kernel.
* `nogil=True` so the EXR writer thread runs while kernels render.
* `error_model="numpy"`: division by zero gives inf/NaN instead of raising; the
  ray kernels rely on IEEE semantics (1/0 = inf) and must not branch on it.
* fastmath only with flags that keep inf/NaN meaning (`arcp`, `nsz`). `contract`
  (FMA fusion) is left out of the traversal kernels on purpose: a fused
  `a*b - c*d` is not antisymmetric, which would break the watertight edge tests.
"""
import os
from functools import partial

import numba
from llvmlite import ir
from numba import njit
from numba.core import cgutils, types
from numba.extending import intrinsic

try:
    from numba.core.cpu import CPUTargetOptions
    from numba.core.options import TargetOptions
except ImportError:              # see vector_kernel
    CPUTargetOptions = TargetOptions = None

from raycore.jit import compile_speed
from raycore.jit import kernel_cache  # noqa: F401  (before any kernel is decorated)

# OpenMP measured faster than the default workqueue on this machine kind.
numba.config.THREADING_LAYER_PRIORITY = ["omp", "tbb", "workqueue"]
# OpenMP's threads (libgomp's) spin for at most ~0.2 ms when a parallel loop
# ends, not for up to milliseconds (its default, 300,000 turns): most
# drivers' workers are Python threads (thread_pool.on_threads), and so are
# the EXR encoder's, and a spinning OpenMP thread takes the core they need. 10,000
# turns keep the build's back-to-back loops as fast as the default spin
# (sleeping at once cost the grid and BVH update 0.3-0.6 ms a frame). Read
# when numba first starts its threads, so set here, before any kernel
# runs; the user's own OMP_WAIT_POLICY or GOMP_SPINCOUNT wins.
if "OMP_WAIT_POLICY" not in os.environ:
    os.environ.setdefault("GOMP_SPINCOUNT", "10000")

SAFE_FASTMATH = {"arcp", "nsz"}
ARITH_FASTMATH = {"contract", "arcp", "nsz"}   # for kernels without edge tests
# numba gives every compiled function a C-callable twin (its "cfunc
# wrapper", for numba.cfunc-style first-class function pointers), which
# frustrace never takes: kernels are called from Python, from kernels, or
# through their numba-ABI address (launch.native_entry). Leaving the twins out
# cuts a cold compile by about a tenth (docs/performance.md, compile time).
jit = partial(njit, no_cfunc_wrapper=True)

kernel = jit(cache=True, nogil=True, error_model="numpy", fastmath=SAFE_FASTMATH)
# Small helpers that take arrays and run per ray, triangle or pixel: inlined at
# numba-IR level. A real call costs an atomic incref/decref per array argument
# (NRT reference counting), measured at 22% of traversal time before this.
helper = jit(cache=True, nogil=True, error_model="numpy", fastmath=SAFE_FASTMATH, inline="always")
# numba tells LLVM nothing of whether two array arguments overlap, so a loop
# that loads through an index (a gather) and stores elsewhere stays scalar.
# `noalias` (numba's own flag, which it sets on a parallel loop's body when
# it sees no aliasing) promises that the arguments do not overlap: for
# kernels whose callers pass distinct arrays only. It is not a decorator
# option, so it is made one here; should numba's internals move, the
# kernels compile without it (scalar loops, the same results).
try:
    CPUTargetOptions.noalias = TargetOptions.Mapping("noalias")
    _NOALIAS = {"noalias": True}
except AttributeError:
    _NOALIAS = {}
vector_kernel = jit(cache=True, nogil=True, error_model="numpy", fastmath=ARITH_FASTMATH, **_NOALIAS)
parallel_kernel = jit(cache=True, nogil=True, parallel=True, error_model="numpy",
                      fastmath=SAFE_FASTMATH)
# Kernels that allocate nothing, without numba's reference counting (NRT):
# numba increments and decrements an array's count (an atomic operation)
# wherever a variable takes it, and IR-level inlining of a helper with array
# arguments (`helper` above) leaves such pairs inside the caller's loops,
# which LLVM's pass that prunes them does not always remove: the shadow
# packets' driver did ~8 of them a ray (its ray-making helper reads four
# arrays). Without NRT the arrays are plain pointers, as in C: such a
# kernel must not allocate, and may be called only while its caller holds
# the arrays. Measured on captured shadow rays, one thread: 4-10 % faster.
flat_kernel = jit(cache=True, nogil=True, error_model="numpy", fastmath=SAFE_FASTMATH, _nrt=False)
arith_kernel = jit(cache=True, nogil=True, error_model="numpy", fastmath=ARITH_FASTMATH)
parallel_arith_kernel = jit(cache=True, nogil=True, parallel=True, error_model="numpy",
                            fastmath=ARITH_FASTMATH)

# Literal arguments: a kernel that calls another kernel with a counter
# started at a constant (`n = 0`, then `n += 1` in a loop) has the call typed
# twice, first with n as the literal 0 (before the loop's n += 1 is typed),
# then as int64, and numba compiles the callee for both: the BVH's camera
# packets compiled their packet walk twice (9.1 s, 4.6 of them for the
# literal version, never run). Such counters start as np.int64(0).


@intrinsic
def fetch_add(typingctx, arr, idx, val):
    """Atomically `old = arr[idx]; arr[idx] += val; return old` (int64 array).

    The basis of dynamic load balancing: threads pull the next tile from a shared
    counter, so fast tiles never leave a core idle (numba's prange is static).
    """
    sig = types.int64(arr, idx, val)

    def codegen(context, builder, signature, args):
        ary_val, idx_val, add_val = args
        aryty = signature.args[0]
        ary = context.make_array(aryty)(context, builder, ary_val)
        ptr = cgutils.get_item_pointer(context, builder, aryty, ary, [idx_val])
        return builder.atomic_rmw("add", ptr, add_val, "monotonic")

    return sig, codegen


def set_threads(n: int) -> int:
    """Use `n` threads (0 = all cores); returns the count in force."""
    limit = numba.config.NUMBA_NUM_THREADS
    n = limit if n <= 0 else min(n, limit)
    numba.set_num_threads(n)
    return n


@intrinsic
def cycle_count(typingctx):
    """The CPU's cycle counter (llvm.readcyclecounter: the time-stamp counter
    on x86, 0 where a target has none): how a kernel that runs several
    phases in one sweep tells their shares of its time apart."""
    sig = types.int64()

    def codegen(context, builder, signature, args):
        fnty = ir.FunctionType(ir.IntType(64), [])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.readcyclecounter")
        return builder.call(fn, [])

    return sig, codegen
