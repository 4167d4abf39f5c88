"""Row-wise products of (n, 3) and (n, 6) arrays, the layout of points, vectors and generalised
directions throughout the project (the array kernels on triangles are :mod:`geometries.triangle_kernels`).

* numpy's elementwise machinery pays per row when the last axis has only 3 entries:
  ``np.einsum("ij,ij->i")`` runs about 5x slower per element than products of the columns, and
  adding a (3,) vector to every row of (30000, 3) takes 190 us against 34 us when the rows are
  viewed 256 at a time. Row dot products go through :func:`row_dot` (no BLAS matrix-vector
  product, which OpenBLAS would also run on several threads, see below) and row offsets
  through :func:`add_rows`.
* OpenBLAS runs a matrix product on several threads once it holds more than about 2.6e5
  multiply-adds (M N K > 65536 x 4). For a tall, narrow product such as (30000, 3) x (3, 3) or
  (17000, 6) x (6, 6) the threads cost more to start and join than the product itself, and on a
  busy machine waiting for a preempted thread stretched one such product from ~0.1 ms to several
  ms (measured on this project's 2 shared cores). :func:`rows_times` multiplies in slices of rows
  small enough to stay on the calling thread.
* In the per-time-point path (the cast, the step, the solve) gathers, nonzero indices and
  reductions of 1-D masks are called as array methods (``a.take(i)``, ``mask.nonzero()[0]``,
  ``mask.any()``): numpy's module functions wrap them in Python layers that cost about 1 us a
  call, several percent of a step at a few thousand springs.
"""

from __future__ import annotations

import numpy as np

# Multiply-adds per product that OpenBLAS keeps on one thread (its GEMM threshold, 65536 x 4).
_SINGLE_THREAD_WORK = 65536 * 4


def row_dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n,) dot products of matching rows of two (n, 3) arrays, column by column."""
    return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]


def rows_times(rows: np.ndarray, matrix: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``rows @ matrix`` for tall (n, k) ``rows`` and a small (k, j) ``matrix``, in slices of
    rows that OpenBLAS multiplies without starting threads (into ``out`` if given)."""
    n = rows.shape[0]
    step = max(1, _SINGLE_THREAD_WORK // max(1, matrix.shape[0] * matrix.shape[1]) - 1)
    if n <= step:  # one slice: the product itself (no slicing, as numpy would do it)
        return np.matmul(rows, matrix, out=out)
    if out is None:
        out = np.empty((n, matrix.shape[1]))
    for start in range(0, n, step):  # a few slices of thousands of rows, not a loop over rows
        np.matmul(rows[start : start + step], matrix, out=out[start : start + step])
    return out


# Rows viewed at once by add_rows: the inner loop then runs over 3 x this many numbers.
_ROWS_PER_BLOCK = 256
# Repeats a (3,) vector along a block of rows by one gather (np.tile's Python layers cost several
# times that at every call).
_BLOCK_REPEAT = np.tile(np.arange(3), _ROWS_PER_BLOCK)


def add_rows(rows: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """``rows + vector`` for (n, 3) ``rows`` and a (3,) ``vector``, the same numbers: blocks of
    _ROWS_PER_BLOCK rows are viewed as one long row and get the vector repeated along it."""
    return _with_each_row(np.add, rows, vector)


def min_rows(rows: np.ndarray, vector: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``np.minimum(rows, vector)`` for (n, 3) ``rows`` and a (3,) ``vector``, as :func:`add_rows`
    (into ``out`` if given, e.g. ``rows`` itself)."""
    return _with_each_row(np.minimum, rows, vector, out)


def _with_each_row(ufunc: np.ufunc, rows: np.ndarray, vector: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``ufunc(rows, vector)`` with the (3,) vector repeated along blocks of _ROWS_PER_BLOCK rows."""
    if rows.shape[0] < 4 * _ROWS_PER_BLOCK:  # (a few blocks at most: broadcasting is as fast)
        return ufunc(rows, vector, out=out)
    rows = np.ascontiguousarray(rows)
    if out is None:
        out = np.empty_like(rows, dtype=np.result_type(rows, vector))
    whole = rows.shape[0] - rows.shape[0] % _ROWS_PER_BLOCK
    width = rows.shape[1] * _ROWS_PER_BLOCK
    ufunc(rows[:whole].reshape(-1, width), np.take(vector, _BLOCK_REPEAT), out=out[:whole].reshape(-1, width))
    ufunc(rows[whole:], vector, out=out[whole:])
    return out
