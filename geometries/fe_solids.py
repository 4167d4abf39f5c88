"""Tetrahedral cartilage solids for the FE reference (docs/method.md#6-the-fe-reference-and-its-discrete-twins).

Two solids are built on the mobile (talus) surface M, both by extruding triangles of M into
prisms along vertex normals and splitting every prism into three tetrahedra (plain numpy; no
mesher needed, every tetrahedron is checked to have positive volume):

* :func:`slab_solid`, the FE twin of the ``threshold`` law: the conforming slab between M's
  candidate surface (triangles with a finite spring length <= h_max) and the tibia. Each bottom
  vertex is moved along its area-weighted vertex normal by a vertex spring length reconstructed
  from the per-triangle lengths (area-weighted linear least-squares fit over the neighbouring
  triangle centroids, so a length field that varies linearly over the surface - the flat plate
  under a tilted plane - is reproduced exactly at every centroid);
* :func:`layer_solid`, the FE twin of the ``gap`` laws: a uniform layer of thickness t offset
  along the vertex normals.

The prism split uses the global vertex numbering (the diagonal of each side quad joins the
lower-numbered vertex at the bottom to the higher-numbered one at the top), so neighbouring
prisms share conforming faces. Physical groups: 1 = bonded face (on the bone, bottom),
2 = contact face (top, towards the tibia), 3 = free faces (sides), 10 = volume.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from geometries.builders.gmsh_session import gmsh_model
from geometries.surface import TriangleSurface, midpoint_subdivision, red_green_subdivision
from geometries.triangle_kernels import triangle_areas


__all__ = [
    "FESolid",
    "BONDED_TAG",
    "CONTACT_TAG",
    "FREE_TAG",
    "VOLUME_TAG",
    "FIXED_BONDED_TAG",
    "FIXED_CONTACT_TAG",
    "FIXED_VOLUME_TAG",
    "pair_solids",
    "slab_solid",
    "layer_solid",
    "vertex_normals",
    "tet_volumes",
]

BONDED_TAG = 1
CONTACT_TAG = 2
FREE_TAG = 3
VOLUME_TAG = 10
#: Two deformable layers in one mesh (:func:`pair_solids`): F's bonded and contact faces and cells
#: (M's keep the tags above)
FIXED_BONDED_TAG = 11
FIXED_CONTACT_TAG = 12
FIXED_VOLUME_TAG = 20
_GROUP_NAMES = {BONDED_TAG: "bonded", CONTACT_TAG: "contact", FREE_TAG: "free",
                VOLUME_TAG: "cartilage", FIXED_BONDED_TAG: "fixed_bonded",
                FIXED_CONTACT_TAG: "fixed_contact", FIXED_VOLUME_TAG: "fixed_cartilage"}


def tet_volumes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volumes of tetrahedra (positive for right-handed (a, b, c, d))."""
    a, b, c, d = (points[tets[:, i]] for i in range(4))
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0


