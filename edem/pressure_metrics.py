"""The regularised peak pressure (docs/method.md#7-comparison-metrics): one definition, used by
every summary.json, the campaigns' metrics and the reports.

The raw peak (the largest nodal or spring pressure) of a contact whose edge is sharp does not
converge under mesh refinement: the continuum's pressure at a rim or a pit edge can be singular,
and the largest value of a field sampled on a finer mesh grows with it. The regularised peak is
the largest mean of the pressure over a disc of 1 mm^2 (:data:`PEAK_DISC_AREA_MM2`) centred on
the surface: for an integrable singularity it converges as the mesh is refined, on the spring bed
and on the FE surface alike (measured in docs/method.md#7-comparison-metrics).

The pressure of a result is the force per area of M, the surface the springs live on
(:func:`pressure_field_on_mobile`): an FE reference's nodal pressure on its contact face times its
columns' area ratio, on the points of M under them; a discrete run's spring pressures on M.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from geometries.errors import InputError
from geometries.triangle_kernels import triangle_areas

#: area (mm^2) of the disc the regularised peak averages the pressure over
PEAK_DISC_AREA_MM2 = 1.0
#: quadrature points per disc radius along a triangle edge: the disc's area is then integrated to
#: a few per cent (~60 points per disc), far below the 10 % bands the metric is judged against
_POINTS_PER_RADIUS = 3.0
#: quadrature points the disc averaging of one surface may hold (measured 113-121 bytes each on
#: coarse meshes, ~260 a triangle on fine ones with their centres: 2.4 GB); a mesh that needs
#: more is refused before its run (check_quadrature_size)
MAX_QUADRATURE_POINTS = 20_000_000
#: (centre, quadrature point) pairs evaluated at once: ~60 bytes each while a chunk is formed
_CHUNK_PAIRS = 2_000_000
#: discs the peak evaluates first, from the largest bound (each next chunk four times as many):
#: on the stances' maps the best of these rules out every other disc
_FIRST_PEAK_DISCS = 128
#: what summary.json says of its regularised_peak_pressure_mpa
REGULARISED_PEAK_DEFINITION = (
    f"the largest mean of the pressure (force per area of M) over a disc of {PEAK_DISC_AREA_MM2:g} mm^2 of the surface, "
    "centred on a triangle centroid or vertex (edem.pressure_metrics): mesh-independent where the raw peak is not")
#: FE point data of the pressure as force per area of M, and the points of M it stands on
PRESSURE_ON_MOBILE = "pressure_on_mobile_mpa"
MOBILE_POINT = "mobile_point_mm"


def _subdivided(points_mm: np.ndarray, triangles: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centroids of the n^2 sub-triangles of each triangle (uniform barycentric grid): their
    positions (m, n^2, 3), barycentric weights (n^2, 3) and areas (m, n^2) in mm^2."""
    bary = []
    for i in range(n):
        for j in range(n - i):
            bary.append(((i + 1 / 3) / n, (j + 1 / 3) / n))  # upright sub-triangle
            if i + j < n - 1:
                bary.append(((i + 2 / 3) / n, (j + 2 / 3) / n))  # inverted one
    uv = np.array(bary)
    weights = np.column_stack([1.0 - uv.sum(axis=1), uv[:, 0], uv[:, 1]])
    corners = points_mm[triangles]  # (m, 3, 3)
    positions = np.einsum("qk,mkx->mqx", weights, corners)
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    area = triangle_areas(a, b, c) / (n * n)
    return positions, weights, np.repeat(area[:, None], len(uv), axis=1)


