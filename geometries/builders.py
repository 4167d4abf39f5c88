"""Built-in geometries of the ankle contact problem (docs/method.md#8-built-in-geometries; thesis sections 4.2.2 and 4.3.3).

Every builder is a plain function with keyword parameters and documented defaults; it returns a
:class:`BuiltGeometry` (the mobile surface M = talus, the fixed surface F = tibia, the ankle axis,
ligament attachment points, a description and the resolved parameters). ``build_geometry(name,
params)`` is the entry point used by scene files: it looks the builder up by name, validates the
parameters (unknown names, types, ranges) and raises :class:`edem.errors.InputError` naming the
key ``geometry.<param>``.

Coordinate convention (all builders, mm):
    x = medio-lateral (the ankle axis / talar cylinder axis; +x lateral, -x medial),
    y = posterior -> anterior, z = inferior -> superior.
    The talar dome top is at z = 0 and the talar cylinder axis runs along x through (0, 0, -R).
Normals (right-hand rule on the triangles): mobile normals point out of the talus towards the
tibia; fixed normals point out of the tibia towards the talus (the plafond faces down, the medial
malleolus faces laterally).

Meshing: the curved surfaces (ideal talar cylinder patch, subject-like talus and tibia) are meshed
with gmsh (imported only inside the functions that mesh; a plate or hemisphere scene never loads
it). Meshing is deterministic: one thread, Frontal-Delaunay (algorithm 6), fixed random seed and
random factor; the same parameters give identical arrays. The icosphere hemispheres and the flat
and tilted plates are exact subdivisions / structured grids built with plain numpy (no mesher is
needed for them).
"""

from __future__ import annotations

import collections
import contextlib
import copy
import inspect
import itertools
import json
import math
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from geometries.errors import InputError
from geometries.surface import TriangleSurface, midpoint_subdivision

__all__ = [
    "BuiltGeometry",
    "LigamentAttachment",
    "build_geometry",
    "builder_names",
    "ideal_ankle",
    "hemispheres",
    "flat_plates",
    "tilted_plane",
    "subject_ankle",
    "SUBJECT_RANGES",
    "icosphere",
]


# --------------------------------------------------------------------------------------------
# result types
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LigamentAttachment:
    """A ligament as a straight line from a point on the talus (M) to a point on tibia/fibula (F).

    The fibula is taken as rigidly attached to the tibia (one fixed body). The rest length is not
    stored: the solver takes the distance at the neutral pose, so every ligament is slack (zero
    force) at the neutral pose and only pulls when stretched.
    """

    name: str
    mobile_point_mm: np.ndarray
    fixed_point_mm: np.ndarray


@dataclass(frozen=True)
class BuiltGeometry:
    """Result of a builder: both surfaces, the ankle axis, ligaments, description, parameters."""

    mobile: TriangleSurface
    fixed: TriangleSurface
    reference_point_mm: np.ndarray | None  # None = centroid of the mobile surface
    ankle_axis_point_mm: np.ndarray
    ankle_axis_direction: np.ndarray
    ligaments: tuple[LigamentAttachment, ...]
    description: str  # what it represents, where its numbers come from
    parameters: dict = field(default_factory=dict)  # the resolved parameters (defaults filled in)


# --------------------------------------------------------------------------------------------
# parameter validation
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _P:
    """Specification of one builder parameter (type, range) for validation and documentation."""

    kind: str  # "float" | "int" | "bool" | "seed" | "float_or_none" | "pairs" | "floats"
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False  # lo excluded
    length: int | None = None  # for "pairs" / "floats"

    def describe(self) -> str:
        base = {
            "float": "a number",
            "float_or_none": "a number",
            "int": "an integer",
            "bool": "true or false",
            "seed": "an integer seed",
            "pairs": f"a list of {self.length} [x_mm, y_mm] pairs",
            "floats": f"a list of {self.length} numbers",
        }[self.kind]
        if self.lo is not None or self.hi is not None:
            lo = "-inf" if self.lo is None else f"{self.lo:g}"
            hi = "inf" if self.hi is None else f"{self.hi:g}"
            base += f" in {'(' if self.lo_open else '['}{lo}, {hi}]"
        return base


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(
        v, (bool, np.bool_))


def _check_value(builder: str, name: str, spec: _P, value: Any) -> Any:
    try:
        return _checked_value(builder, name, spec, value)
    except OverflowError:  # an integer such as 10**400 has no float64 value
        raise InputError(f"{builder}: an integer too large for a float64", key=f"geometry.{name}",
                         expected=spec.describe()) from None


def _checked_value(builder: str, name: str, spec: _P, value: Any) -> Any:
    key = f"geometry.{name}"

    def bad(problem: str) -> InputError:
        return InputError(f"{builder}: {problem}", key=key, expected=spec.describe())

    def in_range(x: float) -> bool:
        if spec.lo is not None and (x < spec.lo or (spec.lo_open and x <= spec.lo)):
            return False
        if spec.hi is not None and x > spec.hi:
            return False
        return True

    if spec.kind == "bool":
        if not isinstance(value, (bool, np.bool_)):
            raise bad(f"wrong type {type(value).__name__}")
        return bool(value)
    if spec.kind in ("int", "seed"):
        if spec.kind == "seed" and value is None:
            return None
        if not isinstance(value, (int, np.integer)) or isinstance(value, (bool, np.bool_)):
            raise bad(f"wrong type {type(value).__name__}")
        if not in_range(float(value)):
            raise bad(f"value {value} out of range")
        return int(value)
    if spec.kind in ("float", "float_or_none"):
        if spec.kind == "float_or_none" and value is None:
            return None
        if not _is_number(value):
            raise bad(f"wrong type {type(value).__name__}")
        x = float(value)
        if not math.isfinite(x) or not in_range(x):
            raise bad(f"value {value} out of range")
        return x
    if spec.kind == "floats":
        try:
            arr = [float(v) for v in value] if not isinstance(value, (str, bytes)) else None
        except TypeError:
            arr = None
        if arr is None or any(not _is_number(v) for v in value) or len(arr) != spec.length:
            raise bad("wrong type or length")
        if not all(math.isfinite(x) and in_range(x) for x in arr):
            raise bad(f"value {value} out of range")
        return tuple(arr)
    if spec.kind == "pairs":
        if value is None:
            return None
        ok = not isinstance(value, (str, bytes)) and hasattr(value, "__len__")
        if ok and len(value) == spec.length:
            out = []
            for pair in value:
                if (isinstance(pair, (str, bytes)) or not hasattr(pair, "__len__") or len(pair) != 2
                        or not all(_is_number(v) and math.isfinite(float(v)) for v in pair)):
                    ok = False
                    break
                out.append((float(pair[0]), float(pair[1])))
            if ok:
                return tuple(out)
        raise bad("wrong type or length")
    raise AssertionError(spec.kind)  # pragma: no cover


def _validate(builder: str, specs: dict[str, _P], given: dict[str, Any]) -> dict[str, Any]:
    unknown = sorted(set(given) - set(specs))
    if unknown:
        raise InputError(
            f"unknown parameter '{unknown[0]}' for geometry builder '{builder}'",
            key=f"geometry.{unknown[0]}",
            expected="one of " + ", ".join(specs),
        )
    return {k: _check_value(builder, k, specs[k], v) for k, v in given.items()}


# --------------------------------------------------------------------------------------------
# gmsh session helpers (gmsh is imported only here)
# --------------------------------------------------------------------------------------------