@dataclass(frozen=True)
class FESolid:
    """A tetrahedral solid with tagged boundary triangles (mm).

    ``facets`` are boundary triangles oriented with outward normals; ``facet_tags`` holds
    BONDED_TAG / CONTACT_TAG / FREE_TAG per facet; every tetrahedron has VOLUME_TAG.
    ``bottom_vertex`` maps every point to the point at the bottom of its column (on the bonded
    face; the layer-0 points come first, in the order of the surface's vertices, unless a column
    of zero thickness is one point, :func:`extrude`) and ``layer`` to its layer (0 = bonded face,
    n = contact face; a collapsed column's point is layer n and on both faces).

    Two layers in one solid (:func:`pair_solids`): ``cell_tags`` (VOLUME_TAG for M's,
    FIXED_VOLUME_TAG for F's tetrahedra), F's faces tagged FIXED_BONDED_TAG / FIXED_CONTACT_TAG,
    and ``partner``: per point, the point of the other contact face it is paired with (-1 off
    the paired contact faces).
    """

    points_mm: np.ndarray  # (n, 3)
    tets: np.ndarray  # (m, 4) int64, positive volume
    facets: np.ndarray  # (k, 3) int64
    facet_tags: np.ndarray  # (k,) int32
    name: str = ""
    layer: np.ndarray | None = None  # (n,) int
    bottom_vertex: np.ndarray | None = None  # (n,) int: the point at the bottom of its column
    cell_tags: np.ndarray | None = None  # (m,) int32; None: VOLUME_TAG everywhere
    partner: np.ndarray | None = None  # (n,) int: the paired point of the other contact face, or -1

    @property
    def volumes_mm3(self) -> np.ndarray:
        return tet_volumes(self.points_mm, self.tets)

    def faces(self, tag: int) -> np.ndarray:
        return self.facets[self.facet_tags == tag]

    def volume_tags(self) -> np.ndarray:
        """(m,) int32 tag per tetrahedron: ``cell_tags``, or VOLUME_TAG for a one-body solid."""
        if self.cell_tags is None:
            return np.full(len(self.tets), VOLUME_TAG, dtype=np.int32)
        return np.asarray(self.cell_tags, dtype=np.int32)

    def write_msh(self, path: str | Path) -> Path:
        """Write a gmsh MSH 4.1 file (via the gmsh API, discrete entities) with physical groups
        1 bonded, 2 contact, 3 free (surfaces) and 10 volume, named bonded/contact/free/
        cartilage (a paired solid adds F's 11, 12 and 20)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        with gmsh_model("fe_solid") as gmsh:
            gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
            gmsh.option.setNumber("Mesh.Binary", 0)
            gmsh.option.setNumber("Mesh.SaveAll", 0)
            cell_tags = self.volume_tags()
            vols = {tag: gmsh.model.addDiscreteEntity(3) for tag in np.unique(cell_tags)}
            node_tags = np.arange(1, len(self.points_mm) + 1, dtype=np.int64)
            gmsh.model.mesh.addNodes(3, next(iter(vols.values())), node_tags, self.points_mm.ravel())
            etag = 1
            for tag, vol in vols.items():
                tets = self.tets[cell_tags == tag] + 1
                gmsh.model.mesh.addElementsByType(vol, 4, np.arange(etag, etag + len(tets)), tets.ravel())
                etag += len(tets)
            surf_of_tag = {}
            for tag in sorted({BONDED_TAG, CONTACT_TAG, FREE_TAG} | set(np.unique(self.facet_tags).tolist())):
                tris = self.faces(tag) + 1
                s = gmsh.model.addDiscreteEntity(2)
                surf_of_tag[tag] = s
                if len(tris):
                    gmsh.model.mesh.addElementsByType(s, 2, np.arange(etag, etag + len(tris)),
                                                      tris.ravel())
                    etag += len(tris)
            for tag, s in surf_of_tag.items():
                gmsh.model.addPhysicalGroup(2, [s], tag, name=_GROUP_NAMES.get(tag, ""))
            for tag, vol in vols.items():
                gmsh.model.addPhysicalGroup(3, [vol], int(tag), name=_GROUP_NAMES.get(int(tag), ""))
            gmsh.write(str(path))
        return path

    def to_dolfinx(self, comm: Any = None) -> tuple[Any, Any, Any]:
        """(mesh, cell_tags, facet_tags) as dolfinx objects, built from the arrays.

        The arrays are handed over from rank 0 of ``comm`` (default COMM_WORLD) and distributed
        by dolfinx; cell tags carry :meth:`volume_tags`, facet tags ``facet_tags``.
        """
        import dolfinx_solver  # noqa: F401  (orders MPI ahead of the dolfinx bindings)

        import basix.ufl
        import dolfinx.graph
        import dolfinx.io
        import dolfinx.mesh
        import ufl
        from dolfinx.io.utils import distribute_entity_data
        from mpi4py import MPI

        comm = MPI.COMM_WORLD if comm is None else comm
        domain = ufl.Mesh(basix.ufl.element("Lagrange", "tetrahedron", 1, shape=(3,)))
        if comm.rank == 0:
            cells = np.ascontiguousarray(self.tets, dtype=np.int64)
            x = np.ascontiguousarray(self.points_mm, dtype=np.float64)
            facets = np.ascontiguousarray(self.facets, dtype=np.int64)
            fvals = np.asarray(self.facet_tags, dtype=np.int32)
            cvals = self.volume_tags()
        else:
            cells = np.empty((0, 4), dtype=np.int64)
            x = np.empty((0, 3), dtype=np.float64)
            facets = np.empty((0, 3), dtype=np.int64)
            fvals = np.empty((0,), dtype=np.int32)
            cvals = np.empty((0,), dtype=np.int32)
        mesh = dolfinx.mesh.create_mesh(comm, cells, domain, x)  # default partitioner
        tdim = mesh.topology.dim
        tags = []
        for dim, ents, vals in ((tdim, cells, cvals), (tdim - 1, facets, fvals)):
            mesh.topology.create_connectivity(dim, tdim)
            local_e, local_v = distribute_entity_data(mesh, dim, ents, vals)
            adj = dolfinx.graph.adjacencylist(local_e)
            mt = dolfinx.mesh.meshtags_from_entities(mesh, dim, adj, local_v.astype(np.int32))
            mt.name = "cell_tags" if dim == tdim else "facet_tags"
            tags.append(mt)
        return mesh, tags[0], tags[1]


# --------------------------------------------------------------------------------------------
# construction helpers
# --------------------------------------------------------------------------------------------


def submesh(surface: TriangleSurface, mask: np.ndarray,
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    tris = np.asarray(surface.triangles, dtype=np.int64)[mask]
    used = np.unique(tris)
    remap = np.full(len(surface.vertices_mm), -1, dtype=np.int64)
    remap[used] = np.arange(used.size)
    verts = np.asarray(surface.vertices_mm, dtype=np.float64)[used]
    return verts, remap[tris], np.flatnonzero(mask)


def vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area-weighted average of the adjacent triangle normals, normalised, per vertex."""
    a, b, c = vertices[triangles[:, 0]], vertices[triangles[:, 1]], vertices[triangles[:, 2]]
    av = np.cross(b - a, c - a)  # 2 * area * unit normal
    n = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(n, triangles[:, k], av)
    norm = np.linalg.norm(n, axis=1)
    if np.any(norm == 0):
        raise ValueError("a vertex has no well-defined normal (degenerate neighbourhood)")
    return n / norm[:, None]


