"""The compiled kernels' shared helpers."""

import numpy as np

from pipeline.core.jit import fma32, kernel


@kernel("float32(float32, float32, float32)")
def _fused(a, b, c):
    return fma32(a, b, c)


@kernel("float32(float32, float32, float32)")
def _separate(a, b, c):
    return a * b + c


def test_fma32_rounds_once():
    # (1 + 2^-12)^2 = 1 + 2^-11 + 2^-24: the product rounded to float32 loses the 2^-24 (half an ulp of 1, a tie
    # rounded to the even 1 + 2^-11), the fused multiply-add keeps it.
    a = np.float32(1 + 2.0 ** -12)
    c = np.float32(-(1 + 2.0 ** -11))
    assert _fused(a, a, c) == np.float32(2.0 ** -24)
    assert _separate(a, a, c) == np.float32(0.0)
    assert _fused(np.float32(1.5), np.float32(2.0), np.float32(0.25)) == np.float32(3.25)
