"""Arithmetic that gives the same bits on every x86-64 CPU: the project's small networks and the
elementary functions outside the simulator kernel.

NumPy and the BLAS libraries choose their code by the processor they run on. A float32
``x @ w`` goes to OpenBLAS's kernel for the CPU (``OPENBLAS_CORETYPE`` picks another), which
sums in a kernel-specific order; ``np.arcsin``, ``np.arctan2``, ``np.exp``, ``np.log1p`` and
``np.tanh`` take NumPy's AVX-512 / AVX2 / baseline loops (``NPY_DISABLE_CPU_FEATURES`` picks
another), which round differently from each other and from the C library. The search plays
chaotic chains (a P3 chain of thousands of shots diverges on one flipped bit of one candidate),
so everything between a committed model and a cited number computes here instead:

* :func:`dense` / :func:`mlp`: Linear(+ReLU) layers in float32 with a fixed summation order
  (each output sums its inputs in index order, the bias last). Compiled by numba without
  fast-math, so nothing is reassociated or fused into FMAs: the same bits whether numba targets
  this host or ``NUMBA_CPU_NAME=generic``. Vector lanes run across outputs (or, for a layer of
  a few outputs, across rows), never within one sum.
* :func:`asin`, :func:`atan2`, :func:`exp`, :func:`log1p`, :func:`tanh`, :func:`sin`,
  :func:`cos`: float64 ufuncs over the C library's functions (the ones the simulator kernel
  calls), whatever NumPy's dispatch would pick. Float32 arguments are widened and the result
  rounded back by the caller.

What is still the machine's: the C library's ``libm``. glibc picks one variant of ``exp``,
``sin``, ``atan2`` ... by CPU feature (FMA + AVX2 or not); every x86-64-v3 CPU (AVX2 + FMA:
Intel since Haswell, 2013; AMD since Excavator, 2015, and every Zen) takes the same one.
``benchmarks/cross_cpu.py`` measures all of this side by side (docs: README "Reproducibility").
"""

from __future__ import annotations

import math

import numba  # Intel's SVML stays off: billiards/__init__ sets NUMBA_DISABLE_INTEL_SVML before numba loads
import numpy as np


SAMPLE_BLOCK = 8  # rows of x that share each row of w while it is in the L1 cache
NARROW = 8  # fewer outputs than this (a network's last layer): lanes across rows instead


@numba.njit(cache=True, nogil=True)
def _dense_kernel(x, w, b, relu, out):
    """out[e, s] = relu?(x[e or 0, s] @ w[e] + b[e]) in float32, inputs summed in index order.

    Two loop orders, the same sums: ``SAMPLE_BLOCK`` rows at a time, each row of ``w`` added into
    all of their outputs while it is cached (lanes across outputs); or, for fewer than ``NARROW``
    outputs, one output at a time over all rows (lanes across rows, ``x`` transposed once)."""
    E, I, O = w.shape
    S = x.shape[1]
    shared = x.shape[0] == 1
    if O < NARROW:
        xt = np.empty((I, S), dtype=np.float32)
        acc = np.empty(S, dtype=np.float32)
        for e in range(E):
            if e == 0 or not shared:
                xe = x[0] if shared else x[e]
                for s in range(S):
                    for i in range(I):
                        xt[i, s] = xe[s, i]
            for o in range(O):
                for s in range(S):
                    acc[s] = np.float32(0.0)
                for i in range(I):
                    wio = w[e, i, o]
                    xi = xt[i]
                    for s in range(S):
                        acc[s] = acc[s] + xi[s] * wio
                bo = b[e, o]
                for s in range(S):
                    v = acc[s] + bo
                    if relu and v < np.float32(0.0):
                        v = np.float32(0.0)
                    out[e, s, o] = v
        return out
    for e in range(E):
        xe = x[0] if shared else x[e]
        oe = out[e]
        for s0 in range(0, S, SAMPLE_BLOCK):
            n = min(SAMPLE_BLOCK, S - s0)
            for j in range(n):
                for o in range(O):
                    oe[s0 + j, o] = np.float32(0.0)
            for i in range(I):
                wi = w[e, i]
                for j in range(n):
                    xi = xe[s0 + j, i]
                    acc = oe[s0 + j]
                    for o in range(O):
                        acc[o] = acc[o] + xi * wi[o]
            for j in range(n):
                acc = oe[s0 + j]
                for o in range(O):
                    v = acc[o] + b[e, o]
                    if relu and v < np.float32(0.0):
                        v = np.float32(0.0)
                    acc[o] = v
    return out


