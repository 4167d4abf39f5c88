"""Repair, orientation and unit checks of triangulated bone surfaces (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs, docs/method.md#8-built-in-geometries).

docs/method.md#8-built-in-geometries: real meshes load "with clear errors for non-manifold,
unoriented, degenerate or unit-mismatched input". docs/method.md#1-two-rigid-bones-and-a-bed-of-springs:
every triangle of the mobile surface M carries one spring along its unit normal, which must point
out of M towards the fixed body F; normals are oriented "from mesh topology, not from the sign of
a dot product with the position vector". This module turns a surface as read
(:func:`geometries.mesh_files.read_surface`) into one that meets those requirements:

1. :func:`clean_surface` merges duplicate vertices, drops degenerate and duplicate triangles and
   unused vertices, refuses non-manifold edges, and orients every connected component
   consistently from its edge topology (:func:`orient_consistently`); closed components are
   turned outward (positive signed volume).
2. :func:`orient_pair` / :func:`orient_towards` choose the global sign of open patches (an
   articular surface) from the other body: normals point towards it.
3. :func:`check_units` and :func:`check_pair_distance` catch unit mismatches and bodies placed
   too far apart for any spring (h <= h_max) to exist.

:func:`prepare_surface` (one file) and :func:`prepare_pair` (mobile + fixed) run the whole chain
from the file; the scene loader calls these. Every bad-input error is an :class:`InputError`
naming the file, the scene key, what is wrong and what was expected. Repairs that change the
mesh are reported with ``warnings.warn`` (category :class:`MeshWarning`) so the caller can
collect them.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from geometries.errors import InputError, MeshWarning
from geometries.mesh_files import read_surface
from geometries.mesh_files.common import fmt_point
from geometries.surface import TriangleSurface

__all__ = [
    "MeshWarning",
    "merge_duplicate_vertices",
    "drop_degenerate_triangles",
    "check_manifold",
    "orient_consistently",
    "orient_towards",
    "orient_pair",
    "clean_surface",
    "check_units",
    "check_pair_distance",
    "prepare_surface",
    "prepare_pair",
    "signed_volume_mm3",
    "component_labels",
]

#: bounding-box diagonal (mm) below which a mesh is taken to be in metres
SMALL_DIAGONAL_MM = 1.0
#: bounding-box diagonal (mm) above which a mesh is taken to be in micrometres or similar
LARGE_DIAGONAL_MM = 2000.0
#: a component whose area vectors sum to less than this fraction of its area is closed
_CLOSED_REL_TOL = 1e-9


def _where(surface: TriangleSurface) -> str:
    return surface.source or surface.name or "surface"


def _warn(text: str) -> None:
    warnings.warn(text, MeshWarning, stacklevel=3)


def _new(
    surface: TriangleSurface, vertices_mm: np.ndarray, triangles: np.ndarray
) -> TriangleSurface:
    return TriangleSurface(
        vertices_mm=np.ascontiguousarray(vertices_mm, dtype=np.float64),
        triangles=np.ascontiguousarray(triangles, dtype=np.int64).reshape(-1, 3),
        name=surface.name,
        source=surface.source,
    )


def _flip(triangles: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Reverse the corner order (and so the normal) of the triangles selected by ``mask``."""
    out = triangles.copy()
    out[mask, 1], out[mask, 2] = triangles[mask, 2], triangles[mask, 1]
    return out


def _bbox_diagonal_mm(vertices_mm: np.ndarray) -> float:
    if len(vertices_mm) == 0:
        return 0.0
    return float(np.linalg.norm(vertices_mm.max(axis=0) - vertices_mm.min(axis=0)))


# --------------------------------------------------------------------------------------------
# cleaning
# --------------------------------------------------------------------------------------------


