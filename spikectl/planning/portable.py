"""Float arithmetic whose every bit is the same on every x86-64 CPU: what the planners decide with.

The training-free controllers turn floats into discrete choices (a spike read at a
threshold, a weight counted as known, the argmax of a score, a tie), so a difference in
the last bit of one number can change an action and, through the rest of the episode, a
return. NumPy and its BLAS do not give the same bits everywhere:

* ``np.exp``, ``np.log``, ``np.log1p``, ``np.expm1`` (and ``np.tanh``) run SIMD kernels
  chosen at import for the CPU (AVX-512, AVX2 or the baseline), which differ in the last
  bit for some inputs (``NPY_DISABLE_CPU_FEATURES`` shows it on one machine);
* ``@``, ``np.matmul``, ``np.dot`` and ``np.linalg.inv`` of floats call OpenBLAS, whose
  kernels (chosen for the CPU: Haswell, SkylakeX, Zen, ...) sum in different orders
  (``OPENBLAS_CORETYPE`` shows it).

The functions here compute the same things with Numba loops in a fixed order, without
fast-math (no reassociation, so the order written is the order summed), calling the C
library's scalar ``exp``/``log``/``log1p``/``expm1`` (Numba has no SIMD maths library
here, and glibc picks the same variant on every CPU with FMA). Element-wise sums,
products, divisions and ``np.sqrt`` are exact IEEE operations in NumPy and need nothing.
tests/test_cpu_kinds.py plays the planners under each CPU-kind emulation and compares.
"""

from __future__ import annotations

import math

import numba
import numpy as np

_JIT = {"cache": True, "fastmath": False, "nogil": True}


@numba.njit(**_JIT)
def _exp(values: np.ndarray, out: np.ndarray) -> None:
    for index in range(values.size):
        out[index] = math.exp(values[index])


@numba.njit(**_JIT)
def _log(values: np.ndarray, out: np.ndarray) -> None:
    for index in range(values.size):
        value = values[index]
        # The C library's log(0) is -inf and log(<0) NaN, as NumPy's (without its warning).
        out[index] = math.log(value) if value > 0.0 else (-math.inf if value == 0.0 else math.nan)


@numba.njit(**_JIT)
def _log1p(values: np.ndarray, out: np.ndarray) -> None:
    for index in range(values.size):
        value = values[index]
        if value > -1.0:
            out[index] = math.log1p(value)
        else:
            out[index] = -math.inf if value == -1.0 else math.nan


@numba.njit(**_JIT)
def _expm1(values: np.ndarray, out: np.ndarray) -> None:
    for index in range(values.size):
        out[index] = math.expm1(values[index])


def _elementwise(kernel, values) -> np.ndarray | float:
    array = np.asarray(values, dtype=np.float64)
    flat = np.ascontiguousarray(array).reshape(-1)
    out = np.empty_like(flat)
    kernel(flat, out)
    if array.ndim == 0:
        return float(out[0])
    return out.reshape(array.shape)


def exp(values) -> np.ndarray:
    """``np.exp`` (float64), the same bits on every CPU."""
    return _elementwise(_exp, values)


def log(values) -> np.ndarray:
    """``np.log`` (float64), the same bits on every CPU."""
    return _elementwise(_log, values)


def log1p(values) -> np.ndarray:
    """``np.log1p`` (float64), the same bits on every CPU."""
    return _elementwise(_log1p, values)


def expm1(values) -> np.ndarray:
    """``np.expm1`` (float64), the same bits on every CPU."""
    return _elementwise(_expm1, values)


def logaddexp(a, b) -> np.ndarray:
    """``np.logaddexp`` (float64): max(a, b) + log1p(exp(-|a - b|)), the same bits on every
    CPU (equal infinities give that infinity)."""
    a, b = np.broadcast_arrays(np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64))
    larger = np.maximum(a, b)
    with np.errstate(invalid="ignore"):
        gap = -np.abs(a - b)
    gap = np.where(np.isnan(gap), -np.inf, gap)  # inf - inf: the infinity itself
    return larger + log1p(exp(gap))