def _vertex_values(vertices: np.ndarray, triangles: np.ndarray, values: np.ndarray,
                   normals: np.ndarray) -> np.ndarray:
    """Per-vertex values from per-triangle values (given at centroids).

    Area-weighted least-squares fit of a linear function over the centroids of the triangles
    around each vertex (1-ring, widened to the 2-ring where the 1-ring centroids do not span the
    tangent plane), evaluated at the vertex: exact for fields linear over a flat surface.
    """
    nv = len(vertices)
    cent = vertices[triangles].mean(axis=1)
    area = triangle_areas(*(vertices[triangles[:, k]] for k in range(3)))
    # vertex -> triangles (CSR)
    vt = np.repeat(np.arange(len(triangles)), 3)
    vv = triangles.ravel()
    order = np.argsort(vv, kind="stable")
    vt, vv = vt[order], vv[order]
    start = np.searchsorted(vv, np.arange(nv + 1))
    ring1 = [vt[start[i]:start[i + 1]] for i in range(nv)]
    out = np.empty(nv)
    for i in range(nv):
        tris = ring1[i]
        for ring in (1, 2, 3):
            n = normals[i]
            # tangent basis
            t1 = np.cross(n, [1.0, 0.0, 0.0])
            if np.linalg.norm(t1) < 0.3:
                t1 = np.cross(n, [0.0, 1.0, 0.0])
            t1 /= np.linalg.norm(t1)
            t2 = np.cross(n, t1)
            d = cent[tris] - vertices[i]
            A = np.column_stack([np.ones(len(tris)), d @ t1, d @ t2])
            w = np.sqrt(area[tris])
            Aw = A * w[:, None]
            s = np.linalg.svd(Aw, compute_uv=False) if len(tris) >= 3 else np.zeros(1)
            if len(tris) >= 3 and s[-1] > 1e-8 * s[0]:
                coef = np.linalg.lstsq(Aw, values[tris] * w, rcond=None)[0]
                out[i] = coef[0]
                break
            if ring == 3:
                out[i] = float(np.average(values[tris], weights=area[tris]))
                break
            verts = np.unique(triangles[tris])
            tris = np.unique(np.concatenate([ring1[v] for v in verts]))
    return out