def _first_equal_rows(rows: np.ndarray) -> np.ndarray:
    """For each of the (n, k) rows, the index of the first row equal to it (n,): ``first[inverse]``
    of ``np.unique(rows, axis=0, return_index=True, return_inverse=True)``, by one stable sort of
    the rows' bits (np.unique compares the rows as structured records: 7-12 ms for the 13k
    triangles of an STL, against about 1 ms). Float rows compare as numbers (-0.0 equals 0.0)."""
    rows = np.ascontiguousarray(rows)
    if rows.dtype.kind == "f":
        rows = rows + 0.0  # -0.0 + 0.0 = 0.0: equal numbers, equal bits
    bits = rows.view(np.dtype(f"u{rows.dtype.itemsize}"))
    order = np.lexsort(bits.T[::-1])  # stable: the first of equal rows comes first
    ordered = bits[order]
    starts = np.concatenate([[True], (ordered[1:] != ordered[:-1]).any(axis=1)])
    first = np.empty(len(rows), dtype=np.int64)
    first[order] = order[starts][np.cumsum(starts) - 1]
    return first


def merge_duplicate_vertices(surface: TriangleSurface, rel_tol: float = 1e-9) -> TriangleSurface:
    """Merge vertices closer than ``rel_tol`` x bounding-box diagonal; drop unused vertices.

    STL stores every triangle with its own three corners, so shared vertices (and with them any
    topology: edges, components, orientation, docs/method.md#1-two-rigid-bones-and-a-bed-of-springs) exist only after this merge. Clusters of
    near-coincident vertices (found with a k-d tree; chained pairs merge transitively, via
    connected components) collapse onto their lowest-index member, whose coordinates are kept
    unchanged. Vertex order is otherwise preserved.
    """
    v, t = surface.vertices_mm, surface.triangles
    n = len(v)
    tol = float(rel_tol) * _bbox_diagonal_mm(v)
    if n > 1:
        # exact duplicates first (cheap, and the only kind in STL), then near-coincident ones
        rep = _first_equal_rows(v)
        if tol > 0:
            pairs = cKDTree(v).query_pairs(r=tol, output_type="ndarray")
            if len(pairs):
                ij = np.concatenate([pairs, np.stack([np.arange(n), rep], axis=1)])
                graph = coo_matrix((np.ones(len(ij)), (ij[:, 0], ij[:, 1])), shape=(n, n))
                _, labels = connected_components(graph, directed=False)
                lowest = np.full(labels.max() + 1, n, dtype=np.int64)
                np.minimum.at(lowest, labels, np.arange(n))
                rep = lowest[labels]
        t = rep[t]
    used, t_new = np.unique(t, return_inverse=True)
    return _new(surface, v[used], t_new.reshape(-1, 3))


def drop_degenerate_triangles(
    surface: TriangleSurface, rel_area_tol: float = 1e-12
) -> TriangleSurface:
    """Drop triangles that cannot carry a spring (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs) and duplicated triangles.

    Dropped: repeated vertex indices, area <= ``rel_area_tol`` x mean triangle area (includes
    zero area), and second copies of a triangle over the same three vertices (either winding).
    Warns with the counts. Unused vertices are removed.
    """
    t = surface.triangles
    if len(t) == 0:
        return surface
    repeated = (t[:, 0] == t[:, 1]) | (t[:, 1] == t[:, 2]) | (t[:, 0] == t[:, 2])
    areas = surface.areas_mm2
    mean_area = float(areas.mean())
    tiny = areas <= rel_area_tol * mean_area
    degenerate = repeated | tiny
    keep = ~degenerate
    unique_mask = _first_equal_rows(np.sort(t, axis=1)) == np.arange(len(t))
    duplicate = keep & ~unique_mask
    # a duplicate whose first copy is degenerate would be degenerate too: counted there
    keep &= unique_mask
    n_deg, n_dup = int(degenerate.sum()), int(duplicate.sum())
    if n_deg:
        _warn(f"{_where(surface)}: {n_deg} degenerate triangles (zero area or repeated "
              "vertices) dropped; they carry no spring")
    if n_dup:
        _warn(f"{_where(surface)}: {n_dup} duplicate triangles (same three vertices) dropped")
    if n_deg == 0 and n_dup == 0:
        return surface
    kept = t[keep]
    used, t_new = np.unique(kept, return_inverse=True)
    return _new(surface, surface.vertices_mm[used], t_new.reshape(-1, 3))


