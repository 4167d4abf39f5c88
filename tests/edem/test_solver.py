"""DEM/EDEM against closed forms and invariants (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs, docs/method.md#2-edem-the-time-dependent-incremental-method, thesis chapter 3)."""

from __future__ import annotations

import numpy as np
import pytest
from support import cylinder_patch, grid_plate, make_scene, plane

from geometries.errors import SolverError
from edem.mechanics import confined_modulus_mpa, generalised_directions
from edem.solver import StepResult, run
from edem.springs import Ligament

E, NU = 10.35, 0.42
E_CONF = confined_modulus_mpa(E, NU)
IN_PLANE = ("tx", "ty", "rz")  # a frictionless flat plate cannot resist these


def assert_kkt(scene, step: StepResult, displacement: np.ndarray, rtol: float = 1e-9) -> None:
    """KKT of the unilateral problem, recomputed from the outputs (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs).

    Pressures are non-negative; an out-of-contact candidate would not be compressed by the
    solved motion; spring forces balance the applied force and moment about G.
    """
    c, n, a = scene.spring_centroid_mm, scene.spring_normal, scene.spring_area_mm2
    g = generalised_directions(c, n, scene.reference_point_mm)
    approach = g @ displacement
    candidate = np.isfinite(step.spring_length_mm) & (step.spring_length_mm <= scene.cartilage.max_spring_length_mm)
    assert np.all(step.pressure_mpa >= 0.0)
    assert np.all(step.pressure_mpa[~step.in_contact] == 0.0)
    assert np.all(approach[candidate & ~step.in_contact] <= 1e-12 * np.abs(approach).max())
    force = (step.pressure_mpa * a)[:, None] * n
    resultant = np.concatenate([force.sum(axis=0), np.cross(c - scene.reference_point_mm, force).sum(axis=0)])
    applied = np.concatenate([step.force_n, step.moment_nmm])
    free = [i for i, d in enumerate(("tx", "ty", "tz", "rx", "ry", "rz")) if d not in scene.fixed_dofs]
    scale = max(np.abs(applied).max(), 1.0)
    np.testing.assert_allclose(resultant[free], applied[free], atol=rtol * scale * 30)


def test_flat_plates_uniform_pressure_and_displacement():
    """Parallel plates: p = F/A everywhere and d = F h / (E' A) (eq. 3.7, 3.13)."""
    h, force = 2.0, 333.0
    scene = make_scene(grid_plate(20, 20, 16), plane(lambda x, y: h), [0, 0, force], fixed_dofs=IN_PLANE)
    step = run(scene, "dem").steps[0]
    np.testing.assert_allclose(step.pressure_mpa, force / 400.0, rtol=1e-12)
    np.testing.assert_allclose(step.displacement_mm, [0, 0, force * h / (E_CONF * 400.0)], rtol=1e-12, atol=1e-15)
    assert step.contact_area_mm2 == pytest.approx(400.0, rel=1e-12)
    assert_kkt(scene, step, np.concatenate([step.displacement_mm, step.rotation_rad]))


def test_tilted_plane_pressure_follows_local_thickness():
    """Plate under a tilted plane, only tz free: p = E' d / h(x), d = F / (E' sum A / h)."""
    h0, slope, force = 2.0, 0.05, 500.0
    fixed_dofs = ("tx", "ty", "rx", "ry", "rz")
    mobile = grid_plate(20, 20, 40)
    scene = make_scene(mobile, plane(lambda x, y: h0 + slope * x), [0, 0, force], fixed_dofs=fixed_dofs)
    step = run(scene, "dem").steps[0]
    h = h0 + slope * mobile.centroids_mm[:, 0]
    np.testing.assert_allclose(step.spring_length_mm, h, rtol=1e-12)
    d_discrete = force / (E_CONF * (mobile.areas_mm2 / h).sum())
    np.testing.assert_allclose(step.pressure_mpa, E_CONF * d_discrete / h, rtol=1e-10)
    # Continuum closed form: d = F slope / (E' W ln(h(a) / h(-a))), midpoint-rule close.
    d_exact = force * slope / (E_CONF * 20.0 * np.log((h0 + 10 * slope) / (h0 - 10 * slope)))
    assert step.displacement_mm[2] == pytest.approx(d_exact, rel=1e-4)


