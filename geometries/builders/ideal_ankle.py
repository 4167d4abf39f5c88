"""a. The idealised ankle of the thesis (section 4.3.3): a gmsh-meshed cylindrical talus under a
planar tibia (docs/method.md#8-built-in-geometries)."""

from __future__ import annotations

import math

import numpy as np

from geometries.builders.common import BuiltGeometry, Param, ankle_ligaments, rotation_about_y, validate_parameters
from geometries.builders.gmsh_session import gmsh_model, gmsh_triangles, orient_like
from geometries.errors import InputError
from geometries.surface import TriangleSurface


IDEAL_ANKLE_PARAMS = {
    "radius_mm": Param("float", 1.0, 200.0, lo_open=True),
    "width_mm": Param("float", 1.0, 200.0, lo_open=True),
    "arc_deg": Param("float", 1.0, 179.0),
    "plafond_gap_mm": Param("float", 0.0, 50.0, lo_open=True),
    "plafond_tilt_deg": Param("float", -15.0, 15.0),
    "malleolus": Param("bool"),
    "malleolus_gap_mm": Param("float", 0.0, 50.0, lo_open=True),
    "mesh_size_mm": Param("float_or_none", 0.05, 50.0),
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
    :func:`ankle_ligaments` (plausible placements, not measured).
    """
    given = {k: v for k, v in locals().items()}
    p = validate_parameters("ideal_ankle", IDEAL_ANKLE_PARAMS, given)
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
        verts, tris = gmsh_triangles(gmsh)
    # project to the exact cylinder (gmsh nodes are on it to round-off already)
    radial = verts - np.array([0.0, 0.0, -R])
    radial[:, 0] = 0.0
    rad_len = np.linalg.norm(radial, axis=1)
    verts[:, 1:] = np.array([0.0, -R]) + radial[:, 1:] * (R / rad_len)[:, None]
    cent = verts[tris].mean(axis=1)
    expected = cent - np.array([0.0, 0.0, -R])
    expected[:, 0] = 0.0
    tris = orient_like(verts, tris, expected, "ideal_ankle talus")
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
    fv = (fv - pivot) @ rotation_about_y(tilt).T + pivot
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
        ligaments=ankle_ligaments(R, W / 2.0, medial_x - 2.0, W / 2.0 + 6.0, rotation_about_y(tilt), pivot),
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
