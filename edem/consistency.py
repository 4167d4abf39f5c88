"""Is an equilibrium inside the geometry it was computed from? (DEM, EDEM; any law, any ligaments)

The spring bed is measured once per solve: DEM measures the springs at M's initial pose and
solves the linearised problem, EDEM measures them at the start of every increment. A solution
that moves M far beyond what was measured (sliding off the fixed surface, turning through it)
balances the load only in the linear model, not in the geometry: such a result is refused
(SolverError, exit 2) with a message naming the DOFs that moved and by how much.

- Both methods: :func:`check_increment` refuses a solve that moves a contact spring by more
  than ``WINDOW_FRACTION`` of the ray window h_max from the pose it was measured at (DEM:
  M's initial pose; EDEM: the start of the increment); the springs' rays then no longer describe
  the surface the solve was computed against.
- Both: :func:`check_contact_kept` refuses an equilibrium without any contact spring under a load
  that pushes M towards F (it is then held by the ligaments or nothing the bed measured).
- DEM: :func:`remeasured_imbalance` places M at the solved pose, casts the rays again and sums
  the spring forces the law gives for the lengths measured there (plus the ligaments at that
  pose). What they leave unbalanced is recorded per time point and warned about beyond
  ``DEM_IMBALANCE_FRACTION``; it is not a refusal: DEM's linearisation of a cylinder under a
  tilted plane (the built-in ideal stance at low load) misses 43 % there while moving 0.6 mm.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from geometries.errors import SolverError
from edem.mechanics import DOF_NAMES, ShearTerms, generalised_directions, rotation_matrix
from edem.raycast import RayCaster
from edem.springs import Cartilage, Ligament, Placement, SpringGeometry, ligament_elements, spring_geometry

# The whole ray window: the rays measured the gap to F up to h_max around every spring, so a
# solve that moves a contact spring further than h_max could have met (or left) surface the
# solve never saw. The built-in scenes move their contact springs by at most 0.53 h_max per
# solve (DEM at toe off of the ideal stance: a 1.8 mm slide of the cylinder under the turned
# plane; EDEM at most 0.39 h_max, on the ideal toe-off); tests/edem/test_consistency.py runs
# the stances under both methods.
WINDOW_FRACTION = 1.0
# DEM: warn when the springs re-measured at the solved pose leave more than a quarter of the
# forces at work (load plus the model's element forces) unbalanced.
DEM_IMBALANCE_FRACTION = 0.25


def describe_motion(u: np.ndarray) -> str:
    """The DOFs of a rigid motion, largest first: 'ty 65 mm, rz 90 deg' (translations mm, rotations deg)."""
    u = np.asarray(u, float)
    values = np.concatenate([u[:3], np.degrees(u[3:])])
    units = ["mm"] * 3 + ["deg"] * 3
    # Order by the motion each DOF causes at 10 mm from G (a joint-sized arm).
    weight = np.abs(np.concatenate([u[:3], 10.0 * u[3:]]))
    parts = [f"{DOF_NAMES[i]} {values[i]:+.3g} {units[i]}" for i in np.argsort(-weight) if weight[i] > 1e-9]
    return ", ".join(parts) if parts else "no motion"


def point_motion_mm(u: np.ndarray, points_mm: np.ndarray, reference_point_mm: np.ndarray) -> np.ndarray:
    """(n,) distance moved by points of M under the finite rigid motion u = (u_G, q) about G."""
    arm = points_mm - reference_point_mm
    moved = arm @ rotation_matrix(u[3:]).T + u[:3]
    return np.linalg.norm(moved - arm, axis=1)


def motion_bound_mm(u: np.ndarray, arm_bound_mm: float) -> float:
    """Upper bound on the distance any point of M within ``arm_bound_mm`` of G moves under the
    finite rigid motion u = (u_G, q): |u_G| + |R(q) - I| r = |u_G| + 2 sin(|q| / 2) r."""
    return math.hypot(*u[:3]) + 2.0 * math.sin(0.5 * min(math.hypot(*u[3:]), math.pi)) * arm_bound_mm


def check_increment(
    u: np.ndarray,
    spring_points_mm: np.ndarray | Callable[[], np.ndarray],
    reference_point_mm: np.ndarray,
    cartilage: Cartilage,
    where: str,
    arm_bound_mm: float = math.inf,
    in_contact: np.ndarray | None = None,
) -> None:
    """Refuse a solve (a DEM pose, an EDEM increment) that moves a contact spring beyond ``WINDOW_FRACTION`` h_max.

    ``spring_points_mm`` (n, 3): the centroids of the springs in contact during the increment, or
    of more springs with ``in_contact`` (n,) bool saying which are (gathered only if needed); or a
    function returning them, called only if the bound below does not settle the check.
    ``arm_bound_mm``: an upper bound on their distance from G (for a rigid M, the largest over
    all its springs at the reference pose, which no motion changes); a motion that cannot move
    any point that close to G by the limit passes without measuring the springs one by one.
    """
    limit = WINDOW_FRACTION * cartilage.max_spring_length_mm
    # (1 + 1e-9): the per-spring measure below has round-off, the bound must stay above it.
    if motion_bound_mm(u, arm_bound_mm) * (1.0 + 1e-9) <= limit:
        return
    if callable(spring_points_mm):
        spring_points_mm = spring_points_mm()
    if spring_points_mm.shape[0] == 0:
        return
    if in_contact is not None:
        spring_points_mm = np.take(spring_points_mm, np.flatnonzero(in_contact), axis=0)
        if spring_points_mm.shape[0] == 0:
            return
    moved = float(point_motion_mm(u, spring_points_mm, reference_point_mm).max())
    if moved > limit:
        raise SolverError(
            f"{where}: the solve moves the mobile body by {describe_motion(u)} (a contact spring by "
            f"{moved:.3g} mm, more than {WINDOW_FRACTION:g} x the ray window "
            f"h_max = {cartilage.max_spring_length_mm:g} mm): the pose leaves the geometry the solve was computed "
            "from. Use more time points (smaller load steps: [load] max_step_s), fix the DOFs nothing resists in [constraints] "
            "fixed_dofs, or check the load's axes and units"
        )


def measured_spring_force_n(initial: SpringGeometry, measured: SpringGeometry, cartilage: Cartilage) -> np.ndarray:
    """(n,) normal force of the springs that were candidates at the initial pose, from the lengths
    measured at a new pose (no linearisation): the law's element force at the approach h0 - h,
    h0 the initial length (threshold: A E' / h0 (h0 - h); gap: A E' (t - h) / t; gap-log:
    -A E' ln(h / t)). Zero for the others and where the ray finds no surface in the window.
    """
    sel = initial.candidate
    h0 = initial.spring_length_mm[sel]
    h = measured.spring_length_mm[sel]
    hit = np.isfinite(h)
    elements = cartilage.spring_law.elements(
        initial.area_mm2[sel], h0, cartilage.confined_modulus_mpa, initial.candidate_thickness_mm(cartilage), np.zeros(h0.shape)
    )
    with np.errstate(divide="ignore", invalid="ignore"):
        force = elements.force_and_stiffness(np.where(hit, h0 - h, 0.0))[0]
    out = np.zeros(initial.spring_length_mm.shape)
    # a log spring pressed past t has no finite force: count it as a huge one (the pose is then refused or warned)
    out[sel] = np.where(hit, np.nan_to_num(np.maximum(force, 0.0), nan=0.0, posinf=1e300), 0.0)
    return out


def remeasured_imbalance(
    *,
    pose: Placement,
    fixed_pose: Placement,
    initial: SpringGeometry,
    spring_centroid_mm: np.ndarray,
    spring_normal: np.ndarray,
    spring_area_mm2: np.ndarray,
    caster: RayCaster,
    cartilage: Cartilage,
    ligaments: tuple[Ligament, ...],
    reference_point_mm: np.ndarray,
    shear: ShearTerms | None,
    u: np.ndarray,
    active: np.ndarray,
    model_force_n: np.ndarray,
    load: np.ndarray,
    free: np.ndarray,
    length_scale_mm: float,
) -> tuple[float, float]:
    """(imbalance, scale) in N: what the springs measured at ``pose`` leave of the load unbalanced.

    The generalised force of the re-measured springs (:func:`measured_spring_force_n`, rows at the
    new pose), of the ligaments at that pose and of the linear model's shear (the shear springs
    are not re-measured: they have no geometry of their own) minus the load, over the free DOFs,
    moments divided by ``length_scale_mm``. ``scale``: the load's size on the same terms plus the
    sum of the element forces of the linear model (``model_force_n``, springs and ligaments): a
    load balanced by pre-tensioned ligaments is measured against the forces actually at work.
    """
    measured = spring_geometry(spring_centroid_mm, spring_normal, spring_area_mm2, pose, caster, fixed_pose, cartilage)
    g = pose.points(reference_point_mm[None])[0]
    force = measured_spring_force_n(initial, measured, cartilage)
    total = generalised_directions(measured.centroid_mm, measured.normal, g).T @ force
    lig_rows, lig_law, _ = ligament_elements(ligaments, pose, fixed_pose, g)
    if len(lig_rows):
        total = total + lig_rows.T @ np.maximum(lig_law.offset_n, 0.0)
    if shear is not None:
        total = total + shear.generalised_force(u, active[: shear.normals.shape[0]])
    to_newton = np.array([1.0, 1.0, 1.0] + [1.0 / length_scale_mm] * 3)
    residual = np.where(free, (total - load) * to_newton, 0.0)
    scale = float(np.linalg.norm(np.where(free, load * to_newton, 0.0))) + float(np.abs(model_force_n).sum())
    return float(np.linalg.norm(residual)), scale


def remeasured_warning(n_points: int, worst_step: int, worst_fraction: float) -> str:
    """The DEM warning for time points whose re-measured springs miss more than ``DEM_IMBALANCE_FRACTION``."""
    return (
        f"{n_points} time point(s) leave more than {DEM_IMBALANCE_FRACTION:.0%} of the forces unbalanced once the springs "
        f"are measured again at the solved pose (worst: time point {worst_step}, {worst_fraction:.0%}): DEM's linearisation "
        "at the initial pose is poor there (e.g. a body sliding on a surface tilted against it); --method edem re-measures "
        "at every step (column remeasured_imbalance of timeseries.csv)"
    )


def check_contact_kept(
    force_n: np.ndarray,
    spring_normal: np.ndarray,
    spring_area_mm2: np.ndarray,
    n_contact: int,
    free: np.ndarray,
    u: np.ndarray,
    where: str,
) -> None:
    """Refuse an equilibrium without contact under a force that pushes M towards F.

    Towards F: the free part of the force has a positive component along the area-weighted mean
    spring normal of M (normals point from M to F) at the current pose. A load pulling M away
    and held by the ligaments is a valid equilibrium and passes. ``u`` is the solved motion
    (named in the message).
    """
    if n_contact:
        return
    f = np.where(free[:3], force_n, 0.0)
    mean_normal = (spring_normal * spring_area_mm2[:, None]).sum(axis=0)
    norm = float(np.linalg.norm(mean_normal))
    if norm == 0.0:
        return
    pushing = float(f @ mean_normal) / norm
    if pushing > 1e-9 * max(float(np.linalg.norm(f)), 1e-300):
        raise SolverError(
            f"{where}: no spring is in contact although the load pushes the mobile body's articular surface "
            f"forward ({pushing:.4g} N along its mean normal): the equilibrium moves it by {describe_motion(u)} "
            "and holds it there by the ligaments or the constraints alone, off the surface the contact was "
            "measured on. Check the kinematics (the fixed body's pose), the load's axes and the geometry"
        )