def test_cylinder_on_plane_matches_discrete_foundation_solution():
    """Cylinder under a plane, vertical load, rotations and tx fixed (the thesis's ideal ankle).

    Each candidate spring's ray meets z = g at h = (g - c_z) / n_z; the approach is d n_z, so the
    discrete foundation solution is d = F / sum(A E' n_z^2 / h), p = E' d n_z / h (eq. 3.7-3.14).
    """
    radius, gap, h_max, force = 20.0, 1.5, 3.5, 333.0
    mobile = cylinder_patch(radius, 28.0, 114.0, 120, 20)
    scene = make_scene(mobile, plane(lambda x, y: gap), [0, 0, force], fixed_dofs=("tx", "rx", "ry", "rz"))
    step = run(scene, "dem").steps[0]
    c, n = mobile.centroids_mm, mobile.unit_normals
    h = (gap - c[:, 2]) / n[:, 2]
    candidate = h <= h_max
    np.testing.assert_allclose(step.spring_length_mm[candidate], h[candidate], rtol=1e-10)
    stiffness = (mobile.areas_mm2 * E_CONF * n[:, 2] ** 2 / h)[candidate].sum()
    d = force / stiffness
    expected = np.where(candidate, E_CONF * d * n[:, 2] / h, 0.0)
    np.testing.assert_allclose(step.pressure_mpa, expected, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(step.displacement_mm, [0, 0, d], atol=1e-12)
    # Candidate fraction: closed form cos(theta) >= (R + g) / (R + h_max) -> 2 theta / arc = 41.8 %.
    theta = np.degrees(np.arccos((radius + gap) / (radius + h_max)))
    fraction = mobile.areas_mm2[candidate].sum() / mobile.areas_mm2.sum()
    assert fraction == pytest.approx(2 * theta / 114.0, abs=0.01)


def test_off_centre_load_with_free_rotations_balances_the_moment():
    """Off-centre load inside the kern, rotations free: the rigid plate on a uniform bed has
    p = a + b x + c y with sum A p (1, y, -x) = (F, M_x, M_y); all springs stay compressed."""
    force, moment = np.array([0, 0, 400.0]), np.array([300.0, -450.0, 0.0])
    mobile = grid_plate(20, 20, 20)
    scene = make_scene(mobile, plane(lambda x, y: 2.0), force, moment_nmm=moment, fixed_dofs=IN_PLANE)
    step = run(scene, "dem").steps[0]
    assert step.in_contact.all()
    assert_kkt(scene, step, np.concatenate([step.displacement_mm, step.rotation_rad]))
    c, a = mobile.centroids_mm, mobile.areas_mm2
    basis = np.column_stack([np.ones(len(a)), c[:, 0], c[:, 1]])
    moments = np.column_stack([np.ones(len(a)), c[:, 1], -c[:, 0]])
    coefficients = np.linalg.solve(moments.T @ (a[:, None] * basis), [force[2], moment[0], moment[1]])
    np.testing.assert_allclose(step.pressure_mpa, basis @ coefficients, rtol=1e-9)


def test_active_set_reactivates_springs_where_removal_only_fails():
    """A load near a corner of a coarse plate: the thesis's removal-only loop ends on a wrong set.

    Removal-only (remove every spring in tension, re-solve, never add back) stops, with a regular
    stiffness matrix, on a set that leaves a spring out of contact although the final motion
    compresses it: a KKT violation. Our semismooth Newton re-activates it and ends on the set that
    satisfies KKT, the unique optimum of this strictly convex problem.
    """
    mobile = grid_plate(20, 20, 6)
    force, moment = np.array([0, 0, 100.0]), np.array([825.0, -750.0, 0.0])  # resultant at (7.5, 8.25) mm
    scene = make_scene(mobile, plane(lambda x, y: 2.0), force, moment_nmm=moment, fixed_dofs=IN_PLANE)
    g = generalised_directions(mobile.centroids_mm, mobile.unit_normals, scene.reference_point_mm)
    stiffness = mobile.areas_mm2 * E_CONF / 2.0
    free = np.array([False, False, True, True, True, False])
    load = np.concatenate([force, moment])
    active = np.ones(len(stiffness), bool)
    while True:
        k = g.T @ (g * (stiffness * active)[:, None])
        assert np.linalg.cond(k[np.ix_(free, free)]) < 1e8
        u = np.zeros(6)
        u[free] = np.linalg.solve(k[np.ix_(free, free)], load[free])
        tension = active & (stiffness * (g @ u) <= 0)
        if not tension.any():
            break
        active &= ~tension
    compressed_but_removed = ~active & (g @ u > 1e-9 * np.abs(g @ u).max())
    assert compressed_but_removed.sum() == 1

    step = run(scene, "dem").steps[0]
    assert_kkt(scene, step, np.concatenate([step.displacement_mm, step.rotation_rad]))
    assert step.in_contact.sum() == active.sum() + 1
    assert step.in_contact[compressed_but_removed].all()


def test_singular_system_names_the_unrestrained_dofs():
    """Frictionless cylinder (k_s = 0): nothing resists sliding along its axis, tx (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs)."""
    scene = make_scene(cylinder_patch(20.0, 28.0, 114.0, 40, 8), plane(lambda x, y: 1.5), [0, 0, 333.0], fixed_dofs=("rx", "ry", "rz"))
    with pytest.raises(SolverError, match=r"nothing resists motion along tx"):
        run(scene, "dem")


def test_regular_solve_matches_lapack_and_refuses_what_unrestrained_dofs_would_diagnose():
    """The 6 x 6 Cholesky in plain floats: the solution of well-posed stiffnesses (random SPD, DOF
    units mm and rad with a 20 mm length) equals LAPACK's to round-off (cond <= 1e6 here: 1e-9);
    a stiffness with a null direction, or one only 1e-9 of the largest pivot, is refused."""
    from edem.mechanics import _regular_solve, unrestrained_dofs

    rng = np.random.default_rng(4)
    scale = np.array([1.0, 1.0, 1.0, 20.0, 20.0, 20.0])
    for _ in range(50):
        q, _ = np.linalg.qr(rng.normal(size=(6, 6)))
        k = np.outer(scale, scale) * (q @ np.diag(10.0 ** rng.uniform(0, 6, 6)) @ q.T)
        b = rng.normal(size=6)
        np.testing.assert_allclose(_regular_solve(k, scale, b), np.linalg.solve(k, b), rtol=1e-9)
        singular = k.copy()
        singular[:, 3] = singular[3, :] = 0.0
        assert _regular_solve(singular, scale, b) is None
        assert unrestrained_dofs(singular, np.ones(6, bool), 20.0) == ["rx"]
    weak = np.diag([1.0, 1.0, 1e-9])
    assert _regular_solve(weak, np.ones(3), np.ones(3)) is None
    assert _regular_solve(np.zeros((0, 0)), np.zeros(0), np.zeros(0)).size == 0


def test_turned_reference_rows_equal_the_rows_at_the_moved_pose():
    """(n, (c - G) x n) measured at the reference pose and turned by R equal the rows of the
    points and normals moved by the rigid placement (R about G, then a translation), to round-off."""
    from edem.mechanics import rotation_matrix, turn_rows
    from edem.springs import Placement

    rng = np.random.default_rng(7)
    points, normals, g0 = rng.normal(size=(50, 3)) * 20.0, rng.normal(size=(50, 3)), np.array([1.0, 2.0, 3.0])
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    pose = Placement(rotation_matrix(np.array([0.3, -0.2, 0.5])), np.array([4.0, -1.0, 2.0]), g0)
    moved = generalised_directions(pose.points(points), pose.vectors(normals), pose.points(g0[None])[0])
    turned = turn_rows(generalised_directions(points, normals, g0), pose.rotation, extra=2)
    assert turned.shape == (52, 6)
    np.testing.assert_allclose(turned[:50], moved, rtol=0, atol=1e-12 * 40.0)  # round-off on 40 mm arms


def test_shear_stiffness_restrains_the_axis():
    """With k_s = G/h > 0 the same cylinder is determinate and a pure vertical load moves it vertically."""
    scene = make_scene(
        cylinder_patch(20.0, 28.0, 114.0, 40, 8), plane(lambda x, y: 1.5), [0, 0, 333.0], fixed_dofs=("rx", "ry", "rz"), shear_modulus_mpa=3.6
    )
    step = run(scene, "dem").steps[0]
    assert abs(step.displacement_mm[0]) < 1e-12 and step.displacement_mm[2] > 0


def test_load_pulling_apart_is_reported():
    """A load pulling M away from F has no equilibrium with compression-only springs."""
    scene = make_scene(grid_plate(20, 20, 8), plane(lambda x, y: 2.0), [0, 0, -100.0], fixed_dofs=IN_PLANE)
    with pytest.raises(SolverError, match="pulls the bodies apart"):
        run(scene, "dem")


def test_zero_load_leaves_no_contact():
    """T = 0: u = 0 and no spring is loaded (the trivial KKT point)."""
    scene = make_scene(grid_plate(20, 20, 8), plane(lambda x, y: 2.0), [0, 0, 0.0], fixed_dofs=IN_PLANE)
    step = run(scene, "dem").steps[0]
    assert step.contact_area_mm2 == 0.0 and not np.any(step.displacement_mm)


def ramp(peak_n: float, n_up: int, n_down: int = 0) -> np.ndarray:
    up = np.linspace(0.0, peak_n, n_up + 1)[1:]
    down = np.linspace(peak_n, 0.0, n_down + 1)[1:]
    return np.column_stack([np.zeros(n_up + n_down), np.zeros(n_up + n_down), np.concatenate([up, down])])


def test_edem_ramp_converges_to_log_law():
    """Flat plates, slow monotonic ramp: EDEM integrates dF = E' A dd / h, i.e. d = h0 (1 - exp(-F / (E' A))).

    The explicit increment is first order in the step: halving it halves the error (docs/method.md#2-edem-the-time-dependent-incremental-method).
    """
    h0, area = 2.0, 400.0
    peak = 0.5 * E_CONF * area  # F / (E' A) = 0.5: clearly non-linear
    exact = h0 * (1.0 - np.exp(-peak / (E_CONF * area)))
    errors = []
    for n in (10, 20, 40, 80):
        scene = make_scene(grid_plate(20, 20, 4), plane(lambda x, y: h0), ramp(peak, n), fixed_dofs=IN_PLANE)
        errors.append(abs(run(scene, "edem").steps[-1].displacement_mm[2] - exact) / exact)
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert errors[-1] < 0.01
    np.testing.assert_allclose(ratios, 2.0, rtol=0.15)


def test_edem_load_then_unload_returns_to_start():
    """Load to 2 kN and back to zero on a cylinder: M returns to its start and no force is left."""
    scene = make_scene(cylinder_patch(20.0, 28.0, 114.0, 60, 10), plane(lambda x, y: 1.5), ramp(2000.0, 40, 40), fixed_dofs=("tx", "rx", "ry", "rz"))
    result = run(scene, "edem")
    peak_disp = max(abs(s.displacement_mm[2]) for s in result.steps)
    last = result.steps[-1]
    assert peak_disp > 0.1
    assert abs(last.displacement_mm[2]) < 0.02 * peak_disp
    assert last.peak_pressure_mpa * last.contact_area_mm2 < 1e-6 * 2000.0


def test_wall_time_is_the_time_points_and_setup_time_what_came_before():
    """The clocks partition the run: wall_time_s holds every time point's geometry and solve
    (the first one's ray cast included), setup_time_s what ran once before them, and neither
    counts anything twice (their sum is at most the call's elapsed time)."""
    import time

    scene = make_scene(cylinder_patch(20.0, 28.0, 114.0, 40, 8), plane(lambda x, y: 1.5), ramp(800.0, 5), fixed_dofs=("tx", "rx", "ry", "rz"))
    start = time.perf_counter()
    result = run(scene, "edem")
    elapsed = time.perf_counter() - start
    assert result.seconds["geometry"] + result.seconds["solve"] <= result.wall_time_s
    assert result.setup_time_s > 0.0
    assert result.wall_time_s + result.setup_time_s <= elapsed


def test_dem_and_edem_agree_on_the_first_step():
    """From rest, the first EDEM increment is the DEM solve (no push-back yet, docs/method.md#2-edem-the-time-dependent-incremental-method)."""
    scene = make_scene(cylinder_patch(20.0, 28.0, 114.0, 40, 8), plane(lambda x, y: 1.5), ramp(800.0, 3), fixed_dofs=("tx", "rx", "ry", "rz"))
    dem, edem = run(scene, "dem").steps[0], run(scene, "edem").steps[0]
    np.testing.assert_allclose(edem.pressure_mpa, dem.pressure_mpa, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(edem.displacement_mm, dem.displacement_mm, rtol=1e-12, atol=1e-15)


def test_edem_every_step_balances_the_load():
    """Force balance at every EDEM step: the springs in contact carry exactly T_k (eq. 3.18)."""
    scene = make_scene(cylinder_patch(20.0, 28.0, 114.0, 40, 8), plane(lambda x, y: 1.5), ramp(3000.0, 10, 5), fixed_dofs=("tx", "rx", "ry", "rz"))
    for step in run(scene, "edem").steps:
        total = step.pressure_mpa * step.area_mm2
        normals = scene.mobile.unit_normals
        resultant = (total[:, None] * normals).sum(axis=0)
        assert resultant[2] == pytest.approx(step.force_n[2], rel=1e-9)
        assert step.force_residual_n < 1e-8 * (1.0 + step.force_n[2])


def ligament(mobile_point, fixed_point, stiffness_area=10.0) -> Ligament:
    length = float(np.linalg.norm(np.subtract(fixed_point, mobile_point)))
    return Ligament("lig", np.array(mobile_point, float), np.array(fixed_point, float), 255.0, stiffness_area, length)


def test_ligaments_pull_but_never_push():
    """Tension-only ligaments (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs): stretched -> T = E A / L0 * dL along the ligament; shortened -> 0."""
    mobile, fixed = grid_plate(20, 20, 8), plane(lambda x, y: 2.0)
    # Below the plate, pulling down: the upward load stretches it.
    below = ligament([0, 0, 0.0], [0, 0, -20.0])
    step = run(make_scene(mobile, fixed, [0, 0, 300.0], fixed_dofs=IN_PLANE, ligaments=(below,)), "dem").steps[0]
    d = step.displacement_mm[2]
    tension = 255.0 * 10.0 / 20.0 * d
    assert step.ligament_force_n[0] == pytest.approx(tension, rel=1e-9)
    assert (step.pressure_mpa * step.area_mm2).sum() == pytest.approx(300.0 - tension, rel=1e-9)  # the ligament holds part of the load
    # Above the plate, the same motion shortens it: it carries nothing.
    above = ligament([0, 0, 0.0], [0, 0, 30.0])
    step = run(make_scene(mobile, fixed, [0, 0, 300.0], fixed_dofs=IN_PLANE, ligaments=(above,)), "dem").steps[0]
    assert step.ligament_force_n[0] == 0.0
    assert (step.pressure_mpa * step.area_mm2).sum() == pytest.approx(300.0, rel=1e-9)


def test_kinematics_rotates_the_fixed_body():
    """A plane rotated about an axis through the plate's edge: h(x) = (h0 + x tan a) exactly."""
    from edem.loads import JointKinematics

    h0, angle = 2.0, np.radians(2.0)
    kin = JointKinematics(np.array([0.0, 0.0, h0]), np.array([0.0, -1.0, 0.0]), np.array([0.0, angle]))
    scene = make_scene(grid_plate(20, 20, 10), plane(lambda x, y: h0), [[0, 0, 100.0], [0, 0, 100.0]], fixed_dofs=IN_PLANE + ("rx", "ry"), kinematics=kin)
    steps = run(scene, "dem").steps
    x = scene.mobile.centroids_mm[:, 0]
    np.testing.assert_allclose(steps[0].spring_length_mm, h0, rtol=1e-12)
    np.testing.assert_allclose(steps[1].spring_length_mm, h0 + x * np.tan(angle), rtol=1e-10)


def test_gap_law_closes_the_gap_before_carrying_load():
    """Linear gap law, plates 0.5 mm further apart than the thickness: d = g0 + F t / (A E') (docs/method.md#2-edem-the-time-dependent-incremental-method)."""
    t, g0, force = 2.0, 0.5, 400.0
    scene = make_scene(grid_plate(20, 20, 10), plane(lambda x, y: t + g0), [0, 0, force], law="gap", thickness_mm=t, max_spring_length_mm=2 * t + g0, fixed_dofs=IN_PLANE)
    step = run(scene, "dem").steps[0]
    assert step.displacement_mm[2] == pytest.approx(g0 + force * t / (400.0 * E_CONF), rel=1e-10)
    np.testing.assert_allclose(step.pressure_mpa, force / 400.0, rtol=1e-10)


def test_gap_log_law_matches_blankevoort_and_edem_does_not_depend_on_steps():
    """gap-log: F = -A E' ln(1 - d/t), so d = t (1 - exp(-F / (A E'))); a total law, hence EDEM's
    final state is the same for 1 or 20 increments (docs/method.md#2-edem-the-time-dependent-incremental-method)."""
    t, area = 2.0, 400.0
    force = 0.8 * E_CONF * area
    exact = t * (1.0 - np.exp(-force / (E_CONF * area)))
    common = dict(law="gap-log", thickness_mm=t, max_spring_length_mm=2 * t, fixed_dofs=IN_PLANE)
    mobile, fixed = grid_plate(20, 20, 10), plane(lambda x, y: t)
    dem = run(make_scene(mobile, fixed, [0, 0, force], **common), "dem").steps[0]
    assert dem.displacement_mm[2] == pytest.approx(exact, rel=1e-9)
    for n in (1, 20):
        edem = run(make_scene(mobile, fixed, ramp(force, n), **common), "edem").steps[-1]
        assert edem.displacement_mm[2] == pytest.approx(exact, rel=1e-9)


def test_gap_law_contact_area_grows_with_load_on_a_tilted_plane():
    """Gap law against a plane tilted by s: only the strip where h(x) - d < t is in contact, so the
    contact edge sits at x_c = (t + d - h0) / s and moves out as the load grows (docs/method.md#2-edem-the-time-dependent-incremental-method)."""
    t, h0, s = 2.0, 2.0, 0.05  # touching at x = 0, gap opening towards +x
    fixed_dofs = ("tx", "ty", "rx", "ry", "rz")
    mobile = grid_plate(20, 20, 80)
    areas = []
    for force in (50.0, 200.0, 800.0):
        scene = make_scene(mobile, plane(lambda x, y: h0 + s * x), [0, 0, force], law="gap", thickness_mm=t, max_spring_length_mm=2 * t, fixed_dofs=fixed_dofs)
        step = run(scene, "dem").steps[0]
        d = step.displacement_mm[2]
        x = mobile.centroids_mm[:, 0]
        np.testing.assert_array_equal(step.in_contact, h0 + s * x - d < t)
        areas.append(step.contact_area_mm2)
    assert areas[0] < areas[1] < areas[2]


def test_overload_past_the_spring_length_is_refused_and_kept_with_a_warning_when_allowed():
    """d = F h / (E' A) = 3 mm on 400 mm^2 of 2 mm springs: a strain over 100 % inside the 3.5 mm
    window, the plates through each other: refused naming the time point and the share of the
    springs in contact (all 128); with [solver] allow_bone_overlap kept, warned; 1e5 N (d = 19 mm,
    far beyond the window the rays measured) is refused either way."""
    force = 3.0 * E_CONF * 400.0 / 2.0
    with pytest.raises(SolverError, match=r"compressed past their length .*bones pass through each other.* at 1 of 1 time points "
                                          r"\(k = 0; t = 0 s\): 128 springs, 100 % of those in contact.*allow_bone_overlap"):
        run(make_scene(grid_plate(20, 20, 8), plane(lambda x, y: 2.0), [0, 0, force], fixed_dofs=IN_PLANE), "dem")
    scene = make_scene(grid_plate(20, 20, 8), plane(lambda x, y: 2.0), [0, 0, force], fixed_dofs=IN_PLANE, allow_bone_overlap=True)
    result = run(scene, "dem")
    assert result.steps[0].displacement_mm[2] == pytest.approx(3.0, rel=1e-10)
    assert any("compressed past their length" in w for w in result.warnings)
    small = run(make_scene(grid_plate(20, 20, 8), plane(lambda x, y: 2.0), [0, 0, 100.0], fixed_dofs=IN_PLANE), "dem")
    assert small.warnings == []
    with pytest.raises(SolverError, match=r"tz \+18.9 mm"):
        run(make_scene(grid_plate(20, 20, 8), plane(lambda x, y: 2.0), [0, 0, 1e5], fixed_dofs=IN_PLANE), "dem")


def test_nearly_unrestrained_axis_of_a_faceted_cylinder_is_warned():
    """The meshed ideal talus's normals tilt slightly off radial (|n_x| ~ 0.01), so its axis is not
    exactly free but ~1e-5 as stiff as the vertical: solvable, yet the talus drifts. Warned."""
    from geometries.builders import build_geometry

    ankle = build_geometry("ideal_ankle", {"cartilage": False})
    free_axis = run(make_scene(ankle.mobile, ankle.fixed, [0, 0, 333.0], fixed_dofs=("rx", "ry", "rz")), "dem")
    assert any("barely resists motion along tx" in w for w in free_axis.warnings)
    fixed = run(make_scene(ankle.mobile, ankle.fixed, [0, 0, 333.0], fixed_dofs=("tx", "rx", "ry", "rz")), "dem")
    assert fixed.warnings == []


@pytest.mark.parametrize("law", ["threshold", "gap-log"])
def test_interpenetrating_bodies_are_refused_by_laws_that_need_h_positive(law):
    """F 0.5 mm inside M: h < 0 where k = E'/h (threshold) and ln(h/t) (gap-log) lose meaning."""
    scene = make_scene(grid_plate(20, 20, 8), plane(lambda x, y: -0.5), [0, 0, 100.0], law=law, thickness_mm=2.0, max_spring_length_mm=3.0, fixed_dofs=IN_PLANE)
    with pytest.raises(SolverError, match="compressed past their length.*linear gap law"):
        run(scene, "dem")


def test_linear_gap_law_handles_interpenetration():
    """The linear gap law takes h < 0 in its stride: d = t - h + approach, p = E' d / t."""
    t, h0, force = 2.0, -0.5, 4000.0
    scene = make_scene(grid_plate(20, 20, 8), plane(lambda x, y: h0), [0, 0, force], law="gap", thickness_mm=t, max_spring_length_mm=3.0, fixed_dofs=IN_PLANE)
    step = run(scene, "dem").steps[0]
    np.testing.assert_allclose(step.pressure_mpa, force / 400.0, rtol=1e-10)
    assert step.displacement_mm[2] == pytest.approx(force * t / (E_CONF * 400.0) - (t - h0), rel=1e-10)


def _kkt_bound_mm(directions, law, solution, load, rtol=1e-10):
    """How far two solutions that both meet the solver's balance tolerance (rtol of the force
    scale, the load plus every element force) on the same active set can differ: twice that
    residual through the inverse stiffness of the set (free DOFs tz, rx, ry)."""
    free = [2, 3, 4]
    _, k = law.force_and_stiffness(directions @ solution.displacement)
    stiffness = directions.T @ (directions * (k * solution.active)[:, None])
    scale = np.linalg.norm(load) + np.abs(solution.element_force_n).sum()
    return 2.0 * rtol * scale * np.linalg.norm(np.linalg.inv(stiffness[np.ix_(free, free)]), 2)


@pytest.mark.parametrize("law_name", ["linear", "log"])
def test_a_start_displacement_reaches_the_cold_start_minimiser(law_name):
    """Pi is convex with one minimiser: from the cold start (u = 0, all active), from the
    solution itself (one iteration), from near it, from far off and from a start where nothing
    is compressed (the fallback to u = 0), the active set is the same and u differs by no more
    than the balance tolerance allows (:func:`_kkt_bound_mm`)."""
    from edem.laws import LinearElements, LogElements
    from edem.mechanics import solve_unilateral

    mobile = grid_plate(20, 20, 8)
    g = generalised_directions(mobile.centroids_mm, mobile.unit_normals, np.zeros(3))
    rng = np.random.default_rng(7)
    stiffness = mobile.areas_mm2 * E_CONF / rng.uniform(1.5, 2.5, len(g))
    offset = rng.uniform(-0.05, 0.05, len(g))  # (mm of compression before the increment: some springs open)
    if law_name == "linear":
        law = LinearElements(stiffness * offset, stiffness)
    else:
        law = LogElements(offset, stiffness, np.full(len(g), 1.5))
    load = np.array([0.0, 0.0, 300.0, 400.0, -250.0, 0.0])
    fixed = IN_PLANE
    cold = solve_unilateral(g, law, load, fixed_dofs=fixed, length_scale_mm=10.0)
    assert 0 < cold.active.sum() < len(g) and cold.iterations > 1  # a partial contact: the set had to be found
    bound = _kkt_bound_mm(g, law, cold, load)
    u = cold.displacement
    starts = {
        "solution": u,
        "near": u + np.array([0, 0, 0.01, 1e-3, -1e-3, 0]),
        "far": u + np.array([0, 0, 0.3, 0.02, 0.01, 0]),
        "nothing compressed": np.array([0, 0, -5.0, 0, 0, 0]),
    }
    for name, start in starts.items():
        warm = solve_unilateral(g, law, load, fixed_dofs=fixed, length_scale_mm=10.0, start_displacement=start)
        assert np.array_equal(warm.active, cold.active), name
        assert np.abs(warm.displacement - u).max() <= bound, name
        if name == "solution":
            assert warm.iterations == 1


def test_log_start_that_crushes_an_element_starts_from_rest():
    """A start past a log element's thickness (infinite force) is not taken: the solve starts from
    u = 0 as the cold start does and gives its answer to round-off."""
    from edem.laws import LogElements
    from edem.mechanics import solve_unilateral

    mobile = grid_plate(20, 20, 6)
    g = generalised_directions(mobile.centroids_mm, mobile.unit_normals, np.zeros(3))
    stiffness = mobile.areas_mm2 * E_CONF / 2.0
    law = LogElements(np.full(len(g), 0.01), stiffness, np.full(len(g), 1.5))
    load = np.array([0.0, 0.0, 500.0, 0.0, 0.0, 0.0])
    cold = solve_unilateral(g, law, load, fixed_dofs=IN_PLANE, length_scale_mm=10.0)
    warm = solve_unilateral(g, law, load, fixed_dofs=IN_PLANE, length_scale_mm=10.0, start_displacement=np.array([0, 0, 2.0, 0, 0, 0]))
    np.testing.assert_allclose(warm.displacement, cold.displacement, rtol=1e-12, atol=1e-15)
    assert warm.iterations == cold.iterations


def test_edem_started_from_the_previous_step_equals_the_cold_start(monkeypatch):
    """Each EDEM increment starts from the previous one (edem.beds.IndependentSprings): over a
    load and unload on a cylinder, where the contact grows and shrinks, every time point's
    contact set equals the cold start's and its pressures agree to the balance tolerance
    (1e-10 of the force scale, against forces of up to 2 kN: 1e-9 of the peak pressure), in
    fewer Newton iterations."""
    import edem.beds
    from edem.mechanics import solve_unilateral

    scene = make_scene(cylinder_patch(20.0, 28.0, 114.0, 60, 10), plane(lambda x, y: 1.5), ramp(2000.0, 20, 20), fixed_dofs=("tx", "rx", "ry", "rz"))
    warm = run(scene, "edem").steps
    monkeypatch.setattr(edem.beds, "solve_unilateral", lambda *args, start_displacement=None, **kw: solve_unilateral(*args, **kw))
    cold = run(scene, "edem").steps
    peak = max(step.peak_pressure_mpa for step in cold)
    for a, b in zip(warm, cold):
        assert np.array_equal(a.in_contact, b.in_contact)
        np.testing.assert_allclose(a.pressure_mpa, b.pressure_mpa, rtol=0, atol=1e-9 * peak)
    assert sum(s.iterations for s in warm) < sum(s.iterations for s in cold)


def test_rotation_vector_inverts_rotation_matrix():
    """rotation_vector(rotation_matrix(v)) = v for angles from 1e-12 rad (the small-angle branch)
    to 2.5 rad; non-finite rotations give nan, for callers to refuse. Tolerance 1e-9 relative:
    acos loses digits near an angle of 0 (there the axial part alone gives v), the round trip
    is otherwise at round-off (about 1e-15 here)."""
    from edem.mechanics import rotation_matrix, rotation_vector

    rng = np.random.default_rng(2)
    for angle in np.r_[1e-12, 1e-9, 10.0 ** rng.uniform(-6, 0.4, 200)]:
        axis = rng.normal(size=3)
        v = angle * axis / np.linalg.norm(axis)
        np.testing.assert_allclose(rotation_vector(rotation_matrix(v)), v, rtol=1e-9, atol=1e-20)
    assert np.array_equal(rotation_vector(np.eye(3)), np.zeros(3))
    assert np.isnan(rotation_vector(np.full((3, 3), np.nan))).all()


def test_the_solves_dof_arrays_shared_across_time_points_cannot_be_changed():
    """The free DOFs, their scales and the moment-to-force factors are built once per constraint
    set and shared by every solve: they are read-only (a solve that wrote into them would change
    the next one), and equal a fresh construction."""
    from edem.mechanics import _dof_frame

    free, dofs, to_newton, to_newton_free, scale = _dof_frame(("tx", "rz"), 12.5)
    assert np.array_equal(free, [False, True, True, True, True, False]) and np.array_equal(dofs, [1, 2, 3, 4])
    assert np.array_equal(to_newton, [1.0, 1.0, 1.0, 1 / 12.5, 1 / 12.5, 1 / 12.5])
    assert np.array_equal(to_newton_free, to_newton[dofs]) and np.array_equal(scale, [1.0, 1.0, 12.5, 12.5])
    for array in (free, dofs, to_newton, to_newton_free, scale):
        with pytest.raises(ValueError):
            array[0] = array[1]
    assert _dof_frame(("tx", "rz"), 12.5)[1] is dofs


def test_balanceable_answers_for_every_row_when_only_rows_outside_its_sample_balance_the_load():
    """balanceable tries a sample of the rows first: a load that only rows left out of the sample
    can carry (here the one row pushing along -z, among 999 pushing along +z) is still balanceable,
    and not without that row; a load the sample carries is balanceable."""
    from edem.mechanics import balanceable

    rows = np.zeros((1000, 6))
    rows[:, 2] = 1.0
    rows[:, 0] = np.linspace(-1.0, 1.0, 1000)
    rows[1] = [0.0, 0.0, -1.0, 0.0, 0.0, 0.0]
    free = np.array([True, False, True, False, False, False])
    to_newton = np.ones(6)
    assert balanceable(rows, np.array([0.0, 0.0, -5.0, 0, 0, 0]), free, to_newton)
    assert balanceable(rows, np.array([0.3, 0.0, 5.0, 0, 0, 0]), free, to_newton)
    rows[1] = rows[2]
    assert not balanceable(rows, np.array([0.0, 0.0, -5.0, 0, 0, 0]), free, to_newton)
