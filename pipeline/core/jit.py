"""Compiled loops (numba) for the render's per-pixel passes that numpy can only do as many passes.

numpy runs one operation over a whole array at a time: a pass that reads a hit's material, picks its colour and
turns its normal needs a dozen temporaries of the image's size, and at 800x600 rays those temporaries, not the
arithmetic, are most of the time. A kernel here does such a pass in one loop over the rays.

Conventions:

- A kernel is compiled for the explicit signatures it declares, when its module is imported: a process pool's
  workers, forked after the import, never compile. Numba caches the machine code on disk (beside the module, or
  under ``NUMBA_CACHE_DIR``), so only the first import after an install or an edit compiles (seconds of CPU per
  kernel: docs/performance.md); later imports load it.
- No fast-math: IEEE arithmetic in the order written (no fused multiply-adds, no reassociation, except where a
  kernel asks for one with :func:`fma32`, as the OpenCV loop it replaces does), float32 where the
  numpy code it replaced was float32 (numba makes a Python float literal float64: write ``np.float32(0.5)``).
  The kernels gave the same bytes on an AMD EPYC with AVX2 (Python 3.11, glibc 2.36) and an Intel Xeon with
  AVX-512 (Python 3.12, glibc 2.39), powf and sqrt included (numba 0.68.1, seeded inputs).
- The signatures take C-contiguous, writeable arrays: pass inputs through :func:`as_input` (a read-only array,
  e.g. one that Arrow owns, is a type of its own to numba). Outputs are allocated by the caller or the kernel.
- Each kernel is a plain function of arrays, documented like any other, and tested in closed form or against
  its definition, ray by ray.
"""

from __future__ import annotations

from collections.abc import Callable

import numba
import numpy as np
from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic


def kernel(*signatures: str) -> Callable[[Callable], Callable]:
    """Decorator: compile a function of arrays now, for ``signatures`` (numba's strings, e.g.
    ``"uint8[::1](float32[::1])"``), without the GIL, cached on disk."""
    return numba.njit(list(signatures), cache=True, nogil=True, error_model="numpy", boundscheck=False)


@intrinsic
def fma32(typingctx, a, b, c):
    """``a * b + c`` of float32 numbers rounded once (IEEE fused multiply-add; LLVM's ``llvm.fma``, the processor's
    instruction where it has one), for use inside kernels: the arithmetic of OpenCV's SIMD loops, which a kernel
    must repeat exactly to give the same bytes as the OpenCV call it replaces (no-fast-math kernels never fuse by
    themselves)."""
    if not all(arg == types.float32 for arg in (a, b, c)):
        return None  # numba reports no matching signature

    def codegen(context, builder, signature, args):
        f32 = ir.FloatType()
        fma = builder.module.declare_intrinsic("llvm.fma", [f32], ir.FunctionType(f32, [f32, f32, f32]))
        return builder.call(fma, args)

    return types.float32(types.float32, types.float32, types.float32), codegen


def as_input(a: np.ndarray, dtype: np.dtype | type) -> np.ndarray:
    """``a`` as a C-contiguous, writeable array of ``dtype``, copied only where it is not one already (a kernel's
    input: the kernels never write their inputs)."""
    return np.require(a, dtype, ("C", "W"))


def as_view_input(a: np.ndarray, dtype: np.dtype | type) -> np.ndarray:
    """``a`` as a writeable array of ``dtype``, copied only where it is not one already: unlike :func:`as_input`,
    a strided view (a column of an (N, 6) ray array) stays a view, for kernels whose signatures take any layout
    (``float32[:]``)."""
    return np.require(a, dtype, ["W"])
