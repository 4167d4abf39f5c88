"""a. The idealised ankle: a gmsh-meshed cylindrical talus under the tibia, with articular cartilage
on both bones (the default), or the thesis's (section 4.3.3) planar plafond without it
(docs/method.md#8-built-in-geometries)."""

from __future__ import annotations

import math

import numpy as np

from geometries.builders.articular import (DEFAULT_TALAR_MM, DEFAULT_TAPER_MM, DEFAULT_TIBIAL_MM, layer_thickness_mm,
                                           talus_with_cartilage, tibia_with_cartilage)
from geometries.builders.common import BuiltGeometry, Param, ankle_geometry, ankle_ligaments, lifted, mode_parameters, rotation_about_y, validate_parameters
from geometries.builders.gmsh_session import gmsh_model, gmsh_triangles, orient_like
from geometries.errors import InputError
from geometries.surface import TriangleSurface


IDEAL_ANKLE_PARAMS = {
    "radius_mm": Param("float", 1.0, 200.0, lo_open=True),
    "width_mm": Param("float", 1.0, 200.0, lo_open=True),
    "arc_deg": Param("float", 1.0, 179.0),
    "cartilage": Param("bool"),
    "talar_cartilage_mm": Param("float_or_none", 0.0, 5.0, lo_open=True),
    "tibial_cartilage_mm": Param("float_or_none", 0.0, 5.0, lo_open=True),
    "cartilage_taper_mm": Param("float_or_none", 0.0, 50.0, lo_open=True),
    "incongruity": Param("float_or_none", 0.0, 2.0, lo_open=True),
    "plafond_length_mm": Param("float_or_none", 1.0, 200.0),
    "plafond_gap_mm": Param("float_or_none", 0.0, 50.0, lo_open=True),
    "plafond_tilt_deg": Param("float_or_none", -15.0, 15.0),
    "malleolus": Param("bool"),
    "malleolus_gap_mm": Param("float", 0.0, 50.0, lo_open=True),
    "mesh_size_mm": Param("float_or_none", 0.05, 50.0),
}
#: the parameters of one mode only: the thesis's planar plafond (``cartilage = false``) or the
#: bones with cartilage (``cartilage = true``), each with its defaults
IDEAL_THESIS_DEFAULTS = {"plafond_gap_mm": 1.5, "plafond_tilt_deg": 2.0}
IDEAL_CARTILAGE_DEFAULTS = {
    "talar_cartilage_mm": DEFAULT_TALAR_MM,
    "tibial_cartilage_mm": DEFAULT_TIBIAL_MM,
    "cartilage_taper_mm": DEFAULT_TAPER_MM,
    "incongruity": 0.08,
    "plafond_length_mm": 30.0,
    "plafond_tilt_deg": 0.0,
}

#: mesh size (relative to the radius) that gives ~3000 triangles for the default patch
_IDEAL_DEFAULT_SIZE_PER_R = 0.047


