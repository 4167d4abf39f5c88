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


# --------------------------------------------------------------------------------------------
# two deformable layers (docs/method.md#two-deformable-layers): paired solids, numpy arrays
# (geometries.fe_solids.FESolid; to_dolfinx() makes the mesh, DeformableCounterpart.from_solid
# the pairing)
# --------------------------------------------------------------------------------------------


def _retag_planes(solid: Any, planes: list[tuple[int, int, float]]) -> Any:
    """``solid`` with its free faces lying in a plane x_axis = value retagged (tag, axis, value)."""
    from dataclasses import replace

    tags = solid.facet_tags.copy()
    x = solid.points_mm[solid.facets]
    scale = float(np.ptp(solid.points_mm, axis=0).max())
    for tag, axis, value in planes:
        on = np.all(np.abs(x[:, :, axis] - value) <= 1e-9 * scale, axis=1)
        tags[on & (tags == FREE_TAG)] = tag
    return replace(solid, facet_tags=tags)


def two_layer_stack(lx: float, ly: float, mobile_thickness: float, fixed_thickness: float,
                    divisions: tuple[int, int], layers: tuple[int, int], gap: float = 0.0) -> Any:
    """Two flat layers, M's on top of F's, their contact faces paired node to node.

    F: [0, lx] x [0, ly] x [-fixed_thickness, 0], bonded at the bottom, contact face z = 0. M:
    z in [gap, gap + mobile_thickness], bonded at the top, contact face z = gap. Both from one
    triangulated rectangle of ``divisions`` squares (two triangles each) extruded in ``layers``
    (M's, F's) element layers; lateral faces on rollers (tag 4 on x = 0, lx, tag 5 on y = 0, ly):
    each layer is laterally confined, p h / E' each."""
    from geometries.fe_solids import extrude, pair_solids

    nx, ny = divisions
    gx, gy = np.meshgrid(np.linspace(0.0, lx, nx + 1), np.linspace(0.0, ly, ny + 1), indexing="ij")
    idx = np.arange((nx + 1) * (ny + 1)).reshape(nx + 1, ny + 1)
    a, b, c, d = (q.ravel() for q in (idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]))
    up = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])  # normals +z
    flat = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    ez = np.tile([0.0, 0.0, 1.0], (len(flat), 1))
    top = gap + mobile_thickness
    mobile = extrude("mobile-layer", flat + [0.0, 0.0, top], up[:, ::-1], -ez, np.full(len(flat), mobile_thickness), layers[0])
    fixed = extrude("fixed-layer", flat - [0.0, 0.0, fixed_thickness], up, ez, np.full(len(flat), fixed_thickness), layers[1])
    planes = [(TAG_ROLLER_X, 0, 0.0), (TAG_ROLLER_X, 0, lx), (TAG_ROLLER_Y, 1, 0.0), (TAG_ROLLER_Y, 1, ly)]
    mobile, fixed = _retag_planes(mobile, planes), _retag_planes(fixed, planes)
    n = len(flat)
    partner = np.full(len(mobile.points_mm), -1, dtype=np.int64)
    partner[layers[0] * n:] = layers[1] * n + np.arange(n)  # the contact faces: the last layer of each
    return pair_solids(mobile, fixed, partner, name="two-layer-stack")


