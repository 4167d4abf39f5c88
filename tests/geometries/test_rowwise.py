"""geometries/rowwise.py: row-wise products equal the plain numpy expressions they replace."""

from __future__ import annotations

import numpy as np

from geometries.rowwise import add_rows, min_rows, row_dot, rows_times


def test_row_dot_is_the_rowwise_dot_product():
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(1000, 3)), rng.normal(size=(1000, 3))
    # three products and two sums per row: within a few ulps of einsum's order of summation
    np.testing.assert_allclose(row_dot(a, b), np.einsum("ij,ij->i", a, b), rtol=0, atol=1e-15 * np.abs(a * b).sum(axis=1).max())


def test_rows_times_equals_the_product_across_its_slices():
    """Sizes on both sides of the slice length (29126 rows for a 3 x 3, 7280 for a 6 x 6), into a
    fresh array and into part of a larger one."""
    rng = np.random.default_rng(2)
    for n, k in ((10, 3), (29126, 3), (70001, 3), (7281, 6), (20000, 6)):
        rows, matrix = rng.normal(size=(n, k)), rng.normal(size=(k, k))
        expected = rows @ matrix
        np.testing.assert_allclose(rows_times(rows, matrix), expected, rtol=1e-15, atol=1e-15 * np.abs(expected).max())
        out = np.full((n + 4, k), np.nan)
        rows_times(rows, matrix.T, out=out[:n])  # a transposed view of the matrix, too
        np.testing.assert_allclose(out[:n], rows @ matrix.T, rtol=1e-15, atol=1e-15 * np.abs(expected).max())
        assert np.isnan(out[n:]).all()


def test_add_rows_is_the_broadcast_sum_bit_for_bit():
    """Row counts below, at and off a multiple of the block (256 rows); float64 and float32 rows."""
    rng = np.random.default_rng(3)
    vector = rng.normal(size=3)
    for n in (0, 5, 256, 1000, 30001):
        rows = rng.normal(size=(n, 3))
        assert np.array_equal(add_rows(rows, vector), rows + vector)
        assert np.array_equal(add_rows(rows.astype(np.float32), vector), rows.astype(np.float32) + vector)


def test_min_rows_is_the_broadcast_minimum_bit_for_bit_into_out():
    """Row counts below, at and off a multiple of the block (256 rows), into ``out`` (the rows
    themselves, as the ray caster's grid look-up does) and into a fresh array; an integer vector
    (the grid's largest cell indices)."""
    rng = np.random.default_rng(4)
    for vector in (rng.normal(size=3), np.array([3, 7, 11])):
        for n in (0, 5, 255, 256, 1000, 30001):
            rows = 10.0 * rng.normal(size=(n, 3))
            expected = np.minimum(rows, vector)
            assert np.array_equal(min_rows(rows, vector), expected)
            same = rows.copy()
            assert min_rows(same, vector, out=same) is same
            assert np.array_equal(same, expected)