@numba.njit(**_JIT)
def _batched_matmul(left: np.ndarray, right: np.ndarray, out: np.ndarray) -> None:
    """out[b] = left[b] @ right[b], each sum taken from k = 0 up."""
    for batch in range(left.shape[0]):
        for row in range(left.shape[1]):
            for column in range(right.shape[2]):
                total = 0.0
                for k in range(left.shape[2]):
                    total += left[batch, row, k] * right[batch, k, column]
                out[batch, row, column] = total


def matmul(a, b) -> np.ndarray:
    """``np.matmul(a, b)`` in float64 (1-D operands and batch broadcasting as NumPy's),
    each dot product summed in index order: the same bits on every CPU."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.ndim == 0 or b.ndim == 0:
        raise ValueError("matmul: operands must have at least one dimension")
    vector_left, vector_right = a.ndim == 1, b.ndim == 1
    if vector_left:
        a = a[None, :]
    if vector_right:
        b = b[:, None]
    if a.shape[-1] != b.shape[-2]:
        raise ValueError(f"matmul: shapes {a.shape} and {b.shape} do not align")
    batch = np.broadcast_shapes(a.shape[:-2], b.shape[:-2])
    left = np.ascontiguousarray(np.broadcast_to(a, batch + a.shape[-2:])).reshape(
        (-1,) + a.shape[-2:]
    )
    right = np.ascontiguousarray(np.broadcast_to(b, batch + b.shape[-2:])).reshape(
        (-1,) + b.shape[-2:]
    )
    out = np.empty((left.shape[0], a.shape[-2], b.shape[-1]))
    _batched_matmul(left, right, out)
    out = out.reshape(batch + (a.shape[-2], b.shape[-1]))
    if vector_left:
        out = out[..., 0, :]
    if vector_right:
        out = out[..., 0]
    return out[()] if out.ndim == 0 else out  # two vectors: a NumPy scalar, as np.matmul


@numba.njit(**_JIT)
def _spd_inverse(matrices: np.ndarray, out: np.ndarray) -> bool:
    """out[b] = inverse of the symmetric positive definite matrices[b] by Cholesky
    (A = L L^T, A^-1 = L^-T L^-1), in a fixed order; False where one is not positive
    definite.

    A posterior's precision is diagonal but for the neurons seen to release (its
    *coupled* indices), and every product that a diagonal index brings into a sum is an
    exact zero. The sums below run over the coupled indices only, in the same ascending
    order, so they give the bits of the dense sums (adding or subtracting an exact zero
    changes no float, and no sum here is ever -0.0) at a cost of the coupled block's
    size cubed; a diagonal index's entries are the exact ones of the dense loops.
    """
    size = matrices.shape[1]
    lower = np.zeros((size, size))
    inverse_lower = np.zeros((size, size))
    coupled = np.empty(size, dtype=np.int64)
    for batch in range(matrices.shape[0]):
        matrix = matrices[batch]
        count = 0
        for i in range(size):
            for j in range(size):
                if j != i and matrix[i, j] != 0.0:
                    coupled[count] = i
                    count += 1
                    break
        lower[:, :] = 0.0
        inverse_lower[:, :] = 0.0
        # A diagonal index: its row and column of L and L^-1 are the diagonal alone.
        for j in range(size):
            total = matrix[j, j]
            if not total > 0.0:
                return False
            lower[j, j] = math.sqrt(total)
            inverse_lower[j, j] = 1.0 / lower[j, j]
        for q in range(count):
            j = coupled[q]
            total = matrix[j, j]
            for p in range(q):
                k = coupled[p]
                total -= lower[j, k] * lower[j, k]
            if not total > 0.0:
                return False
            diagonal = math.sqrt(total)
            lower[j, j] = diagonal
            for s in range(q + 1, count):
                i = coupled[s]
                total = matrix[i, j]
                for p in range(q):
                    k = coupled[p]
                    total -= lower[i, k] * lower[j, k]
                lower[i, j] = total / diagonal
        for q in range(count):
            j = coupled[q]
            inverse_lower[j, j] = 1.0 / lower[j, j]
            for s in range(q + 1, count):
                i = coupled[s]
                total = 0.0
                for p in range(q, s):
                    k = coupled[p]
                    total -= lower[i, k] * inverse_lower[k, j]
                inverse_lower[i, j] = total / lower[i, i]
        for i in range(size):
            for j in range(i + 1):
                out[batch, i, j] = 0.0
                out[batch, j, i] = 0.0
            out[batch, i, i] = 0.0 + inverse_lower[i, i] * inverse_lower[i, i]
        for s in range(count):
            i = coupled[s]
            for r in range(s + 1):
                j = coupled[r]
                total = 0.0
                for p in range(s, count):
                    k = coupled[p]
                    total += inverse_lower[k, i] * inverse_lower[k, j]
                out[batch, i, j] = total
                out[batch, j, i] = total
    return True


def spd_inverse(matrices) -> np.ndarray:
    """The inverse of each symmetric positive definite matrix [..., m, m] (a posterior's
    precision), by Cholesky in a fixed order: the same bits on every CPU. A matrix that is
    not positive definite is a ValueError."""
    matrices = np.asarray(matrices, dtype=np.float64)
    if matrices.ndim < 2 or matrices.shape[-1] != matrices.shape[-2]:
        raise ValueError(f"spd_inverse needs square matrices [..., m, m], got {matrices.shape}")
    flat = np.ascontiguousarray(matrices).reshape((-1,) + matrices.shape[-2:])
    out = np.empty_like(flat)
    if not _spd_inverse(flat, out):
        raise ValueError("spd_inverse: a matrix is not symmetric positive definite")
    return out.reshape(matrices.shape)


@numba.njit(**_JIT)
def _gaussian_posterior(precision: np.ndarray, moment: np.ndarray, covariance: np.ndarray,
                        mean: np.ndarray, sd: np.ndarray) -> bool:  # fmt: skip
    """covariance[b] = precision[b]^-1 (:func:`_spd_inverse`), mean[b] = covariance[b] @
    moment[b] summed from k = 0 up (as :func:`matmul`), sd[b] = the square root of its
    diagonal; False where a precision is not positive definite."""
    if not _spd_inverse(precision, covariance):
        return False
    for batch in range(precision.shape[0]):
        for row in range(precision.shape[1]):
            total = 0.0
            for k in range(precision.shape[2]):
                total += covariance[batch, row, k] * moment[batch, k]
            mean[batch, row] = total
            sd[batch, row] = math.sqrt(covariance[batch, row, row])
    return True


def gaussian_posterior(precision: np.ndarray, moment: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(mean, standard deviation), each [b, m], of Gaussians with precisions [b, m, m] and
    moments (precision @ mean) [b, m]: ``matmul(spd_inverse(precision), moment)`` and the
    square root of the inverse's diagonal in one compiled call, the same bits. A precision
    that is not positive definite is a ValueError."""
    precision = np.ascontiguousarray(precision, dtype=np.float64)
    moment = np.ascontiguousarray(moment, dtype=np.float64)
    if precision.ndim != 3 or precision.shape[1] != precision.shape[2] \
            or moment.shape != precision.shape[:2]:  # fmt: skip
        raise ValueError(f"gaussian_posterior needs precisions [b, m, m] and moments [b, m], "
                         f"got {precision.shape} and {moment.shape}")  # fmt: skip
    covariance = np.empty_like(precision)
    mean, sd = np.empty(moment.shape), np.empty(moment.shape)
    if not _gaussian_posterior(precision, moment, covariance, mean, sd):
        raise ValueError("gaussian_posterior: a precision is not symmetric positive definite")
    return mean, sd
