"""d. The subject-like ankle: a talar dome and tibial plafond with seeded anatomical variation, with
articular cartilage on both bones (the default) or without it (the thesis's kind of geometry),
meshed with gmsh (docs/method.md#8-built-in-geometries)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from geometries.builders.articular import (DEFAULT_TALAR_MM, DEFAULT_TAPER_MM, DEFAULT_TIBIAL_MM, layer_thickness_mm,
                                           talus_with_cartilage, tibia_with_cartilage)
from geometries.builders.common import BuiltGeometry, Param, ankle_geometry, ankle_ligaments, lifted, mode_parameters, rotation_about_y, validate_parameters
from geometries.builders.gmsh_session import mesh_planar_domain, orient_like
from geometries.errors import InputError
from geometries.surface import TriangleSurface


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
    # centre thickness of the talar and tibial cartilage (with cartilage = true): a layer whose
    # tapered margins bring its mean to 0.81-0.84 of its centre value, so that the means cover the
    # published ones (docs/references.md: talar 1.10 +- 0.18 mm and tibial 1.16 +- 0.14 mm by
    # stereophotography, talar 1.34 +- 0.14 mm by MRI) within about two standard deviations
    "talar_cartilage_mm": (1.0, 1.7),
    "tibial_cartilage_mm": (1.0, 1.7),
}
#: the parameters of one mode only (docs/method.md#8-built-in-geometries): the thesis's kind of
#: plafond, placed plafond_gap_mm above the talus (cartilage = false), or the bones with cartilage,
#: placed touching (cartilage = true; None: drawn or the default of SUBJECT_DEFAULTS)
SUBJECT_THESIS_ONLY = {"plafond_gap_mm": None}
SUBJECT_CARTILAGE_ONLY = {"talar_cartilage_mm": None, "tibial_cartilage_mm": None, "cartilage_taper_mm": DEFAULT_TAPER_MM}

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
    "talar_cartilage_mm": DEFAULT_TALAR_MM,
    "tibial_cartilage_mm": DEFAULT_TIBIAL_MM,
}

SUBJECT_PARAMS: dict[str, Param] = {"seed": Param("seed", 0, None), "cartilage": Param("bool")}
SUBJECT_PARAMS.update({k: Param("float_or_none", lo, hi) for k, (lo, hi) in SUBJECT_RANGES.items()})
SUBJECT_PARAMS["cartilage_taper_mm"] = Param("float_or_none", 0.0, 50.0, lo_open=True)
SUBJECT_PARAMS["depression_positions"] = Param("pairs", length=2)
SUBJECT_PARAMS["mesh_size_mm"] = Param("float_or_none", 0.05, 50.0)
SUBJECT_PARAMS["fixed_mesh_size_mm"] = Param("float_or_none", 0.05, 50.0)

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
    cartilage: bool = True,
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
    talar_cartilage_mm: float | None = None,
    tibial_cartilage_mm: float | None = None,
    cartilage_taper_mm: float | None = None,
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

    With ``cartilage = true`` (the default) the surfaces above are the subchondral bones and both
    carry an articular layer (:mod:`geometries.builders.articular`), as on the idealised ankle:
    the talar one ``talar_cartilage_mm`` thick at its centre, out along the bone's normal, the
    tibial one ``tibial_cartilage_mm`` towards the plafond's axis, each tapered to 0
    at its margin over ``cartilage_taper_mm`` (default 3); the malleolus wall carries a uniform
    layer of the tibial thickness. The plafond's articular radius is then (R + t_talus) (1 +
    ``incongruity``): it is incongruent with the talar articular surface, keeps its ridge and
    depressions, and the tibia is lifted until the articular surfaces touch (at one point with a
    tilt, the meshes to 1e-4 mm) instead of being placed ``plafond_gap_mm`` above the talus:
    that parameter belongs to ``cartilage = false`` (the thesis's kind of plafond, without
    cartilage) and the thickness parameters to ``cartilage = true``; one given for the other
    mode is refused. The scene's mobile and fixed surfaces are the articular ones; the bones are
    ``mobile_bone`` and ``fixed_bone`` of the result (docs/method.md#measured-cartilage-thickness).

    Ligaments: :func:`ankle_ligaments` with this talus's radius and mean half width (plausible
    placements, not measured).
    """
    given = dict(locals())
    checked = validate_parameters("subject_ankle", SUBJECT_PARAMS, given)
    checked = mode_parameters("subject_ankle", checked, SUBJECT_THESIS_ONLY, SUBJECT_CARTILAGE_ONLY)
    seed, with_cartilage = checked["seed"], checked["cartilage"]

    # --- draw (always every parameter, fixed order) then override with explicit values; the
    # other mode's parameters are drawn too (so that a seed gives the same subject in both) and dropped
    resolved: dict[str, Any] = {"cartilage": with_cartilage}
    rng = np.random.default_rng(seed) if seed is not None else None
    def draw(names: list[str]) -> None:
        for name in names:
            lo, hi = SUBJECT_RANGES[name]
            drawn = float(rng.uniform(lo, hi)) if rng is not None else SUBJECT_DEFAULTS[name]
            if name in checked:
                resolved[name] = checked[name] if checked[name] is not None else drawn

    # the cartilage thicknesses last: the shape and the depressions a seed drew before them stay as they were
    draw([name for name in SUBJECT_RANGES if name not in SUBJECT_CARTILAGE_ONLY])
    fr_pos = []
    for (xr, sr), default in zip(SUBJECT_DEPRESSION_RANGES, _SUBJECT_DEPRESSION_DEFAULTS):
        if rng is not None:
            fr_pos.append((float(rng.uniform(*xr)), float(rng.uniform(*sr))))
        else:
            fr_pos.append(default)
    draw([name for name in SUBJECT_RANGES if name in SUBJECT_CARTILAGE_ONLY])

    R = resolved["talar_radius_mm"]
    W = resolved["talar_width_mm"]
    widen = resolved["anterior_widening_mm"]
    arc = math.radians(resolved["talar_arc_deg"])
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
    if with_cartilage:
        resolved["cartilage_taper_mm"] = checked["cartilage_taper_mm"]
    resolved = {"seed": seed, **resolved}
    groove_half = 0.3 * W
    dgroove = resolved["groove_depth_mm"]
    rim = resolved["rim_rolloff_mm"]

    def hw_of_u(u: np.ndarray) -> np.ndarray:
        return W / 2.0 + (widen / 4.0) * (np.asarray(u) / U)

    # --- talus: mesh the trapezoid (x, u), map onto the trochlea
    talus_poly = [(-hw_of_u(-U), -U), (hw_of_u(-U), -U), (hw_of_u(U), U), (-hw_of_u(U), U)]
    q, tt, _ = mesh_planar_domain("subject_talus", [[(float(a), float(b)) for a, b in talus_poly]],
                                   size)
    medial_x = -(hw_max + resolved["malleolus_gap_mm"])
    lateral_x = hw_max + 2.0
    tilt = math.radians(resolved["tilt_deg"])

    def depressions(x: np.ndarray, s_mm: np.ndarray) -> np.ndarray:
        dep = np.zeros_like(x)
        for (x0, s0), rad in zip(resolved["depression_positions"], radii):
            dep += resolved["depression_depth_mm"] * _plateau(np.hypot(x - x0, s_mm - s0) / rad)
        return dep

    def ridge(x: np.ndarray) -> np.ndarray:
        return np.where(np.abs(x) < groove_half, dgroove * np.cos(np.pi * x / (2.0 * groove_half)) ** 2, 0.0)

    if with_cartilage:
        return _subject_with_cartilage(resolved, q, tt, R, U, S, hw_of_u, medial_x, lateral_x, tilt, ridge, depressions, radii, fsize,
                                       lambda x, u: _subject_talus_radius(x, u, R, hw_of_u, dgroove, groove_half, rim))
    Rt = R * (1.0 + resolved["incongruity"])
    g = resolved["plafond_gap_mm"]
    x, u = q[:, 0], q[:, 1]
    r = _subject_talus_radius(x, u, R, hw_of_u, dgroove, groove_half, rim)
    psi = u / R
    tv = np.column_stack([x, r * np.sin(psi), -R + r * np.cos(psi)])
    cen = tv[tt].mean(axis=1)
    expected = cen - np.array([0.0, 0.0, -R])
    expected[:, 0] = 0.0
    tt = orient_like(tv, tt, expected, "subject_ankle talus")
    mobile = TriangleSurface(tv, tt, name="subject-like talus", source="subject_ankle")

    # --- tibia: plafond (x, s) + unfolded malleolus (x < medial_x)
    mall_depth = 0.6 * R
    plaf = [(medial_x, -S), (lateral_x, -S), (lateral_x, S), (medial_x, S)]
    mall = [(medial_x - mall_depth, -S), (medial_x, -S), (medial_x, S), (medial_x - mall_depth, S)]
    q2, ft, region = mesh_planar_domain("subject_tibia", [plaf, mall], fsize)
    xs, ss = q2[:, 0], q2[:, 1]
    xe = np.maximum(xs, medial_x)  # on the plafond (malleolus points use the medial edge)
    below = np.maximum(medial_x - xs, 0.0)  # distance below the plafond edge (malleolus)
    rt = Rt - ridge(xe) + depressions(xe, ss)
    psi_t = ss / Rt
    fv = np.column_stack([xe, rt * np.sin(psi_t), (g - Rt) + rt * np.cos(psi_t) - below])
    pivot = np.array([0.0, 0.0, g])
    fv = (fv - pivot) @ rotation_about_y(tilt).T + pivot
    # expected normals: plafond towards the tibial axis (down), malleolus lateral (+x)
    fcen = np.column_stack([xe, rt * np.sin(psi_t), (g - Rt) + rt * np.cos(psi_t)])[ft].mean(axis=1)
    exp_n = np.column_stack([np.zeros(len(ft)), -fcen[:, 1], -(fcen[:, 2] - (g - Rt))])
    exp_n[region == 1] = np.array([1.0, 0.0, 0.0])
    exp_n = exp_n @ rotation_about_y(tilt).T
    ft = orient_like(fv, ft, exp_n, "subject_ankle tibia")
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
        + ". Both surfaces: gmsh-meshed planar domains mapped onto the parametric surfaces; no cartilage. "
        "Ligament attachments are plausible anatomical placements, not measured."
    )
    return ankle_geometry(R, mobile, fixed, ankle_ligaments(R, W / 2.0, medial_x - 2.0, hw_max + 6.0, rotation_about_y(tilt), pivot), description, resolved)