def dense(x: np.ndarray, w: np.ndarray, b: np.ndarray, relu: bool = False) -> np.ndarray:
    """A stack of E Linear layers: ``x`` (E or 1, S, I), ``w`` (E, I, O), ``b`` (E, O), all
    cast to float32 -> (E, S, O) float32; ReLU after the bias when ``relu``. An ``x`` with a
    leading 1 feeds every layer of the stack."""
    x = np.ascontiguousarray(x, dtype=np.float32)
    w = np.ascontiguousarray(w, dtype=np.float32)
    b = np.ascontiguousarray(b, dtype=np.float32)
    if x.ndim != 3 or w.ndim != 3 or b.ndim != 2 or x.shape[0] not in (1, w.shape[0]) or x.shape[2] != w.shape[1] \
            or b.shape != (w.shape[0], w.shape[2]):
        raise ValueError(f"dense: shapes do not chain: x {x.shape}, w {w.shape}, b {b.shape}")
    out = np.empty((w.shape[0], x.shape[1], w.shape[2]), dtype=np.float32)
    return _dense_kernel(x, w, b, bool(relu), out)


def mlp(x: np.ndarray, weights, biases) -> np.ndarray:
    """Linear/ReLU/.../Linear (no activation after the last layer) of E stacked networks:
    ``x`` (E or 1, S, I), ``weights[l]`` (E, in, out), ``biases[l]`` (E, out) -> (E, S, out)."""
    last = len(weights) - 1
    for layer, (w, b) in enumerate(zip(weights, biases)):
        x = dense(x, w, b, relu=layer < last)
    return x


class _Ufunc:
    """A float64 ufunc that numba builds at its first call (``numba.vectorize`` with the
    signature, ``cache=True``): loading the seven from numba's cache at import would cost every
    process that imports this module, and each of the apps does, most of a second."""

    def __init__(self, signature: str, py):
        self.__name__, self.__doc__, self.__wrapped__ = py.__name__, py.__doc__, py
        self._signature, self._ufunc = signature, None

    def __call__(self, *args, **kwargs):
        if self._ufunc is None:
            self._ufunc = numba.vectorize([self._signature], cache=True)(self.__wrapped__)
        return self._ufunc(*args, **kwargs)


def _ufunc(signature: str):
    return lambda py: _Ufunc(signature, py)


@_ufunc("float64(float64)")
def asin(x):
    return math.asin(x)


@_ufunc("float64(float64, float64)")
def atan2(y, x):
    return math.atan2(y, x)


@_ufunc("float64(float64)")
def exp(x):
    return math.exp(x)


@_ufunc("float64(float64)")
def log1p(x):
    return math.log1p(x)


@_ufunc("float64(float64)")
def tanh(x):
    return math.tanh(x)


@_ufunc("float64(float64)")
def sin(x):
    return math.sin(x)


@_ufunc("float64(float64)")
def cos(x):
    return math.cos(x)


def softplus32(z: np.ndarray) -> np.ndarray:
    """torch's softplus (threshold 20: the identity above it) of a float32 array, in float32."""
    z = np.asarray(z, dtype=np.float32)
    soft = log1p(exp(np.minimum(z, np.float32(20.0)).astype(np.float64))).astype(np.float32)
    return np.where(z > np.float32(20.0), z, soft)


def tanh32(z: np.ndarray) -> np.ndarray:
    """tanh of a float32 array, computed in float64 and rounded once to float32."""
    return tanh(np.asarray(z, dtype=np.float64)).astype(np.float32)


__all__ = ["asin", "atan2", "cos", "dense", "exp", "log1p", "mlp", "sin", "softplus32", "tanh", "tanh32"]