def ideal_ankle(
    radius_mm: float = 20.0,
    width_mm: float = 28.0,
    arc_deg: float = 114.0,
    cartilage: bool = True,
    talar_cartilage_mm: float | None = None,
    tibial_cartilage_mm: float | None = None,
    cartilage_taper_mm: float | None = None,
    incongruity: float | None = None,
    plafond_length_mm: float | None = None,
    plafond_gap_mm: float | None = None,
    plafond_tilt_deg: float | None = None,
    malleolus: bool = True,
    malleolus_gap_mm: float = 1.5,
    mesh_size_mm: float | None = None,
) -> BuiltGeometry:
    """Idealised ankle: a cylindrical talus under the tibia, with cartilage on both bones, or the thesis's (section 4.3.3).

    Talus (mobile): the patch of a cylinder of radius ``radius_mm`` whose axis runs along x
    through (0, 0, -R) (so the dome top is at z = 0), ``width_mm`` wide in x (centred on x = 0)
    and spanning ``arc_deg`` centred on the top. Its area is R * arc * width (11.15 cm^2 for the
    defaults, the thesis's talar articular area). Meshed with gmsh (OpenCASCADE circle arc
    extruded along x, Frontal-Delaunay); the default ``mesh_size_mm`` (0.047 R = 0.94 mm) gives
    about 3000 triangles (thesis: 2974).

    With ``cartilage = true`` (the default; docs/method.md#8-built-in-geometries) that cylinder
    is the talar subchondral bone and both bodies carry an articular layer
    (:mod:`geometries.builders.articular`):

      * talus: the scene's mobile surface is the articular surface, the bone moved out along its
        radius by ``talar_cartilage_mm`` (default 1.3) times the taper of each margin over
        ``cartilage_taper_mm`` (default 3): 0 on the patch's edges, the centre value from 3 mm
        inside them;
      * tibia: the plafond is a concave cylinder about an axis along x, its articular surface of
        radius R_F = (R + t_talus) (1 + ``incongruity``) (default 0.08: flatter than the talar
        articular surface, so the two do not conform), ``plafond_length_mm`` (default 30) long
        (arc length, centred over the dome) and as wide as the talus plus ``malleolus_gap_mm`` on
        each side; its bone lies ``tibial_cartilage_mm`` (default 1.4) above it, the layer tapered
        at the plafond's margins as the talar one. ``plafond_tilt_deg`` (default 0) turns the
        tibia about y. The tibia is lifted until its articular surface touches the talar one (a
        line along x over the dome top without tilt, a point with it; the meshes to 1e-4 mm, so
        that no spring starts compressed): the patch grows from there with the load;
      * the malleolus (``malleolus=True``): the vertical wall x = -(width/2 +
        ``malleolus_gap_mm``) facing laterally, 0.6 R deep below the plafond's medial edge,
        with a uniform layer of the tibial thickness (its bone the wall moved medially); the
        dome's rays never reach it.

    The bones are ``mobile_bone`` and ``fixed_bone`` of the result: a scene reads its measured
    thickness from them as from bone mesh files (docs/method.md#measured-cartilage-thickness).

    With ``cartilage = false`` the thesis's geometry, without cartilage, two planes for the tibia
    (the thesis needed 4 triangles for them):

      * plafond: a plane ``plafond_gap_mm`` (default 1.5) above the dome top, facing down, tilted
        about the y axis (through the point above the dome top) by ``plafond_tilt_deg`` (default
        2); a positive tilt brings the lateral (+x) side closer to the talus. The thesis explains
        its medio-lateral pressure asymmetry (peak laterally, decreasing medially, minimum
        thickness laterally) by the talar cylinder being tilted relative to the load; we keep the
        cylinder on the ankle axis (x) and tilt the plafond instead by a small default 2 deg (gap
        1.01 mm at the lateral edge, 1.99 mm at the medial edge). The spring length along the
        radial ray at angle phi from the top is (R + g(x)) / cos(phi) - R with g(x) = gap - x
        tan(tilt), so with h_max = 3.5 mm and no tilt the candidate fraction is 2 acos((R+g)/(R+h_max))
        / arc = 41.8 % (thesis: 42 %); the default 2 deg tilt keeps it at ~41.6 %. The plafond
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

    A parameter of the other mode is refused (``plafond_gap_mm`` places the thesis's plafond;
    the cartilage parameters need ``cartilage = true``).

    Ankle axis: the cylinder axis, point (0, 0, -R), direction +x. Ligaments: see
    :func:`ankle_ligaments` (plausible placements, not measured).
    """
    given = {k: v for k, v in locals().items()}
    p = validate_parameters("ideal_ankle", IDEAL_ANKLE_PARAMS, given)
    p = mode_parameters("ideal_ankle", p, IDEAL_THESIS_DEFAULTS, IDEAL_CARTILAGE_DEFAULTS)
    R, W, arc = p["radius_mm"], p["width_mm"], math.radians(p["arc_deg"])
    tilt = math.radians(p["plafond_tilt_deg"])
    size = p["mesh_size_mm"] if p["mesh_size_mm"] is not None else _IDEAL_DEFAULT_SIZE_PER_R * R
    p["mesh_size_mm"] = size
    if p["cartilage"]:
        return _ideal_with_cartilage(p, R, W, arc, tilt, size)
    g = p["plafond_gap_mm"]
    if abs(W / 2.0 * math.tan(tilt)) >= g:
        raise InputError(
            "ideal_ankle: the tilted plafond would cut into the talus at its edge",
            key="geometry.plafond_tilt_deg",
            expected=f"|tan(tilt)| * width/2 < plafond_gap_mm ({g:g} mm)",
        )
    if p["malleolus"]:
        _check_malleolus(R, W, arc, tilt, g, p["malleolus_gap_mm"])

    verts, tris = _talus_mesh(R, W, arc, size)
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
        + "; no cartilage (the thesis's idealisation). Ligament attachments are plausible anatomical placements, not measured."
    )
    return ankle_geometry(R, mobile, fixed, ankle_ligaments(R, W / 2.0, medial_x - 2.0, W / 2.0 + 6.0, rotation_about_y(tilt), pivot), description, p)


def _check_malleolus(R: float, W: float, arc: float, tilt: float, pivot_z: float, malleolus_gap: float) -> None:
    """The tilted malleolus wall x(z) = (m + sin(tilt) (z - z_p)) / cos(tilt) (turned about y through
    (0, 0, z_p)) must stay medial of the talus down to the talus's lowest point."""
    m = -(W / 2.0 + malleolus_gap)
    z_low = -R * (1.0 - math.cos(arc / 2.0))
    if (m + math.sin(tilt) * (z_low - pivot_z)) / math.cos(tilt) >= -W / 2.0:
        raise InputError(
            "ideal_ankle: the tilted medial malleolus would cut into the talus",
            key="geometry.plafond_tilt_deg",
            expected="a smaller (or positive) tilt, or a larger malleolus_gap_mm",
        )