_MODEL_COUNTER = itertools.count()


@contextlib.contextmanager
def gmsh_model(name: str) -> Iterator[Any]:
    """A fresh gmsh model with deterministic meshing options; yields the ``gmsh`` module.

    Works whether or not gmsh is already initialised by the caller: an existing session is left
    as it was (its current model and the options set here are restored); otherwise gmsh is
    initialised (quietly, without touching the SIGINT handler) and finalised on exit.
    """
    import gmsh

    owns = not gmsh.isInitialized()
    if owns:
        gmsh.initialize(readConfigFiles=False, interruptible=False)
    options = {
        "General.Terminal": 0,
        "General.Verbosity": 0,
        "General.NumThreads": 1,
        "Mesh.MaxNumThreads1D": 1,
        "Mesh.MaxNumThreads2D": 1,
        "Mesh.MaxNumThreads3D": 1,
        "Mesh.Algorithm": 6,
        "Mesh.RandomSeed": 1,
        "Mesh.RandomFactor": 1e-9,
        "Mesh.MeshSizeFromCurvature": 0,
        "Mesh.MeshSizeExtendFromBoundary": 1,
        "Mesh.MeshSizeFromPoints": 1,
        "Mesh.MeshSizeMin": 0,
        "Mesh.MeshSizeMax": 1e22,
        "Mesh.Optimize": 0,
        "Mesh.Smoothing": 1,
    }
    previous_model = None
    saved: dict[str, float] = {}
    try:
        if not owns:
            with contextlib.suppress(Exception):
                previous_model = gmsh.model.getCurrent()
            for k in options:
                with contextlib.suppress(Exception):
                    saved[k] = gmsh.option.getNumber(k)
        for k, v in options.items():
            with contextlib.suppress(Exception):  # an option missing in some gmsh version
                gmsh.option.setNumber(k, v)
        model_name = f"edem_{name}_{next(_MODEL_COUNTER)}"
        gmsh.model.add(model_name)
        yield gmsh
    finally:
        if owns:
            gmsh.finalize()
        else:
            with contextlib.suppress(Exception):
                gmsh.model.remove()
            for k, v in saved.items():
                with contextlib.suppress(Exception):
                    gmsh.option.setNumber(k, v)
            if previous_model:
                with contextlib.suppress(Exception):
                    gmsh.model.setCurrent(previous_model)