def inverted_prisms(vertices: np.ndarray, triangles: np.ndarray, normals: np.ndarray,
                     thickness: np.ndarray) -> np.ndarray:
    """(n_tri,) bool: the triangles whose one-layer prism along the vertex normals has a
    tetrahedron of non-positive volume (the extrusion turns inside out there). A column of zero
    thickness is one point (:func:`extrude`): the tetrahedron through both its ends is not built,
    so it is not checked."""
    nv = len(vertices)
    points = np.vstack([vertices, vertices + thickness[:, None] * normals])
    srt = np.sort(triangles, axis=1)
    a, b, c = srt[:, 0], srt[:, 1], srt[:, 2]
    ta, tb, tc = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    even = ((ta == a) & (tb == b)) | ((tb == a) & (tc == b)) | ((tc == a) & (ta == b))
    collapsed = np.asarray(thickness) == 0.0
    bad = np.zeros(len(triangles), dtype=bool)
    # each of the three tetrahedra holds both ends of one column: c's, b's, a's
    for t, column in ((np.column_stack([a, b, c, c + nv]), c), (np.column_stack([a, b, c + nv, b + nv]), b),
                      (np.column_stack([a, b + nv, c + nv, a + nv]), a)):
        t[~even] = t[~even][:, [1, 0, 2, 3]]
        bad |= (tet_volumes(points, t) <= 0) & ~collapsed[column]
    return bad


def rim_triangles(triangles: np.ndarray) -> np.ndarray:
    """(n_tri,) bool: triangles with an edge no other triangle shares (the surface's rim)."""
    edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
    _, inverse, counts = np.unique(edges, axis=0, return_inverse=True, return_counts=True)
    once = counts[inverse.ravel()] == 1
    return once.reshape(3, -1).any(axis=0)