def _quarter_disk(gmsh: Any, radius: float, slice_thickness: float, size_contact: float, size_far: float,
                  fine_radius: float, coarse_radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Points and tetrahedra (gmsh, this rank) of the quarter disk x >= 0 of a cylinder of
    ``radius`` whose axis runs along y through (0, ., radius): the arc from the bottom (0, 0, 0)
    up to (R, 0, R), the diameter z = R; one element thick in y; element size ``size_contact``
    within ``fine_radius`` of the bottom line, growing to ``size_far`` at ``coarse_radius``."""
    geo = gmsh.model.geo
    r = radius
    centre, bottom, side = geo.addPoint(0, 0, r), geo.addPoint(0, 0, 0), geo.addPoint(r, 0, r)
    arc = geo.addCircleArc(bottom, centre, side)
    surf = geo.addPlaneSurface([geo.addCurveLoop([arc, geo.addLine(side, centre), geo.addLine(centre, bottom)])])
    geo.extrude([(2, surf)], 0, slice_thickness, 0, numElements=[1], recombine=False)
    geo.synchronize()
    field = gmsh.model.mesh.field
    dist = field.add("Distance")
    field.setNumbers(dist, "PointsList", [bottom])
    thr = field.add("Threshold")
    for key, value in (("InField", dist), ("SizeMin", size_contact), ("SizeMax", size_far),
                       ("DistMin", fine_radius), ("DistMax", coarse_radius)):
        field.setNumber(thr, key, value)
    field.setAsBackgroundMesh(thr)
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
    gmsh.model.mesh.generate(3)
    tags, coords, _ = gmsh.model.mesh.getNodes()
    index = np.full(int(tags.max()) + 1, -1, dtype=np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    _, nodes = gmsh.model.mesh.getElementsByType(4)
    tets = index[nodes.astype(np.int64).reshape(-1, 4)]
    used = np.unique(tets)
    remap = np.full(len(tags), -1, dtype=np.int64)
    remap[used] = np.arange(used.size)
    return coords.reshape(-1, 3)[used], remap[tets]


def hertz_cylinder(comm: Any, *, radius: float, slice_thickness: float, size_contact: float, size_far: float,
                   fine_radius: float, coarse_radius: float, contact_extent: float) -> Any:
    """One elastic cylinder for Hertz line contact, plane strain (a one-element slice), as an
    :class:`~geometries.fe_solids.FESolid` on every rank (built on rank 0).

    The quarter disk x >= 0 of a cylinder of ``radius`` (axis along y at z = radius), touching
    z = 0 at the origin: bonded on its diameter z = radius (tag 1), contact face the arc up to
    x = ``contact_extent`` (tag 2), symmetry plane x = 0 (tag 4), plane-strain faces y = 0 and
    y = ``slice_thickness`` (tag 5), the rest of the arc free (tag 3)."""
    from geometries.fe_solids import FESolid, boundary_facets, tet_volumes

    gmsh = _gmsh_start()
    pts = tets = None
    if comm.rank == 0:
        saved = {k: gmsh.option.getNumber(k) for k in _GMSH_OPTIONS}
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add(f"fem_reference_{np.random.randint(1 << 30)}")
        try:
            pts, tets = _quarter_disk(gmsh, radius, slice_thickness, size_contact, size_far, fine_radius, coarse_radius)
        finally:
            gmsh.model.remove()
            for k, v in saved.items():
                gmsh.option.setNumber(k, v)
    pts, tets = comm.bcast((pts, tets), root=0)
    negative = tet_volumes(pts, tets) < 0
    tets[negative] = tets[negative][:, [1, 0, 2, 3]]
    facets = boundary_facets(tets)
    x = pts[facets]
    tol = 1e-9 * radius
    tags = np.full(len(facets), FREE_TAG, dtype=np.int32)
    on_arc = np.all(np.abs(np.hypot(x[:, :, 0], x[:, :, 2] - radius) - radius) <= 1e-6 * radius, axis=1)
    slice_face = np.all(np.abs(x[:, :, 1]) <= tol, axis=1) | np.all(np.abs(x[:, :, 1] - slice_thickness) <= tol, axis=1)
    tags[on_arc & ~slice_face & np.all(x[:, :, 0] <= contact_extent + tol, axis=1)] = CONTACT_TAG
    tags[np.all(np.abs(x[:, :, 2] - radius) <= tol, axis=1)] = BONDED_TAG
    tags[np.all(np.abs(x[:, :, 0]) <= tol, axis=1)] = TAG_ROLLER_X
    tags[slice_face] = TAG_ROLLER_Y
    return FESolid(pts, tets, facets, tags, name="hertz-cylinder")


def mirror_solid(solid: Any, axis: int = 2) -> Any:
    """``solid``'s mirror image through the plane x_axis = 0 (same tags, points in the same order)."""
    from geometries.fe_solids import FESolid

    points = solid.points_mm.copy()
    points[:, axis] *= -1.0
    # a reflection turns every tetrahedron and facet inside out: two vertices swapped right them
    return FESolid(points, solid.tets[:, [1, 0, 2, 3]], solid.facets[:, [1, 0, 2]], solid.facet_tags.copy(),
                   name=f"{solid.name}-mirror")


def mirrored_pair(solid: Any, axis: int = 2) -> Any:
    """``solid`` (M) and its mirror image through the plane x_axis = 0 (F), each contact-face
    point paired with its mirror image (:func:`geometries.fe_solids.pair_solids`)."""
    from geometries.fe_solids import pair_solids

    partner = np.full(len(solid.points_mm), -1, dtype=np.int64)
    contact = np.unique(solid.faces(CONTACT_TAG))
    partner[contact] = contact
    return pair_solids(solid, mirror_solid(solid, axis), partner, name=f"{solid.name}-pair")


def cylinder_on_flat_layers(*, bone_radius: float, mobile_thickness: float, fixed_thickness: float,
                            half_angle_deg: float, n_arc: int, arc_progression: float, slice_thickness: float,
                            layers: tuple[int, int]) -> tuple[Any, Any]:
    """A cylindrical layer on a flat one, plane strain (a one-element slice), as paired solids.

    M: the layer of ``mobile_thickness`` on a bone cylinder of ``bone_radius`` (axis along y at
    z = bone_radius + mobile_thickness), touching z = 0 at x = 0, its arc from the bottom up to
    ``half_angle_deg`` in ``n_arc`` elements growing by ``arc_progression``. F: the flat layer
    z in [-fixed_thickness, 0] under M's contact face, built by carrying M's contact
    triangulation along M's normals (the springs' rays) onto z = 0. Tags: bonded 1 / 11,
    contact 2 / 12, symmetry x = 0 tag 4, plane-strain faces tag 5, the ends free.
    Returns (the paired solid, M's layer alone with the same tags)."""
    from geometries.fe_solids import extrude, pair_solids

    steps = arc_progression ** np.arange(n_arc)
    angle = np.concatenate([[0.0], np.cumsum(steps) / steps.sum() * np.radians(half_angle_deg)])
    na = len(angle)
    centre = bone_radius + mobile_thickness
    ring = np.column_stack([np.sin(angle), np.zeros(na), -np.cos(angle)])  # outward normals
    bone = np.vstack([centre * np.array([0.0, 0.0, 1.0]) + bone_radius * ring,
                      centre * np.array([0.0, 0.0, 1.0]) + bone_radius * ring + [0.0, slice_thickness, 0.0]])
    normals = np.vstack([ring, ring])
    i = np.arange(na - 1)
    tris = np.concatenate([np.column_stack([i, i + na, i + 1]), np.column_stack([i + 1, i + na, i + 1 + na])])
    mobile = extrude("cylinder-layer", bone, tris, normals, np.full(len(bone), mobile_thickness), layers[0])
    nv = len(bone)
    top = mobile.points_mm[layers[0] * nv:]
    facing = top - (top[:, 2] / normals[:, 2])[:, None] * normals  # along M's normals onto z = 0
    ez = np.tile([0.0, 0.0, 1.0], (nv, 1))
    fixed = extrude("flat-layer", facing - fixed_thickness * ez, tris[:, ::-1], ez, np.full(nv, fixed_thickness), layers[1])
    planes = [(TAG_ROLLER_X, 0, 0.0), (TAG_ROLLER_Y, 1, 0.0), (TAG_ROLLER_Y, 1, slice_thickness)]
    mobile, fixed = _retag_planes(mobile, planes), _retag_planes(fixed, planes)
    partner = np.full(len(mobile.points_mm), -1, dtype=np.int64)
    partner[layers[0] * nv:] = layers[1] * nv + np.arange(nv)
    return pair_solids(mobile, fixed, partner, name="cylinder-on-flat"), mobile
