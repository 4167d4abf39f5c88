"""Sparse factors of the coupled layer's matrices, and their low-rank updates.

The coupled layer's vertex matrices are SPD and banded once renumbered by reverse Cuthill-McKee
(half-bandwidth about the square root of the vertex count on a surface patch), so LAPACK's banded
Cholesky factors them; it took 0.35-0.65x the time of SuperLU's symmetric-mode LU on the ankle
surfaces (1.1k-14k vertices). The ordering depends on the sparsity only and is found once per
cell set (``OperatorPattern``); past ``MAX_BANDED_HALF_WIDTH`` the sparse LU takes over. A
refactorisation on the same pattern keeps the factor's columns before the first one whose
entries changed and factors only the trailing block (``OperatorPattern._banded_cholesky``).
Of the fill-reducing sparse factors measured on the stances' matrices (0.6k-14k vertices,
``benchmarks/bench_factorisations.py``, docs/method.md), QDLDL's LDL^T with its ordering kept
and only the numbers refactored took 1.2-3.6x the banded path's time, CHOLMOD through cholespy
(no numeric-only refactorisation) 3.1-6.2x, SuperLU 2.7-4.1x; CHOLMOD through cvxopt (the
optional extra ``cholmod``: a supernodal Cholesky, its symbolic analysis once per pattern, then
the numbers only) beat it where the pattern is kept over a run and large, the gap laws' layer
over the whole surface at 5k-14k vertices (0.5-0.8x), and lost on smaller layers and on the
threshold law's, a new pattern at every time point (1.2-2.8x). So CHOLMOD factors the whole
surface's pattern past ``CHOLMOD_MIN_BAND_WORK`` where cvxopt is installed
(``SupernodalCholesky``), the banded path everything else; the two agree to round-off. The
two-pole's block matrix is indefinite; QDLDL factors it, each solve checked against its backward
error (``indefinite_solve``).

A factor is kept over a run and corrected rather than refactored where only a few springs'
weights changed (``LowRankUpdate``, the Woodbury identity).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.linalg import cho_solve_banded, lu_factor, lu_solve
from scipy.linalg.lapack import dpbtrf
from scipy.sparse.csgraph import reverse_cuthill_mckee
from scipy.sparse.linalg import splu

from geometries.errors import SolverError


@functools.cache
def cholmod_module():
    """cvxopt's CHOLMOD (the optional extra "cholmod": SuiteSparse inside cvxopt's wheels), or
    None where cvxopt is not installed (imported on first use: the independent springs never need it)."""
    try:
        from cvxopt import cholmod
    except ImportError:
        return None
    return cholmod


def concatenated_ranges(start: np.ndarray, count: np.ndarray) -> np.ndarray:
    """The positions start[i], ..., start[i] + count[i] - 1 of every i, concatenated (a CSR
    matrix's entries of chosen rows, given their indptr starts and lengths)."""
    return np.repeat(start - (np.cumsum(count) - count), count) + np.arange(int(count.sum()))


# CHOLMOD (cvxopt) factors the whole surface's pattern where the banded factor's work, n w^2 for
# n vertices of half-bandwidth w, is at least this. On the stances' gap-law layers (the whole
# surface) it took 1.5-1.8x the banded path's time at n w^2 = 3e6 (1.5k vertices) and 0.5-0.8x
# from 4e7 on (5k-14k vertices, and the 30k-spring layer's coarse space); on the threshold law,
# whose pattern is new at every time point, the symbolic analysis each time made it 1.2-2.8x
# slower (benchmarks/bench_factorisations.py, docs/method.md).
CHOLMOD_MIN_BAND_WORK = 1e7

# Past this half-bandwidth (after reverse Cuthill-McKee) the sparse LU is the cheaper factor: on
# the ankle surfaces LAPACK's banded Cholesky took 0.35-0.65x SuperLU's time at half-bandwidths
# 47-156 (1.1k-14k vertices), a ratio growing about like the bandwidth (benchmarks/bench_thin_layer.py).
MAX_BANDED_HALF_WIDTH = 256


@dataclass
class OperatorPattern:
    """Sparsity of H = M + K on a cell set (v, v), canonical CSC, and the transfer Q (m, v).

    ``slots[t]`` (9,) int: where triangle t's corner pair (i, j), row-major, sits in the
    matrix's data, -1 for a pair on the free edge; Q^T diag(x) Q is then the pattern with x / 9
    added at the slots (no sparse product, no re-assembly). The band layout of the factorisation
    (an ordering and where each stored entry goes) depends on the pattern only, so it is found
    at the first factorisation and reused; so is the last band factor, in part
    (``_banded_cholesky``). A pattern that is not one cell set's H (a coarse space's, a stack
    of terms', ``StackedPattern``) has no slots and may have no Q: it is factored the same way.
    """

    indices: np.ndarray
    indptr: np.ndarray
    slots: np.ndarray = field(default_factory=lambda: np.zeros((0, 9), np.int64))  # (m, 9) int
    q: sp.csr_matrix | None = None  # (m, v)
    #: the pattern of the whole surface (or of its coarse space): the cell set a run keeps at
    #: every time point (the gap laws' layer), where one symbolic analysis serves the whole run
    whole_surface: bool = False
    #: the stored lower entries and band factor of the last banded factorisation on this pattern
    last_factor: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False)

    @property
    def n_vertices(self) -> int:
        return self.indptr.shape[0] - 1

    def matrix(self, data: np.ndarray) -> sp.csc_matrix:
        return sp.csc_matrix((data, self.indices, self.indptr), shape=(self.n_vertices, self.n_vertices))

    def sum_at_slots(self, per_pair: np.ndarray) -> np.ndarray:
        """Matrix data (nnz,) from values per triangle and corner pair (m, 9), or per triangle
        (m,) for the same value on its nine pairs, summed where they meet."""
        if per_pair.ndim == 1:
            return self.triangle_sums @ per_pair
        kept, slot = self.kept_pairs
        return np.bincount(slot, weights=per_pair.ravel()[kept], minlength=self.indices.shape[0])

    @functools.cached_property
    def triangle_sums(self) -> sp.csc_matrix:
        """(nnz, m): the sum at each slot of the values of the triangles whose pairs sit there, a
        sparse product in place of a gather and a bincount (the coupled matrix's data at each
        factorisation; several times cheaper). Column t holds triangle t's pairs in their order
        in ``kept_pairs`` and its entries are ones, so each sum is the bincount's to the bit."""
        kept, slot = self.kept_pairs
        m = self.slots.shape[0]
        indptr = np.zeros(m + 1, np.int64)
        np.cumsum(np.bincount(kept // 9, minlength=m), out=indptr[1:])
        return sp.csc_matrix((np.ones(kept.shape[0]), slot, indptr), shape=(self.indices.shape[0], m))

    @functools.cached_property
    def kept_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """The corner pairs off the free edge: their flat positions in (m, 9) and their slots."""
        kept = np.flatnonzero(self.slots.ravel() >= 0)
        return kept, self.slots.ravel()[kept]

    @functools.cached_property
    def band(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """(ordering, the stored entries in the lower band, their flat positions in LAPACK's band
        storage (column-major, as LAPACK reads it), half-width) of the reverse Cuthill-McKee
        renumbering; built on first use."""
        n = self.n_vertices
        # The pattern is symmetric, so its CSC arrays read as CSR are the same graph (no conversion).
        graph = sp.csr_matrix((np.ones(self.indices.shape[0]), self.indices, self.indptr), shape=(n, n))
        order = reverse_cuthill_mckee(graph, symmetric_mode=True).astype(np.int64)
        position = np.empty(n, np.int64)
        position[order] = np.arange(n)
        row = position[self.indices]
        col = position[np.repeat(np.arange(n), np.diff(self.indptr))]
        lower = np.flatnonzero(row >= col)  # LAPACK's lower band storage: ab[i - j, j] = A[i, j]
        width = int((row - col)[lower].max(initial=0))
        return order, lower, col[lower] * (width + 1) + (row - col)[lower], width

    def factorise(self, data: np.ndarray):
        """Factor of the SPD matrix with this pattern and ``data`` (nnz,); returns solve(rhs (v,) or (v, k)).

        CHOLMOD where it wins (``uses_cholmod``); otherwise the banded Cholesky in reverse
        Cuthill-McKee order up to MAX_BANDED_HALF_WIDTH (of the trailing part only where the last
        factor on this pattern can be kept, ``_banded_cholesky``), SuperLU's symmetric-mode LU
        (diagonal pivots, minimum-degree ordering) beyond.
        """
        n = self.n_vertices
        if n == 0:  # every vertex on a free edge: the smoothed field vanishes, the layer is local
            return np.zeros_like
        if self.uses_cholmod:
            return self.supernodal.factorise(data)
        order, lower, flat, width = self.band
        try:
            if width > MAX_BANDED_HALF_WIDTH:
                return splu(self.matrix(data), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}).solve
            entries = data[lower]
            factor = self._banded_cholesky(entries)
        except (np.linalg.LinAlgError, RuntimeError) as error:  # RuntimeError: SuperLU's "singular matrix"
            raise SolverError(f"the coupled thin-layer matrix is not positive definite ({error})") from None
        self.last_factor = (entries, factor)

        def solve(rhs: np.ndarray) -> np.ndarray:
            out = np.empty_like(rhs)
            out[order] = cho_solve_banded((factor, True), rhs[order], overwrite_b=True, check_finite=False)
            return out

        return solve

    @property
    def uses_cholmod(self) -> bool:
        """Whether the factorisations on this pattern go to CHOLMOD (``SupernodalCholesky``):
        where it is installed, on the whole surface's pattern (its symbolic analysis once serves
        the run), where the banded factor's work n w^2 is at least CHOLMOD_MIN_BAND_WORK."""
        if not self.whole_surface or cholmod_module() is None:
            return False
        width = self.band[3]
        return self.n_vertices * width * width >= CHOLMOD_MIN_BAND_WORK

    @functools.cached_property
    def supernodal(self) -> "SupernodalCholesky":
        return SupernodalCholesky(self.indices, self.indptr)

    def _banded_cholesky(self, entries: np.ndarray) -> np.ndarray:
        """LAPACK's lower band factor (width + 1, v), column-major, of the matrix whose lower band
        holds ``entries`` (the stored lower entries, in ``band`` order).

        Only the trailing part is refactored where the matrix differs from the last one factored
        on this pattern from band column k on: with A = L L^T split at k, L11 and L21 depend on
        A11 and A21 alone and are kept, and L22 = chol(A22 - L21 L21^T), where L21 L21^T touches
        A22's leading w x w block only (w the half-width). The active-set iterations change the
        weights of the springs at the contact's edge, so on the gap law's layer (the whole surface,
        the same operators over a run) k sat at 0.12-0.6 of the vertices on the 30k-spring ankle.
        Exact to round-off.
        """
        order, lower, flat, width = self.band
        n = self.n_vertices
        band = np.zeros((width + 1) * n)
        band[flat] = entries
        band = band.reshape((width + 1, n), order="F")  # column j of the band is contiguous
        last = self.last_factor
        start = 0
        if last is not None:
            changed = np.flatnonzero(entries != last[0])
            start = int(flat[changed].min()) // (width + 1) if changed.size else n  # the first column that differs
        if start == n:
            return last[1]
        if start > 0:
            factor = last[1]
            band[:, :start] = factor[:, :start]
            # L21: rows start .. start + w - 1, columns start - w .. start - 1, L[i, j] = factor[i - j, j].
            rows = np.arange(start, min(start + width, n))
            cols = np.arange(max(start - width, 0), start)
            offset = rows[:, None] - cols[None, :]
            l21 = np.where(offset <= width, factor[np.minimum(offset, width), cols[None, :]], 0.0)
            a, b = _lower_triangle(rows.size)
            band[a - b, start + b] -= (l21 @ l21.T)[a, b]
        trailing, info = dpbtrf(band[:, start:], lower=1, overwrite_ab=1)  # in place: the view is column-major
        if info > 0:
            raise np.linalg.LinAlgError(f"leading minor {start + info} is not positive definite")
        if not np.shares_memory(trailing, band):  # LAPACK worked on a copy
            band[:, start:] = trailing
        return band


@dataclass(frozen=True)
class StackedPattern:
    """The pattern of the stacked vertex matrix sigma H + Z diag(x) Z^T of several terms
    (``edem.thin_layer.LayerCompliance``): sigma H = diag(sigma_1 H_1, sigma_2 H_2, ...) and
    Z (V, m) the terms' Z stacked, whose column j couples the fields of every term at spring j.

    Its pattern holds every term's H (``block_slots``: where their entries go) and every pair
    (a, b) of the entries of a row of Z^T (m, V), so Z diag(x) Z^T is one sparse product
    (``coupling``: (nnz, m), spring j's pairs in its column), with no sparse assembly per
    factorisation. Where the terms have one sign (a Pade sandwich) the matrix is sigma times an
    SPD one (docs/method.md), factored as one term's is (``OperatorPattern``: the banded Cholesky
    in reverse Cuthill-McKee order over the stacked fields, or CHOLMOD); where they have both (the
    two-pole's), the LDL^T takes the pairs of the springs in contact only (``KeptOrderingLDL``).
    """

    pattern: OperatorPattern
    block_slots: tuple[np.ndarray, ...]  # each term's stored entries' positions in the stacked data
    pair_first: np.ndarray  # (pairs,) the entries of Z^T's data whose product each pair is, in slot order
    pair_second: np.ndarray
    pair_spring: np.ndarray  # (pairs,) its spring
    pair_indptr: np.ndarray  # (nnz + 1,) the pairs of each slot

    @staticmethod
    def build(patterns: list[OperatorPattern], z_t: sp.csr_matrix) -> "StackedPattern":
        """From the terms' patterns and Z^T (m, V) as the terms' Z^T side by side (CSR, laid out
        as the layers' Z^T will be)."""
        offsets = np.cumsum([0] + [p.n_vertices for p in patterns])
        n = int(offsets[-1])
        # keys row * n + column in int64: scipy's int32 indices would wrap past n = 46341 stacked fields
        block_keys = [(np.repeat(np.arange(p.n_vertices, dtype=np.int64), np.diff(p.indptr)) + o) * n + p.indices.astype(np.int64) + o
                      for p, o in zip(patterns, offsets)]
        # every ordered pair of entries (first, second) of each row of Z^T
        count = np.diff(z_t.indptr)
        spring = np.repeat(np.arange(count.shape[0]), count * count)
        k = np.arange(spring.shape[0]) - np.repeat(np.cumsum(count * count) - count * count, count * count)
        first, second = z_t.indptr[spring] + k // count[spring], z_t.indptr[spring] + k % count[spring]
        # canonical CSC: by column, then row
        columns = z_t.indices.astype(np.int64)
        stored, slot = np.unique(np.concatenate(block_keys + [columns[second] * n + columns[first]]), return_inverse=True)
        indptr = np.zeros(n + 1, np.int64)
        np.cumsum(np.bincount(stored // n, minlength=n), out=indptr[1:])
        ends = np.cumsum([keys.shape[0] for keys in block_keys])
        pair_slot = slot[ends[-1]:]
        order = np.argsort(pair_slot, kind="stable")
        pair_indptr = np.zeros(stored.shape[0] + 1, np.int64)
        np.cumsum(np.bincount(pair_slot, minlength=stored.shape[0]), out=pair_indptr[1:])
        pattern = OperatorPattern(stored % n, indptr, whole_surface=all(p.whole_surface for p in patterns))
        return StackedPattern(pattern, tuple(np.split(slot[: ends[-1]], ends[:-1])), first[order], second[order], spring[order], pair_indptr)

    def blocks(self, h_data: list[np.ndarray]) -> np.ndarray:
        """The stacked data (nnz,) of diag(H_1, H_2, ...) from each term's H data."""
        out = np.zeros(self.pattern.indices.shape[0])
        for slots, data in zip(self.block_slots, h_data):
            out[slots] = data
        return out

    @functools.cached_property
    def _entries(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(row, column (nnz,) of each stored entry, whether it is one of the terms' H's (nnz,) bool)."""
        n = self.pattern.n_vertices
        block = np.zeros(self.pattern.indices.shape[0], bool)
        for slots in self.block_slots:
            block[slots] = True
        return self.pattern.indices, np.repeat(np.arange(n), np.diff(self.pattern.indptr)), block

    def coupling(self, z_t: sp.csr_matrix) -> sp.csr_matrix:
        """(nnz, m): the stacked data of Z diag(x) Z^T is this times x (m,), for Z^T (m, V) laid
        out as the one the pattern was built from."""
        products = z_t.data[self.pair_first] * z_t.data[self.pair_second]
        return sp.csr_matrix((products, self.pair_spring, self.pair_indptr), shape=(self.pair_indptr.shape[0] - 1, z_t.shape[0]))


class SupernodalCholesky:
    """CHOLMOD's Cholesky factor (cvxopt) of the matrices on one sparsity pattern: the symbolic
    analysis (fill-reducing ordering, elimination tree, supernodes) once, then a numeric
    factorisation per matrix into the same factor object."""

    def __init__(self, indices: np.ndarray, indptr: np.ndarray) -> None:
        from cvxopt import matrix, spmatrix

        self.cholmod, self.dense = cholmod_module(), matrix
        n = indptr.shape[0] - 1
        column = np.repeat(np.arange(n), np.diff(indptr))
        self.lower = np.flatnonzero(indices >= column)  # CHOLMOD reads the lower triangle, in CSC order
        self.matrix = spmatrix(1.0, indices[self.lower], column[self.lower], (n, n))
        self.factor = self.cholmod.symbolic(self.matrix)
        self.numbers = None  # the lower entries the factor holds now

    def factorise(self, data: np.ndarray):
        """solve(rhs (v,) or (v, k)) with the matrix of this pattern and ``data`` (nnz,), SPD.

        The factor object is shared by every factorisation on the pattern, so a solve whose
        numbers it no longer holds (another factorisation came since) factors them again first."""
        entries = data[self.lower]
        self._numeric(entries)

        def solve(rhs: np.ndarray) -> np.ndarray:
            if self.numbers is not entries:
                self._numeric(entries)
            x = self.dense(rhs)
            self.cholmod.solve(self.factor, x)
            return np.array(x).reshape(rhs.shape)

        return solve

    def _numeric(self, entries: np.ndarray) -> None:
        self.matrix.V = self.dense(entries)
        try:
            self.cholmod.numeric(self.matrix, self.factor)
        except ArithmeticError as error:
            self.numbers = None
            raise SolverError(f"the coupled thin-layer matrix is not positive definite (CHOLMOD: {error})") from None
        self.numbers = entries


@functools.lru_cache(maxsize=8)
def _lower_triangle(n: int) -> tuple[np.ndarray, np.ndarray]:
    """np.tril_indices(n), kept (read-only): a run refactors with the same half-width over and over."""
    rows, cols = np.tril_indices(n)
    rows.flags.writeable = cols.flags.writeable = False
    return rows, cols


# Past this many changed spring weights the coupled matrix is refactored rather than corrected by
# the Woodbury identity: each changed weight costs one solve with the old factor, and on the ankle
# surfaces (14k vertices, half-bandwidth 156) a banded factorisation cost about 16 single solves
# (benchmarks/bench_thin_layer.py). The two-pole's indefinite block (QDLDL, each solve checked)
# cost 24-25 checked single solves a factorisation at 3k and 29k springs (3k and 29k unknowns) where
# its ordering is found anew (the threshold law's cells, new at every time point), so it takes
# twice as many there; on a kept ordering (``KeptOrderingLDL``) a refactorisation costs about 13
# (2.3 against 0.17 ms at 3k), and the two-pole's gap-law stance at 3k springs took 0.321 s with
# 8, 0.330 s with 12 and 0.351 s with 16 (medians of 5, load 0.5, 2026-11-28), so it takes 8.
LOW_RANK_MAX = 8
LOW_RANK_MAX_INDEFINITE = 16


@dataclass
class LowRankUpdate:
    """A factor of A(w0) = sigma H + Z diag(w0) Z^T, reused for A(w) with w - w0 nonzero on k springs:

        A(w)^-1 = A0^-1 - Y (I + D Z_k^T Y)^-1 D Z_k^T A0^-1,   Y = A0^-1 Z_k,  D = diag(w - w0)_k,

    (the Woodbury identity; the k x k capacitance is nonsingular whenever A(w) is). The columns Y
    of the springs met so far are kept (up to 8 LOW_RANK_MAX of them), so a spring toggling back
    and forth is solved for once.
    """

    key: tuple  # edem.thin_layer.LayerCompliance._operator_key() of the factored matrix
    weight: np.ndarray  # (m,) w0
    solve: object  # A0^-1
    columns: dict = field(default_factory=dict)  # spring -> its column of Y (V,)

    def matches(self, key: tuple, n_springs: int) -> bool:
        if self.weight.shape[0] != n_springs or len(key) != len(self.key):
            return False
        same = lambda x, y: x is y or np.array_equal(x, y)  # noqa: E731 (the layer kept over a run holds the same arrays)
        return all(a[:2] == b[:2] and same(a[2], b[2]) and same(a[3], b[3]) for a, b in zip(key, self.key))

    def updated(self, z_t: sp.csr_matrix, changed: np.ndarray, delta: np.ndarray):
        """solve(rhs) with A(w) for the weights changed by ``delta`` (k,) on the springs ``changed``
        (k,); ``z_t`` (m, V): Z^T."""
        z_k = _dense_columns(z_t, changed)  # (V, k): each spring's column has its triangle's corners
        new = [j for j in changed.tolist() if j not in self.columns]
        if len(self.columns) + len(new) > 8 * LOW_RANK_MAX:  # bounded memory: keep the columns in use
            self.columns = {j: self.columns[j] for j in changed.tolist() if j in self.columns}
        if new:
            solved = self.solve(z_k[:, np.searchsorted(changed, new)])
            self.columns.update(zip(new, solved.T))
        y = np.column_stack([self.columns[j] for j in changed.tolist()])
        capacitance = lu_factor(np.eye(changed.size) + delta[:, None] * (z_k.T @ y), check_finite=False)

        def solve(rhs: np.ndarray) -> np.ndarray:
            x = self.solve(rhs)
            return x - y @ lu_solve(capacitance, delta[:, None] * (z_k.T @ x) if x.ndim > 1 else delta * (z_k.T @ x), check_finite=False)

        return solve


def _dense_columns(z_t: sp.csr_matrix, rows: np.ndarray) -> np.ndarray:
    """(V, k): the rows ``rows`` (k,) of the CSR matrix ``z_t`` (m, V) as dense columns (a CSR row cut
    and conversion cost several times as much)."""
    start, count = z_t.indptr[rows], np.diff(z_t.indptr)[rows]
    column = np.repeat(np.arange(rows.shape[0]), count)
    entry = concatenated_ranges(start, count)
    out = np.zeros((rows.shape[0], z_t.shape[1]))
    out[column, z_t.indices[entry]] = z_t.data[entry]
    return out.T


def indefinite_solve(matrix: sp.csc_matrix, upper: sp.csc_matrix | None = None):
    """solve(rhs (v,) or (v, k)) with a symmetric indefinite matrix (v, v): QDLDL's LDL^T, checked.
    ``upper``: its upper triangle (CSC), where the caller has it (QDLDL reads only that).

    QDLDL (approximate minimum degree, then an LDL^T with its pivots on the diagonal) factored
    and solved the two-pole's block matrices of the ankle stances in 0.55-0.77x SuperLU's time
    (symmetric mode, threshold pivoting), with residuals at round-off (relative <= 5e-15 against
    SuperLU's 2e-15; ``benchmarks/bench_factorisations.py``). The
    block is not quasi-definite (the bulge term's local compliance is below its strength, so its
    diagonal block is indefinite where springs are in contact), so no pivot order is guaranteed
    stable; each solve is therefore checked (``checked_solve``).
    """
    import qdldl  # a core dependency, imported where the two-pole needs it

    try:
        ldl = qdldl.Solver(matrix) if upper is None else qdldl.Solver(upper, upper=True)
    except RuntimeError:  # a zero pivot
        return checked_solve(matrix, None)
    return checked_solve(matrix, ldl.solve)


def checked_solve(matrix: sp.csc_matrix, ldl_solve, norm: float | None = None):
    """solve(rhs (v,) or (v, k)) with the symmetric matrix (v, v) by ``ldl_solve`` (one vector at a
    time; None: none), checked: past a normwise backward error of v times the unit round-off (the
    bound of a factorisation without element growth) the matrix is factored by SuperLU with
    threshold pivoting instead, as it is where there is no ``ldl_solve`` (QDLDL met a zero pivot).
    ``norm``: ||A||_inf where the caller has it."""
    n = matrix.shape[0]
    if norm is None:
        norm = float(np.abs(matrix).sum(axis=1).max()) if n else 0.0  # ||A||_inf
    pivoted = []

    def superlu():
        if not pivoted:
            try:
                pivoted.append(splu(matrix, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.1, options={"SymmetricMode": True}).solve)
            except RuntimeError as error:  # SuperLU's "singular matrix"
                raise SolverError(f"the coupled thin-layer matrix is singular ({error})") from None
        return pivoted[0]

    def solve(rhs: np.ndarray) -> np.ndarray:
        if ldl_solve is None or pivoted:
            return superlu()(rhs)
        columns = rhs.reshape(n, -1)
        x = np.column_stack([ldl_solve(b) for b in columns.T])  # QDLDL solves one vector at a time
        # the normwise backward error, as a product (a zero column, x = 0, is exact: no 0 / 0)
        residual = np.abs(matrix @ x - columns).max(axis=0)
        if not np.all(residual <= n * np.finfo(float).eps * (norm * np.abs(x).max(axis=0) + np.abs(columns).max(axis=0))):  # also NaN
            return superlu()(rhs)
        return x.reshape(rhs.shape)

    return solve


# An ordering is found for the springs in contact and this many rings of springs around them (the
# springs sharing an unknown with them, ring by ring), so the next time points' growing contact stays
# within it. On the 3k-spring gap-law stance (two-pole; cProfile, 2026-11-28) 24 / 10 / 5 / 4 / 3
# orderings were found with 0 / 1 / 2 / 3 / 4 rings, each refactorisation on them cost 2.2 / 2.3 /
# 2.4 / 2.4 / 2.6 ms (the rings' fill) and the stance 0.389 / 0.356 / 0.351 / 0.346 / 0.367 s; the
# 29k-spring stance took 10.0 s with none or two (one run each, load 1).
ORDERING_RINGS = 2


class KeptOrderingLDL:
    """QDLDL's checked LDL^T (``checked_solve``) of the two-pole's stacked matrices on one
    ``StackedPattern``, its symbolic analysis (ordering, elimination tree) kept while the springs
    of nonzero weight stay among those it was found for.

    The stacked matrix couples the terms' fields only through springs in contact (nonzero
    weight), so its pattern is the terms' H and the pairs of those springs: an ordering found for
    a contact set (grown by ``ORDERING_RINGS`` rings of springs) serves every subset of it, with
    the pairs of the springs out of contact as stored zeros. The active set's first iterate at a
    time point is the contact extrapolated from the last two
    (``edem.thin_layer_contact.ContactHistory``), which on the ankle stances held the answer (the
    later iterates remove springs), and grown by two rings an ordering served four time points
    on the 3k-spring gap-law stance (5 orderings for its 55 factorisations): the other
    factorisations refactor the numbers only (``qdldl.Solver.update``: 2.3 against 4.4 ms with a new ordering at the 3k-spring ankle's
    3k unknowns). A set with a spring outside finds a new ordering. One pattern holding every
    spring of the layer would keep it over the run, but its fill made each factorisation 2x
    slower at 30k springs (docs/method.md).
    """

    def __init__(self, stack: StackedPattern, z_t: sp.csr_matrix) -> None:
        self.stack = stack
        self.z_t = z_t
        self.support: np.ndarray | None = None  # (m,) bool: the springs the ordering was found for
        self.kept: np.ndarray | None = None  # positions in the stacked data of the upper triangle's stored entries
        self.ordering: _Ordering | None = None

    @functools.cached_property
    def _held(self) -> sp.csr_matrix:
        """(nnz, m): 1 where spring j holds a pair at entry i."""
        return sp.csr_matrix((np.ones(self.stack.pair_spring.shape[0]), self.stack.pair_spring, self.stack.pair_indptr),
                             shape=(self.stack.pair_indptr.shape[0] - 1, self.z_t.shape[0]))

    def factorise(self, data: np.ndarray, spring_weight: np.ndarray):
        """solve(rhs) with the stacked matrix of ``data`` (nnz,) and its springs' weights (m,)."""
        support = spring_weight != 0.0
        matrix = self.stack.pattern.matrix(data)  # every pair stored (zeros included): for the check
        row, column, block = self.stack._entries
        norm = float(np.bincount(column, weights=np.abs(data), minlength=matrix.shape[0]).max(initial=0.0))  # ||A||_inf, A symmetric
        ordering = self.ordering
        if ordering is not None and not np.any(support & ~self.support):
            upper = data[self.kept]
            try:
                ordering.numeric(upper)
            except RuntimeError:  # a zero pivot in this ordering: find a new one
                ordering = None
        else:
            ordering = None
        if ordering is None:
            grown = support.astype(float)
            for _ in range(ORDERING_RINGS):
                grown = (self.z_t @ (self.z_t.T @ grown) > 0.0).astype(float)
            support = grown > 0.0
            self.kept = np.flatnonzero((block | (self._held @ grown > 0.0)) & (row <= column))
            n = matrix.shape[0]
            indptr = np.zeros(n + 1, np.int64)
            np.cumsum(np.bincount(column[self.kept], minlength=n), out=indptr[1:])
            self.support, upper = support, data[self.kept]
            try:
                ordering = _Ordering(row[self.kept], indptr, upper)
            except RuntimeError:  # a zero pivot
                self.ordering = None
                return checked_solve(matrix, None, norm)
            self.ordering = ordering

        def ldl_solve(rhs: np.ndarray) -> np.ndarray:
            if ordering.numbers is not upper:  # another factorisation came since: its numbers back first
                ordering.numeric(upper)
            return ordering.solver.solve(rhs)

        return checked_solve(matrix, ldl_solve, norm)


class _Ordering:
    """A QDLDL factor on one upper-triangle pattern (indices, indptr) and the data it holds."""

    def __init__(self, indices: np.ndarray, indptr: np.ndarray, upper: np.ndarray) -> None:
        import qdldl  # a core dependency, imported where the two-pole needs it

        self.indices, self.indptr = indices, indptr
        self.solver = qdldl.Solver(self._matrix(upper), upper=True)
        self.numbers = upper

    def _matrix(self, upper: np.ndarray) -> sp.csc_matrix:
        n = self.indptr.shape[0] - 1
        return sp.csc_matrix((upper, self.indices, self.indptr), shape=(n, n))

    def numeric(self, upper: np.ndarray) -> None:
        """Refactor the numbers ``upper`` on this pattern (RuntimeError at a zero pivot)."""
        self.numbers = None
        self.solver.update(self._matrix(upper), upper=True)
        self.numbers = upper
