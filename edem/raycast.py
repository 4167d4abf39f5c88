"""Spring lengths by ray casting against the fixed body F (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs; thesis section 4.2.1).

Every spring i of the mobile body M sits at the centroid c_i of one of M's triangles and points
along that triangle's unit normal n_i, towards F. Its length is where the ray c_i + s n_i meets F
(Moller-Trumbore ray/triangle intersection, thesis section 4.2.1), nearest hit first.

What is computed here, for a window half-width h = ``max_length_mm``:

* the ray is cast over the *signed window* s in (-h, h] (origin c_i - h n_i, parameter 0..2h), so
  surfaces that touch or interpenetrate M are still found; the signed length s is negative where
  F has crossed M's surface (interpenetration) and positive across an open gap;
* only triangles of F facing the ray count: F's triangle normals (right-hand rule) point out of F
  towards M, so a valid hit has dot(n_F, n_i) < 0. Hits on wrong-facing triangles (for example
  the tibial walls behind the talus) are skipped and the ray continues past them;
* the nearest valid hit in the window gives ``spring_length_mm`` (= s) and ``triangle`` (index into
  F's triangles); no valid hit gives ``inf`` and ``-1``.

Two interchangeable backends sit behind :class:`RayCaster`:

``"embree"``
    Intel Embree through ``embreex`` (a BVH built once per fixed surface, in F's own frame, with
    Embree's robust scene flag). Embree traverses in float32; every returned hit is re-measured in
    float64 with one vectorised Moller-Trumbore test on the returned triangle, so lengths are exact
    to round-off wherever Embree picked the right triangle. The float32 failures are re-solved
    exactly and locally: a ray that float64 puts on an edge or vertex of the returned triangle,
    or just off it, is re-solved among the triangles sharing a vertex with it (float32 ties are
    between neighbours; structured meshes whose edges line up with the rays meet this often);
    a ray Embree lost on an edge or vertex (or whose returned triangle has no neighbour on the
    ray) is found again from the triangles around a slightly shifted probe ray's hit (only rays
    whose window passes near F get a probe: one look-up in a coarse grid of the cells within the
    window's half-length of F, built once, sorts out the rays that point away from F); a skipped
    wrong-facing hit first has the triangles around it checked (a fold ties a back-facing and a
    front-facing triangle at the same point). Only a ray still crossing wrong-facing sheets after
    a few re-casts goes to the exact brute-force caster.
    Limits: two sheets of F closer than ~2e-6 x (size of F) along a ray count as one; a hit Embree
    loses while it reports a farther one is not detected (never seen with the robust flag).
``"numpy"``
    A brute-force float64 Moller-Trumbore over all rays x all triangles (chunked to bound memory).
    Exact, and the reference the tests check Embree against; fine for small meshes only.

Kinematics moves F, but the acceleration structure is not rebuilt: ``cast(..., rotation=R,
translation=t)`` says F currently sits at x_world = R x_local + t, and the rays are moved into F's
local frame instead (lengths are invariant under the rigid motion).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Literal

import numpy as np

from geometries.rowwise import add_rows, min_rows, row_dot, rows_times
from geometries.triangle_kernels import cross_rows

Backend = Literal["embree", "numpy"]

# A float64 Moller-Trumbore test that misses the triangle Embree returned by less than this (in
# barycentric units) is a float32 tie at a shared edge or vertex: the plane distance of the
# returned triangle is then kept, it is the hit point to round-off.
_BARYCENTRIC_SLACK = 1e-6
# The exact reference counts hits that land on an edge or vertex up to this barycentric round-off,
# so a ray aimed exactly at a shared vertex cannot slip between the triangles around it.
_REFERENCE_SLACK = 1e-12
# Rounds of "skip the wrong-facing (or out-of-window) hit and cast again" before the few rays left
# are handed to the exact brute-force caster.
_MAX_ROUNDS = 8
# Upper bound on rays x triangles handled at once by the brute-force caster (about 15 float64
# arrays of this size are alive at a time: ~ 60 MB).
_CHUNK_PAIRS = 1 << 19
# Directions must be unit vectors (a length is measured in units of |direction|).
_UNIT_TOLERANCE = 1e-6
# The grid of cells near F (RayCaster._near_cells): at most this many cells along the longest
# side of F's padded box, and at most this many cell marks from the triangles' boxes before the
# grid is given up (every missed ray is then probed).
_GRID_CELLS = 96
_GRID_MAX_MARKS = 1 << 24
# Cells marked per vectorised slice of triangles while the grid is built (~50 bytes each at once).
_GRID_SLICE_MARKS = 1 << 19


# The grid of cells near F (RayCaster._near_cells): flat marks, lower corner (mm), 1 / cell size
# (1/mm), largest cell index per axis, flat-index strides.
_Grid = tuple[np.ndarray, np.ndarray, float, np.ndarray, np.ndarray]


@dataclass(frozen=True)
class RayHits:
    """Result of one :meth:`RayCaster.cast` (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs): one entry per ray."""

    # (n,) float64 signed length in (-h_max, h_max]; np.inf where no valid hit
    spring_length_mm: np.ndarray
    # (n,) int64 index of the hit triangle of F; -1 where none
    triangle: np.ndarray


@dataclass(frozen=True)
class Rays:
    """Rays checked once by :meth:`RayCaster.prepare`, cast many times by :meth:`RayCaster.cast_rays`."""

    origins_mm: np.ndarray  # (n, 3) float64, read-only
    directions: np.ndarray  # (n, 3) float64 unit or zero rows, read-only
    live: np.ndarray | None  # (l,) indices of the rays with a direction; None: every ray has one

    @cached_property
    def homogeneous_origins(self) -> np.ndarray:
        """(l, 4) rows (x, y, z, 1) of the live rays' origins: moved by one affine product."""
        origins = self.origins_mm if self.live is None else self.origins_mm[self.live]
        return np.column_stack([origins, np.ones(origins.shape[0])])