def _lean_deg(vertices: np.ndarray, triangles: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(n_tri,) largest angle between a triangle's normal and the vertex normals at its corners."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1)[:, None]
    cos = np.min(np.einsum("ikj,ij->ik", normals[triangles], n), axis=1)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _trim_inverting_rim(name: str, surface: TriangleSurface, mask: np.ndarray, thickness_of,
                        max_rounds: int = 4) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The submesh of ``mask`` with its vertex normals and thicknesses, without the rim
    triangles whose prisms would turn inside out.

    Real (segmented) surfaces end in sliver rim triangles whose vertex normals lean far from
    their own (61 deg on an MRI knee): extruded along those normals their prisms invert. Such
    rim triangles are dropped (warned, with their number and lean), repeatedly, since dropping
    makes a new rim. An inverting prism inside the surface cannot be dropped without a hole:
    ValueError naming those triangles (indices of ``surface``) and their lean.
    ``thickness_of(vertices, triangles, triangle_index, normals)`` gives the per-vertex thickness.
    Returns (vertices, triangles, triangle_index, normals, thickness).
    """
    dropped: list[np.ndarray] = []
    worst = 0.0
    keep = mask.copy()
    for _ in range(max_rounds + 1):
        verts, tris, tri_index = submesh(surface, keep)
        normals = vertex_normals(verts, tris)
        thickness = thickness_of(verts, tris, tri_index, normals)
        bad = inverted_prisms(verts, tris, normals, thickness)
        if not bad.any():
            break
        lean = _lean_deg(verts, tris, normals)
        rim = bad & rim_triangles(tris)  # dropped first: their neighbours' normals change with them
        if not rim.any() or len(dropped) == max_rounds:
            which = tri_index[bad]
            raise ValueError(
                f"{name}: the prisms over {which.size} triangles turn inside out when extruded along the vertex "
                f"normals (triangles {', '.join(str(int(i)) for i in which[:12])}{', ...' if which.size > 12 else ''} "
                f"of the mobile surface; their vertex normals lean up to {float(lean[bad].max()):.0f} deg "
                "from their own): smooth or remesh the surface there, or use a thinner layer")
        worst = max(worst, float(lean[rim].max()))
        dropped.append(tri_index[rim])
        keep[tri_index[rim]] = False
        if not keep.any():
            raise ValueError(f"{name}: every triangle's prism turns inside out along the vertex normals")
    if dropped:
        count = int(sum(d.size for d in dropped))
        warnings.warn(
            f"{name}: {count} rim triangles dropped from the FE solid (triangles "
            f"{', '.join(str(int(i)) for i in np.concatenate(dropped)[:12])}{', ...' if count > 12 else ''}): their "
            f"vertex normals lean up to {worst:.0f} deg from their own, so their prisms would turn inside out",
            stacklevel=3,
        )
    return verts, tris, tri_index, normals, thickness


def boundary_facets(tets: np.ndarray) -> np.ndarray:
    """(k, 3) the faces used by exactly one tetrahedron, oriented outward (the tetrahedra
    right-handed: positive volume)."""
    faces = np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 3, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 1]]])
    _, inv, counts = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=True, return_counts=True)
    return faces[counts[inv.ravel()] == 1]


def pair_solids(mobile: FESolid, fixed: FESolid, partner: np.ndarray, name: str = "") -> FESolid:
    """M's and F's layers in one solid (two disconnected regions), their contact faces paired
    point to point (docs/method.md#two-deformable-layers).

    ``partner`` (n_mobile_points,): per point of ``mobile``, the point of ``fixed`` it faces
    (-1: none). A contact triangle of M stays a contact face (CONTACT_TAG) when its three
    partners are a contact triangle of F (the same connectivity: the pairing is DOF to DOF); the
    other contact triangles of either body become free faces. F's faces are retagged
    FIXED_BONDED_TAG / FIXED_CONTACT_TAG, its tetrahedra FIXED_VOLUME_TAG; other tags (rollers)
    are kept. ValueError when no contact triangle is paired.
    """
    n_m = len(mobile.points_mm)
    partner = np.asarray(partner, dtype=np.int64).reshape(-1)
    if partner.shape != (n_m,):
        raise ValueError(f"pair_solids: partner has {partner.size} entries for {n_m} points")
    m_tags = np.asarray(mobile.facet_tags).copy()
    f_tags = np.asarray(fixed.facet_tags).copy()
    m_contact = np.flatnonzero(m_tags == CONTACT_TAG)
    f_contact = np.flatnonzero(f_tags == CONTACT_TAG)
    images = partner[mobile.facets[m_contact]]
    f_keys = {tuple(k): i for i, k in zip(f_contact, np.sort(fixed.facets[f_contact], axis=1).tolist())}
    matched = np.array([np.all(img >= 0) and tuple(sorted(img.tolist())) in f_keys for img in images], dtype=bool)
    if not matched.any():
        raise ValueError("pair_solids: no contact triangle of the mobile layer faces one of the fixed layer")
    kept_f = np.array([f_keys[tuple(sorted(img.tolist()))] for img in images[matched]], dtype=np.int64)
    m_tags[m_contact[~matched]] = FREE_TAG
    f_new = np.where(f_tags == BONDED_TAG, FIXED_BONDED_TAG, np.where(f_tags == CONTACT_TAG, FREE_TAG, f_tags))
    f_new[kept_f] = FIXED_CONTACT_TAG
    paired = np.unique(mobile.facets[m_contact[matched]])
    both = np.full(n_m + len(fixed.points_mm), -1, dtype=np.int64)
    both[paired] = n_m + partner[paired]
    both[n_m + partner[paired]] = paired

    def joined(a: np.ndarray | None, b: np.ndarray | None, offset: int = 0) -> np.ndarray | None:
        return None if a is None or b is None else np.concatenate([a, np.asarray(b) + offset])

    return FESolid(
        points_mm=np.vstack([mobile.points_mm, fixed.points_mm]),
        tets=np.vstack([mobile.tets, fixed.tets + n_m]),
        facets=np.vstack([mobile.facets, fixed.facets + n_m]),
        facet_tags=np.concatenate([m_tags, f_new]).astype(np.int32),
        name=name or f"{mobile.name}+{fixed.name}",
        layer=joined(mobile.layer, fixed.layer),
        bottom_vertex=joined(mobile.bottom_vertex, fixed.bottom_vertex, n_m),
        cell_tags=np.concatenate([mobile.volume_tags(), np.full(len(fixed.tets), FIXED_VOLUME_TAG, dtype=np.int32)]),
        partner=both,
    )


def extrude(name: str, bottom: np.ndarray, triangles: np.ndarray, normals: np.ndarray,
             thickness: np.ndarray, layers: int) -> FESolid:
    """Prisms from ``bottom + k/layers * thickness * normal``, 3 tetrahedra each.

    A vertex of thickness exactly 0 (a layer tapered to zero on its bone) has no column: its
    copies are one point (the top one, on both the bonded and the contact face), and the
    tetrahedra through two of them, which would be flat, are not built: a prism with such a
    corner is a pyramid of two tetrahedra (three: one), so the solid follows the layer down to
    nothing at its margin. ``bottom_vertex`` of the result is, per point, the point at the bottom
    of its column (itself for a collapsed one)."""
    nv = len(bottom)
    thickness = np.asarray(thickness, dtype=float)
    if np.any(~np.isfinite(thickness)) or np.any(thickness < 0) or not np.any(thickness > 0):
        raise ValueError(f"{name}: negative or non-finite thickness at a vertex, or none above zero")
    frac = np.arange(layers + 1) / layers
    pts = bottom[None, :, :] + frac[:, None, None] * (thickness[:, None] * normals)[None, :, :]
    pts = pts.reshape(-1, 3)
    layer = np.repeat(np.arange(layers + 1), nv)
    base = np.tile(np.arange(nv), layers + 1)

    # sort each triangle's vertices by index; the parity of that permutation tells whether the
    # sorted triangle is still oriented like the surface (normal towards the top)
    srt = np.sort(triangles, axis=1)
    a, b, c = srt[:, 0], srt[:, 1], srt[:, 2]
    ta, tb, tc = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    # the sorted order is an even permutation of the original iff it is one of its rotations
    even = ((ta == a) & (tb == b)) | ((tb == a) & (tc == b)) | ((tc == a) & (ta == b))
    tets = []
    for k in range(layers):
        lo, hi = k * nv, (k + 1) * nv
        A0, B0, C0 = a + lo, b + lo, c + lo
        A1, B1, C1 = a + hi, b + hi, c + hi
        # diagonals: (a0-b1), (b0-c1), (a0-c1)
        t1 = np.column_stack([A0, B0, C0, C1])
        t2 = np.column_stack([A0, B0, C1, B1])
        t3 = np.column_stack([A0, B1, C1, A1])
        for t in (t1, t2, t3):
            t = t.copy()
            # (a0, b0, c0, top) is right-handed iff (a, b, c) is oriented like the surface
            t[~even] = t[~even][:, [1, 0, 2, 3]]
            tets.append(t)
    tets = np.concatenate(tets)
    bottom_point = base.copy()  # the layer-0 copy of each point's column
    collapsed = thickness == 0.0
    both_faces = np.zeros(len(pts), bool)
    if collapsed.any():
        # every copy of a collapsed column is its top one; the flat tetrahedra through two go, and the
        # unused copies with them (points renumbered)
        merged = np.where(collapsed[base], layers * nv + base, np.arange(len(pts)))
        tets = merged[tets]
        s = np.sort(tets, axis=1)
        tets = tets[np.all(s[:, 1:] != s[:, :-1], axis=1)]
        used = np.unique(tets)
        renumber = np.full(len(pts), -1, dtype=np.int64)
        renumber[used] = np.arange(used.size)
        pts, layer, tets = pts[used], layer[used], renumber[tets]
        bottom_point = renumber[merged[base[used]]]
        both_faces = collapsed[base[used]]
    vol = tet_volumes(pts, tets)
    if not np.all(vol > 0):
        bad = int(np.sum(vol <= 0))
        raise ValueError(f"{name}: {bad} tetrahedra with non-positive volume (surface too curved "
                         "for this thickness, or inconsistent orientation)")

    bnd = boundary_facets(tets)
    lay, ends = layer[bnd], both_faces[bnd]
    tags = np.full(len(bnd), FREE_TAG, dtype=np.int32)
    tags[np.all((lay == 0) | ends, axis=1)] = BONDED_TAG
    tags[np.all((lay == layers) | ends, axis=1)] = CONTACT_TAG
    order = np.lexsort((np.arange(len(bnd)), tags))
    return FESolid(
        points_mm=pts, tets=np.ascontiguousarray(tets, dtype=np.int64),
        facets=np.ascontiguousarray(bnd[order], dtype=np.int64), facet_tags=tags[order],
        name=name, layer=layer, bottom_vertex=bottom_point,
    )


def refine(vertices: np.ndarray, triangles: np.ndarray, vertex_fields: list[np.ndarray],
           levels: int, contact: "ContactRefinement | None" = None) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Midpoint subdivision (1 -> 4) ``levels`` times, then where ``contact`` asks, its further
    levels on the triangles that can reach the other body (red-green closure around them:
    :func:`geometries.surface.red_green_subdivision`). Fields are interpolated linearly; vector
    fields renormalised when they are unit normals (shape (n, 3))."""
    fine = np.zeros(len(triangles), bool) if contact is None else contact.triangles(vertices, triangles)
    for _ in range(levels):
        triangles, pairs = midpoint_subdivision(triangles, len(vertices))
        fine = np.repeat(fine, 4)  # child k of triangle i is row 4 i + k
        vertices, vertex_fields = _with_midpoints(vertices, vertex_fields, pairs)
    local = contact.levels_beyond(levels, vertices, triangles) if contact is not None and fine.any() else 0
    green = np.zeros(len(triangles), bool)
    for level in range(local):
        # Each pass marks the reach grown by two rings of its triangles per pass still to come, so a
        # pass's marked triangles lie at least two of the last pass's rings inside its marked ones,
        # away from its bisected (green) border, and the finest size covers the reach itself.
        marked = _grown(fine, triangles, 2 * (local - 1 - level))
        triangles, pairs, parent, green = red_green_subdivision(triangles, len(vertices), marked, green)
        fine = fine[parent]  # the reach's triangles' children (all of them split 1 -> 4)
        vertices, vertex_fields = _with_midpoints(vertices, vertex_fields, pairs)
    return vertices, triangles, vertex_fields


def _grown(mask: np.ndarray, triangles: np.ndarray, rings: int) -> np.ndarray:
    """(n,) bool: ``mask`` grown by ``rings`` rings of triangles (sharing a vertex)."""
    for _ in range(rings):
        touched = np.zeros(int(triangles.max()) + 1, bool)
        touched[triangles[mask]] = True
        mask = touched[triangles].any(axis=1)
    return mask


def _with_midpoints(vertices: np.ndarray, vertex_fields: list[np.ndarray], pairs: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """The vertices and fields with the midpoints of the edges ``pairs`` (e, 2) appended."""
    fields = []
    for f in vertex_fields:
        mid = 0.5 * (f[pairs[:, 0]] + f[pairs[:, 1]])
        if f.ndim == 2:
            mid /= np.linalg.norm(mid, axis=1)[:, None]
        fields.append(np.concatenate([f, mid]))
    return np.vstack([vertices, 0.5 * (vertices[pairs[:, 0]] + vertices[pairs[:, 1]])]), fields


@dataclass(frozen=True)
class ContactRefinement:
    """A finer surface where the contact can reach: the triangles with a vertex that ``reaches``
    are subdivided until their edges are at most ``mesh_size_mm`` (the rest keep the solid's
    mesh size), with a conforming red-green transition around them."""

    mesh_size_mm: float
    #: ``reaches(vertices (k, 3) mm) -> (k,) bool``: where the contact can reach
    reaches: Any

    def triangles(self, vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
        """(n,) bool: the triangles to refine (a vertex of theirs reaches)."""
        return np.asarray(self.reaches(vertices), bool)[triangles].any(axis=1)

    def levels_beyond(self, levels: int, vertices: np.ndarray, triangles: np.ndarray) -> int:
        """Local levels after ``levels`` uniform ones (the surface then at hand) to reach the size."""
        return levels_for(self.mesh_size_mm, vertices, triangles)


def mean_edge(vertices: np.ndarray, triangles: np.ndarray) -> float:
    e = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    return float(np.mean(np.linalg.norm(vertices[e[:, 0]] - vertices[e[:, 1]], axis=1)))


def levels_for(size: float | None, vertices: np.ndarray, triangles: np.ndarray) -> int:
    if size is None:
        return 0
    h = mean_edge(vertices, triangles)
    return max(0, int(math.ceil(math.log2(h / size) - 1e-9))) if h > size else 0


def layers_for(layers: int | None, max_thickness: float, size: float) -> int:
    if layers is not None:
        if int(layers) < 1:
            raise ValueError("layers_through_thickness must be >= 1")
        return int(layers)
    return max(1, int(math.ceil(max_thickness / size - 1e-9)))


# --------------------------------------------------------------------------------------------
# public builders
# --------------------------------------------------------------------------------------------


def slab_solid(
    mobile: TriangleSurface,
    spring_length_mm: np.ndarray,
    max_spring_length_mm: float,
    mesh_size_mm: float | None = None,
    layers_through_thickness: int | None = None,
) -> FESolid:
    """Conforming cartilage slab between M's candidate surface and the tibia (docs/method.md#6-the-fe-reference-and-its-discrete-twins).

    Candidates are M's triangles with a finite spring length 0 < h <= ``max_spring_length_mm``
    (``spring_length_mm`` has one entry per triangle of ``mobile``; ``inf``/``nan`` = no hit).
    Each candidate-surface vertex is moved along its area-weighted vertex normal by the
    reconstructed vertex length (see the module docstring); the slab is split into
    ``layers_through_thickness`` layers (default: ceil(h_max_found / mesh size)). With
    ``mesh_size_mm`` smaller than the surface's mean edge length the candidate surface is first
    midpoint-subdivided (lengths and normals interpolated linearly) until its edges are about
    ``mesh_size_mm`` long. ``bottom_vertex`` of the result indexes the candidate submesh.
    """
    h = np.asarray(spring_length_mm, dtype=np.float64).reshape(-1)
    if h.shape[0] != mobile.n_triangles:
        raise ValueError(
            f"spring_length_mm has {h.shape[0]} values for {mobile.n_triangles} triangles")
    with np.errstate(invalid="ignore"):
        mask = np.isfinite(h) & (h > 0) & (h <= max_spring_length_mm) & (mobile.areas_mm2 > 0)
    if not np.any(mask):
        raise ValueError("slab_solid: no candidate spring (no finite length <= h_max)")

    def thickness_of(verts, tris, tri_index, normals):
        hv = _vertex_values(verts, tris, h[tri_index], normals)
        # an extrapolated vertex value may undershoot near a touching point: keep it positive
        return np.maximum(hv, 0.25 * float(np.min(h[tri_index])))

    verts, tris, tri_index, normals, hv = _trim_inverting_rim("slab", mobile, mask, thickness_of)
    size = mesh_size_mm if mesh_size_mm is not None else mean_edge(verts, tris)
    levels = levels_for(mesh_size_mm, verts, tris)
    verts, tris, (normals, hv) = refine(verts, tris, [normals, hv], levels)
    nl = layers_for(layers_through_thickness, float(hv.max()), size)
    return extrude("slab", verts, tris, normals, hv, nl)


def layer_solid(
    mobile: TriangleSurface,
    thickness_mm: float,
    mesh_size_mm: float | None = None,
    layers_through_thickness: int | None = None,
    contact: ContactRefinement | None = None,
) -> FESolid:
    """Uniform cartilage layer of thickness t bonded to the whole mobile surface (docs/method.md#6-the-fe-reference-and-its-discrete-twins).

    Every vertex of M is offset along its area-weighted vertex normal by ``thickness_mm``
    (exactly t at the vertices); layers default to ceil(t / mesh size); the surface is
    midpoint-subdivided first when ``mesh_size_mm`` is below its mean edge length, and further
    where ``contact`` reaches (:class:`ContactRefinement`, judged on M's vertices).
    """
    t = float(thickness_mm)
    if not (math.isfinite(t) and t > 0):
        raise ValueError("layer_solid: thickness_mm must be a positive number")
    mask = mobile.areas_mm2 > 0
    verts, tris, _, normals, _ = _trim_inverting_rim("layer", mobile, mask, lambda v, *_: np.full(len(v), t))
    size = mesh_size_mm if mesh_size_mm is not None else mean_edge(verts, tris)
    levels = levels_for(mesh_size_mm, verts, tris)
    verts, tris, (normals,) = refine(verts, tris, [normals], levels, contact)
    nl = layers_for(layers_through_thickness, t, size)
    return extrude("layer", verts, tris, normals, np.full(len(verts), t), nl)