class _Topology:
    """Edge table of a triangle mesh: undirected edges, their use count and the triangle graph.

    Half-edge h = 3 t + k runs from corner k to corner k+1 (mod 3) of triangle t.
    """

    def __init__(self, triangles: np.ndarray, n_vertices: int) -> None:
        n_tri = len(triangles)
        self.n_triangles = n_tri
        he = np.stack([triangles, np.roll(triangles, -1, axis=1)], axis=2).reshape(-1, 2)
        lo, hi = he.min(axis=1), he.max(axis=1)
        self.forward = he[:, 0] < he[:, 1]
        keys = lo.astype(np.int64) * max(int(n_vertices), 1) + hi
        uniq, inv, counts = np.unique(keys, return_inverse=True, return_counts=True)
        inv = inv.ravel()
        self.edge_of_half = inv
        self.edge_count = counts
        self.edge_vertices = np.stack([uniq // max(int(n_vertices), 1),
                                       uniq % max(int(n_vertices), 1)], axis=1)
        order = np.argsort(inv, kind="stable")
        first = np.concatenate([[0], np.cumsum(counts)[:-1]])
        self.half_sorted = order
        self.edge_first = first
        interior = np.flatnonzero(counts == 2)
        h1, h2 = order[first[interior]], order[first[interior] + 1]
        self.pair_a = h1 // 3
        self.pair_b = h2 // 3
        # the two triangles agree when they run the shared edge in opposite directions
        self.pair_disagree = self.forward[h1] == self.forward[h2]
        graph = coo_matrix((np.ones(len(interior)), (self.pair_a, self.pair_b)),
                           shape=(n_tri, n_tri))
        self.n_components, self.component = connected_components(graph, directed=False)
        boundary_half = order[first[counts == 1]]
        self.component_open = np.bincount(self.component[boundary_half // 3],
                                          minlength=self.n_components) > 0


def component_labels(surface: TriangleSurface) -> np.ndarray:
    """Connected component (through shared edges) of every triangle, 0..n_components-1."""
    return _Topology(surface.triangles, len(surface.vertices_mm)).component


def check_manifold(surface: TriangleSurface, *, key: str | None = None) -> None:
    """Raise InputError if an edge is shared by more than two triangles (docs/method.md#8-built-in-geometries).

    A spring bed needs a surface with one side towards the other body; non-manifold edges
    (T-junction sheets, internal walls) have no consistent sides. The message names how many
    such edges there are and the location of one.
    """
    t = surface.triangles
    n_v = max(len(surface.vertices_mm), 1)
    he = np.stack([t, np.roll(t, -1, axis=1)], axis=2).reshape(-1, 2)
    keys = he.min(axis=1).astype(np.int64) * n_v + he.max(axis=1)
    uniq, counts = np.unique(keys, return_counts=True)
    bad = counts > 2
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        mid = surface.vertices_mm[[uniq[i] // n_v, uniq[i] % n_v]].mean(axis=0)
        raise InputError(
            f"{int(bad.sum())} non-manifold edges (shared by more than two triangles); "
            f"e.g. the edge at {fmt_point(mid)} is shared by {int(counts[i])} triangles",
            file=surface.source or None, key=key,
            expected="a manifold surface: every edge shared by one or two triangles",
        )


def _component_sums(values: np.ndarray, component: np.ndarray, n: int) -> np.ndarray:
    if values.ndim == 1:
        return np.bincount(component, weights=values, minlength=n)
    return np.stack([np.bincount(component, weights=values[:, j], minlength=n)
                     for j in range(values.shape[1])], axis=1)


def _closed_components(surface: TriangleSurface, topo: _Topology) -> np.ndarray:
    """Closed: no boundary edge, or boundary loops enclosing no area (sum of area vectors zero,
    e.g. after a zero-area triangle was dropped). Signed volume is well defined for these."""
    av = surface.area_vectors_mm2
    total = _component_sums(surface.areas_mm2, topo.component, topo.n_components)
    vec = np.linalg.norm(_component_sums(av, topo.component, topo.n_components), axis=1)
    return (~topo.component_open) | (vec <= _CLOSED_REL_TOL * total)


def signed_volume_mm3(surface: TriangleSurface) -> float:
    """Signed enclosed volume, sum of (a . (b x c)) / 6 about the vertex centroid.

    Positive when a closed surface's normals point outward.
    """
    v = surface.vertices_mm - surface.vertices_mm.mean(axis=0)
    a, b, c = (v[surface.triangles[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def orient_consistently(surface: TriangleSurface, *, key: str | None = None) -> TriangleSurface:
    """Orient every connected component consistently from its topology (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs).

    Two triangles sharing an edge agree when they traverse it in opposite directions. The
    orientation problem is solved on the double cover of the triangle adjacency graph (node
    (t, s): triangle t with flip state s; an agreeing pair links equal states, a disagreeing
    pair opposite states): a component is orientable iff (t, 0) and (t, 1) fall in different
    connected components of the cover, otherwise InputError (Moebius-like surface). Within a
    component the minority orientation is flipped (warning with the count). A closed component
    is then turned outward (positive signed volume); an open patch keeps its majority
    orientation until :func:`orient_towards` / :func:`orient_pair` choose its global sign.
    Non-manifold edges raise InputError (see :func:`check_manifold`).
    """
    return _orient_consistently(surface, key)[0]


def _orient_consistently(surface: TriangleSurface, key: str | None) -> tuple[TriangleSurface, _Topology | None]:
    """:func:`orient_consistently`, and the topology it built (None without triangles): its
    components and open edges are the oriented surface's too (a flip changes no adjacency)."""
    t = surface.triangles
    n = len(t)
    if n == 0:
        return surface, None
    topo = _Topology(t, len(surface.vertices_mm))
    if (topo.edge_count > 2).any():
        check_manifold(surface, key=key)  # raises, naming the edges
    a, b, dis = topo.pair_a, topo.pair_b, topo.pair_disagree
    rows = np.concatenate([a, a + n])
    cols = np.concatenate([np.where(dis, b + n, b), np.where(dis, b, b + n)])
    cover = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(2 * n, 2 * n))
    _, lab = connected_components(cover, directed=False)
    comp = topo.component
    bad = lab[:n] == lab[n:]
    if bad.any():
        bad_comps = np.unique(comp[bad])
        c0 = bad_comps[0]
        members = comp == c0
        where = surface.centroids_mm[np.flatnonzero(members)[0]]
        raise InputError(
            f"{len(bad_comps)} connected piece(s) of the surface cannot be oriented "
            f"consistently (Moebius-like); e.g. the piece of {int(members.sum())} triangles "
            f"near {fmt_point(where)}",
            file=surface.source or None, key=key,
            expected="an orientable surface (a consistent inside and outside)",
        )
    _, root = np.unique(comp, return_index=True)
    state = lab[:n] != lab[root[comp]]  # True: opposite orientation to the component's root
    n_flip_state = np.bincount(comp, weights=state, minlength=topo.n_components)
    size = np.bincount(comp, minlength=topo.n_components)
    invert = n_flip_state > size - n_flip_state  # flip the minority, not the majority
    flip = state ^ invert[comp]
    n_flipped = int(flip.sum())
    if n_flipped:
        _warn(f"{_where(surface)}: {n_flipped} triangles were oriented against their "
              "neighbours and have been flipped")
        surface = _new(surface, surface.vertices_mm, _flip(t, flip))

    closed = _closed_components(surface, topo)
    if closed.any():
        v = surface.vertices_mm - surface.vertices_mm.mean(axis=0)
        tt = surface.triangles
        vol = np.einsum("ij,ij->i", v[tt[:, 0]], np.cross(v[tt[:, 1]], v[tt[:, 2]])) / 6.0
        comp_vol = np.bincount(comp, weights=vol, minlength=topo.n_components)
        turn = closed & (comp_vol < 0)
        if turn.any():
            surface = _new(surface, surface.vertices_mm, _flip(tt, turn[comp]))
    return surface, topo


def _winding_numbers(surface: TriangleSurface, mask: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Generalised winding number of ``points`` w.r.t. the triangles selected by ``mask``
    (solid angles, Van Oosterom-Strackee): about 1 inside an outward closed surface, 0 outside."""
    tri = surface.triangles[mask]
    v = surface.vertices_mm
    out = np.empty(len(points))
    chunk = max(1, 2_000_000 // max(len(tri), 1))
    for s in range(0, len(points), chunk):
        p = points[s:s + chunk, None, :]
        a, b, c = (v[tri[:, k]][None, :, :] - p for k in range(3))
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        num = np.einsum("pti,pti->pt", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("pti,pti->pt", a, b) * lc
               + np.einsum("pti,pti->pt", a, c) * lb + np.einsum("pti,pti->pt", b, c) * la)
        out[s:s + chunk] = 2.0 * np.arctan2(num, den).sum(axis=1) / (4.0 * np.pi)
    return out


def orient_towards(
    surface: TriangleSurface, points_mm: np.ndarray, *, key: str | None = None,
    near_mm: float | None = None, n_winding_samples: int = 15,
) -> TriangleSurface:
    """Give every connected component the global sign that makes its normals face ``points_mm``.

    The surface is first oriented consistently (:func:`orient_consistently`). Then, per
    component:
    - open patch: flipped as a whole if sum_t A_t n_t . (p_t - c_t) < 0 over the triangles
      *near* the points only, where c_t is the triangle centroid and p_t the point of
      ``points_mm`` nearest to it (k-d tree). Near means within ``near_mm`` of the component's
      closest approach d_min (the ray window h_max when the caller knows it), or, without
      ``near_mm``, no further than the closest tenth of the component's triangles. Only the
      near triangles carry evidence: a patch that wraps round a condyle has far triangles whose
      nearest point of the other body lies behind them, and counting those flips the patch
      inside out (a 180 deg wrap over a small plateau already does);
    - closed surface: outward (positive signed volume), unless the points lie inside it
      (median generalised winding number of up to ``n_winding_samples`` of them > 1/2: a
      fixed shell around the mobile body), then inward. The dot-product rule is not used for
      closed surfaces: it is negative for any outward closed surface seen from outside.
    docs/method.md#1-two-rigid-bones-and-a-bed-of-springs: the spring normals of M point towards F; F's normals point towards M.
    """
    points = np.asarray(points_mm, dtype=np.float64).reshape(-1, 3)
    surface, topo = _orient_consistently(surface, key)
    if len(points) == 0 or topo is None:
        return surface
    comp, nc = topo.component, topo.n_components
    closed = _closed_components(surface, topo)
    turn = np.zeros(nc, dtype=bool)
    if (~closed).any():
        sel = np.flatnonzero(~closed[comp])
        cent = surface.centroids_mm[sel]
        distance, idx = cKDTree(points).query(cent)
        score_t = np.einsum("ij,ij->i", surface.area_vectors_mm2[sel], points[idx] - cent)
        near = _near_triangles(comp[sel], distance, nc, near_mm)
        score = np.bincount(comp[sel][near], weights=score_t[near], minlength=nc)
        turn |= (~closed) & (score < 0)
    if closed.any():
        sample = points[np.unique(np.linspace(0, len(points) - 1, n_winding_samples).astype(int))]
        for c in np.flatnonzero(closed):
            w = _winding_numbers(surface, comp == c, sample)
            turn[c] = np.median(w) > 0.5
    if turn.any():
        surface = _new(surface, surface.vertices_mm, _flip(surface.triangles, turn[comp]))
    return surface


def _near_triangles(comp: np.ndarray, distance_mm: np.ndarray, n_comp: int, near_mm: float | None) -> np.ndarray:
    """Mask of the triangles within the near band of their component's closest approach.

    The band is ``near_mm`` beyond the component's smallest distance, or (``near_mm`` None)
    up to the component's 10th-percentile distance, so at least a tenth of every component
    votes.
    """
    d_min = np.full(n_comp, np.inf)
    np.minimum.at(d_min, comp, distance_mm)
    if near_mm is not None:
        limit = d_min + float(near_mm)
    else:
        limit = np.full(n_comp, np.inf)
        order = np.lexsort((distance_mm, comp))
        size = np.bincount(comp, minlength=n_comp)
        start = np.concatenate([[0], np.cumsum(size)[:-1]])
        present = size > 0
        tenth = start[present] + (size[present] - 1) // 10
        limit[present] = distance_mm[order[tenth]]
    return distance_mm <= limit[comp] * (1 + 1e-12) + 1e-12


def orient_pair(
    mobile: TriangleSurface, fixed: TriangleSurface, *, mobile_key: str | None = None,
    fixed_key: str | None = None, near_mm: float | None = None,
) -> tuple[TriangleSurface, TriangleSurface]:
    """Orient M's normals towards F and F's normals towards M (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs), per component.

    Each body is oriented with :func:`orient_towards` against the other body's vertices: open
    patches by the nearest other-body vertex of their triangles near it (within ``near_mm`` of
    the closest approach, see :func:`orient_towards`), closed surfaces outward (inward if they
    enclose the other body). Returns ``(mobile, fixed)``.
    """
    mobile_out = orient_towards(mobile, fixed.vertices_mm, key=mobile_key, near_mm=near_mm)
    fixed_out = orient_towards(fixed, mobile.vertices_mm, key=fixed_key, near_mm=near_mm)
    return mobile_out, fixed_out


def clean_surface(
    surface: TriangleSurface, *, key: str | None = None, merge_rel_tol: float = 1e-9,
    degenerate_rel_area: float = 1e-12,
) -> TriangleSurface:
    """Merge duplicate vertices, drop degenerate/duplicate triangles, refuse non-manifold
    edges, orient consistently (closed components outward). docs/method.md#1-two-rigid-bones-and-a-bed-of-springs and 6.

    Raises InputError if nothing is left, for non-manifold edges and for non-orientable pieces.
    """
    s = merge_duplicate_vertices(surface, rel_tol=merge_rel_tol)
    s = drop_degenerate_triangles(s, rel_area_tol=degenerate_rel_area)
    if s.n_triangles == 0:
        raise InputError("every triangle of the mesh is degenerate (zero area)",
                         file=surface.source or None, key=key,
                         expected="a surface with non-degenerate triangles")
    return orient_consistently(s, key=key)  # (which refuses non-manifold edges)


def check_units(surface: TriangleSurface, units: str = "mm", *, refuse: bool = False, key: str | None = None) -> float:
    """Warn (or with ``refuse``, raise InputError) when the bounding-box diagonal (in mm)
    suggests the wrong length unit (docs/method.md#8-built-in-geometries).

    Below 1 mm the mesh most likely is in metres (suggest ``units = "m"``); above 2000 mm it
    is larger than any joint, most likely micrometres or another unit. A scene refuses such a
    mesh: solved as given it yields absurd contact numbers. Returns the diagonal.
    """
    diag = _bbox_diagonal_mm(surface.vertices_mm)
    where = _where(surface)
    problem = None
    if diag < SMALL_DIAGONAL_MM:
        if units == "m":
            problem = f"the mesh is only {diag:.4g} mm across even after converting from metres"
            expected = "a joint-sized mesh (1 to 2000 mm across): check the units of the file"
        else:
            problem = f"the mesh is only {diag:.4g} mm across; it looks like it is in metres"
            expected = 'units = "m" in the [geometry] section'
    elif diag > LARGE_DIAGONAL_MM:
        problem = f"the mesh is {diag:.4g} mm across, larger than any joint; it looks like micrometres or another unit"
        expected = 'lengths in mm, or in m with units = "m"'
    if problem is None:
        return diag
    if refuse:
        raise InputError(problem, file=surface.source or None, key=key, expected=expected)
    _warn(f"{where}: {problem} (expected {expected})")
    return diag


def _max_edge_mm(surface: TriangleSurface) -> float:
    if surface.n_triangles == 0:
        return 0.0
    v, t = surface.vertices_mm, surface.triangles
    e = v[np.roll(t, -1, axis=1)] - v[t]
    return float(np.sqrt((e * e).sum(axis=2)).max())


def check_pair_distance(
    mobile: TriangleSurface, fixed: TriangleSurface, max_spring_length_mm: float, *,
    key: str | None = None,
) -> float:
    """Smallest vertex-to-vertex distance between the bodies (mm), checked against h_max.

    No spring can be a candidate (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs: ray length h <= h_max) when the bodies are further
    apart than 10 h_max + the longest triangle edge of either body (the edge term covers the
    gap between vertex-to-vertex and surface-to-surface distance). Raises InputError then;
    the distance it quotes is then taken over evenly spaced subsets of the vertices (an upper
    estimate, enough to see a unit or frame mismatch). Returns the exact smallest distance
    otherwise.
    """
    bound = 10.0 * float(max_spring_length_mm) + max(_max_edge_mm(mobile), _max_edge_mm(fixed))
    vm, vf = mobile.vertices_mm, fixed.vertices_mm
    # an upper estimate from evenly spaced subsets, then an exact search pruned by it
    sub_f, sub_m = vf[:: max(1, len(vf) // 2000)], vm[:: max(1, len(vm) // 2000)]
    estimate = float(cKDTree(sub_f).query(sub_m)[0].min())
    limit = min(estimate, bound)
    d, _ = cKDTree(vf).query(vm, distance_upper_bound=limit * (1 + 1e-9) + 1e-12)
    dist = float(d.min())  # exact when finite; inf only when estimate > bound
    if not np.isfinite(dist):
        dist = estimate
    if dist > bound:
        files = " and ".join(x for x in (mobile.source, fixed.source) if x) or None
        raise InputError(
            f"bodies too far apart: no spring can be a candidate (closest vertices about "
            f"{dist:.4g} mm apart, max_spring_length_mm = {max_spring_length_mm:g})",
            file=files, key=key,
            expected=f"surfaces within about {bound:.4g} mm of each other, in the same "
            "coordinate frame and units",
        )
    return dist


def prepare_surface(
    path: str | Path, *, units: str = "mm", key: str | None = None, name: str = "",
    merge_rel_tol: float = 1e-9, refuse_units: bool = False,
) -> TriangleSurface:
    """Read a mesh file and clean it: the entry point for one scene mesh (docs/method.md#8-built-in-geometries).

    read (:func:`read_surface`) -> unit check (:func:`check_units`) -> clean and orient
    (:func:`clean_surface`). Open patches come back with consistent but not yet globally
    signed normals: call :func:`orient_pair` (or use :func:`prepare_pair`).
    """
    s = read_surface(path, units=units, key=key, name=name)
    check_units(s, units, refuse=refuse_units, key=key)
    return clean_surface(s, key=key, merge_rel_tol=merge_rel_tol)


def prepare_pair(
    mobile_path: str | Path, fixed_path: str | Path, *, units: str = "mm",
    max_spring_length_mm: float | None = None, mobile_key: str | None = "geometry.mobile",
    fixed_key: str | None = "geometry.fixed",
) -> tuple[TriangleSurface, TriangleSurface]:
    """Read, clean and orient the mobile and fixed surfaces of a scene (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs, docs/method.md#8-built-in-geometries).

    Returns ``(mobile, fixed)`` with M's normals towards F and F's towards M. With
    ``max_spring_length_mm`` the bodies are also checked to be close enough for springs. A mesh
    whose size says its unit is wrong (under 1 mm or over 2000 mm across) is refused.
    """
    mobile = prepare_surface(mobile_path, units=units, key=mobile_key, name="mobile", refuse_units=True)
    fixed = prepare_surface(fixed_path, units=units, key=fixed_key, name="fixed", refuse_units=True)
    mobile, fixed = orient_pair(mobile, fixed, mobile_key=mobile_key, fixed_key=fixed_key, near_mm=max_spring_length_mm)
    if max_spring_length_mm is not None:
        check_pair_distance(mobile, fixed, max_spring_length_mm, key="geometry")
    return mobile, fixed
