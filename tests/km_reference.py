"""An independent high-precision Kubelka-Munk, for tests: the textbook form of Curtis et al. (1997, sec. 5) in mpmath."""

import mpmath

mpmath.mp.dps = 50


def layer(K, S, x):
    """R, T of one layer, textbook hyperbolic form, with its exact limits at S = 0, K = 0, x = 0."""
    K, S, x = mpmath.mpf(K), mpmath.mpf(S), mpmath.mpf(x)
    if x == 0:
        return mpmath.mpf(0), mpmath.mpf(1)
    if S == 0:
        return mpmath.mpf(0), mpmath.exp(-K * x)
    if K == 0:
        return S * x / (1 + S * x), 1 / (1 + S * x)
    a = 1 + K / S
    # b = sqrt(a^2 - 1), written as sqrt(K (K + 2S)) / S so that it keeps its precision for tiny K/S.
    b = mpmath.sqrt(K * (K + 2 * S)) / S
    c = a * mpmath.sinh(b * S * x) + b * mpmath.cosh(b * S * x)
    return mpmath.sinh(b * S * x) / c, b / c
