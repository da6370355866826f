"""Non-temporal (streaming) stores of 8 floats, for image rows written
once and not read again by this frame's kernels.

A plain store first reads its cache line from memory (read for
ownership), so writing the 20 MB of a 1024^2 frame's RGBA and Z moves 40
MB; a streaming store of whole lines skips that read and leaves the
caches to the data the frame still uses. LLVM's `!nontemporal` store is
vmovntps on x86; it needs its 32-byte alignment (else the CPU faults), so
callers check the address first (shade.write_block). Streaming stores are
weakly ordered: `store_fence` (x86 sfence) makes them visible before the
caller's later stores are. On other CPUs they are plain stores.
"""
import llvmlite.binding as llvm
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

from raycore.jit.row8 import vector_pointer

X86 = llvm.get_process_triple().startswith(("x86_64", "i686", "i386"))


@intrinsic
def stream8(typingctx, dst, i, src, k):
    """dst[i:i + 8] = src[k:k + 8] (1-d float32 arrays) by a streaming
    store; dst's address at i must be a multiple of 32 bytes."""
    sig = types.void(dst, types.uint64, src, types.uint64)

    def codegen(context, builder, signature, args):
        d_ty, _, s_ty, _ = signature.args
        pd = vector_pointer(context, builder, d_ty, args[0], [args[1]])
        ps = vector_pointer(context, builder, s_ty, args[2], [args[3]])
        v = builder.load(ps, align=4)
        st = builder.store(v, pd, align=32)
        if X86:
            st.set_metadata("nontemporal", builder.module.add_metadata([ir.Constant(ir.IntType(32), 1)]))
        return context.get_dummy_value()
    return sig, codegen


@intrinsic
def store_fence(typingctx):
    """The streaming stores before it are visible before any store after it (x86 sfence)."""
    sig = types.void()

    def codegen(context, builder, signature, args):
        if X86:
            fn = builder.module.declare_intrinsic("llvm.x86.sse.sfence", fnty=ir.FunctionType(ir.VoidType(), []))
            builder.call(fn, [])
        return context.get_dummy_value()
    return sig, codegen