def _talus_mesh(R: float, W: float, arc: float, size: float) -> tuple[np.ndarray, np.ndarray]:
    """The cylinder patch (vertices on the exact cylinder, normals outward): gmsh OCC arc extruded along x."""
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
    return verts, orient_like(verts, tris, expected, "ideal_ankle talus")


def _ideal_with_cartilage(p: dict, R: float, W: float, arc: float, tilt: float, size: float) -> BuiltGeometry:
    """:func:`ideal_ankle` with ``cartilage = true``: the bones, their layers, the tibia placed touching."""
    t_talus, t_tibia, taper = p["talar_cartilage_mm"], p["tibial_cartilage_mm"], p["cartilage_taper_mm"]
    half_width, half_arc_mm, half_length = W / 2.0, R * arc / 2.0, p["plafond_length_mm"] / 2.0
    medial_x = -(half_width + p["malleolus_gap_mm"])
    lateral_x = half_width + p["malleolus_gap_mm"]
    narrowest = min(half_width, half_arc_mm, half_length)
    if taper > narrowest:
        raise InputError(
            f"ideal_ankle: a {taper:g} mm taper leaves no plateau of the centre thickness on a layer {2 * narrowest:g} mm across",
            key="geometry.cartilage_taper_mm", expected=f"at most {narrowest:g} mm (half the narrowest of width_mm, the talar arc length and plafond_length_mm)",
        )
    radius_f = (R + t_talus) * (1.0 + p["incongruity"])  # the plafond's articular radius
    if half_length / radius_f > math.radians(80.0):
        raise InputError(
            f"ideal_ankle: a plafond {p['plafond_length_mm']:g} mm long wraps {math.degrees(2 * half_length / radius_f):.0f} deg round the talus",
            key="geometry.plafond_length_mm", expected=f"at most {2 * radius_f * math.radians(80.0):.3g} mm (160 deg of its radius)",
        )
    pivot = np.array([0.0, 0.0, t_talus])  # over the dome top, on the talar articular surface
    if p["malleolus"]:
        _check_malleolus(R, W, arc, tilt, t_talus, p["malleolus_gap_mm"])

    def talar_thickness(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return layer_thickness_mm(t_talus, taper, half_width - np.abs(x), half_arc_mm - np.abs(u))

    verts, tris = _talus_mesh(R, W, arc, size)
    params = np.column_stack([verts[:, 0], R * np.arctan2(verts[:, 1], verts[:, 2] + R)])
    mobile, mobile_bone = talus_with_cartilage(params, tris, R, lambda x, u: np.full(np.shape(x), R), talar_thickness, "ideal_ankle")

    def tibial_thickness(x: np.ndarray, s: np.ndarray) -> np.ndarray:
        return layer_thickness_mm(t_tibia, taper, np.minimum(x - medial_x, lateral_x - x), half_length - np.abs(s))

    rotation = rotation_about_y(tilt)
    fixed, fixed_bone, lift, touch = tibia_with_cartilage(
        "ideal_ankle", medial_x, lateral_x, half_length, 0.6 * R if p["malleolus"] else 0.0, radius_f, t_talus - radius_f,
        lambda x, s: np.full(np.shape(x), radius_f + t_tibia), tibial_thickness, t_tibia, rotation, pivot,
        mobile, size)
    description = (
        "Idealised ankle with cartilage (docs/method.md#8-built-in-geometries): talar bone = cylinder patch "
        f"R = {R:g} mm, width {W:g} mm, arc {p['arc_deg']:g} deg, under a {t_talus:g} mm talar layer; tibial "
        f"plafond = concave cylinder, articular radius {radius_f:.2f} mm (incongruity {p['incongruity']:g}), "
        f"{p['plafond_length_mm']:g} mm long, under a {t_tibia:g} mm tibial layer"
        + (f", tilted {p['plafond_tilt_deg']:g} deg about y" if p["plafond_tilt_deg"] else "")
        + (" + medial malleolus wall with its facet's layer" if p["malleolus"] else "")
        + f"; each layer tapered to 0 over {taper:g} mm at its margin; the articular surfaces touch at "
        f"({touch[0]:.1f}, {touch[1]:.1f}, {touch[2]:.2f}) mm at zero load ({mobile.n_triangles} talar, "
        f"{fixed.n_triangles} tibial triangles, gmsh, size {size:.3g} mm). Ligament attachments are plausible "
        "anatomical placements, not measured."
    )
    ligaments = lifted(ankle_ligaments(R, half_width, medial_x - 2.0, half_width + 6.0, rotation, pivot), lift)
    return ankle_geometry(R, mobile, fixed, ligaments, description, p, bones=(mobile_bone, fixed_bone), contact_point_mm=touch)


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