def _moller_trumbore(
    origins: np.ndarray,
    directions: np.ndarray,
    v0: np.ndarray,
    edge1: np.ndarray,
    edge2: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Moller-Trumbore (thesis 4.2.1) for matched rows of rays and triangles, in float64.

    All arguments broadcast against each other with the xyz axis last. Returns (t, u, v, det):
    the ray parameter of the hit on the triangle's plane, the barycentric coordinates of the hit,
    and det = -dot(direction, edge1 x edge2), so det > 0 exactly when the ray meets the front
    (right-hand-rule) side of the triangle. Where det == 0 the ray is parallel to the plane and t,
    u, v are nan or inf.
    """
    dx, dy, dz = directions[..., 0], directions[..., 1], directions[..., 2]
    e1x, e1y, e1z = edge1[..., 0], edge1[..., 1], edge1[..., 2]
    e2x, e2y, e2z = edge2[..., 0], edge2[..., 1], edge2[..., 2]
    # p = d x e2
    px = dy * e2z - dz * e2y
    py = dz * e2x - dx * e2z
    pz = dx * e2y - dy * e2x
    det = e1x * px + e1y * py + e1z * pz
    sx = origins[..., 0] - v0[..., 0]
    sy = origins[..., 1] - v0[..., 1]
    sz = origins[..., 2] - v0[..., 2]
    # q = s x e1
    qx = sy * e1z - sz * e1y
    qy = sz * e1x - sx * e1z
    qz = sx * e1y - sy * e1x
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        u = (sx * px + sy * py + sz * pz) * inv
        v = (dx * qx + dy * qy + dz * qz) * inv
        t = (e2x * qx + e2y * qy + e2z * qz) * inv
    return t, u, v, det


def _determinant(matrix: np.ndarray) -> float:
    """det of a (3, 3) matrix as the triple product of its rows, in Python floats: a cast checks
    its rotation at every time point, where np.linalg.det's dispatch costs ~10 us."""
    (a, b, c), (d, e, f), (g, h, i) = matrix.tolist()
    return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)


def _inside(u: np.ndarray, v: np.ndarray, slack: float) -> np.ndarray:
    """Barycentric point inside the triangle, edges and vertices included, up to ``slack``."""
    return (u >= -slack) & (v >= -slack) & (u + v <= 1.0 + slack)


def _nearest_per_ray(
    ray: np.ndarray, t: np.ndarray, triangle: np.ndarray, n_rays: int
) -> tuple[np.ndarray, np.ndarray]:
    """Smallest t per ray over (ray, t, triangle) candidate rows; ties go to the lowest index."""
    length = np.full(n_rays, np.inf)
    hit = np.full(n_rays, -1, dtype=np.int64)
    if ray.size:
        order = np.lexsort((triangle, t, ray))
        first_rows = order[np.unique(ray[order], return_index=True)[1]]
        length[ray[first_rows]] = t[first_rows]
        hit[ray[first_rows]] = triangle[first_rows]
    return length, hit