class DiscMeans:
    """The disc averaging of one surface, applied to any number of pressure fields on it (a
    run's time points share one, :class:`RegularisedPeaks`).

    The mean over the disc of a centre is a sum over the quadrature points within the radius of
    it, always in the same order (the surface's: grouped by subdivision, then by triangle), so it
    is the same float whichever other centres are evaluated with it, in whichever chunk, and
    whichever triangles beyond its disc carry quadrature points. That makes the peak's saving
    exact (:meth:`peak`): a centre whose disc cannot beat the best mean found is never
    evaluated. A disc's mean is at most the largest value of the triangles with quadrature
    points in it, and such a triangle's centroid lies within the radius plus its longest edge of
    the centre: in the 27 cubic cells (side: the radius plus the longest edge of the surface)
    around the centre's cell, whose triangles' largest value bounds the mean. The centres are
    evaluated from the largest bound down, in chunks of 128, 512, ... discs, each by an
    averaging built for those discs only (the quadrature of the triangles within their reach),
    until the next bound is below the best: the peak never builds the whole surface's quadrature.

    :meth:`means` (every loaded centre's) builds the quadrature of the triangles within reach of
    the candidate centres when first asked, and evaluates the discs in chunks of at most
    ``chunk_pairs`` pairs. Memory is linear in the quadrature (the mesh) plus one chunk, whatever
    the size of the contact.

    Parameters
    ----------
    points_mm : (n, 3) float
        Surface points, mm.
    triangles : (m, 3) int
        Triangles.
    at_points : bool
        Whether the pressure fields are nodal (linear on each triangle) or one value per triangle.
    disc_area_mm2 : float
        Area of the disc (radius sqrt(area / pi) in 3D: a ball cut by the surface, a disc where
        the surface is flat over the radius).
    only_for : (n,) or (m,) float, optional
        One pressure field this is built for: only its loaded centres are candidates and only the
        triangles within reach of them carry quadrature points (what one evaluation needs). None:
        every centre and triangle, for any field on the surface.
    centres : (k,) int, optional
        The candidate centres themselves (ascending centre indices, :meth:`loaded_centres`), in
        place of ``only_for``; ``near``: triangles among which those within their reach are
        (default: all).
    chunk_pairs : int
        The most (centre, quadrature point) pairs evaluated at once.
    """

    def __init__(self, points_mm: np.ndarray, triangles: np.ndarray, *, at_points: bool, disc_area_mm2: float = PEAK_DISC_AREA_MM2,
                 only_for: np.ndarray | None = None, centres: np.ndarray | None = None, near: np.ndarray | None = None,
                 chunk_pairs: int = _CHUNK_PAIRS) -> None:
        points = np.asarray(points_mm, dtype=np.float64).reshape(-1, 3)
        tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
        self.at_points, self.disc_area_mm2, self.radius_mm = at_points, disc_area_mm2, math.sqrt(disc_area_mm2 / math.pi)
        self.chunk_pairs = max(int(chunk_pairs), 1)
        self._points, self._triangles, self._n_points = points, tris, len(points)
        self._edge, self._centroids = _longest_edges(points, tris)
        self._set_centres(self.loaded_centres(only_for) if only_for is not None else centres, near)

    def _set_centres(self, centres: np.ndarray | None, near: np.ndarray | None) -> None:
        """The candidate centres (None: all) and the quadrature of the triangles within their reach."""
        tris, centroids, points = self._triangles, self._centroids, self._points
        # centre indices: the centroid of triangle t is centre t, point v is centre m + v
        if centres is None:
            self._centres = None  # all of them
            self._centre_mm = np.concatenate([centroids, points])
            quadrature_on = np.arange(len(tris))
        else:
            self._centres = np.asarray(centres, dtype=np.int64)
            self._centre_mm = self._positions(self._centres, centroids, points)
            # only triangles that reach within a radius of a centre can meet a disc (zero pressure counts)
            near = np.arange(len(tris)) if near is None else np.asarray(near, dtype=np.int64)
            reach = np.full(len(near), np.inf)
            if len(self._centres) and len(near):
                reach = _kdtree(self._centre_mm).query(centroids[near], distance_upper_bound=self.radius_mm + float(self._edge[near].max()))[0]
            quadrature_on = np.sort(near[reach <= self.radius_mm + self._edge[near]])
        # each triangle split into n^2 sub-triangles, n by its longest edge; the quadrature points
        # grouped by n, each group's triangles in their order: the order every sum runs in
        self._quadrature_on = quadrature_on
        self._subdivisions = _subdivisions(self._edge[quadrature_on], self.radius_mm)
        if self.n_quadrature_points > MAX_QUADRATURE_POINTS:
            raise InputError(f"the regularised peak of this surface needs {self.n_quadrature_points:,} quadrature points, more than the "
                             f"{MAX_QUADRATURE_POINTS:,} it holds in memory", expected=_QUADRATURE_EXPECTED)
        self._quadrature: tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray, np.ndarray] | None = None
        self._q_tree = self._cells = self._cells_of_centroids = None
        #: discs evaluated so far, over every field given (what the bounds saved)
        self.rows_evaluated = 0

    @staticmethod
    def _positions(centres: np.ndarray, centroids: np.ndarray, points: np.ndarray) -> np.ndarray:
        m = len(centroids)
        return np.concatenate([centroids[centres[centres < m]], points[centres[centres >= m] - m]])

    @property
    def n_quadrature_points(self) -> int:
        return int((self._subdivisions**2).sum())

    def _built(self) -> tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray, np.ndarray]:
        """The quadrature (built when first needed): the groups (triangles, barycentric weights)
        by subdivision, the points' positions (n_q, 3) and areas (n_q,)."""
        if self._quadrature is None:
            groups, positions, areas = [], [], []
            for n in np.flatnonzero(np.bincount(self._subdivisions)):
                group = self._quadrature_on[self._subdivisions == n]
                q_pos, weights, q_area = _subdivided(self._points, self._triangles[group], int(n))
                groups.append((group, weights))
                positions.append(q_pos.reshape(-1, 3))
                areas.append(q_area.ravel())
            self._quadrature = (groups, np.concatenate(positions) if positions else np.zeros((0, 3)),
                                np.concatenate(areas) if areas else np.zeros(0))
        return self._quadrature

    def loaded_centres(self, pressure_mpa: np.ndarray) -> np.ndarray:
        """Centre indices (k,), ascending: the centroids, then the points, of the triangles that
        carry pressure (the candidate centres of the definition)."""
        p = np.asarray(pressure_mpa, dtype=np.float64).ravel()
        expected = self._n_points if self.at_points else len(self._triangles)
        if p.shape != (expected,):
            raise ValueError(f"{len(p)} pressure values for a surface of {expected} {'points' if self.at_points else 'triangles'}")
        loaded = (p[self._triangles].max(axis=1, initial=-np.inf) if self.at_points else p) > 0.0
        corner = np.zeros(self._n_points, dtype=bool)
        corner[self._triangles[loaded]] = True
        return np.concatenate([np.flatnonzero(loaded), len(self._triangles) + np.flatnonzero(corner)])

    def _candidates(self, centres: np.ndarray) -> np.ndarray:
        """Positions of centre indices among the candidates (ValueError for one that is not)."""
        if self._centres is None:
            return centres
        where = np.minimum(np.searchsorted(self._centres, centres), max(len(self._centres) - 1, 0))
        if len(centres) and (not len(self._centres) or np.any(self._centres[where] != centres)):
            raise ValueError("a pressure field loads centres this averaging was not built for (only_for)")
        return where

    def _values(self, pressure_mpa: np.ndarray) -> np.ndarray:
        """The pressure at every quadrature point (n_q,), MPa."""
        p = np.asarray(pressure_mpa, dtype=np.float64).ravel()
        groups = self._built()[0]
        if not groups:
            return np.zeros(0)
        return np.concatenate([(np.einsum("qk,mk->mq", weights, p[self._triangles[group]]) if self.at_points
                                else np.repeat(p[group][:, None], weights.shape[0], axis=1)).ravel() for group, weights in groups])

    def _rows(self, candidates: np.ndarray) -> tuple[Any, np.ndarray]:
        """The averaging rows of candidate centres: a CSR matrix (k, n_q) of the areas of the
        quadrature points in each disc (columns ascending), and the disc areas (k,)."""
        from scipy.sparse import csr_matrix

        _, q_mm, q_area = self._built()
        if self._q_tree is None:
            self._q_tree = _kdtree(q_mm)
        n_q = len(q_area)
        pairs = _kdtree(self._centre_mm[candidates]).sparse_distance_matrix(self._q_tree, self.radius_mm, output_type="ndarray")
        # the (row, column) pairs in order as one sorted key: several times cheaper than an argsort
        key = np.sort(pairs["i"] * n_q + pairs["j"])
        del pairs
        row = key // n_q
        columns = (key - row * n_q).astype(np.int32 if n_q < 2**31 else np.int64)
        indptr = np.concatenate([[0], np.cumsum(np.bincount(row, minlength=len(candidates)))]).astype(columns.dtype)
        del key, row
        rows = csr_matrix((q_area[columns], columns, indptr), shape=(len(candidates), n_q))
        # (a product, not a reduction: the sum runs along each row in order, as the mean's does)
        return rows, rows @ np.ones(n_q)

    @staticmethod
    def _means(rows: Any, area: np.ndarray, values: np.ndarray) -> np.ndarray:
        return np.divide(rows @ values, area, out=np.zeros(len(area)), where=area > 0)

    def _chunks(self, candidates: np.ndarray) -> list[tuple[int, int]]:
        """Consecutive slices of ``candidates`` of at most ``chunk_pairs`` pairs each, counted by
        the quadrature points in the 27 cells (side: the radius) around each centre's (at least
        one centre a slice)."""
        if self._cells is None:
            _, q_mm, q_area = self._built()
            cell, neighbour = _grid(np.concatenate([q_mm, self._centre_mm]), self.radius_mm)
            count = np.append(np.bincount(cell[:len(q_area)], minlength=neighbour.shape[1]), 0)
            self._cells = (cell[len(q_area):], count[neighbour].sum(axis=0))
        centre_cell, around = self._cells
        reach = np.cumsum(around[centre_cell[candidates]])
        slices, start = [], 0
        while start < len(candidates):
            before = reach[start - 1] if start else 0
            stop = max(start + 1, int(np.searchsorted(reach, before + self.chunk_pairs, side="right")))
            slices.append((start, stop))
            start = stop
        return slices

    def means(self, pressure_mpa: np.ndarray, centres: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The disc means of ``centres`` (default every loaded one, :meth:`loaded_centres`): centre
        indices (k,) and means (k,), MPa (zero pressure outside the contact counts; off the
        surface's edge nothing does)."""
        centres = self.loaded_centres(pressure_mpa) if centres is None else np.asarray(centres, dtype=np.int64)
        candidates = self._candidates(centres)
        out = np.zeros(len(centres))
        if not len(centres):
            return centres, out
        values = self._values(pressure_mpa)
        for start, stop in self._chunks(candidates):
            rows, area = self._rows(candidates[start:stop])
            out[start:stop] = self._means(rows, area, values)
            self.rows_evaluated += stop - start
        return centres, out

    def centres_mm(self, centres: np.ndarray) -> np.ndarray:
        """Positions (k, 3) of centre indices, mm."""
        return self._centre_mm[self._candidates(centres)]

    def _peak_cells(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The cells of the peak's bounds (class docstring; mesh only, built once): the triangles
        cell by cell and where each cell's start, the 27 cells around each cell (27, n_cells;
        n_cells for none) and every candidate's cell."""
        if self._cells_of_centroids is None:
            m = len(self._triangles)
            cell, neighbour = _grid(np.concatenate([self._centroids, self._centre_mm]), self.radius_mm + float(self._edge.max(initial=0.0)))
            order = np.argsort(cell[:m], kind="stable")
            starts = np.searchsorted(cell[:m][order], np.arange(neighbour.shape[1] + 1))
            self._cells_of_centroids = (order, starts, neighbour, cell[m:])
        return self._cells_of_centroids

    def _bounds(self, pressure_mpa: np.ndarray, candidates: np.ndarray) -> np.ndarray:
        """An upper bound (k,) of each candidate's disc mean: the largest value of the triangles
        whose centroids lie in the 27 cells around its centre's (class docstring)."""
        order, starts, neighbour, centre_cell = self._peak_cells()
        p = np.asarray(pressure_mpa, dtype=np.float64).ravel()
        triangle_largest = p[self._triangles].max(axis=1) if self.at_points else p
        largest = np.full(len(starts), -np.inf)  # (the last: no cell)
        occupied = np.flatnonzero(np.diff(starts) > 0)
        if occupied.size:
            largest[occupied] = np.maximum.reduceat(triangle_largest[order], starts[occupied])
        bound = largest[neighbour[0]]
        for around in neighbour[1:]:  # (the 27 cells one at a time: memory of one value a cell)
            np.maximum(bound, largest[around], out=bound)
        return bound[centre_cell[candidates]]

    def _near(self, candidates: np.ndarray) -> np.ndarray:
        """The triangles (ascending) whose centroids lie in the 27 cells around the candidates':
        every triangle within reach of them is among these."""
        order, starts, neighbour, centre_cell = self._peak_cells()
        cells = _sorted_unique(neighbour[:, centre_cell[candidates]].ravel())
        cells = cells[cells < len(starts) - 1]
        lengths = starts[cells + 1] - starts[cells]
        ends = np.cumsum(lengths)
        return np.sort(order[np.arange(ends[-1] if len(ends) else 0) - np.repeat(ends - lengths - starts[cells], lengths)])

    def peak(self, pressure_mpa: np.ndarray) -> float:
        """The largest of :meth:`means` (0 with no pressure), MPa: the same float, from only the
        discs the bounds cannot rule out (class docstring)."""
        centres = self.loaded_centres(pressure_mpa)
        candidates = self._candidates(centres)
        if not candidates.size:
            return 0.0
        # A computed mean exceeds its bound by rounding only, at most (pairs) x eps x the largest
        # |value|: 1e-6 of that value is far above it for any disc of fewer than 1e9 points.
        margin = 1e-6 * float(np.abs(np.asarray(pressure_mpa, dtype=np.float64)).max(initial=0.0))
        bound = self._bounds(pressure_mpa, candidates)
        order = np.argsort(-bound, kind="stable")
        descending = bound[order]
        best, start, size = 0.0, 0, _FIRST_PEAK_DISCS
        while start < len(order) and descending[start] + margin >= best:
            # (the next discs whose bound can still beat the best)
            stop = min(start + size, int(np.searchsorted(-descending, margin - best, side="right")))
            chunk = np.sort(order[start:stop])
            discs = copy.copy(self)  # (the same surface: its arrays shared)
            discs._set_centres(centres[chunk], self._near(candidates[chunk]))
            best = max(best, float(discs.means(pressure_mpa, centres[chunk])[1].max()))
            self.rows_evaluated += len(chunk)
            start, size = stop, 4 * size
        return best


def _grid(positions_mm: np.ndarray, side_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """Cubic cells of side >= ``side_mm`` (at most 2^20 a side: the keys fit int64) over the
    occupied space: each position's cell (k,) and the 27 cells around each cell (27, n_cells;
    n_cells where there is none)."""
    if not len(positions_mm):
        return np.zeros(0, np.int64), np.zeros((27, 0), np.int32)
    origin = positions_mm.min(axis=0)
    side = max(side_mm, float(np.ptp(positions_mm, axis=0).max()) / 2**20)
    index = np.floor((positions_mm - origin) / side).astype(np.int64) + 1  # (an empty layer of cells on every side)
    dims = index.max(axis=0) + 2
    keys = np.ravel_multi_index(index.T, dims)
    del index
    cells = _sorted_unique(keys)
    cell_of = np.searchsorted(cells, keys)
    del keys
    n_cells = len(cells)
    shifts = np.array([[i, j, k] for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)]) @ np.array([dims[1] * dims[2], dims[2], 1])
    around = cells[None, :] + shifts[:, None]  # (27, n_cells): the maxima over the 27 run along rows
    neighbour = np.searchsorted(cells, around)
    found = cells[np.minimum(neighbour, n_cells - 1)] == around
    return cell_of, np.where(found, neighbour, n_cells).astype(np.int32 if n_cells < 2**31 else np.int64)


_QUADRATURE_EXPECTED = ("a surface of fewer or shorter triangles: each is split into n^2 sub-triangles, n its longest edge over "
                        "a third of the disc radius (0.19 mm), so long thin ones need many; remesh them")


def _longest_edges(points: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The longest edge (m,) and the centroid (m, 3) of each triangle, mm."""
    a, b, c = points[triangles[:, 0]], points[triangles[:, 1]], points[triangles[:, 2]]
    return np.sqrt(np.maximum(np.maximum(_squared(b - a), _squared(c - b)), _squared(a - c))), (a + b + c) / 3.0


def _subdivisions(edge_mm: np.ndarray, radius_mm: float) -> np.ndarray:
    """n of each triangle's n^2 sub-triangles: its longest edge over a third of the radius."""
    return np.maximum(1, np.ceil(edge_mm * _POINTS_PER_RADIUS / radius_mm)).astype(np.int64)


def quadrature_size(points_mm: np.ndarray, triangles: np.ndarray, disc_area_mm2: float = PEAK_DISC_AREA_MM2) -> int:
    """The quadrature points the disc averaging of a whole surface holds (:class:`DiscMeans`)."""
    points = np.asarray(points_mm, dtype=np.float64).reshape(-1, 3)
    edge, _ = _longest_edges(points, np.asarray(triangles, dtype=np.int64).reshape(-1, 3))
    return int((_subdivisions(edge, math.sqrt(disc_area_mm2 / math.pi)) ** 2).sum())


def check_quadrature_size(points_mm: np.ndarray, triangles: np.ndarray, *, file: str | None, key: str) -> None:
    """InputError (before a run) when the regularised peak of its maps on this surface would need
    more than :data:`MAX_QUADRATURE_POINTS` quadrature points."""
    n = quadrature_size(points_mm, triangles)
    if n > MAX_QUADRATURE_POINTS:
        raise InputError(f"the regularised peak pressure of its results (docs/method.md#7-comparison-metrics) needs {n:,} quadrature "
                         f"points on this mesh of {len(triangles):,} triangles, more than the {MAX_QUADRATURE_POINTS:,} it holds in memory",
                         file=file, key=key, expected=_QUADRATURE_EXPECTED)


def _squared(v: np.ndarray) -> np.ndarray:
    """|v|^2 of rows (k, 3), summed in the order np.linalg.norm sums them."""
    return v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1] + v[:, 2] * v[:, 2]


def _sorted_unique(values: np.ndarray) -> np.ndarray:
    """np.unique of integers by a sort (several times faster than its hashing for millions of
    distinct values)."""
    ordered = np.sort(values)
    return ordered[np.concatenate([[True], ordered[1:] != ordered[:-1]])] if len(ordered) else ordered


def _kdtree(points: np.ndarray):
    from scipy.spatial import cKDTree

    return cKDTree(points, balanced_tree=False)  # (half the build time of a median split; the same pairs)


def disc_mean_pressure_mpa(points_mm: np.ndarray, triangles: np.ndarray, pressure_mpa: np.ndarray, *, at_points: bool,
                           disc_area_mm2: float = PEAK_DISC_AREA_MM2) -> tuple[np.ndarray, np.ndarray]:
    """The mean pressure over the disc of area ``disc_area_mm2`` around candidate centres.

    Parameters
    ----------
    points_mm : (n, 3) float
        Surface points, mm.
    triangles : (m, 3) int
        Triangles.
    pressure_mpa : (n,) or (m,) float
        Nodal pressure (``at_points``, linear on each triangle) or one value per triangle, MPa.
    at_points : bool
        Whether ``pressure_mpa`` is nodal.
    disc_area_mm2 : float
        Area of the disc (radius sqrt(area / pi) in 3D: a ball cut by the surface, a disc where the
        surface is flat over the radius).

    Returns
    -------
    centres_mm : (k, 3) float
        The centroids and vertices of the triangles that carry pressure (others cannot hold the peak).
    mean_mpa : (k,) float
        The area-weighted mean pressure over the part of the surface within the disc of each
        centre (zero pressure outside the contact counts; off the surface's edge nothing does).
    """
    discs = DiscMeans(points_mm, triangles, at_points=at_points, disc_area_mm2=disc_area_mm2, only_for=pressure_mpa)
    centres, mean = discs.means(pressure_mpa)
    return discs.centres_mm(centres), mean


def regularised_peak_pressure_mpa(points_mm: np.ndarray, triangles: np.ndarray, pressure_mpa: np.ndarray, *, at_points: bool,
                                  disc_area_mm2: float = PEAK_DISC_AREA_MM2) -> float:
    """The regularised peak: the largest :func:`disc_mean_pressure_mpa` (0 with no pressure), MPa
    (by :meth:`DiscMeans.peak`, in memory linear in the mesh)."""
    return DiscMeans(points_mm, triangles, at_points=at_points, disc_area_mm2=disc_area_mm2).peak(pressure_mpa)


class RegularisedPeaks:
    """The regularised peaks of pressure maps on one surface, one call per map: the disc
    averaging (:class:`DiscMeans`) is built once for the surface the maps share, and again only
    when a map stands on another surface.

    A discrete run's maps are M at each time point's pose, an FE run's the same contact face at
    every time point: the same triangles, points that differ by a rigid motion at most, which
    changes no distance, so no disc (each peak is that of the map alone to the rounding of the
    posed points)."""

    def __init__(self) -> None:
        self._surface: tuple[np.ndarray, np.ndarray, bool] | None = None
        self._discs: DiscMeans | None = None

    def __call__(self, surface) -> float:
        """:func:`surface_regularised_peak_mpa` of a pressure map (an edem.resultdir.SurfaceFrame), MPa."""
        points, triangles, pressure, at_points = pressure_field_on_mobile(surface)
        if self._discs is None or not self._same_surface(points, triangles, at_points):
            self._discs = DiscMeans(points, triangles, at_points=at_points)
            self._surface = (np.asarray(points, dtype=np.float64), triangles, at_points)
        return self._discs.peak(pressure)

    def _same_surface(self, points: np.ndarray, triangles: np.ndarray, at_points: bool) -> bool:
        known_points, known_triangles, known_at_points = self._surface
        if at_points != known_at_points or not (triangles is known_triangles or np.array_equal(triangles, known_triangles)):
            return False
        return _rigidly_moved(known_points, np.asarray(points, dtype=np.float64))


def pressure_bound_mpa(surface) -> float:
    """An upper bound of every disc mean of a pressure map (MPa): its largest pressure (a mean of
    the field is at most its largest value; the nodal field is linear on each triangle), plus
    1e-6 of its largest magnitude for the rounding of a computed mean (as :meth:`DiscMeans.peak`)."""
    pressure = np.asarray(pressure_field_on_mobile(surface)[2], dtype=np.float64)
    return float(pressure.max(initial=0.0)) + 1e-6 * float(np.abs(pressure).max(initial=0.0))


def largest_regularised_peak_mpa(map_at: Callable[[int], Any], bounds_mpa: Sequence[float]) -> float:
    """The largest regularised peak of a run's pressure maps (0 with none), MPa.

    Parameters
    ----------
    map_at : callable
        ``map_at(i)``: pressure map i (an edem.resultdir.SurfaceFrame), asked only of the maps
        measured.
    bounds_mpa : sequence of float
        :func:`pressure_bound_mpa` of each map.

    The maps are measured from the largest bound down until the next bound is below the best
    peak found: no map after it can hold a larger one. The result is the largest of every map's
    peak (a stance's 65 maps: 1-4 measured). They share one disc averaging
    (:class:`RegularisedPeaks`); a single map has its own, built for its contact only.
    """
    bounds = np.asarray(bounds_mpa, dtype=np.float64)
    if len(bounds) == 1:
        return surface_regularised_peak_mpa(map_at(0))
    measure, best = RegularisedPeaks(), 0.0
    for i in np.argsort(-bounds, kind="stable"):
        if bounds[i] < best:
            break
        best = max(best, measure(map_at(int(i))))
    return best


def _rigidly_moved(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether the points b are the points a moved rigidly (an orthogonal map and a translation,
    found by orthogonal Procrustes), to 1e-9 of their extent: far below any disc's resolution,
    far above the rounding of placing a mesh at a pose."""
    if a.shape != b.shape:
        return False
    if a is b or np.array_equal(a, b):
        return True
    a0, b0 = a - a.mean(axis=0), b - b.mean(axis=0)
    u, _, vt = np.linalg.svd(a0.T @ b0)
    size = max(float(np.ptp(a, axis=0).max(initial=0.0)), 1e-300)
    return float(np.abs(a0 @ (u @ vt) - b0).max(initial=0.0)) <= 1e-9 * size


def pressure_field_on_mobile(surface) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """(points, triangles, pressure, at_points) of a pressure map (an edem.resultdir.SurfaceFrame)
    as force per area of M: an FE contact face's ``pressure_on_mobile_mpa`` on the points of M
    under it (``mobile_point_mm``; its own points without them), else its nodal ``pressure_mpa``,
    else the spring (cell) pressures of a discrete run. ValueError when the surface has no pressure."""
    point, cell = surface.point_data, surface.cell_data
    if PRESSURE_ON_MOBILE in point:
        return np.asarray(point.get(MOBILE_POINT, surface.points_mm), float), surface.triangles, point[PRESSURE_ON_MOBILE], True
    if "pressure_mpa" in point:
        return surface.points_mm, surface.triangles, point["pressure_mpa"], True
    if "pressure_mpa" in cell:
        return surface.points_mm, surface.triangles, cell["pressure_mpa"], False
    raise ValueError("the surface has no pressure_mpa array")


def has_pressure(surface) -> bool:
    """Whether a pressure map has a pressure field (:func:`pressure_field_on_mobile` reads it)."""
    return "pressure_mpa" in surface.point_data or "pressure_mpa" in surface.cell_data or PRESSURE_ON_MOBILE in surface.point_data


def surface_regularised_peak_mpa(surface) -> float:
    """:func:`regularised_peak_pressure_mpa` of a pressure map's :func:`pressure_field_on_mobile`."""
    points, triangles, pressure, at_points = pressure_field_on_mobile(surface)
    return regularised_peak_pressure_mpa(points, triangles, pressure, at_points=at_points)