def _subject_with_cartilage(resolved: dict[str, Any], params: np.ndarray, triangles: np.ndarray, R: float, U: float, S: float,
                            hw_of_u: Callable, medial_x: float, lateral_x: float, tilt: float, ridge: Callable, depressions: Callable,
                            radii: tuple[float, float], fixed_size: float, talar_bone_radius: Callable) -> BuiltGeometry:
    """:func:`subject_ankle` with ``cartilage = true``: the bones, their layers, the tibia placed touching."""
    t_talus, t_tibia, taper = resolved["talar_cartilage_mm"], resolved["tibial_cartilage_mm"], resolved["cartilage_taper_mm"]
    narrowest = min(float(hw_of_u(-U)), U, S)
    if taper > narrowest:
        raise InputError(
            f"subject_ankle: a {taper:g} mm taper leaves no plateau of the centre thickness on a layer {2 * narrowest:.3g} mm across",
            key="geometry.cartilage_taper_mm", expected=f"at most {narrowest:.3g} mm (half the narrowest extent of the talar and tibial layers)",
        )

    def talar_thickness(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return layer_thickness_mm(t_talus, taper, hw_of_u(u) - np.abs(x), U - np.abs(u))

    def tibial_thickness(x: np.ndarray, s_mm: np.ndarray) -> np.ndarray:
        return layer_thickness_mm(t_tibia, taper, np.minimum(x - medial_x, lateral_x - x), S - np.abs(s_mm))

    mobile, mobile_bone = talus_with_cartilage(params, triangles, R, talar_bone_radius, talar_thickness, "subject_ankle")
    radius_f = (R + t_talus) * (1.0 + resolved["incongruity"])  # the plafond's articular radius (without ridge and depressions)
    pivot = np.array([0.0, 0.0, t_talus])
    rotation = rotation_about_y(tilt)
    fixed, fixed_bone, lift, touch = tibia_with_cartilage(
        "subject_ankle", medial_x, lateral_x, S, 0.6 * R, radius_f, t_talus - radius_f,
        lambda x, s_mm: radius_f + t_tibia - ridge(x) + depressions(x, s_mm), tibial_thickness, t_tibia, rotation, pivot,
        mobile, fixed_size)
    seed = resolved["seed"]
    description = (
        "Subject-like ankle with cartilage (docs/method.md#8-built-in-geometries): parametric talar trochlea (bone radius "
        f"{R:.2f} mm, width {resolved['talar_width_mm']:.2f} mm, {resolved['anterior_widening_mm']:.2f} mm wider anteriorly, arc "
        f"{resolved['talar_arc_deg']:.1f} deg, central groove {resolved['groove_depth_mm']:.2f} mm, rim roll-off "
        f"{resolved['rim_rolloff_mm']:.2f} mm) under a {t_talus:.2f} mm talar layer ({mobile.n_triangles} triangles), against an "
        f"incongruent plafond (articular radius {radius_f:.2f} mm, length {2 * S:.1f} mm, two depressions "
        f"{resolved['depression_depth_mm']:.2f} mm deep, radii {radii[0]:.1f} and {radii[1]:.1f} mm, tilt "
        f"{resolved['tilt_deg']:.2f} deg) under a {t_tibia:.2f} mm tibial layer, with a medial malleolus wall "
        f"({fixed.n_triangles} triangles); each layer tapered to 0 over {taper:g} mm at its margin; the articular "
        f"surfaces touch at ({touch[0]:.1f}, {touch[1]:.1f}, {touch[2]:.2f}) mm at zero load; "
        + (f"parameters drawn with seed {seed} within documented anatomical ranges" if seed is not None else "default parameters")
        + ". Ligament attachments are plausible anatomical placements, not measured."
    )
    ligaments = lifted(ankle_ligaments(R, resolved["talar_width_mm"] / 2.0, medial_x - 2.0, lateral_x + 4.0, rotation, pivot), lift)
    return ankle_geometry(R, mobile, fixed, ligaments, description, resolved, bones=(mobile_bone, fixed_bone), contact_point_mm=touch)