class RayCaster:
    """Casts spring rays against one fixed triangulated surface F (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs; thesis 4.2.1).

    Built once per fixed surface, in F's own frame: the Embree BVH is never rebuilt when F moves,
    the rays are moved into F's frame instead (see :meth:`cast`).

    Parameters
    ----------
    vertices_mm
        (m, 3) vertex coordinates of F in its local frame, mm.
    triangles
        (k, 3) vertex indices; right-hand-rule normals must point out of F, towards M.
        Degenerate (zero-area) triangles are never hit.
    backend
        ``"embree"`` (Embree BVH, float64 re-measurement of every hit) or ``"numpy"`` (exact
        brute force over all triangles; small meshes and tests).
    """

    def __init__(
        self, vertices_mm: np.ndarray, triangles: np.ndarray, backend: Backend = "embree"
    ) -> None:
        vertices = np.asarray(vertices_mm, dtype=np.float64)
        tri = np.asarray(triangles)
        if vertices.ndim != 2 or vertices.shape[1] != 3:
            raise ValueError(f"vertices_mm must have shape (m, 3), got {vertices.shape}")
        if not np.all(np.isfinite(vertices)):
            raise ValueError("vertices_mm contains non-finite coordinates")
        if tri.ndim != 2 or tri.shape[1] != 3:
            raise ValueError(f"triangles must have shape (k, 3), got {tri.shape}")
        if tri.size and not np.issubdtype(tri.dtype, np.integer):
            raise ValueError(f"triangles must hold integer vertex indices, got dtype {tri.dtype}")
        tri = tri.astype(np.int64, copy=False)
        if tri.size and (tri.min() < 0 or tri.max() >= len(vertices)):
            raise ValueError(
                f"triangles index vertices outside 0..{len(vertices) - 1} "
                f"(found {tri.min()}..{tri.max()})"
            )
        if backend not in ("embree", "numpy"):
            raise ValueError(f"backend must be 'embree' or 'numpy', got {backend!r}")

        self.backend: Backend = backend
        self.vertices_mm = vertices
        self.triangles = tri
        if len(vertices):
            lo, hi = vertices.min(axis=0), vertices.max(axis=0)
        else:
            lo = hi = np.zeros(3)
        # Every ray and triangle is handled relative to the centre of F's box, by Embree (float32
        # resolution is best near 0) and by the float64 tests alike: rays are moved there once.
        self._centre_mm = 0.5 * (lo + hi)
        self._v0 = vertices[tri[:, 0]] - self._centre_mm
        self._edge1 = vertices[tri[:, 1]] - vertices[tri[:, 0]]
        self._edge2 = vertices[tri[:, 2]] - vertices[tri[:, 0]]
        self._extent_mm = float(np.max(hi - lo)) if len(vertices) else 0.0
        self._box_mm = hi - lo
        self._scene = None
        # Grids of the cells near F, per reach (see _near_cells), built on first use.
        self._grids: dict[float, _Grid | None] = {}
        # Float64 ray/triangle tests done so far (re-measures, local re-solves, brute force): the
        # machine-independent cost of the exact work around Embree.
        self.pairs_tested = 0
        if backend == "embree" and len(tri):
            self._build_embree()

    # -- Embree scene ----------------------------------------------------------------------------

    def _build_embree(self) -> None:
        from embreex import mesh_construction, rtcore_scene

        # robust=True sets RTC_SCENE_FLAG_ROBUST: without it Embree's fast traversal lets rays
        # aimed at shared edges and vertices slip through (measured here: up to ~10 % of them).
        self._scene = rtcore_scene.EmbreeScene(robust=True)
        local32 = np.ascontiguousarray(self.vertices_mm - self._centre_mm, dtype=np.float32)
        # Held for as long as the scene, which it was attached to.
        self._mesh = mesh_construction.TriangleMesh(
            self._scene, local32, np.ascontiguousarray(self.triangles, dtype=np.int32)
        )
        # embreex builds the BVH lazily on the first query; pay for it here, once.
        empty = np.zeros((0, 3), dtype=np.float32)
        self._scene.run(empty, empty, dists=np.zeros(0, dtype=np.float32), output=1)

        # Star (incident triangles) of every vertex, CSR, on vertices welded by position so that
        # triangle soups (STL) have stars too: lets a near-miss or a tie at a shared edge/vertex
        # be re-solved exactly against the few triangles around that point.
        _, weld = np.unique(self.vertices_mm, axis=0, return_inverse=True)
        self._welded_corners = weld.reshape(-1)[self.triangles]
        flat = self._welded_corners.ravel()
        order = np.argsort(flat, kind="stable")
        self._star_triangles = order // 3
        self._star_start = np.searchsorted(flat[order], np.arange(int(weld.max()) + 2))
        edges = np.concatenate([self._edge1, self._edge2, self._edge2 - self._edge1])
        edge_len = np.linalg.norm(edges, axis=1)
        edge_len = edge_len[edge_len > 0]
        median_edge = float(np.median(edge_len)) if edge_len.size else 1.0
        scale = max(self._extent_mm, median_edge, 1.0)
        # Step past a rejected hit, and padding of the float32 window: well above Embree's float32
        # error on coordinates of size `scale` (~1e-7 relative), far below any cartilage length.
        self._step_mm = 2e-6 * scale
        # Sideways shift of the probe ray used to find the triangles around a missed vertex/edge
        # hit: small against the triangles, large against float32 round-off.
        self._probe_shift_mm = max(1e-4 * median_edge, 4e-6 * scale)
        # Far enough to cross all of F from anywhere near it.
        self._reach_mm = 4.0 * scale
        # Plane of every triangle (normal e1 x e2, unnormalised, and its offset n . v0) for the
        # float64 re-measure of hits well inside their triangle.
        self._normal = np.cross(self._edge1, self._edge2)
        self._plane_offset = np.einsum("ij,ij->i", self._normal, self._v0)
        # Barycentric distance from the edges that float32 round-off (Embree's coordinates are
        # ~6e-8 x scale off) cannot cross, per triangle: 64 ulps of the scale over its smallest
        # altitude (twice the area over the longest edge); beyond 1/3 nothing counts as interior.
        longest = np.max(np.linalg.norm(np.stack([self._edge1, self._edge2, self._edge2 - self._edge1]), axis=2), axis=0)
        twice_area = np.linalg.norm(self._normal, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            altitude = np.where(longest > 0, twice_area / longest, 0.0)
            margin = 64 * float(np.finfo(np.float32).eps) * scale / altitude
        self._interior_margin = np.where(np.isfinite(margin), np.minimum(margin, 1.0), 1.0)
        # What the re-measure reads per hit, one gather of (5, hits): n_x, n_y, n_z, n . v0 and the
        # margin as contiguous rows (the products then run along them; measured faster than a
        # gather of (hits, 5) rows read by column, on 4 triangles and on 34k alike).
        self._plane_columns = np.vstack([self._normal.T, self._plane_offset, self._interior_margin])

    def _embree_run(
        self, origins: np.ndarray, directions: np.ndarray, tfar: np.ndarray
    ) -> dict[str, np.ndarray]:
        """One Embree pass, rays already in F's frame relative to its box centre: float32
        ``primID`` (-1 = none), ``tfar`` (distance along the ray) and barycentric ``u``, ``v`` of
        every ray's hit."""
        return self._scene.run(
            # Already relative to the box centre (in float64), rounded once.
            np.ascontiguousarray(origins, dtype=np.float32),
            np.ascontiguousarray(directions, dtype=np.float32),
            # embreex writes the hit distances into this array in place: always pass a fresh one.
            dists=np.ascontiguousarray(tfar, dtype=np.float32),
            output=1,
        )

    # -- public ----------------------------------------------------------------------------------

    def prepare(self, origins_mm: np.ndarray, directions: np.ndarray) -> Rays:
        """Check rays once for casting many times (e.g. one spring bed at every time point).

        Parameters
        ----------
        origins_mm, directions
            (n, 3) origins (mm) and unit directions, as for :meth:`cast`; zero direction rows are
            rays without a spring (never hit).

        Returns
        -------
        Rays
            Float64 read-only copies, checked finite and unit (:meth:`cast_rays` casts them).
        """
        origins = np.array(origins_mm, dtype=np.float64)
        dirs = np.array(directions, dtype=np.float64)
        if origins.ndim != 2 or origins.shape[1] != 3:
            raise ValueError(f"origins_mm must have shape (n, 3), got {origins.shape}")
        if dirs.shape != origins.shape:
            raise ValueError(f"directions must have shape {origins.shape}, got {dirs.shape}")
        # One reduction instead of two full isfinite passes; a finite sum can only overflow for
        # coordinates near 1e308, which then take the exact check.
        if not np.isfinite(origins.sum() + dirs.sum()) and not (
            np.all(np.isfinite(origins)) and np.all(np.isfinite(dirs))
        ):
            raise ValueError("origins_mm and directions must be finite")
        # |d| within _UNIT_TOLERANCE of 1, compared squared (no square root, no masked gather).
        squared = row_dot(dirs, dirs)
        unit = (squared >= (1.0 - _UNIT_TOLERANCE) ** 2) & (squared <= (1.0 + _UNIT_TOLERANCE) ** 2)
        live = None
        if not unit.all():
            has_direction = squared > 0
            if np.any(has_direction & ~unit):
                raise ValueError("directions must be unit vectors (or zero rows for no spring)")
            live = np.flatnonzero(has_direction)
        for array in (origins, dirs):
            array.flags.writeable = False
        return Rays(origins, dirs, live)

    def cast(
        self,
        origins_mm: np.ndarray,
        directions: np.ndarray,
        max_length_mm: float,
        rotation: np.ndarray | None = None,
        translation: np.ndarray | None = None,
    ) -> RayHits:
        """Signed spring lengths: nearest front-facing hit on F along each ray (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs; thesis 4.2.1).

        Parameters
        ----------
        origins_mm
            (n, 3) spring origins c_i (centroids of M's triangles), world frame, mm.
        directions
            (n, 3) unit directions n_i (M's outward normals, towards F), world frame. Zero rows
            (degenerate triangles of M) get no hit.
        max_length_mm
            Window half-width h_max: hits are searched for over signed lengths s in (-h, h].
        rotation, translation
            F's current placement, x_world = rotation @ x_local + translation (defaults: identity,
            zero). The rays are moved into F's local frame, where the BVH was built.

        Returns
        -------
        RayHits
            Signed length s_i (negative = interpenetration; ``inf`` if no valid hit in the
            window) and the hit triangle of F (-1 if none).
        """
        return self.cast_rays(self.prepare(origins_mm, directions), max_length_mm, rotation, translation)

    def cast_rays(
        self,
        rays: Rays,
        max_length_mm: float,
        rotation: np.ndarray | None = None,
        translation: np.ndarray | None = None,
    ) -> RayHits:
        """:meth:`cast` of rays checked once by :meth:`prepare` (same arguments and result)."""
        h = float(max_length_mm)
        if not (np.isfinite(h) and h > 0):
            raise ValueError(f"max_length_mm must be finite and > 0, got {max_length_mm}")
        rot = np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64)
        shift = np.zeros(3) if translation is None else np.asarray(translation, float)
        if rotation is not None:
            if rot.shape != (3, 3) or np.abs(rot.T @ rot - np.eye(3)).max() > 1e-9:
                raise ValueError("rotation must be a 3x3 orthogonal matrix")
            if _determinant(rot) < 0:
                raise ValueError("rotation must be proper (det = +1), not a reflection")
        if shift.shape != (3,):
            raise ValueError(f"translation must have shape (3,), got {shift.shape}")

        n = rays.origins_mm.shape[0]
        if not (len(self.triangles) and n):
            return RayHits(spring_length_mm=np.full(n, np.inf), triangle=np.full(n, -1, dtype=np.int64))
        dirs = rays.directions if rays.live is None else rays.directions[rays.live]
        # Row-vector form of x_local = R^T (x_world - t), then relative to F's box centre: one
        # product of the rows (x, 1) with the 4 x 3 affine matrix (R; -t R - centre).
        affine = np.empty((4, 3))
        affine[:3] = rot
        affine[3] = -(shift @ rot + self._centre_mm)
        origins = rows_times(rays.homogeneous_origins, affine)
        dirs = rows_times(dirs, rot)
        cast = self._cast_bruteforce if self.backend == "numpy" else self._cast_embree
        if rays.live is None:
            length, hit = cast(origins, dirs, h)
            return RayHits(spring_length_mm=length, triangle=hit)
        length = np.full(n, np.inf)
        hit = np.full(n, -1, dtype=np.int64)
        if rays.live.size:
            length[rays.live], hit[rays.live] = cast(origins, dirs, h)
        return RayHits(spring_length_mm=length, triangle=hit)

    # -- backends --------------------------------------------------------------------------------

    def _cast_bruteforce(
        self, origins: np.ndarray, dirs: np.ndarray, h: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Exact reference: float64 Moller-Trumbore of every ray against every triangle."""
        n, k = len(origins), len(self.triangles)
        length = np.full(n, np.inf)
        hit = np.full(n, -1, dtype=np.int64)
        rows = max(1, _CHUNK_PAIRS // max(k, 1))
        v0, e1, e2 = self._v0[None], self._edge1[None], self._edge2[None]
        for start in range(0, n, rows):  # chunks bound memory; each chunk is fully vectorised
            stop = min(start + rows, n)
            t, u, v, det = _moller_trumbore(
                origins[start:stop, None], dirs[start:stop, None], v0, e1, e2
            )
            self.pairs_tested += t.size
            valid = (det > 0) & _inside(u, v, _REFERENCE_SLACK) & (t > -h) & (t <= h)
            t = np.where(valid, t, np.inf)
            best = np.argmin(t, axis=1)
            best_t = t[np.arange(stop - start), best]
            found = np.isfinite(best_t)
            length[start:stop][found] = best_t[found]
            hit[start:stop][found] = best[found]
        return length, hit

    def _cast_embree(
        self, origins: np.ndarray, dirs: np.ndarray, h: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Embree traversal, float64 re-measurement, wrong-facing skipping, exact repairs."""
        n = len(origins)
        length = np.full(n, np.inf)
        hit = np.full(n, -1, dtype=np.int64)
        step = self._step_mm
        # Where each ray's remaining search segment starts (signed length); the window end is h.
        # The padding keeps float32 round-off at both ends from hiding a hit inside the window;
        # hits in the padding are filtered out in float64 below.
        seg_start = np.full(n, -h - step)
        active: np.ndarray | None = None  # the rays still searched; None: all (the first round)
        missed: list[np.ndarray] = []
        hard: list[np.ndarray] = []

        for _ in range(_MAX_ROUNDS):
            # Traverse past the window end (up to the far side of F): a ray whose nearest hit
            # lies beyond the window is then a plain 'no spring', not a miss worth a repair probe.
            if active is None:  # first round: every ray, one common start (a scalar), no gather
                o, d, s0 = origins, dirs, seg_start
                start = -h - step
                start_points = d * start
                start_points += o
                ray = self._embree_run(start_points, d, np.full(n, (h + self._reach_mm) - start, np.float32))
                window_end = (h + step) - start
            elif not active.size:
                break
            else:
                o, d, s0 = origins[active], dirs[active], seg_start[active]
                ray = self._embree_run(o + s0[:, None] * d, d, (h + self._reach_mm) - s0)
                window_end = (h + step) - s0
            prim = ray["primID"]
            none = prim < 0
            missed.append(none.nonzero()[0] if active is None else active[none])
            # A nearest float32 hit beyond the window (and its padding) ends the search: no spring.
            found = ray["tfar"] <= window_end
            found &= ~none
            if found.all():  # e.g. every spring facing F: no gather
                idx, k, u32, v32 = np.arange(n) if active is None else active, prim.astype(np.int64), ray["u"], ray["v"]
            else:
                # Integer row gathers by take: a boolean mask (or []) over (n, 3) rows is
                # several times slower.
                rows = found.nonzero()[0]
                k = prim.take(rows).astype(np.int64)
                # (the first round's rays all start at one place: no gather of it)
                idx, s0 = (rows, np.broadcast_to(start, rows.shape)) if active is None else (active[rows], s0[rows])
                o, d = o.take(rows, axis=0), d.take(rows, axis=0)
                u32, v32 = ray["u"].take(rows), ray["v"].take(rows)
            t, det, edge, u_edge, v_edge = self._remeasure(o, d, k, u32, v32)
            # Embree's float32 answer is only trusted where float64 puts the ray on its triangle;
            # a ray that lands at (or, in float64, just past) an edge or vertex of it is re-solved
            # exactly among the triangles around that triangle: a float32 tie is always between
            # neighbours, so this stays local (never a pass over all of F).
            # Only the rows the re-measure tested in full can be off their triangle (the others
            # are inside by more than float32 round-off); nan barycentrics, det == 0, are too.
            fix = edge[~_inside(u_edge, v_edge, _REFERENCE_SLACK)]
            lost = fix[:0]
            if fix.size:
                far = np.full(fix.size, h + self._reach_mm)
                t_fix, k_fix, det_fix = self._star_hits(o[fix], d[fix], k[fix], s0[fix], far, front_only=False)
                found_fix = k_fix >= 0
                t[fix], det[fix] = t_fix, det_fix
                k[fix[found_fix]] = k_fix[found_fix]
                # No neighbour meets the ray: Embree's triangle was not where the ray passes at
                # all; it counts as a miss and goes to the probe repair below.
                lost = fix[~found_fix]
            in_window = t <= h
            accept = (det > 0) & (t > -h)
            accept &= in_window
            accept[lost] = False
            if accept.all():  # e.g. every spring facing F from in front: no mask
                length[idx], hit[idx] = t, k
                active = idx[:0]
                break
            taken = accept.nonzero()[0]  # (one index for both scatters, not four boolean masks)
            accepted = idx.take(taken)
            length[accepted], hit[accepted] = t.take(taken), k.take(taken)
            missed.append(idx[lost])
            # Wrong-facing, or in the padding before the window: skip it and continue past it.
            # (Any hit beyond the window ends the search: nothing nearer was found.)
            skip = in_window & ~accept
            skip[lost] = False
            # Before resuming past a skipped hit, look at the triangles around it: where F folds
            # (a ridge between a front- and a back-facing triangle) Embree may have returned the
            # back-facing one of a tie, and the valid hit sits at the same point.
            if not skip.any():
                active = idx[:0]
                break
            sk, t_sk = idx[skip], t[skip]
            resume = np.maximum(t_sk, s0[skip]) + step
            low, high = np.maximum(t_sk - step, np.nextafter(-h, h)), np.minimum(resume, h)
            tie_t, tie_tri, _ = self._star_hits(o[skip], d[skip], k[skip], low, high)
            tie = np.isfinite(tie_t)
            length[sk[tie]] = tie_t[tie]
            hit[sk[tie]] = tie_tri[tie]
            seg_start[sk[~tie]] = resume[~tie]
            active = sk[~tie]
        hard.append(active)  # still bouncing between wrong-facing sheets after _MAX_ROUNDS

        missed_idx = np.concatenate(missed)
        if missed_idx.size:
            self._repair_misses(origins, dirs, h, missed_idx, seg_start, length, hit)
        hard_idx = np.concatenate(hard)
        if hard_idx.size:
            length[hard_idx], hit[hard_idx] = self._cast_bruteforce(
                origins[hard_idx], dirs[hard_idx], h
            )
        return length, hit

    def _remeasure(
        self, o: np.ndarray, d: np.ndarray, k: np.ndarray, u32: np.ndarray, v32: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(t, det, edge, u, v) in float64 of rays o + t d on Embree's triangles k (see _moller_trumbore).

        Where Embree's float32 barycentrics put the hit well inside the triangle (further from every
        edge than float32 round-off can move it) the triangle is certainly right and only the
        plane distance is recomputed in float64 (signed length directly from the true origin).
        The other rows, ``edge`` (ascending), get a full Moller-Trumbore test: u, v are theirs
        (``edge``'s rows only).
        """
        nx, ny, nz, offset, interior = self._plane_columns.take(k, axis=1)  # take: far cheaper than []
        along = nx * d[:, 0] + ny * d[:, 1] + nz * d[:, 2]  # (row_dot's order of sums)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (offset - (nx * o[:, 0] + ny * o[:, 1] + nz * o[:, 2])) / along
        det = -along
        # Distance from the nearest edge in float64 without converting u and v: the float32 min(u, v)
        # is exact, 1 - u - v is formed in float64 (each float32 term converted exactly).
        third = np.subtract(1.0, u32, dtype=np.float64)
        third -= v32
        margin = np.minimum(np.minimum(u32, v32), third)
        edge = (~(margin > interior)).nonzero()[0]
        u = v = third[:0]
        if edge.size:
            ke = k[edge]
            t[edge], u, v, det[edge] = _moller_trumbore(
                o[edge], d[edge], self._v0[ke], self._edge1[ke], self._edge2[ke]
            )
        self.pairs_tested += k.size
        return t, det, edge, u, v

    def _repair_misses(
        self,
        origins: np.ndarray,
        dirs: np.ndarray,
        h: float,
        missed: np.ndarray,
        seg_start: np.ndarray,
        length: np.ndarray,
        hit: np.ndarray,
    ) -> None:
        """Recover hits Embree's float32 traversal lost exactly on an edge or vertex of F.

        Each missed ray is re-cast shifted sideways by a tiny amount; if the shifted probe hits a
        triangle, the true ray passed within that shift of it, so its hit (if any) lies on a
        triangle sharing a vertex with it. Those few candidates are tested exactly in float64.
        Rays that genuinely miss stay missed (the probe misses too, or no candidate is valid).
        Only rays whose window passes near F (:meth:`_may_meet_surface`) can have lost a hit: the
        others are not probed.
        """
        s0 = seg_start[missed]
        near_f = self._may_meet_surface(origins, dirs, missed, s0, h + self._step_mm)
        if not near_f.any():
            return
        keep = near_f.nonzero()[0]
        missed, s0 = missed[keep], s0[keep]
        o, d = origins.take(missed, axis=0), dirs.take(missed, axis=0)
        # A sideways direction that never lines up with a mesh's axes or diagonals.
        side = cross_rows(d, np.array([0.5377, 0.8326, 0.1329]))
        size = row_dot(side, side)
        small = (size < 0.09).nonzero()[0]  # d nearly along that direction: another one
        if small.size:
            side[small] = cross_rows(d[small], np.array([0.1329, -0.5377, 0.8326]))
            size[small] = row_dot(side[small], side[small])
        side /= np.sqrt(size)[:, None]
        probe = o + s0[:, None] * d + self._probe_shift_mm * side
        prim = self._embree_run(probe, d, (h + self._step_mm) - s0)["primID"].astype(np.int64)
        near = (prim >= 0).nonzero()[0]
        if not near.size:
            return
        low, high = np.full(near.size, np.nextafter(-h, h)), np.full(near.size, h)
        best_t, best_tri, _ = self._star_hits(o[near], d[near], prim[near], low, high)
        got = np.isfinite(best_t)
        length[missed[near[got]]] = best_t[got]
        hit[missed[near[got]]] = best_tri[got]

    def _may_meet_surface(
        self, origins: np.ndarray, dirs: np.ndarray, rows: np.ndarray, s_start: np.ndarray, s_end: float
    ) -> np.ndarray:
        """(len(rows),) bool: False only where the segment o + s d, s_start <= s <= s_end, of ray
        ``rows[i]`` certainly stays away from F, so Embree cannot have lost a hit on it.

        Every point of the segment lies within half its length of its midpoint, and a window
        never starts before -s_end, so within s_end: one lookup of the midpoint in a grid whose
        marked cells cover every point that close to F (:meth:`_near_cells`) replaces a probe
        ray. The reach depends on s_end alone, so one grid serves every call with the same h_max.
        Most missed rays point away from F from springs far from it.
        """
        reach = s_end + self._step_mm
        grid = self._near_cells(reach)
        if grid is None:  # F's triangles too large for a grid: every ray is probed
            return np.ones(rows.size, bool)
        marked, lower, inverse_cell, top, strides = grid
        point = origins.take(rows, axis=0)
        middle = 0.5 * (s_start + s_end)
        if middle.any():  # (a first-round miss's window is centred on its origin)
            point += middle[:, None] * dirs.take(rows, axis=0)
        point = add_rows(point, -lower)
        point *= inverse_cell
        # Clipping sends points outside the grid to its border cells, which are never marked: the
        # grid reaches one cell beyond the marks on every side. The cell indices, and the flat
        # index from them, are whole numbers held exactly in float64 (cheaper than integer rows).
        np.maximum(point, 0.0, out=point)
        min_rows(point, top, out=point)
        np.floor(point, out=point)
        # (one product: its terms and sums are whole numbers below 2^53, exact in any order)
        return marked[(point @ strides).astype(np.int64)]

    def _near_cells(self, reach_mm: float) -> _Grid | None:
        """A grid over F's box padded by ``reach_mm`` whose marked cells hold every point within
        ``reach_mm`` of F (built once per reach, cached): (flat marks, lower corner, 1 / cell
        size, largest cell index per axis, flat-index strides), or None if F's triangles would
        mark too many cells.

        Cells overlapping a triangle's bounding box are marked, then the marks are dilated by
        ceil(reach / cell) cells along each axis (a box, which holds the ball of radius reach).
        """
        cached = self._grids.get(reach_mm)
        if cached is not None or reach_mm in self._grids:
            return cached
        # Cells a fraction of the reach (a tight cover), at most _GRID_CELLS along the longest side.
        cell = max(float(self._box_mm.max() + 2.0 * reach_mm) / _GRID_CELLS, reach_mm / 4.0)
        width = int(np.ceil(reach_mm / cell))
        # F's box, the marks' dilation and one unmarked border cell on every side.
        box_lo = -0.5 * self._box_mm - (width + 1) * cell  # (rays are relative to the box centre)
        shape = np.ceil(self._box_mm / cell).astype(np.int64) + 2 * width + 3
        corners = self.vertices_mm[self.triangles] - self._centre_mm
        first = np.floor((corners.min(axis=1) - box_lo) / cell).astype(np.int64)
        count = np.floor((corners.max(axis=1) - box_lo) / cell).astype(np.int64) - first + 1
        per_triangle = count.prod(axis=1)
        total = int(per_triangle.sum())
        grid = None
        if total <= _GRID_MAX_MARKS:
            marked = np.zeros(tuple(shape), bool)
            # Every cell of every triangle's box, enumerated without a loop over triangles, in
            # slices of triangles holding about _GRID_SLICE_MARKS cells (bounded memory).
            ends = np.cumsum(per_triangle)
            cuts = np.searchsorted(ends, np.arange(_GRID_SLICE_MARKS, total, _GRID_SLICE_MARKS), side="right")
            for lo, hi in zip(np.r_[0, cuts], np.r_[cuts, len(count)]):
                per, cnt = per_triangle[lo:hi], count[lo:hi]
                owner = np.repeat(np.arange(hi - lo), per)
                j = np.arange(owner.size) - np.repeat(np.cumsum(per) - per, per)
                nx, ny = cnt[owner, 0], cnt[owner, 1]
                index = first[lo:hi][owner] + np.stack([j % nx, (j // nx) % ny, j // (nx * ny)], axis=1)
                marked[index[:, 0], index[:, 1], index[:, 2]] = True
            for axis in range(3):  # box dilation by `width` cells: a window sum of a cumsum
                total_along = np.cumsum(marked, axis=axis, dtype=np.int32)
                padded = np.concatenate([np.zeros_like(np.take(total_along, [0], axis=axis)), total_along], axis=axis)
                n_axis = marked.shape[axis]
                upper = np.take(padded, np.minimum(np.arange(n_axis) + width + 1, n_axis), axis=axis)
                lower = np.take(padded, np.maximum(np.arange(n_axis) - width, 0), axis=axis)
                marked = upper > lower
            strides = np.array([shape[1] * shape[2], shape[2], 1])
            grid = (marked.ravel(), box_lo, 1.0 / cell, shape - 1, strides)
        self._grids[reach_mm] = grid
        return grid

    def _star_hits(
        self,
        origins: np.ndarray,
        dirs: np.ndarray,
        triangle: np.ndarray,
        t_low: np.ndarray,
        t_high: np.ndarray,
        front_only: bool = True,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Exact nearest hit of ray i among the triangles sharing a vertex with triangle[i].

        Counted: on the triangle (edges and vertices included), t in [t_low[i], t_high[i]], and
        front-facing unless ``front_only`` is False. Returns (t, triangle, det) of the nearest
        hit, (inf, -1, nan) where there is none; det > 0 marks a front-facing hit.
        """
        corner = self._welded_corners[triangle].ravel()
        counts = self._star_start[corner + 1] - self._star_start[corner]
        total = int(counts.sum())
        offsets = np.arange(total) - np.repeat(np.cumsum(counts) - counts, counts)
        cand = self._star_triangles[np.repeat(self._star_start[corner], counts) + offsets]
        ray = np.repeat(np.repeat(np.arange(len(triangle)), 3), counts)
        t, u, v, det = _moller_trumbore(
            origins[ray], dirs[ray], self._v0[cand], self._edge1[cand], self._edge2[cand]
        )
        self.pairs_tested += cand.size
        valid = (det != 0) & _inside(u, v, _REFERENCE_SLACK) & (t >= t_low[ray]) & (t <= t_high[ray])
        if front_only:
            valid &= det > 0
        best_t, best_tri = _nearest_per_ray(ray[valid], t[valid], cand[valid], len(triangle))
        best_det = np.full(len(triangle), np.nan)
        found = best_tri >= 0
        # det of the chosen pair: one more exact test on the winner (cheap, one per ray).
        if found.any():
            _, _, _, best_det[found] = _moller_trumbore(
                origins[found], dirs[found], self._v0[best_tri[found]],
                self._edge1[best_tri[found]], self._edge2[best_tri[found]],
            )
        return best_t, best_tri, best_det
