"""Small tagged tetrahedral meshes for FE verification (dolfinx create_box or gmsh).

Facet tags: 1 bonded, 2 contact, 3 free, 4/5/6 zero x/y/z displacement (roller or symmetry).
Builders take the MPI communicator and return an :class:`~fem_reference.problem.FEMesh`; gmsh
models are built on rank 0 and distributed. dolfinx/gmsh are imported inside the functions.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from fem_reference.problem import TAG_ROLLER_X, TAG_ROLLER_Y, FEMesh
from geometries.fe_solids import BONDED_TAG, CONTACT_TAG, FREE_TAG


def _dolfinx() -> Any:
    import dolfinx_solver  # noqa: F401
    import dolfinx
    import dolfinx.mesh

    return dolfinx


def box_slab(comm: Any, lx: float, ly: float, thickness: float, n: tuple[int, int, int], *,
             confined: bool = True, quarter: bool = False) -> FEMesh:
    """Slab [0, lx] x [0, ly] x [0, thickness]: bonded bottom (z = 0), contact top, lateral faces
    on rollers (tags 4 for x faces, 5 for y faces) when ``confined`` else free (tag 3).

    ``quarter`` (with ``confined=False``): the quarter x, y >= 0 of a free slab twice as wide;
    symmetry planes x = 0 (tag 4) and y = 0 (tag 5), faces x = lx and y = ly free (tag 3)."""
    if quarter and confined:
        raise ValueError("quarter slabs have free outer faces: pass confined=False")
    dolfinx = _dolfinx()
    mesh = dolfinx.mesh.create_box(comm, [np.zeros(3), np.array([lx, ly, thickness])], list(n),
                                   cell_type=dolfinx.mesh.CellType.tetrahedron)
    fdim = 2
    tol = 1e-9 * max(lx, ly, thickness)
    markers = [
        (BONDED_TAG, lambda x: np.isclose(x[2], 0.0, atol=tol)),
        (CONTACT_TAG, lambda x: np.isclose(x[2], thickness, atol=tol)),
    ]
    if quarter:
        markers += [
            (TAG_ROLLER_X, lambda x: np.isclose(x[0], 0.0, atol=tol)),
            (TAG_ROLLER_Y, lambda x: np.isclose(x[1], 0.0, atol=tol)),
            (FREE_TAG, lambda x: np.isclose(x[0], lx, atol=tol) | np.isclose(x[1], ly, atol=tol)),
        ]
        return FEMesh(mesh, _tag_facets(dolfinx, mesh, fdim, markers))
    # one marker per plane: with one cell across, every vertex of a y face lies on x = 0 or
    # x = lx, so a marker "x = 0 or x = lx" would take the y faces too
    markers += [(TAG_ROLLER_X if confined else FREE_TAG, lambda x, c=c: np.isclose(x[0], c, atol=tol)) for c in (0.0, lx)]
    markers += [(TAG_ROLLER_Y if confined else FREE_TAG, lambda x, c=c: np.isclose(x[1], c, atol=tol)) for c in (0.0, ly)]
    return FEMesh(mesh, _tag_facets(dolfinx, mesh, fdim, markers))


def _tag_facets(dolfinx: Any, mesh: Any, fdim: int, markers: list) -> Any:
    """Facet tags from (tag, marker) pairs; earlier pairs win where facets match several."""
    mesh.topology.create_connectivity(fdim, fdim + 1)
    idx, val = [], []
    seen: set[int] = set()
    for tag, marker in markers:
        facets = dolfinx.mesh.locate_entities_boundary(mesh, fdim, marker)
        new = np.array([f for f in facets if f not in seen], dtype=np.int32)
        seen.update(int(f) for f in new)
        idx.append(new)
        val.append(np.full(len(new), tag, dtype=np.int32))
    i = np.concatenate(idx)
    v = np.concatenate(val)
    order = np.argsort(i)
    return dolfinx.mesh.meshtags(mesh, fdim, i[order], v[order])


_GMSH_OPTIONS = ("General.Terminal", "Mesh.MeshSizeExtendFromBoundary",
                 "Mesh.MeshSizeFromPoints", "Mesh.MeshSizeFromCurvature")


def _gmsh_start() -> Any:
    import gmsh

    if not gmsh.isInitialized():
        gmsh.initialize(interruptible=False)
    return gmsh


def _gmsh_to_dolfinx(comm: Any, gmsh: Any, build: Any) -> FEMesh:
    """Run ``build(gmsh)`` on rank 0 in a model of its own (it creates the tagged model; global
    gmsh options it changes are restored), distribute the mesh over ``comm``."""
    _dolfinx()
    import dolfinx.io.gmsh as dgmsh

    saved = {}
    if comm.rank == 0:
        saved = {k: gmsh.option.getNumber(k) for k in _GMSH_OPTIONS}
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add(f"fem_reference_{np.random.randint(1 << 30)}")
        try:
            build(gmsh)
        except Exception:
            gmsh.model.remove()
            for k, v in saved.items():
                gmsh.option.setNumber(k, v)
            raise
    try:
        data = dgmsh.model_to_mesh(gmsh.model, comm, 0, gdim=3)
    finally:
        if comm.rank == 0:
            gmsh.model.remove()
            for k, v in saved.items():
                gmsh.option.setNumber(k, v)
    return FEMesh(data.mesh, data.facet_tags, data.cell_tags)


def _surfaces_in_box(gmsh: Any, lo: tuple, hi: tuple, eps: float) -> list[int]:
    ents = gmsh.model.getEntitiesInBoundingBox(lo[0] - eps, lo[1] - eps, lo[2] - eps,
                                               hi[0] + eps, hi[1] + eps, hi[2] + eps, 2)
    return [t for _, t in ents]


def hertz_block(comm: Any, *, width: float, height: float, slice_thickness: float,
                size_contact: float, size_far: float, fine_radius: float,
                coarse_radius: float | None = None, half: bool = True) -> FEMesh:
    """Half of a plane-strain block for Hertz line contact, as a one-element-thick 3D slice.

    Block x in [0, width], y in [0, slice_thickness], z in [0, height]; bonded bottom (tag 1),
    contact top (tag 2), symmetry plane x = 0 (tag 4), plane-strain faces y = 0 and
    y = slice_thickness (tag 5), free side x = width (tag 3). Element size ``size_contact``
    within ``fine_radius`` of the top corner (0, 0, height), growing to ``size_far`` at
    ``coarse_radius``. ``half=False``: the whole block x in [-width, width] (both sides free).
    """
    gmsh = _gmsh_start()
    rc = coarse_radius if coarse_radius is not None else 0.5 * max(width, height)

    def build(g: Any) -> None:
        geo = g.model.geo
        x0 = 0.0 if half else -width
        corners = [(x0, 0.0), (width, 0.0), (width, height)]
        corners += [(0.0, height)] if half else [(0.0, height), (x0, height)]
        p = [geo.addPoint(cx, 0, cz) for cx, cz in corners]
        lines = [geo.addLine(p[i], p[(i + 1) % len(p)]) for i in range(len(p))]
        centre = p[3]  # top centre (0, 0, height): refine around it
        surf = geo.addPlaneSurface([geo.addCurveLoop(lines)])
        geo.extrude([(2, surf)], 0, slice_thickness, 0, numElements=[1], recombine=False)
        geo.synchronize()
        f_dist = g.model.mesh.field.add("Distance")
        g.model.mesh.field.setNumbers(f_dist, "PointsList", [centre])
        f_thr = g.model.mesh.field.add("Threshold")
        g.model.mesh.field.setNumber(f_thr, "InField", f_dist)
        g.model.mesh.field.setNumber(f_thr, "SizeMin", size_contact)
        g.model.mesh.field.setNumber(f_thr, "SizeMax", size_far)
        g.model.mesh.field.setNumber(f_thr, "DistMin", fine_radius)
        g.model.mesh.field.setNumber(f_thr, "DistMax", rc)
        g.model.mesh.field.setAsBackgroundMesh(f_thr)
        g.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
        g.option.setNumber("Mesh.MeshSizeFromPoints", 0)
        g.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        eps = 1e-6 * max(width, height)
        t = slice_thickness
        vols = [tag for _, tag in g.model.getEntities(3)]
        g.model.addPhysicalGroup(3, vols, 1)
        g.model.addPhysicalGroup(2, _surfaces_in_box(g, (x0, 0, 0), (width, t, 0), eps),
                                 BONDED_TAG)
        g.model.addPhysicalGroup(2, _surfaces_in_box(g, (x0, 0, height), (width, t, height), eps),
                                 CONTACT_TAG)
        sides = _surfaces_in_box(g, (width, 0, 0), (width, t, height), eps)
        if half:
            g.model.addPhysicalGroup(2, _surfaces_in_box(g, (0, 0, 0), (0, t, height), eps),
                                     TAG_ROLLER_X)
        else:
            sides += _surfaces_in_box(g, (x0, 0, 0), (x0, t, height), eps)
        g.model.addPhysicalGroup(2, sides, FREE_TAG)
        g.model.addPhysicalGroup(2, _surfaces_in_box(g, (x0, 0, 0), (width, 0, height), eps)
                                 + _surfaces_in_box(g, (x0, t, 0), (width, t, height), eps),
                                 TAG_ROLLER_Y)
        g.model.mesh.generate(3)

    return _gmsh_to_dolfinx(comm, gmsh, build)


def cylinder_layer_quarter(comm: Any, *, bone_radius: float = 20.0, thickness: float = 2.0,
                           length: float = 30.0, half_angle_deg: float = 30.0,
                           n_radial: int = 2, n_arc: int = 20, arc_progression: float = 1.08,
                           n_length: int = 15, half_length: bool = True) -> FEMesh:
    """Quarter of a cylindrical layer (bone radius R, layer thickness t, length L) bonded on the
    bone, its outer surface touching the plane z = 0 at the bottom line x = 0.

    Cylinder axis along y at (x, z) = (0, R + t). Modelled part: x >= 0 (symmetry plane x = 0,
    tag 4) and y in [0, L/2] (mid-length symmetry plane y = L/2, tag 5; free end y = 0, tag 3),
    arc from the bottom up to ``half_angle_deg`` (end face free, tag 3). Bonded inner surface
    tag 1, contact outer surface tag 2. Structured: ``n_radial`` x ``n_arc`` (sizes growing by
    ``arc_progression`` away from the bottom) triangulated quads, extruded in ``n_length``
    layers. Loads on this model are a quarter of the full-cylinder load. With
    ``half_length=False`` the whole length y in [0, L] is modelled (both ends free; half load).
    """
    gmsh = _gmsh_start()
    ri, ro = bone_radius, bone_radius + thickness
    zc = ro
    th = math.radians(half_angle_deg)

    def build(g: Any) -> None:
        geo = g.model.geo
        c = geo.addPoint(0, 0, zc)
        pi0 = geo.addPoint(0, 0, zc - ri)
        po0 = geo.addPoint(0, 0, zc - ro)
        pi1 = geo.addPoint(ri * math.sin(th), 0, zc - ri * math.cos(th))
        po1 = geo.addPoint(ro * math.sin(th), 0, zc - ro * math.cos(th))
        arc_in = geo.addCircleArc(pi0, c, pi1)
        arc_out = geo.addCircleArc(po0, c, po1)
        rad0 = geo.addLine(po0, pi0)
        rad1 = geo.addLine(pi1, po1)
        loop = geo.addCurveLoop([arc_out, -rad1, -arc_in, -rad0])
        surf = geo.addPlaneSurface([loop])
        geo.mesh.setTransfiniteCurve(arc_in, n_arc + 1, "Progression", arc_progression)
        geo.mesh.setTransfiniteCurve(arc_out, n_arc + 1, "Progression", arc_progression)
        geo.mesh.setTransfiniteCurve(rad0, n_radial + 1)
        geo.mesh.setTransfiniteCurve(rad1, n_radial + 1)
        geo.mesh.setTransfiniteSurface(surf)
        ly = length / 2.0 if half_length else length
        geo.extrude([(2, surf)], 0, ly, 0, numElements=[n_length], recombine=False)
        geo.synchronize()
        vols = [tag for _, tag in g.model.getEntities(3)]
        g.model.addPhysicalGroup(3, vols, 1)
        bonded, contact, xsym, ysym, free = [], [], [], [], []
        for _, s in g.model.getEntities(2):
            xmin, ymin, zmin, xmax, ymax, zmax = g.model.getBoundingBox(2, s)
            tol = 1e-3 * thickness
            if xmax < tol:
                xsym.append(s)
            elif ymin > ly - tol:
                (ysym if half_length else free).append(s)
            elif ymax < tol:
                free.append(s)
            elif zmin < tol:
                contact.append(s)  # only the outer surface reaches z = 0
            elif abs(zmin - (zc - ri)) < tol:
                bonded.append(s)
            else:
                free.append(s)  # end face at the arc's half-angle
        g.model.addPhysicalGroup(2, bonded, BONDED_TAG)
        g.model.addPhysicalGroup(2, contact, CONTACT_TAG)
        g.model.addPhysicalGroup(2, xsym, TAG_ROLLER_X)
        if ysym:
            g.model.addPhysicalGroup(2, ysym, TAG_ROLLER_Y)
        g.model.addPhysicalGroup(2, free, FREE_TAG)
        g.model.mesh.generate(3)

    return _gmsh_to_dolfinx(comm, gmsh, build)