def _gmsh_triangles(gmsh: Any, dim_tags: list[tuple[int, int]] | None = None,
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (n, 3) and 3-node triangles (m, 3) of the current gmsh model, compacted.

    With ``dim_tags`` only triangles of those surfaces are returned (in the given order).
    """
    node_tags, coords, _ = gmsh.model.mesh.getNodes()
    node_tags = np.asarray(node_tags, dtype=np.int64)
    coords = np.asarray(coords, dtype=np.float64).reshape(-1, 3)
    tris = []
    surfaces = dim_tags if dim_tags is not None else [(2, -1)]
    for _dim, tag in surfaces:
        _etags, enodes = gmsh.model.mesh.getElementsByType(2, tag)
        tris.append(np.asarray(enodes, dtype=np.int64).reshape(-1, 3))
    tri_tags = np.concatenate(tris, axis=0)
    lookup = np.full(int(node_tags.max()) + 1, -1, dtype=np.int64)
    lookup[node_tags] = np.arange(node_tags.size)
    tri_idx = lookup[tri_tags]
    used = np.unique(tri_idx)
    compact = np.full(node_tags.size, -1, dtype=np.int64)
    compact[used] = np.arange(used.size)
    return coords[used].copy(), compact[tri_idx]


def _mesh_planar_domain(
    name: str,
    polygons: list[list[tuple[float, float]]],
    mesh_size: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mesh a set of planar polygons in the (a, b) plane with gmsh, conforming on shared edges.

    ``polygons`` are counter-clockwise vertex lists; polygons may share whole edges (same two
    vertices), which are then meshed once. Returns the 2D vertices (n, 2), triangles (m, 3)
    oriented counter-clockwise in (a, b), and the index of the polygon each triangle belongs to.
    """
    with gmsh_model(name) as gmsh:
        geo = gmsh.model.geo
        point_tag: dict[tuple[float, float], int] = {}
        line_tag: dict[tuple[int, int], int] = {}
        surfaces = []
        for poly in polygons:
            pts = []
            for a, b in poly:
                key = (round(a, 12), round(b, 12))
                if key not in point_tag:
                    point_tag[key] = geo.addPoint(a, b, 0.0, mesh_size)
                pts.append(point_tag[key])
            loop = []
            for i in range(len(pts)):
                p, q = pts[i], pts[(i + 1) % len(pts)]
                if (q, p) in line_tag:
                    loop.append(-line_tag[(q, p)])
                else:
                    if (p, q) not in line_tag:
                        line_tag[(p, q)] = geo.addLine(p, q)
                    loop.append(line_tag[(p, q)])
            surfaces.append(geo.addPlaneSurface([geo.addCurveLoop(loop)]))
        geo.synchronize()
        gmsh.model.mesh.generate(2)
        counts = []
        for s in surfaces:
            _e, en = gmsh.model.mesh.getElementsByType(2, s)
            counts.append(len(en) // 3)
        verts, tris = _gmsh_triangles(gmsh, [(2, s) for s in surfaces])
    verts2 = verts[:, :2]
    # orient counter-clockwise in the (a, b) plane
    a, b, c = verts2[tris[:, 0]], verts2[tris[:, 1]], verts2[tris[:, 2]]
    cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    tris = tris.copy()
    flip = cross < 0
    tris[flip] = tris[flip][:, [0, 2, 1]]
    region = np.repeat(np.arange(len(surfaces)), counts)
    return verts2, tris, region


def _orient_like(vertices: np.ndarray, triangles: np.ndarray, expected_normals: np.ndarray,
                 what: str) -> np.ndarray:
    """Flip the whole (consistently oriented) mesh if its normals oppose ``expected_normals``.

    gmsh orients every triangle of one surface alike; we flip globally (never per triangle) and
    then assert every triangle agrees with the analytic normal, so orientation comes from the
    mesh topology and the check only confirms it.
    """
    a, b, c = vertices[triangles[:, 0]], vertices[triangles[:, 1]], vertices[triangles[:, 2]]
    n = np.cross(b - a, c - a)
    s = np.einsum("ij,ij->i", n, expected_normals)
    if np.sum(s) < 0:
        triangles = triangles[:, [0, 2, 1]]
        s = -s
    if not np.all(s > 0):
        raise RuntimeError(f"{what}: inconsistent triangle orientation from the mesher")
    return np.ascontiguousarray(triangles, dtype=np.int64)


# --------------------------------------------------------------------------------------------
# shared pieces
# --------------------------------------------------------------------------------------------


def _rot_y(angle_rad: float) -> np.ndarray:
    """Rotation about +y; a positive angle moves points with x > 0 downwards (-z)."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _ligaments(radius: float, half_width: float, medial_x: float, lateral_x: float,
               fixed_rotation: np.ndarray | None = None, pivot: np.ndarray | None = None,
               ) -> tuple[LigamentAttachment, ...]:
    """Four ankle ligaments at plausible (not measured) anatomical positions.

    Talar points lie on the medial (x = -half_width) and lateral (x = +half_width) faces of the
    talus body, below the articular dome (the dome top is z = 0, the axis at z = -R); tibial
    points lie in the medial malleolus (x = medial_x, medial of the malleolar facet), fibular
    points in the lateral malleolus (x = lateral_x). Positions scale with the talar radius R:
      ATiTL anterior tibiotalar: anterior medial malleolus -> medial talar neck (anterior-inferior)
      PTiTL posterior tibiotalar: posterior medial malleolus -> posteromedial talus
      ATFL  anterior talofibular: anterior fibular tip -> lateral talar neck, roughly horizontal
      PTFL  posterior talofibular: fibular malleolar fossa -> posterolateral talar process
    They are slack (zero force) at the neutral pose: the solver takes their neutral length as
    rest length. The fixed points move with the tibia when it is tilted (``fixed_rotation``
    about ``pivot``).
    """
    r, hw = radius, half_width

    def p(*xyz: float) -> np.ndarray:
        return np.array(xyz, dtype=np.float64)

    def f(*xyz: float) -> np.ndarray:
        x = p(*xyz)
        if fixed_rotation is not None:
            c = np.zeros(3) if pivot is None else np.asarray(pivot, dtype=np.float64)
            x = (x - c) @ fixed_rotation.T + c
        return x

    return (
        LigamentAttachment("ATiTL", p(-hw, 0.60 * r, -0.55 * r), f(medial_x, 0.30 * r, -0.25 * r)),
        LigamentAttachment("PTiTL", p(-hw, -0.60 * r, -0.60 * r),
                           f(medial_x, -0.35 * r, -0.30 * r)),
        LigamentAttachment("ATFL", p(hw, 0.65 * r, -0.60 * r), f(lateral_x, 0.05 * r, -0.75 * r)),
        LigamentAttachment("PTFL", p(hw - 3.0, -0.90 * r, -0.85 * r),
                           f(lateral_x, -0.25 * r, -0.75 * r)),
    )


def _structured_grid(x0: float, x1: float, y0: float, y1: float, nx: int, ny: int,
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Structured triangulated rectangle in the z = 0 plane, triangles with normal +z."""
    xs = np.linspace(x0, x1, nx + 1)
    ys = np.linspace(y0, y1, ny + 1)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    verts = np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    i, j = i.ravel(), j.ravel()
    v00 = i * (ny + 1) + j
    v10 = (i + 1) * (ny + 1) + j
    v01 = i * (ny + 1) + j + 1
    v11 = (i + 1) * (ny + 1) + j + 1
    tris = np.concatenate([np.column_stack([v00, v10, v11]), np.column_stack([v00, v11, v01])])
    return verts, tris.astype(np.int64)


# --------------------------------------------------------------------------------------------
# a. idealised ankle (thesis 4.3.3)
# --------------------------------------------------------------------------------------------

IDEAL_ANKLE_PARAMS = {
    "radius_mm": _P("float", 1.0, 200.0, lo_open=True),
    "width_mm": _P("float", 1.0, 200.0, lo_open=True),
    "arc_deg": _P("float", 1.0, 179.0),
    "plafond_gap_mm": _P("float", 0.0, 50.0, lo_open=True),
    "plafond_tilt_deg": _P("float", -15.0, 15.0),
    "malleolus": _P("bool"),
    "malleolus_gap_mm": _P("float", 0.0, 50.0, lo_open=True),
    "mesh_size_mm": _P("float_or_none", 0.05, 50.0),
}

#: mesh size (relative to the radius) that gives ~3000 triangles for the default patch
_IDEAL_DEFAULT_SIZE_PER_R = 0.047


def ideal_ankle(
    radius_mm: float = 20.0,
    width_mm: float = 28.0,
    arc_deg: float = 114.0,
    plafond_gap_mm: float = 1.5,
    plafond_tilt_deg: float = 2.0,
    malleolus: bool = True,
    malleolus_gap_mm: float = 1.5,
    mesh_size_mm: float | None = None,
) -> BuiltGeometry:
    """Idealised ankle of the thesis (section 4.3.3): cylindrical talus under a planar tibia.

    Talus (mobile): the patch of a cylinder of radius ``radius_mm`` whose axis runs along x
    through (0, 0, -R) (so the dome top is at z = 0), ``width_mm`` wide in x (centred on x = 0)
    and spanning ``arc_deg`` centred on the top. Its area is R * arc * width (11.15 cm^2 for the
    defaults, the thesis's talar articular area). Meshed with gmsh (OpenCASCADE circle arc
    extruded along x, Frontal-Delaunay); the default ``mesh_size_mm`` (0.047 R = 0.94 mm) gives
    about 3000 triangles (thesis: 2974).

    Tibia (fixed), two planes as in the thesis (which needed 4 triangles for them):
      * plafond: a plane ``plafond_gap_mm`` above the dome top, facing down, tilted about the y
        axis (through the point above the dome top) by ``plafond_tilt_deg``; a positive tilt
        brings the lateral (+x) side closer to the talus. The thesis explains its medio-lateral
        pressure asymmetry (peak laterally, decreasing medially, minimum thickness laterally) by
        the talar cylinder being tilted relative to the load; we keep the cylinder on the ankle
        axis (x) and tilt the plafond instead by a small default 2 deg (gap 1.01 mm at the
        lateral edge, 1.99 mm at the medial edge). The spring length along the radial ray at
        angle phi from the top is (R + g(x)) / cos(phi) - R with g(x) = gap - x tan(tilt), so
        with h_max = 3.5 mm and no tilt the candidate fraction is 2 acos((R+g)/(R+h_max)) / arc
        = 41.8 % (thesis: 42 %); the default 2 deg tilt keeps it at ~41.6 %. The plafond
        covers every radial ray of the patch at the neutral pose, and every ray shorter than
        R/2 at any rotation of the tibia about the ankle axis.
      * medial malleolus (``malleolus=True``): the vertical plane x = -(width/2 +
        ``malleolus_gap_mm``) facing laterally (+x), from the plafond's medial edge down to
        below the talar patch. Our talus patch is only the cylindrical dome (no medial facet),
        whose rays are radial up to faceting (|n_x| ~ 0.01): they run (almost) parallel to this
        plane and meet the plafond long before they could drift the malleolus gap medially, at
        the neutral pose and under rotations about the ankle axis, so the malleolus carries no
        spring of this talus. Because the whole talus lies lateral of the plane, a ray can only
        ever reach its front (talus-facing) side, never its back, so it cannot produce a length
        measured from behind; it is there for completeness (rendering, imported or rotated
        talus meshes with a medial facet).

    Ankle axis: the cylinder axis, point (0, 0, -R), direction +x. Ligaments: see
    :func:`_ligaments` (plausible placements, not measured).
    """
    given = {k: v for k, v in locals().items()}
    p = _validate("ideal_ankle", IDEAL_ANKLE_PARAMS, given)
    R, W, arc = p["radius_mm"], p["width_mm"], math.radians(p["arc_deg"])
    g, tilt = p["plafond_gap_mm"], math.radians(p["plafond_tilt_deg"])
    size = p["mesh_size_mm"] if p["mesh_size_mm"] is not None else _IDEAL_DEFAULT_SIZE_PER_R * R
    p["mesh_size_mm"] = size
    if abs(W / 2.0 * math.tan(tilt)) >= g:
        raise InputError(
            "ideal_ankle: the tilted plafond would cut into the talus at its edge",
            key="geometry.plafond_tilt_deg",
            expected=f"|tan(tilt)| * width/2 < plafond_gap_mm ({g:g} mm)",
        )

    if p["malleolus"]:
        # the tilted malleolus wall x(z) = (m + sin(tilt) (z - g)) / cos(tilt) must stay medial
        # of the talus down to the talus's lowest point
        m = -(W / 2.0 + p["malleolus_gap_mm"])
        z_low = -R * (1.0 - math.cos(arc / 2.0))
        if (m + math.sin(tilt) * (z_low - g)) / math.cos(tilt) >= -W / 2.0:
            raise InputError(
                "ideal_ankle: the tilted medial malleolus would cut into the talus",
                key="geometry.plafond_tilt_deg",
                expected="a smaller (or positive) tilt, or a larger malleolus_gap_mm",
            )

    # --- talus: cylinder patch, gmsh OCC arc extruded along x
    with gmsh_model("ideal_talus") as gmsh:
        occ = gmsh.model.occ
        # circle in the y-z plane (normal x), angle measured from +z
        arc_tag = occ.addCircle(-W / 2.0, 0.0, -R, R, -1, -arc / 2.0, arc / 2.0,
                                zAxis=[1.0, 0.0, 0.0], xAxis=[0.0, 0.0, 1.0])
        occ.extrude([(1, arc_tag)], W, 0.0, 0.0)
        occ.synchronize()
        gmsh.model.mesh.setSize(gmsh.model.getEntities(0), size)
        gmsh.model.mesh.generate(2)
        verts, tris = _gmsh_triangles(gmsh)
    # project to the exact cylinder (gmsh nodes are on it to round-off already)
    radial = verts - np.array([0.0, 0.0, -R])
    radial[:, 0] = 0.0
    rad_len = np.linalg.norm(radial, axis=1)
    verts[:, 1:] = np.array([0.0, -R]) + radial[:, 1:] * (R / rad_len)[:, None]
    cent = verts[tris].mean(axis=1)
    expected = cent - np.array([0.0, 0.0, -R])
    expected[:, 0] = 0.0
    tris = _orient_like(verts, tris, expected, "ideal_ankle talus")
    mobile = TriangleSurface(verts, tris, name="ideal talus (cylinder patch)", source="ideal_ankle")

    # --- tibia: plafond (+ malleolus), planes rotated about y through (0, 0, g)
    medial_x = -(W / 2.0 + p["malleolus_gap_mm"])
    lateral_x = W / 2.0 + R / 2.0
    # half extent in y: every radial ray of the patch at the neutral pose, and (in the plafond's
    # own frame) every ray shorter than R/2 whatever the rotation about the ankle axis
    y_half = max((R + g) * math.tan(min(arc / 2.0, math.radians(80.0))),
                 math.sqrt(max((1.5 * R) ** 2 - (R + g) ** 2, 0.0))) + R / 2.0
    plafond = np.array([
        [medial_x, -y_half, g], [lateral_x, -y_half, g],
        [lateral_x, y_half, g], [medial_x, y_half, g],
    ])
    fixed_tris = [np.array([[0, 2, 1], [0, 3, 2]], dtype=np.int64)]  # normal -z (towards talus)
    fixed_verts = [plafond]
    if p["malleolus"]:
        bottom = -R * (1.0 - math.cos(arc / 2.0)) - R / 4.0
        mall = np.array([
            [medial_x, -y_half, g], [medial_x, y_half, g],
            [medial_x, y_half, bottom], [medial_x, -y_half, bottom],
        ])
        # (0,2,1), (0,3,2): normal +x (lateral, towards the talus)
        fixed_tris.append(np.array([[0, 2, 1], [0, 3, 2]], dtype=np.int64) + 4)
        fixed_verts.append(mall)
    fv = np.vstack(fixed_verts)
    pivot = np.array([0.0, 0.0, g])
    fv = (fv - pivot) @ _rot_y(tilt).T + pivot
    ft = np.vstack(fixed_tris)
    fixed = TriangleSurface(fv, ft, name="ideal tibia (plafond + medial malleolus)"
                            if p["malleolus"] else "ideal tibia (plafond)", source="ideal_ankle")
    n_f = fixed.unit_normals
    assert n_f[0, 2] < 0 and (not p["malleolus"] or n_f[-1, 0] > 0)

    description = (
        "Idealised ankle (thesis section 4.3.3, docs/method.md#8-built-in-geometries): talus = cylinder patch "
        f"R = {R:g} mm, width {W:g} mm, arc {p['arc_deg']:g} deg "
        f"({R * arc * W / 100.0:.2f} cm^2; thesis 11.15 cm^2, 2974 triangles), "
        f"{mobile.n_triangles} triangles (gmsh, size {size:.3g} mm); tibia = plafond plane "
        f"{g:g} mm above the dome top tilted {p['plafond_tilt_deg']:g} deg about y (lateral side "
        "closer; the thesis attributes its medio-lateral asymmetry to such a tilt)"
        + (" + vertical medial malleolus plane (parallel to the dome's rays: not hit by them)"
           if p["malleolus"] else "")
        + ". Ligament attachments are plausible anatomical placements, not measured."
    )
    return BuiltGeometry(
        mobile=mobile,
        fixed=fixed,
        reference_point_mm=None,
        ankle_axis_point_mm=np.array([0.0, 0.0, -R]),
        ankle_axis_direction=np.array([1.0, 0.0, 0.0]),
        ligaments=_ligaments(R, W / 2.0, medial_x - 2.0, W / 2.0 + 6.0, _rot_y(tilt), pivot),
        description=description,
        parameters=p,
    )


def ideal_candidate_fraction(radius_mm: float, gap_mm: float, max_spring_length_mm: float,
                             arc_deg: float, width_mm: float | None = None,
                             tilt_deg: float = 0.0, n_x: int = 2001) -> float:
    """Closed-form fraction of the ideal talar patch whose radial ray meets the plafond within
    ``max_spring_length_mm``: 2 acos((R + g(x)) / (R + h_max)) / arc, averaged over x for a tilted
    plafond (g(x) = gap - x tan(tilt))."""
    arc = math.radians(arc_deg)
    if tilt_deg == 0.0 or width_mm is None:
        xs = np.array([0.0])
    else:
        xs = np.linspace(-width_mm / 2.0, width_mm / 2.0, n_x)
    gx = gap_mm - xs * math.tan(math.radians(tilt_deg))
    c = np.clip((radius_mm + gx) / (radius_mm + max_spring_length_mm), -1.0, 1.0)
    theta = np.minimum(np.arccos(c), arc / 2.0)
    return float(np.mean(2.0 * theta / arc))


# --------------------------------------------------------------------------------------------
# b. hemispheres (thesis 4.2.2)
# --------------------------------------------------------------------------------------------


def icosphere(subdivisions: int, radius: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Icosahedron with one vertex at the north pole, midpoint-subdivided ``subdivisions`` times,
    every vertex projected onto the sphere. Triangles are outward-oriented. Exact subdivision:
    plain numpy, no mesher."""
    phi = (1.0 + math.sqrt(5.0)) / 2.0
    v = np.array([
        [-1, phi, 0], [1, phi, 0], [-1, -phi, 0], [1, -phi, 0],
        [0, -1, phi], [0, 1, phi], [0, -1, -phi], [0, 1, -phi],
        [phi, 0, -1], [phi, 0, 1], [-phi, 0, -1], [-phi, 0, 1],
    ], dtype=np.float64)
    f = np.array([
        [0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11],
        [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8],
        [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
        [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1],
    ], dtype=np.int64)
    v /= np.linalg.norm(v, axis=1)[:, None]
    # rotate vertex 5 = (0, 1, phi)/|.| onto +z: rotation about x by the angle between them
    a = v[5]
    ang = math.atan2(a[1], a[2])
    c, s = math.cos(ang), math.sin(ang)
    rot = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    v = v @ rot.T
    for _ in range(subdivisions):
        f, pairs = midpoint_subdivision(f, len(v))
        mid = v[pairs[:, 0]] + v[pairs[:, 1]]
        v = np.vstack([v, mid / np.linalg.norm(mid, axis=1)[:, None]])
    # outward orientation check (a convex polyhedron around the origin)
    cen = v[f].mean(axis=1)
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    if np.any(np.einsum("ij,ij->i", n, cen) <= 0):  # pragma: no cover - construction invariant
        raise RuntimeError("icosphere orientation")
    return v * radius, f


def _upper_hemisphere(subdivisions: int, radius: float, inward: bool, name: str) -> TriangleSurface:
    v, f = icosphere(subdivisions, radius)
    keep = v[f].mean(axis=1)[:, 2] > 0.0
    f = f[keep]
    used = np.unique(f)
    remap = np.full(len(v), -1, dtype=np.int64)
    remap[used] = np.arange(used.size)
    f = remap[f]
    if inward:
        f = f[:, [0, 2, 1]]
    return TriangleSurface(v[used].copy(), np.ascontiguousarray(f), name=name, source="hemispheres")


HEMISPHERE_PARAMS = {
    "subdivisions": _P("int", 0, 8),
    "reference_subdivisions": _P("int", 0, 8),
    "radius_mm": _P("float", 0.0, 1e4, lo_open=True),
    "target_radius_mm": _P("float", 0.0, 1e4, lo_open=True),
}


def hemispheres(
    subdivisions: int = 3,
    reference_subdivisions: int = 6,
    radius_mm: float = 1.0,
    target_radius_mm: float = 1.5,
) -> BuiltGeometry:
    """Ray-cast thickness convergence test of the thesis (section 4.2.2).

    Mobile (reference) = upper hemisphere (z > 0, centroid criterion) of an icosphere of radius
    ``radius_mm`` with ``reference_subdivisions`` midpoint subdivisions, normals outward; fixed
    (target) = upper hemisphere of radius ``target_radius_mm`` from ``subdivisions``
    subdivisions, normals inward (towards the mobile). The icosahedron is oriented with a vertex
    on the pole, so from one subdivision on the equator is a chain of edges and the hemisphere
    holds exactly half of the 20 * 4^n triangles. The exact spring length on the true spheres is
    target_radius - radius (0.5) everywhere; faceting makes the computed lengths converge to it
    from below as ``subdivisions`` grows. Built with plain numpy (exact subdivision, no mesher).

    Note on counts: the thesis's 6-subdivision reference had 10 388 triangles, which matches 5 of
    our midpoint subdivisions (10 240); its counting presumably starts at 1 for the icosahedron.
    """
    p = _validate("hemispheres", HEMISPHERE_PARAMS, dict(locals()))
    if p["target_radius_mm"] <= p["radius_mm"]:
        raise InputError("hemispheres: the target must enclose the reference",
                         key="geometry.target_radius_mm",
                         expected=f"> radius_mm ({p['radius_mm']:g})")
    mobile = _upper_hemisphere(p["reference_subdivisions"], p["radius_mm"], False,
                               "reference hemisphere")
    fixed = _upper_hemisphere(p["subdivisions"], p["target_radius_mm"], True, "target hemisphere")
    return BuiltGeometry(
        mobile=mobile,
        fixed=fixed,
        reference_point_mm=np.zeros(3),
        ankle_axis_point_mm=np.zeros(3),
        ankle_axis_direction=np.array([1.0, 0.0, 0.0]),
        ligaments=(),
        description=(
            "Concentric hemispheres (thesis section 4.2.2, docs/method.md#8-built-in-geometries): reference radius "
            f"{p['radius_mm']:g} ({p['reference_subdivisions']} icosahedron subdivisions, "
            f"{mobile.n_triangles} triangles), target radius {p['target_radius_mm']:g} "
            f"({p['subdivisions']} subdivisions, {fixed.n_triangles} triangles); exact spring "
            f"length {p['target_radius_mm'] - p['radius_mm']:g} (thesis converged mean 0.499, "
            "sd 1.5e-5). Plain numpy icosphere (exact subdivision, vertices on the sphere). "
            "The reference point is the common centre."
        ),
        parameters=p,
    )


# --------------------------------------------------------------------------------------------
# c. plates for closed-form tests
# --------------------------------------------------------------------------------------------

PLATE_PARAMS = {
    "width_mm": _P("float", 0.0, 1e4, lo_open=True),
    "depth_mm": _P("float", 0.0, 1e4, lo_open=True),
    "gap_mm": _P("float", 0.0, 1e4, lo_open=True),
    "n_per_side": _P("int", 1, 2000),
}
TILTED_PARAMS = dict(PLATE_PARAMS, tilt_deg=_P("float", -60.0, 60.0))


def _plates(width_mm: float, depth_mm: float, gap_mm: float, tilt_deg: float,
            n_per_side: int) -> tuple[TriangleSurface, TriangleSurface]:
    verts, tris = _structured_grid(-width_mm / 2, width_mm / 2, -depth_mm / 2, depth_mm / 2,
                                   n_per_side, n_per_side)
    mobile = TriangleSurface(verts, tris, name="plate", source="plates")
    # fixed plane: larger than the plate by a margin, through (0, 0, gap), rotated about y
    mx, my = width_mm / 2 + max(width_mm, depth_mm) / 2, depth_mm / 2 + max(width_mm, depth_mm) / 2
    t = math.tan(math.radians(tilt_deg))
    corners = np.array([[-mx, -my], [mx, -my], [mx, my], [-mx, my]])
    fv = np.column_stack([corners, gap_mm + corners[:, 0] * t])
    fixed = TriangleSurface(fv, np.array([[0, 2, 1], [0, 3, 2]], dtype=np.int64),
                            name="plane", source="plates")  # normal points down
    return mobile, fixed


def flat_plates(width_mm: float = 20.0, depth_mm: float = 20.0, gap_mm: float = 2.0,
                n_per_side: int = 20) -> BuiltGeometry:
    """Square plate (mobile, z = 0, normal +z, a structured grid of n_per_side^2 squares split
    into 2 n_per_side^2 triangles) under a parallel plane at z = ``gap_mm`` (fixed, normal -z,
    two triangles, larger than the plate so every ray hits). Every spring has length gap_mm:
    under a normal force F the pressure is uniform, F / (width * depth)."""
    p = _validate("flat_plates", PLATE_PARAMS, dict(locals()))
    mobile, fixed = _plates(p["width_mm"], p["depth_mm"], p["gap_mm"], 0.0, p["n_per_side"])
    return BuiltGeometry(
        mobile=mobile, fixed=fixed, reference_point_mm=None,
        ankle_axis_point_mm=np.zeros(3), ankle_axis_direction=np.array([1.0, 0.0, 0.0]),
        ligaments=(),
        description=(f"Flat plate {p['width_mm']:g} x {p['depth_mm']:g} mm under a parallel plane "
                     f"{p['gap_mm']:g} mm above: uniform spring length, uniform pressure F/A "
                     "(closed form). The ankle axis is nominal (x through the origin)."),
        parameters=p,
    )


def tilted_plane(width_mm: float = 20.0, depth_mm: float = 20.0, gap_mm: float = 2.0,
                 tilt_deg: float = 2.0, n_per_side: int = 20) -> BuiltGeometry:
    """Square plate (as in :func:`flat_plates`) under a plane through (0, 0, gap_mm) tilted about
    the y axis: the spring length is h(x) = gap_mm + x tan(tilt_deg), exact for every centroid;
    under a rigid normal approach d the pressure is p = E' d / h(x) (closed form). The plane must
    stay above the plate: gap_mm > width/2 * |tan(tilt)|."""
    p = _validate("tilted_plane", TILTED_PARAMS, dict(locals()))
    if p["width_mm"] / 2 * abs(math.tan(math.radians(p["tilt_deg"]))) >= p["gap_mm"]:
        raise InputError("tilted_plane: the tilted plane would touch or cut the plate",
                         key="geometry.tilt_deg",
                         expected=f"width_mm/2 * |tan(tilt)| < gap_mm ({p['gap_mm']:g})")
    mobile, fixed = _plates(p["width_mm"], p["depth_mm"], p["gap_mm"], p["tilt_deg"],
                            p["n_per_side"])
    return BuiltGeometry(
        mobile=mobile, fixed=fixed, reference_point_mm=None,
        ankle_axis_point_mm=np.zeros(3), ankle_axis_direction=np.array([1.0, 0.0, 0.0]),
        ligaments=(),
        description=(f"Flat plate {p['width_mm']:g} x {p['depth_mm']:g} mm under a plane tilted "
                     f"{p['tilt_deg']:g} deg about y, h(x) = {p['gap_mm']:g} + x tan(tilt): "
                     "closed-form pressure p = E' d / h(x). The ankle axis is nominal."),
        parameters=p,
    )


# --------------------------------------------------------------------------------------------
# d. subject-like ankle
# --------------------------------------------------------------------------------------------

#: documented anatomical ranges of the subject-like parameters; ``seed`` draws uniformly in them
SUBJECT_RANGES: dict[str, tuple[float, float]] = {
    # sagittal radius of the talar trochlea: typically ~17-24 mm in adults
    "talar_radius_mm": (17.0, 24.0),
    # mean trochlear (dome) width: ~25-32 mm
    "talar_width_mm": (25.0, 32.0),
    # the trochlea is wider anteriorly than posteriorly, by ~2-6 mm
    "anterior_widening_mm": (2.0, 6.0),
    # sagittal arc of the trochlear articular surface: ~100-125 deg
    "talar_arc_deg": (100.0, 125.0),
    # depth of the shallow central sagittal groove of the trochlea: ~0.5-2 mm
    "groove_depth_mm": (0.5, 2.0),
    # drop of the medial/lateral trochlear rims below the cylinder (rounded shoulders): ~0.5-2 mm
    "rim_rolloff_mm": (0.5, 2.0),
    # sagittal incongruity R_tibia / R_talus - 1: the plafond is slightly flatter, ~2-30 %
    "incongruity": (0.02, 0.30),
    # antero-posterior (arc) length of the tibial plafond, shorter than the talar trochlea:
    # ~26-36 mm
    "plafond_length_mm": (26.0, 36.0),
    # bone-to-bone gap at the dome top (two cartilage layers, ~1.5-3 mm in total)
    "plafond_gap_mm": (1.5, 3.0),
    # depth of the two shallow plafond depressions (thesis subject): ~0.8-2.5 mm
    "depression_depth_mm": (0.8, 2.5),
    # medio-lateral tilt of the plafond relative to the talar axis: ~0-4 deg (lateral closer)
    "tilt_deg": (0.0, 4.0),
    # gap between the medial talar rim and the medial malleolus facet: ~1-2.5 mm
    "malleolus_gap_mm": (1.0, 2.5),
}

#: depression centres (x_mm, s_mm) on the plafond, ranges as fractions: x of the talar half
#: width (+ lateral), s of the plafond half arc length (+ anterior). The first (larger, radius
#: 0.20 W) sits on the lateral border, the second (smaller, radius 0.13 W) nearer the centre,
#: like the thesis subject's two non-contact areas.
SUBJECT_DEPRESSION_RANGES = (((0.45, 0.80), (-0.35, 0.35)), ((-0.10, 0.40), (-0.55, 0.55)))
_SUBJECT_DEPRESSION_DEFAULTS = ((0.62, 0.10), (0.15, -0.30))
_SUBJECT_DEPRESSION_RADII = (0.20, 0.13)  # fractions of the talar width

SUBJECT_DEFAULTS: dict[str, float] = {
    "talar_radius_mm": 20.0,
    "talar_width_mm": 28.0,
    "anterior_widening_mm": 4.0,
    "talar_arc_deg": 114.0,
    "groove_depth_mm": 1.0,
    "rim_rolloff_mm": 1.5,
    "incongruity": 0.08,
    "plafond_length_mm": 29.0,
    "plafond_gap_mm": 2.5,
    "depression_depth_mm": 1.5,
    "tilt_deg": 2.0,
    "malleolus_gap_mm": 1.5,
}

SUBJECT_PARAMS: dict[str, _P] = {"seed": _P("seed", 0, None)}
SUBJECT_PARAMS.update({k: _P("float_or_none", lo, hi) for k, (lo, hi) in SUBJECT_RANGES.items()})
SUBJECT_PARAMS["depression_positions"] = _P("pairs", length=2)
SUBJECT_PARAMS["mesh_size_mm"] = _P("float_or_none", 0.05, 50.0)
SUBJECT_PARAMS["fixed_mesh_size_mm"] = _P("float_or_none", 0.05, 50.0)

_SUBJECT_DEFAULT_SIZE = 0.93  # mm, ~3000 talar triangles for the default talus


def _plateau(rho: np.ndarray) -> np.ndarray:
    """Depression profile: 1 for rho <= 0.35, a cos^2 shoulder down to 0 at rho = 1, then 0."""
    t = np.clip((rho - 0.35) / 0.65, 0.0, 1.0)
    return np.cos(0.5 * np.pi * t) ** 2


def _subject_talus_radius(x: np.ndarray, u: np.ndarray, R: float, hw_of_u: Callable,
                          groove_depth: float, groove_half: float, rim: float) -> np.ndarray:
    groove = np.where(np.abs(x) < groove_half,
                      groove_depth * np.cos(np.pi * x / (2.0 * groove_half)) ** 2, 0.0)
    hw = hw_of_u(u)
    t = np.clip((np.abs(x) - 0.6 * hw) / (0.4 * hw), 0.0, None)
    return R - groove - rim * t ** 2


def subject_ankle(
    seed: int | None = None,
    talar_radius_mm: float | None = None,
    talar_width_mm: float | None = None,
    anterior_widening_mm: float | None = None,
    talar_arc_deg: float | None = None,
    groove_depth_mm: float | None = None,
    rim_rolloff_mm: float | None = None,
    incongruity: float | None = None,
    plafond_length_mm: float | None = None,
    plafond_gap_mm: float | None = None,
    depression_depth_mm: float | None = None,
    depression_positions: tuple[tuple[float, float], tuple[float, float]] | None = None,
    tilt_deg: float | None = None,
    malleolus_gap_mm: float | None = None,
    mesh_size_mm: float | None = None,
    fixed_mesh_size_mm: float | None = None,
) -> BuiltGeometry:
    """Subject-like talar dome and tibial plafond with seeded anatomical variation (docs/method.md#8-built-in-geometries).

    Parameters (documented ranges in :data:`SUBJECT_RANGES`, defaults in
    :data:`SUBJECT_DEFAULTS`): with ``seed=None`` every unset parameter takes its default; with
    an integer ``seed`` every parameter is drawn uniformly within its range by
    ``numpy.random.default_rng(seed)`` (all parameters are always drawn in a fixed order, so an
    explicit value overrides only its own draw and leaves the others unchanged).

    Talus (mobile): a trochlea in cylinder-like form about the ankle axis (x through
    (0, 0, -R)); at arc length u (u > 0 anterior) and medio-lateral x its radius is
    R - groove(x) - rim(x, u): a shallow central sagittal groove (cos^2 profile, half-width
    0.3 W, depth ``groove_depth_mm``) and a quadratic roll-off of the outer 40 % towards the rims
    (``rim_rolloff_mm`` at the rim). The outline in (x, u) is a trapezoid, wider anteriorly
    (width W + widening/2 at the anterior end, W - widening/2 at the posterior end).

    Tibia (fixed): the plafond is a concave cylinder-like surface of radius R_t = R (1 +
    ``incongruity``) (slightly flatter than the talus, i.e. incongruent), touching height
    ``plafond_gap_mm`` above the talar cylinder at the top, ``plafond_length_mm`` long (arc
    length, antero-posterior, centred on the top), following the talar groove with a matching
    ridge (medio-lateral congruence), with two shallow flat-bottomed depressions (plateau over
    0.35 of the radius, cos^2 shoulder; radii 0.20 W and 0.13 W) of depth
    ``depression_depth_mm`` (the larger on the lateral border, the smaller nearer the centre;
    centres ``depression_positions`` as (x_mm, s_mm), s = arc length along the plafond,
    + anterior) like the thesis subject's two non-contact areas; it reaches laterally 2 mm
    beyond the widest talar rim. The medial malleolus is a vertical wall
    x = -(W/2 + widening/4 + ``malleolus_gap_mm``) (medial of the widest talar rim) facing
    laterally, from the plafond's medial edge 0.6 R down, meshed together with the plafond
    (shared edge). The whole tibia is tilted by ``tilt_deg`` about the y axis through the
    plafond top (lateral side closer), as in the idealised model. The talus lies entirely
    lateral of the malleolus wall, so a talar ray can only meet the wall's front (talus-facing)
    side; only rays from the rolled-off medial rim can reach it at all, and for the default and
    typical seeds none does within 3.5 mm.

    Meshing: each surface is a planar parameter domain ((x, u) for the talus; (x, s) for the
    plafond, unfolded with the malleolus (distance below the plafond edge) beside it) meshed
    with gmsh (Frontal-Delaunay, deterministic) and mapped onto the surface by the formulas
    above; the maps are close to isometric, so triangle sizes stay near ``mesh_size_mm``
    (default 0.93 mm: ~3000 talar triangles for the default talus; the fixed surface uses
    ``fixed_mesh_size_mm``, default the same).

    Ligaments: :func:`_ligaments` with this talus's radius and mean half width (plausible
    placements, not measured).
    """
    given = dict(locals())
    checked = _validate("subject_ankle", SUBJECT_PARAMS, given)
    seed = checked["seed"]

    # --- draw (always every parameter, fixed order) then override with explicit values
    resolved: dict[str, Any] = {}
    rng = np.random.default_rng(seed) if seed is not None else None
    for name, (lo, hi) in SUBJECT_RANGES.items():
        drawn = float(rng.uniform(lo, hi)) if rng is not None else SUBJECT_DEFAULTS[name]
        resolved[name] = checked[name] if checked[name] is not None else drawn
    fr_pos = []
    for (xr, sr), default in zip(SUBJECT_DEPRESSION_RANGES, _SUBJECT_DEPRESSION_DEFAULTS):
        if rng is not None:
            fr_pos.append((float(rng.uniform(*xr)), float(rng.uniform(*sr))))
        else:
            fr_pos.append(default)

    R = resolved["talar_radius_mm"]
    W = resolved["talar_width_mm"]
    widen = resolved["anterior_widening_mm"]
    arc = math.radians(resolved["talar_arc_deg"])
    Rt = R * (1.0 + resolved["incongruity"])
    g = resolved["plafond_gap_mm"]
    U = R * arc / 2.0  # talar half arc length
    S = resolved["plafond_length_mm"] / 2.0  # plafond half arc length
    hw_max = W / 2.0 + widen / 4.0
    if checked["depression_positions"] is not None:
        positions = checked["depression_positions"]
        for i, (x0, s0) in enumerate(positions):
            if not (-hw_max <= x0 <= hw_max and -S <= s0 <= S):
                raise InputError(
                    f"subject_ankle: depression {i + 1} centre ({x0:g}, {s0:g}) is off the plafond",
                    key="geometry.depression_positions",
                    expected=f"x in [{-hw_max:.3g}, {hw_max:.3g}] mm, s in [{-S:.3g}, {S:.3g}] mm",
                )
    else:
        positions = tuple((fx * W / 2.0, fs * S) for fx, fs in fr_pos)
    resolved["depression_positions"] = tuple((float(a), float(b)) for a, b in positions)
    radii = tuple(f * W for f in _SUBJECT_DEPRESSION_RADII)
    size = checked["mesh_size_mm"] if checked["mesh_size_mm"] is not None else _SUBJECT_DEFAULT_SIZE
    fsize = checked["fixed_mesh_size_mm"] if checked["fixed_mesh_size_mm"] is not None else size
    resolved["mesh_size_mm"] = size
    resolved["fixed_mesh_size_mm"] = fsize
    resolved = {"seed": seed, **resolved}
    groove_half = 0.3 * W
    dgroove = resolved["groove_depth_mm"]
    rim = resolved["rim_rolloff_mm"]

    def hw_of_u(u: np.ndarray) -> np.ndarray:
        return W / 2.0 + (widen / 4.0) * (np.asarray(u) / U)

    # --- talus: mesh the trapezoid (x, u), map onto the trochlea
    talus_poly = [(-hw_of_u(-U), -U), (hw_of_u(-U), -U), (hw_of_u(U), U), (-hw_of_u(U), U)]
    q, tt, _ = _mesh_planar_domain("subject_talus", [[(float(a), float(b)) for a, b in talus_poly]],
                                   size)
    x, u = q[:, 0], q[:, 1]
    r = _subject_talus_radius(x, u, R, hw_of_u, dgroove, groove_half, rim)
    psi = u / R
    tv = np.column_stack([x, r * np.sin(psi), -R + r * np.cos(psi)])
    cen = tv[tt].mean(axis=1)
    expected = cen - np.array([0.0, 0.0, -R])
    expected[:, 0] = 0.0
    tt = _orient_like(tv, tt, expected, "subject_ankle talus")
    mobile = TriangleSurface(tv, tt, name="subject-like talus", source="subject_ankle")

    # --- tibia: plafond (x, s) + unfolded malleolus (x < medial_x)
    medial_x = -(hw_max + resolved["malleolus_gap_mm"])
    lateral_x = hw_max + 2.0
    mall_depth = 0.6 * R
    plaf = [(medial_x, -S), (lateral_x, -S), (lateral_x, S), (medial_x, S)]
    mall = [(medial_x - mall_depth, -S), (medial_x, -S), (medial_x, S), (medial_x - mall_depth, S)]
    q2, ft, region = _mesh_planar_domain("subject_tibia", [plaf, mall], fsize)
    xs, ss = q2[:, 0], q2[:, 1]
    xe = np.maximum(xs, medial_x)  # on the plafond (malleolus points use the medial edge)
    below = np.maximum(medial_x - xs, 0.0)  # distance below the plafond edge (malleolus)
    groove_t = np.where(np.abs(xe) < groove_half,
                        dgroove * np.cos(np.pi * xe / (2.0 * groove_half)) ** 2, 0.0)
    dep = np.zeros_like(xs)
    for (x0, s0), rad in zip(resolved["depression_positions"], radii):
        d = np.hypot(xe - x0, ss - s0)
        dep += resolved["depression_depth_mm"] * _plateau(d / rad)
    rt = Rt - groove_t + dep
    psi_t = ss / Rt
    fv = np.column_stack([xe, rt * np.sin(psi_t), (g - Rt) + rt * np.cos(psi_t) - below])
    pivot = np.array([0.0, 0.0, g])
    tilt = math.radians(resolved["tilt_deg"])
    fv = (fv - pivot) @ _rot_y(tilt).T + pivot
    # expected normals: plafond towards the tibial axis (down), malleolus lateral (+x)
    fcen = np.column_stack([xe, rt * np.sin(psi_t), (g - Rt) + rt * np.cos(psi_t)])[ft].mean(axis=1)
    exp_n = np.column_stack([np.zeros(len(ft)), -fcen[:, 1], -(fcen[:, 2] - (g - Rt))])
    exp_n[region == 1] = np.array([1.0, 0.0, 0.0])
    exp_n = exp_n @ _rot_y(tilt).T
    ft = _orient_like(fv, ft, exp_n, "subject_ankle tibia")
    fixed = TriangleSurface(fv, ft, name="subject-like tibia (plafond + medial malleolus)",
                            source="subject_ankle")

    description = (
        "Subject-like ankle (docs/method.md#8-built-in-geometries): parametric talar trochlea (radius "
        f"{R:.2f} mm, width {W:.2f} mm, {widen:.2f} mm wider anteriorly, arc "
        f"{resolved['talar_arc_deg']:.1f} deg, central groove {dgroove:.2f} mm, rim roll-off "
        f"{rim:.2f} mm; {mobile.n_triangles} triangles) under an incongruent plafond (radius "
        f"{Rt:.2f} mm, length {2 * S:.1f} mm, gap {g:.2f} mm, two depressions "
        f"{resolved['depression_depth_mm']:.2f} mm deep, radii {radii[0]:.1f} and "
        f"{radii[1]:.1f} mm, tilt {resolved['tilt_deg']:.2f} deg) "
        f"with a medial malleolus wall ({fixed.n_triangles} triangles); "
        + (f"parameters drawn with seed {seed} within documented anatomical ranges"
           if seed is not None else "default parameters")
        + ". Both surfaces: gmsh-meshed planar domains mapped onto the parametric surfaces. "
        "Ligament attachments are plausible anatomical placements, not measured."
    )
    return BuiltGeometry(
        mobile=mobile,
        fixed=fixed,
        reference_point_mm=None,
        ankle_axis_point_mm=np.array([0.0, 0.0, -R]),
        ankle_axis_direction=np.array([1.0, 0.0, 0.0]),
        ligaments=_ligaments(R, W / 2.0, medial_x - 2.0, hw_max + 6.0, _rot_y(tilt), pivot),
        description=description,
        parameters=resolved,
    )


# --------------------------------------------------------------------------------------------
# registry
# --------------------------------------------------------------------------------------------

_BUILDERS: dict[str, tuple[Callable[..., BuiltGeometry], dict[str, _P]]] = {
    "ideal_ankle": (ideal_ankle, IDEAL_ANKLE_PARAMS),
    "hemispheres": (hemispheres, HEMISPHERE_PARAMS),
    "subject_ankle": (subject_ankle, SUBJECT_PARAMS),
    "flat_plates": (flat_plates, PLATE_PARAMS),
    "tilted_plane": (tilted_plane, TILTED_PARAMS),
}


def builder_names() -> tuple[str, ...]:
    """Names accepted by :func:`build_geometry`."""
    return tuple(_BUILDERS)


def builder_defaults(name: str) -> dict[str, Any]:
    """Keyword defaults of a builder (``None`` = derived at build time)."""
    func = _BUILDERS[name][0]
    return {k: v.default for k, v in inspect.signature(func).parameters.items()}


#: Built geometries kept per process, most recent last: (builder function, parameters as JSON) ->
#: (the geometry, the warnings its build emitted). A campaign worker builds the same geometry
#: for hundreds of cases (the sensitivity grid varies the cartilage, not the bones); meshing is
#: deterministic (module docstring), so a kept geometry is the one a new build would give.
_BUILT: collections.OrderedDict[tuple[Callable[..., BuiltGeometry], str], tuple[BuiltGeometry, tuple[warnings.WarningMessage, ...]]] = collections.OrderedDict()
#: geometries kept: a few (a population's subjects differ, so there the cache only misses)
BUILT_CACHE_SIZE = 4


def _cache_key(func: Callable[..., BuiltGeometry], params: dict[str, Any]) -> tuple[Callable[..., BuiltGeometry], str] | None:
    """The cache key of a build, or None for parameters with no exact JSON text (never cached).

    JSON keeps every float exactly (repr) and tells 1 from 1.0 and true from 1, so two
    parameter sets share a key only when the builder sees the same values. The function, not
    its registered name, is part of the key: a builder replaced under the same name is a miss."""
    try:
        return func, json.dumps(params, sort_keys=True, allow_nan=False)
    except (TypeError, ValueError):
        return None


def clear_geometry_cache() -> None:
    """Forget the built geometries kept by :func:`build_geometry`."""
    _BUILT.clear()


def build_geometry(name: str, params: dict, *, file: str | None = None) -> BuiltGeometry:
    """Build the named geometry with ``params`` (a scene file's ``[geometry]`` parameters).

    The last :data:`BUILT_CACHE_SIZE` geometries are kept per process: a repeated build returns
    a copy of the kept one (the caller may change it freely) and emits again the warnings the
    first build emitted, so each caller sees the same geometry and the same warnings as from a
    fresh build, without meshing again.

    Raises :class:`InputError` (with ``file`` and key ``geometry.<param>``) for an unknown
    builder, unknown parameters, wrong types or out-of-range values.
    """
    if not isinstance(name, str) or name not in _BUILDERS:
        raise InputError(
            f"unknown geometry builder '{name}'",
            file=file,
            key="geometry.builtin",
            expected="one of " + ", ".join(_BUILDERS),
        )
    func, specs = _BUILDERS[name]
    params = dict(params or {})
    try:
        _validate(name, specs, params)
        key = _cache_key(func, params)
        if key is None:
            return func(**params)
        if key in _BUILT:
            _BUILT.move_to_end(key)
            kept, caught = _BUILT[key]
            built = copy.deepcopy(kept)
        else:
            with warnings.catch_warnings(record=True) as record:
                warnings.simplefilter("always")  # every warning kept, to be re-emitted on each build
                built = func(**params)
            caught = tuple(record)
            _BUILT[key] = (copy.deepcopy(built), caught)
            while len(_BUILT) > BUILT_CACHE_SIZE:
                _BUILT.popitem(last=False)
        for w in caught:  # where the builder emitted it and never deduplicated: each build reports its own
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno, source=w.source)
        return built
    except InputError as err:
        if file is not None and err.file is None:
            raise InputError(err.problem, file=file, key=err.key, expected=err.expected) from None
        raise
