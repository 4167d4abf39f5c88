"""d. The subject-like ankle: a talar dome and tibial plafond with seeded anatomical variation,
meshed with gmsh (docs/method.md#8-built-in-geometries)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from geometries.builders.common import BuiltGeometry, Param, ankle_ligaments, rotation_about_y, validate_parameters
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

SUBJECT_PARAMS: dict[str, Param] = {"seed": Param("seed", 0, None)}
SUBJECT_PARAMS.update({k: Param("float_or_none", lo, hi) for k, (lo, hi) in SUBJECT_RANGES.items()})
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

    Ligaments: :func:`ankle_ligaments` with this talus's radius and mean half width (plausible
    placements, not measured).
    """
    given = dict(locals())
    checked = validate_parameters("subject_ankle", SUBJECT_PARAMS, given)
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
    q, tt, _ = mesh_planar_domain("subject_talus", [[(float(a), float(b)) for a, b in talus_poly]],
                                   size)
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
    medial_x = -(hw_max + resolved["malleolus_gap_mm"])
    lateral_x = hw_max + 2.0
    mall_depth = 0.6 * R
    plaf = [(medial_x, -S), (lateral_x, -S), (lateral_x, S), (medial_x, S)]
    mall = [(medial_x - mall_depth, -S), (medial_x, -S), (medial_x, S), (medial_x - mall_depth, S)]
    q2, ft, region = mesh_planar_domain("subject_tibia", [plaf, mall], fsize)
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
        + ". Both surfaces: gmsh-meshed planar domains mapped onto the parametric surfaces. "
        "Ligament attachments are plausible anatomical placements, not measured."
    )
    return BuiltGeometry(
        mobile=mobile,
        fixed=fixed,
        reference_point_mm=None,
        ankle_axis_point_mm=np.array([0.0, 0.0, -R]),
        ankle_axis_direction=np.array([1.0, 0.0, 0.0]),
        ligaments=ankle_ligaments(R, W / 2.0, medial_x - 2.0, hw_max + 6.0, rotation_about_y(tilt), pivot),
        description=description,
        parameters=resolved,
    )
