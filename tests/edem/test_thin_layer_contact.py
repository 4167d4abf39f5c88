"""DEM / EDEM / viscoelastic EDEM on the coupled thin layer: invariants and closed forms."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from support import cylinder_patch, disk_plate, grid_plate, make_scene, plane

from geometries.errors import InputError
from edem.beds import CoupledThinLayer, on_bed
from edem.laws import LinearElements
from edem.mechanics import confined_modulus_mpa, generalised_directions
from edem.raycast import RayCaster
from edem.scene import Viscoelastic, load_scene
from edem.solver import run
from edem.springs import Ligament, Placement, spring_geometry
from edem.layer_symbols import pade_symbol, taylor_coefficients, two_pole_symbol
from edem.thin_layer_contact import CoupledStep, coupled_layer_mesh, solve_thin_layer, thin_layer_viscoelastic_increment
from geometries.surface import TriangleSurface

E = 10.35
CYLINDER_DOFS = ("tx", "rx", "ry", "rz")


def coupled(scene, **keys):
    """The scene on the coupled layer, with the layer's own keys ``keys``."""
    return replace(scene, cartilage=on_bed(scene.cartilage, CoupledThinLayer.coupling, **keys))


def ramp(force: float, n_up: int, n_down: int = 0) -> np.ndarray:
    magnitude = np.concatenate([np.linspace(force / n_up, force, n_up), np.linspace(force, 0.0, n_down + 1)[1:]])
    return np.column_stack([np.zeros_like(magnitude), np.zeros_like(magnitude), magnitude])


def balance(scene, step) -> np.ndarray:
    """Resultant force and moment about G of the output pressures minus the applied load."""
    c, n, a = scene.spring_centroid_mm, scene.spring_normal, scene.spring_area_mm2
    g = generalised_directions(c, n, scene.reference_point_mm)
    return g.T @ (step.pressure_mpa * a) - np.concatenate([step.force_n, step.moment_nmm])


def test_default_coupling_none_is_bit_identical_to_the_spring_bed():
    default = run(load_scene("cylinder-layer")).steps[0]
    explicit = run(load_scene("cylinder-layer", {"cartilage.coupling": "none"})).steps[0]
    assert np.array_equal(default.pressure_mpa, explicit.pressure_mpa)
    assert np.array_equal(default.displacement_mm, explicit.displacement_mm)


def test_gap_log_columns_follow_the_logarithmic_law_where_the_coupling_vanishes():
    """nu = 1/4 (c1 = 0): a flat plate pressed by F onto a gap-log layer of thickness t stays
    uniform, p = F / A, and compresses by the inverted log law d = t (1 - exp(-p / E')): 26 % of
    t here, where the linear law gives 30 % (the Newton on the columns converged, to round-off)."""
    t, nu, area = 2.0, 0.25, 400.0
    force = 0.3 * confined_modulus_mpa(E, nu) * area
    scene = make_scene(grid_plate(20, 20, 16), plane(lambda x, y: t), [0, 0, force], fixed_dofs=("tx", "ty", "rz"),
                       poissons_ratio=nu, law="gap-log", thickness_mm=t, max_spring_length_mm=2 * t)
    step = run(coupled(scene), "dem").steps[0]
    np.testing.assert_allclose(step.pressure_mpa, force / area, rtol=1e-9)
    assert step.displacement_mm[2] == pytest.approx(t * -np.expm1(-0.3), rel=1e-9)


def test_coupled_gap_log_past_its_columns_range_is_warned_not_a_linear_algebra_error():
    """At p = 3 E' (nu 0.45) the coupled layer's linear part carries the approach past t, where the
    log column's own law has no finite stiffness. The weak-DOF check weighs the rows by the
    columns' small-strain stiffness (it once evaluated the log law there and ended in an
    eigensolver's LinAlgError): the run ends, balanced, with the strain warning."""
    t, nu, area = 2.0, 0.45, 400.0
    force = 3.0 * confined_modulus_mpa(E, nu) * area
    scene = make_scene(grid_plate(20, 20, 16), plane(lambda x, y: t), [0, 0, force], fixed_dofs=("tx", "ty", "rz"),
                       poissons_ratio=nu, law="gap-log", thickness_mm=t, max_spring_length_mm=5 * t, allow_bone_overlap=True)
    result = run(coupled(scene), "dem")
    assert result.steps[0].displacement_mm[2] > t
    assert abs(balance(scene, result.steps[0])[2]) <= 1e-9 * force
    assert any("strain >= 100 %" in w for w in result.warnings)


def test_gap_log_on_the_coupled_layer_is_the_gap_law_at_small_strain_and_stiffer_beyond():
    """Coupled cylinder (nu 0.45): the log law's column differs from the linear one by about d / 2t
    relative, so at 3 N the two coupled solutions agree within the largest strain (0.4 %), and at
    1500 N (31 % strain at the apex) the log layer is the stiffer (3.7 % less approach); its
    solution satisfies w = C f + excess(f) (the Newton's fixed point) to round-off, with KKT and
    balance as for the linear layer."""
    cylinder, tibia = cylinder_patch(20.0, 28.0, 114.0, 40, 8), plane(lambda x, y: 2.0)
    common = dict(fixed_dofs=CYLINDER_DOFS, poissons_ratio=0.45, thickness_mm=2.0)
    for force in (3.0, 1500.0):
        gap, log = (run(coupled(make_scene(cylinder, tibia, [0, 0, force], law=law, **common)), "dem").steps[0] for law in ("gap", "gap-log"))
        strain = log.displacement_mm[2] / 2.0
        ratio = log.displacement_mm[2] / gap.displacement_mm[2]
        if force < 10.0:
            assert strain < 0.01 and abs(ratio - 1.0) <= strain
        else:
            assert strain > 0.05 and ratio < 1.0  # excess(f) <= 0: every column is stiffer
    scene = coupled(make_scene(cylinder, tibia, [0, 0, 1500.0], law="gap-log", **common))
    geometry = spring_geometry(scene.spring_centroid_mm, scene.spring_normal, scene.spring_area_mm2, Placement.identity(scene.reference_point_mm),
                               RayCaster(scene.fixed.vertices_mm, scene.fixed.triangles), scene.fixed_placement(0), scene.cartilage)
    cand = geometry.candidate_index
    rows = generalised_directions(scene.spring_centroid_mm[cand], scene.spring_normal[cand], scene.reference_point_mm)
    step = CoupledStep.build(coupled_layer_mesh(scene), geometry, scene.cartilage, np.zeros(cand.size), rows, np.zeros((0, 6)),
                             LinearElements(np.zeros(0), np.zeros(0)))
    solution = step.solve(np.array([0, 0, 1500.0, 0, 0, 0]), CYLINDER_DOFS, None, 10.0)
    f = np.zeros(step.directions.shape[0])
    f[step.candidate] = solution.element_force_n
    expected = step.layer.deflection(f) + step.column(f)[0]
    np.testing.assert_allclose(solution.deflection_mm, expected[step.candidate], atol=1e-9 * np.abs(expected).max())
    assert solution.force_residual_n <= 1e-9 * 1500.0 and solution.element_force_n.min() >= 0.0
    assert solution.max_penetration_mm <= 1e-9 * 2.0


def test_gap_log_edem_and_viscoelastic_edem_balance_on_the_coupled_layer():
    """EDEM's first step is DEM's; every step of EDEM and of viscoelastic EDEM (the thesis's
    increment: the creeping contact set takes linear laws only) balances the load (elastic +
    viscous forces), and the dashpots hold the body back while loading."""
    load = np.column_stack([np.zeros(5), np.zeros(5), np.linspace(300.0, 1500.0, 5)])
    common = dict(fixed_dofs=CYLINDER_DOFS, time_s=np.arange(5.0), poissons_ratio=0.45, law="gap-log", thickness_mm=2.0)
    cylinder, tibia = cylinder_patch(20.0, 28.0, 114.0, 40, 8), plane(lambda x, y: 2.0)
    scene = coupled(make_scene(cylinder, tibia, load, **common))
    dem, edem = run(scene, "dem"), run(scene, "edem")
    np.testing.assert_allclose(edem.steps[0].pressure_mpa, dem.steps[0].pressure_mpa, rtol=1e-12, atol=1e-14)
    slow_scene = coupled(make_scene(cylinder, tibia, load, viscoelastic=Viscoelastic(2.0, contact_set="frozen"), **common))
    slow = run(slow_scene, "edem")
    for step in edem.steps + slow.steps:
        assert abs(balance(scene, step)[2]) <= 1e-9 * step.force_n[2]
    assert all(s.displacement_mm[2] < e.displacement_mm[2] for s, e in zip(slow.steps[1:], edem.steps[1:]))


def test_squeeze_film_under_a_plate_with_a_free_edge():
    """A rigid plane pressed onto a bonded disk layer (radius a = 8 h) at nu = 0.4999: the layer
    squeezes out at its free edge. The Pade layer with e -> 0 and S p = 0 on the free edge has the
    closed form p = (3 G d / 4 h^3)(a^2 - r^2) + 3 b G d / h (d the approach): the classical
    squeeze-film paraboloid plus an edge term 4 b (h/a)^2 of its peak. Area-weighted L2 within
    3 % (mesh h / 3, O((ks)^2) and the e = 2e-4 compressibility, (a/l)^2/8 < 1 %)."""
    h, a, nu, force = 0.75, 6.0, 0.4999, 200.0
    plate = disk_plate(a, 24)
    scene = coupled(make_scene(plate, plane(lambda x, y: h), [0, 0, force], fixed_dofs=("tx", "ty", "rx", "ry", "rz"),
                               poissons_ratio=nu, law="gap", thickness_mm=h, max_spring_length_mm=2 * h))
    step = run(scene, "dem").steps[0]
    assert np.all(step.in_contact)
    r = np.linalg.norm(scene.spring_centroid_mm[:, :2], axis=1)
    g = E / (2 * (1 + nu))
    d = step.displacement_mm[2]
    b = 1.8  # the Pade b at nu = 1/2 (test_thin_layer)
    expected = 3 * g * d / (4 * h**3) * (a**2 - r**2) + 3 * b * g * d / h
    area = scene.spring_area_mm2
    error = np.sqrt((area * (step.pressure_mpa - expected) ** 2).sum() / (area * expected**2).sum())
    assert error < 0.03
    assert abs(balance(scene, step)[2]) <= 1e-9 * force


def test_threshold_layer_ends_with_a_free_face_where_the_candidates_end():
    """The threshold law's layer is the candidates (the gap the cartilage fills, as the FE slab):
    a wide plate under a rigid disk of radius a = 8 h at the spring length h (the plate's springs
    beyond the disk see nothing) is the squeeze film of the bonded disk above, its edge at the
    candidates' boundary: the same closed form within the same 3 % (measured 0.75 %). A layer
    going on beyond the disk (the gap laws' extent) confines the edge instead: 44 % off."""
    h, a, nu, force = 0.75, 6.0, 0.4999, 200.0
    plate = disk_plate(2 * a, 48)  # ring 24 at r = a: the candidates' boundary is a ring of vertices
    scene = coupled(make_scene(plate, disk(a, h), [0, 0, force], fixed_dofs=("tx", "ty", "rx", "ry", "rz"),
                               poissons_ratio=nu, law="threshold", max_spring_length_mm=2 * h))
    step = run(scene, "dem").steps[0]
    r = np.linalg.norm(scene.spring_centroid_mm[:, :2], axis=1)
    inside = r < a
    assert np.array_equal(step.in_contact, inside)
    g = E / (2 * (1 + nu))
    d = step.displacement_mm[2]
    b = 1.8  # the Pade b at nu = 1/2 (test_thin_layer)
    expected = 3 * g * d / (4 * h**3) * (a**2 - r[inside] ** 2) + 3 * b * g * d / h
    area = scene.spring_area_mm2[inside]
    error = np.sqrt((area * (step.pressure_mpa[inside] - expected) ** 2).sum() / (area * expected**2).sum())
    assert error < 0.03
    assert abs(balance(scene, step)[2]) <= 1e-9 * force


def test_a_layer_without_interior_vertices_is_its_local_columns():
    """A rigid disk small enough that the threshold law's layer (its candidates) has every vertex
    on its free edge: the smoothed field vanishes, so each column has the local compliance c_loc
    alone (squeezing out on every side): d = F c_loc / (G_c A) with G_c the columns' total area."""
    h, nu, force = 1.0, 0.45, 5.0
    # (the columns' approach passes their 1 mm length: kept, as the operator's limit is what is checked)
    scene = coupled(make_scene(grid_plate(10, 10, 20), disk(0.3, h), [0, 0, force], fixed_dofs=("tx", "ty", "rx", "ry", "rz"),
                               poissons_ratio=nu, law="threshold", max_spring_length_mm=2 * h, allow_bone_overlap=True))
    step = run(scene, "dem").steps[0]
    area = scene.spring_area_mm2[step.in_contact].sum()
    c_loc = pade_symbol(nu).local * h / (E / (2 * (1 + nu)))
    assert 0 < step.in_contact.sum() <= 8
    assert step.displacement_mm[2] == pytest.approx(force * float(c_loc) / area, rel=1e-9)
    np.testing.assert_allclose(step.pressure_mpa[step.in_contact], force / area, rtol=1e-9)


@pytest.mark.parametrize("law", ("threshold", "gap"))
def test_flat_plates_at_the_uncoupled_poisson_ratio_stay_uniform(law):
    """nu = 1/4 (c1 = 0): no lateral coupling even with free edges: p = F / A, d = F t / (E' A)."""
    t, force, nu = 2.0, 333.0, 0.25
    scene = make_scene(grid_plate(20, 20, 16), plane(lambda x, y: t), [0, 0, force], fixed_dofs=("tx", "ty", "rz"),
                       poissons_ratio=nu, law=law, thickness_mm=t if law == "gap" else None, max_spring_length_mm=2 * t)
    step = run(coupled(scene), "dem").steps[0]
    np.testing.assert_allclose(step.pressure_mpa, force / 400.0, rtol=1e-12)
    assert step.displacement_mm[2] == pytest.approx(force * t / (confined_modulus_mpa(E, nu) * 400.0), rel=1e-12)


def test_poisson_ratio_zero_gives_back_the_independent_springs():
    """nu = 0: c1 = 0, the coupled layer is the spring bed: same solve to round-off."""
    scene = load_scene("cylinder-layer", {"cartilage.poissons_ratio": 0.0})
    springs, layer = run(scene).steps[0], run(coupled(scene)).steps[0]
    np.testing.assert_allclose(layer.pressure_mpa, springs.pressure_mpa, rtol=1e-9, atol=1e-12 * springs.peak_pressure_mpa)
    np.testing.assert_allclose(layer.displacement_mm, springs.displacement_mm, rtol=1e-9)


@pytest.mark.parametrize("resolution", (0.0, 1.0))
@pytest.mark.parametrize("symbol", ("pade", "two-pole"))
@pytest.mark.parametrize("nu", (0.3, 0.45, 0.499))
def test_coupled_cylinder_satisfies_kkt_with_the_bulge_outside_contact(nu, symbol, resolution):
    """Bonded cylinder layer: p >= 0, balance to round-off, and the recomputed surface
    (w = C f from the output pressures) touches the plane in contact and stays off it outside,
    including where it bulges (w < 0) at high nu. With a coarse smoothing space (resolution 1:
    cells sqrt(b) h, 2.5 mm for the Pade on the 2 mm layer, about 2.5 springs across) the gap
    law's layer, the whole surface, solves its bulge term on it and the same holds."""
    scene = coupled(load_scene("cylinder-layer", {"cartilage.poissons_ratio": nu}), thin_layer_symbol=symbol,
                    thin_layer_smoothing_resolution=resolution)
    step = run(scene).steps[0]
    assert np.all(step.pressure_mpa >= 0.0) and np.all(step.pressure_mpa[~step.in_contact] == 0.0)
    residual = balance(scene, step)
    assert np.abs(residual[[1, 2]]).max() <= 1e-10 * 333.0  # the free DOFs ty, tz
    geometry = spring_geometry(scene.spring_centroid_mm, scene.spring_normal, scene.spring_area_mm2,
                               Placement.identity(scene.reference_point_mm), RayCaster(scene.fixed.vertices_mm, scene.fixed.triangles),
                               scene.fixed_placement(0), scene.cartilage)
    cand = geometry.candidate
    rows = generalised_directions(geometry.centroid_mm[cand], geometry.normal[cand], scene.reference_point_mm)
    step_model = CoupledStep.build(coupled_layer_mesh(scene), geometry, scene.cartilage, np.zeros(cand.sum()), rows,
                                   np.zeros((0, 6)), None)
    if resolution > 0.0 and nu > 0.4:  # the two-pole's bulge at nu 0.3 (sqrt(b) h = 1.4 mm) is under two springs across: fine
        bulge = [t for t in step_model.layer.terms if t.sigma < 0.0]
        assert bulge[0].coarse is not None and bulge[0].h.shape[0] < bulge[0].coarse.transfer.shape[0] / 2
    forces = np.zeros(step_model.candidate.shape[0])
    forces[step_model.candidate] = (step.pressure_mpa * scene.spring_area_mm2)[cand]
    u = np.concatenate([step.displacement_mm, step.rotation_rad])
    w = step_model.layer.deflection(forces)[step_model.candidate]
    compression = step_model.overlap_mm[step_model.candidate] + rows @ u
    contact = step.in_contact[cand]
    scale = np.abs(compression).max()
    np.testing.assert_allclose(w[contact], compression[contact], atol=1e-9 * scale)
    assert np.all(w[~contact] >= compression[~contact] - 1e-9 * scale)
    if nu > 0.4:
        assert w[~contact].min() < -1e-3 * w.max()  # the surface bulges beside the contact


@pytest.mark.parametrize("symbol", ("pade", "two-pole"))
def test_dem_and_edem_agree_on_the_first_step_and_edem_balances_every_step(symbol):
    scene = coupled(make_scene(cylinder_patch(20.0, 28.0, 114.0, 40, 8), plane(lambda x, y: 1.5), ramp(1500.0, 4),
                               fixed_dofs=CYLINDER_DOFS, poissons_ratio=0.45), thin_layer_symbol=symbol)
    dem, edem = run(scene, "dem"), run(scene, "edem")
    np.testing.assert_allclose(edem.steps[0].pressure_mpa, dem.steps[0].pressure_mpa, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(edem.steps[0].displacement_mm, dem.steps[0].displacement_mm, rtol=1e-12, atol=1e-15)
    for step in edem.steps:
        assert abs(balance(scene, step)[2]) <= 1e-9 * step.force_n[2]
    # The push-back carries the coupled field: EDEM ends near DEM at the same load (the threshold
    # law is incremental, so not equal; within the 10 % the spring bed itself shows, test_solver).
    # Not a bound for the two-pole layer, which concentrates strain at the contact edge: EDEM
    # integrates the current-length stiffness (a logarithmic strain) and DEM does not, so they
    # part by about the local strain there (measured 11 %); the first step and balance hold.
    if symbol == "pade":
        assert edem.steps[-1].displacement_mm[2] == pytest.approx(dem.steps[-1].displacement_mm[2], rel=0.1)


def test_previous_contact_as_first_guess_finds_the_cold_start_solution():
    """DEM over a load ramp starts each active set from the previous time point's contact; the
    programme is strictly convex, so every time point equals its cold solve (a one-point scene)
    to round-off (1e-9 of the peak: the balance's own 1e-7 cycle tolerance is not reached by a
    set that converges) in no more iterations."""
    cylinder, tibia = cylinder_patch(20.0, 28.0, 114.0, 40, 8), plane(lambda x, y: 2.3)
    common = dict(fixed_dofs=CYLINDER_DOFS, poissons_ratio=0.45, law="gap", thickness_mm=2.0)
    loads = ramp(1500.0, 5)
    warm = run(coupled(make_scene(cylinder, tibia, loads, **common)), "dem").steps
    cold = [run(coupled(make_scene(cylinder, tibia, load, **common)), "dem").steps[0] for load in loads]
    for w, c in zip(warm, cold):
        np.testing.assert_allclose(w.pressure_mpa, c.pressure_mpa, rtol=0.0, atol=1e-9 * c.peak_pressure_mpa)
        assert np.array_equal(w.in_contact, c.in_contact)
    assert sum(w.iterations for w in warm[1:]) < sum(c.iterations for c in cold[1:])


@pytest.mark.parametrize("symbol", ["pade", "two-pole"])
def test_the_first_iterates_without_history_all_find_the_same_solution(symbol, monkeypatch):
    """A solve without two time points of history starts its active set from the independent
    springs' contact set (``CoupledThinLayer._springs_contact``); without that, a cold start
    takes the springs whose surfaces overlap before the layer deflects. The programme is strictly
    convex, so both end where a start from every candidate ends: the same contact set and
    pressures to round-off (1e-9 of the peak, as above), each in no more iterations than the
    last (here 4 / 4 / 4 for the Pade, 4 / 5 / 5 for the two-pole)."""
    import edem.thin_layer_contact as thin_layer_contact

    cylinder, tibia = cylinder_patch(20.0, 28.0, 114.0, 40, 8), plane(lambda x, y: 2.3)
    scene = coupled(make_scene(cylinder, tibia, ramp(1500.0, 3)[1], fixed_dofs=CYLINDER_DOFS, poissons_ratio=0.45, law="gap",
                               thickness_mm=2.0), thin_layer_symbol=symbol)
    springs = run(scene, "dem").steps[0]
    monkeypatch.setattr(CoupledThinLayer, "_springs_contact", staticmethod(lambda step, load: None))
    overlapping = run(scene, "dem").steps[0]
    solve = thin_layer_contact.solve_thin_layer

    def from_every_candidate(directions, layer, overlap_mm, load, **keys):
        return solve(directions, layer, overlap_mm, load, **{**keys, "initial_active": np.ones(directions.shape[0], bool)})

    monkeypatch.setattr(thin_layer_contact, "solve_thin_layer", from_every_candidate)
    every = run(scene, "dem").steps[0]
    for step in (springs, overlapping):
        np.testing.assert_allclose(step.pressure_mpa, every.pressure_mpa, rtol=0.0, atol=1e-9 * every.peak_pressure_mpa)
        assert np.array_equal(step.in_contact, every.in_contact)
    assert springs.iterations <= overlapping.iterations <= every.iterations


def test_the_extrapolated_contact_as_first_guess_finds_the_same_edem_path_in_fewer_iterations(monkeypatch):
    """EDEM on the gap law's layer under a growing load: starting each active set from the
    extrapolation of the last two time points' forces and gaps (``ContactHistory.first_set``)
    instead of the previous contact set gives the same pressures at every time point to round-off
    (1e-9 of the peak, as for the cold start above: a converged set is exact to the 6 x 6 solve)
    and the same contact sets, in fewer active-set iterations."""
    from edem.thin_layer_contact import ContactHistory

    cylinder, tibia = cylinder_patch(20.0, 28.0, 114.0, 40, 8), plane(lambda x, y: 2.3)
    scene = coupled(make_scene(cylinder, tibia, ramp(1500.0, 8), fixed_dofs=CYLINDER_DOFS, poissons_ratio=0.45, law="gap", thickness_mm=2.0))
    extrapolated = run(scene, "edem").steps
    # the previous set as it is: no extrapolation (the history of one time point)
    monkeypatch.setattr(ContactHistory, "record", lambda self, index, solution, record=ContactHistory.record: (
        record(self, index, solution), setattr(self, "recorded", 1)))
    previous = run(scene, "edem").steps
    for a, b in zip(extrapolated, previous):
        np.testing.assert_allclose(a.pressure_mpa, b.pressure_mpa, rtol=0.0, atol=1e-9 * b.peak_pressure_mpa)
        assert np.array_equal(a.in_contact, b.in_contact)
    assert sum(s.iterations for s in extrapolated) < sum(s.iterations for s in previous)


def test_edem_load_then_unload_retraces_its_path_on_the_coupled_layer():
    """Load to 2 kN and back to zero (threshold law, nu 0.45). At 1000 N the unloading pose
    matches the loading one up to the incremental law's first-order error (the coupled thickness
    follows the current spring lengths, the layer's extent the candidates): the gap halves when
    the steps halve (ratio 2 +- 10 %), so it vanishes with the step (measured 1.12 % at 20 steps
    each way, 0.56 % at 40, 0.28 % at 80; the spring bed's 0.59 / 0.29 / 0.15 %). At zero load no
    force is left (the pose itself is then not unique: nothing holds the body)."""
    gaps = []
    for n in (20, 40):
        scene = coupled(make_scene(cylinder_patch(20.0, 28.0, 114.0, 60, 10), plane(lambda x, y: 1.5), ramp(2000.0, n, n),
                                   fixed_dofs=CYLINDER_DOFS, poissons_ratio=0.45))
        steps = run(scene, "edem").steps
        up, down = steps[n // 2 - 1], steps[2 * n - 1 - n // 2]
        assert up.force_n[2] == down.force_n[2] == 1000.0
        gaps.append(abs(down.displacement_mm[2] / up.displacement_mm[2] - 1.0))
        assert steps[-1].peak_pressure_mpa * steps[-1].contact_area_mm2 < 1e-6 * 2000.0
    assert gaps[0] / gaps[1] == pytest.approx(2.0, rel=0.1)


@pytest.mark.parametrize("contact_set", ("creeping", "frozen"))
@pytest.mark.parametrize("symbol", ("pade", "two-pole"))
def test_viscoelastic_edem_on_the_coupled_layer(symbol, contact_set):
    """tau -> 0 is elastic EDEM; with tau, elastic + viscous forces balance the load every step."""
    load = np.column_stack([np.zeros(6), np.zeros(6), np.linspace(0.0, 1500.0, 6)])
    common = dict(fixed_dofs=CYLINDER_DOFS, time_s=np.arange(6.0), poissons_ratio=0.45)
    cylinder, tibia = cylinder_patch(20.0, 28.0, 114.0, 40, 8), plane(lambda x, y: 1.5)
    elastic = run(coupled(make_scene(cylinder, tibia, load, **common), thin_layer_symbol=symbol), "edem")
    fast = run(coupled(make_scene(cylinder, tibia, load, viscoelastic=Viscoelastic(1e-9, contact_set=contact_set), **common),
                       thin_layer_symbol=symbol), "edem")
    np.testing.assert_allclose([s.displacement_mm[2] for s in fast.steps], [s.displacement_mm[2] for s in elastic.steps], rtol=1e-7)
    scene = coupled(make_scene(cylinder, tibia, load, viscoelastic=Viscoelastic(2.0, contact_set=contact_set), **common), thin_layer_symbol=symbol)
    slow = run(scene, "edem")
    for step in slow.steps:
        assert np.all(step.pressure_mpa - step.viscous_pressure_mpa >= 0.0)
        assert abs(balance(scene, step)[2]) <= 1e-9 * step.force_n[2]
    lag = [s.displacement_mm[2] / e.displacement_mm[2] for s, e in zip(slow.steps[1:], elastic.steps[1:])]
    assert all(0.0 < v < 1.0 for v in lag[1:])  # the dashpots hold the body back while loading


def disk(radius_mm: float, z_mm: float, n: int = 256) -> TriangleSurface:
    """A flat disk facing down (-z): the rigid punch."""
    angle = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    vertices = np.vstack([[0.0, 0.0, z_mm], np.column_stack([radius_mm * np.cos(angle), radius_mm * np.sin(angle), np.full(n, z_mm)])])
    ring = np.arange(1, n + 1)
    return TriangleSurface(vertices, np.column_stack([np.zeros(n, int), np.roll(ring, -1), ring]))


def test_incompressible_flat_punch_gives_the_thin_layer_paraboloid_through_the_solve():
    """Rigid flat punch (a = 8 h) on a bonded layer at nu = 0.4999, only tz free: the pressure under
    it is the thin-layer paraboloid p0 - (3 G d / 4 h^3) r^2 (lap p = -3 G d / h^3, d the solved
    approach); curvature within 3 % as in test_thin_layer (mesh h / 3, least-squares fit over
    r < a - 3h). The layer beside the punch is free and bulges."""
    h, a, nu, force = 0.75, 6.0, 0.4999, 200.0
    scene = coupled(make_scene(grid_plate(24, 24, 96), disk(a, h), [0, 0, force], fixed_dofs=("tx", "ty", "rx", "ry", "rz"),
                               poissons_ratio=nu, law="gap", thickness_mm=h, max_spring_length_mm=2 * h))
    step = run(scene, "dem").steps[0]
    r = np.linalg.norm(scene.spring_centroid_mm[:, :2], axis=1)
    assert np.all(step.in_contact[r < a - 0.3]) and not np.any(step.in_contact[r > a + 0.3])
    core = r < a - 3 * h
    fit = np.linalg.lstsq(np.column_stack([np.ones(core.sum()), r[core] ** 2]), step.pressure_mpa[core], rcond=None)[0]
    g = E / (2 * (1 + nu))
    assert -fit[1] == pytest.approx(3 * g * step.displacement_mm[2] / (4 * h**3), rel=0.03)
    assert abs(balance(scene, step)[2]) <= 1e-9 * force


def test_ligaments_and_shear_springs_act_beside_the_coupled_layer():
    """A ligament below the plate takes T = E A / L0 d (tension only) and the layer the rest; shear
    springs carry a tangential load on the coupled cylinder (balance in every free DOF)."""
    mobile, fixed = grid_plate(20, 20, 8), plane(lambda x, y: 2.0)
    below = Ligament("lig", np.zeros(3), np.array([0.0, 0.0, -20.0]), 255.0, 10.0, 20.0)
    scene = coupled(make_scene(mobile, fixed, [0, 0, 300.0], fixed_dofs=("tx", "ty", "rz"), ligaments=(below,), poissons_ratio=0.49))
    step = run(scene, "dem").steps[0]
    tension = 255.0 * 10.0 / 20.0 * step.displacement_mm[2]
    assert step.ligament_force_n[0] == pytest.approx(tension, rel=1e-9)
    assert (step.pressure_mpa * step.area_mm2).sum() == pytest.approx(300.0 - tension, rel=1e-9)
    scene = coupled(make_scene(cylinder_patch(20.0, 28.0, 114.0, 40, 8), plane(lambda x, y: 1.5), [20.0, 0, 333.0],
                               fixed_dofs=("rx", "ry", "rz"), shear_modulus_mpa=3.6, poissons_ratio=0.45))
    step = run(scene, "dem").steps[0]
    assert step.displacement_mm[0] > 0 and step.force_residual_n <= 1e-9 * 333.0


def test_coupled_dem_is_not_judged_by_the_independent_springs_remeasure():
    """The DEM re-measure check evaluates the independent law at the solved pose; the coupled layer's
    forces are not a function of each spring's length, so a coupled run records none (and no warning)."""
    scene = load_scene("ideal-standing", {"cartilage.coupling": "thin-layer", "cartilage.poissons_ratio": 0.49, "ligaments": []})
    result = run(scene, "dem")
    assert not any("measured again" in w for w in result.warnings)
    assert result.steps[0].remeasured_imbalance is None


def test_thin_layer_symbol_is_refused_without_the_coupling_or_when_unknown():
    """Exit-2 errors name the key and what it expects: the symbol only means something under the
    coupling, only the registered symbols exist, and the log law's columns need a local compliance
    of at least G/E'."""
    with pytest.raises(InputError) as alone:
        load_scene("cylinder-layer", {"cartilage.thin_layer_symbol": "two-pole"})
    assert alone.value.key == "cartilage.thin_layer_symbol" and 'coupling = "thin-layer"' in alone.value.expected
    with pytest.raises(InputError) as unknown:
        load_scene("cylinder-layer", {"cartilage.coupling": "thin-layer", "cartilage.thin_layer_symbol": "pade-2"})
    assert unknown.value.key == "cartilage.thin_layer_symbol" and all(name in unknown.value.expected for name in ("pade", "two-pole"))
    # gap-log linearises its columns into the local compliance, taking up to G/E' off it: refused
    # where the symbol's local part is below G/E' (the two-pole; the Pade between nu 0 and 1/4,
    # whose factor then lost definiteness under 4 kN), taken from G/E' up (the Pade at nu 0, 1/4, 0.3)
    log = {"cartilage.coupling": "thin-layer", "cartilage.law": "gap-log"}
    with pytest.raises(InputError) as two_pole:
        load_scene("cylinder-layer", {**log, "cartilage.thin_layer_symbol": "two-pole"})
    assert two_pole.value.key == "cartilage.thin_layer_symbol" and "G/E'" in str(two_pole.value)
    with pytest.raises(InputError) as low_nu:
        load_scene("cylinder-layer", {**log, "cartilage.poissons_ratio": 0.1})
    assert low_nu.value.key == "cartilage.law"
    for nu in (0.0, 0.25, 0.3):
        assert pade_symbol(nu).local >= taylor_coefficients(nu)[0] * (1 - 1e-12)
        load_scene("cylinder-layer", {**log, "cartilage.poissons_ratio": nu})
    scene = load_scene("cylinder-layer", {"cartilage.coupling": "thin-layer", "cartilage.thin_layer_symbol": "two-pole"})
    assert scene.cartilage.bed_keys.thin_layer_symbol == "two-pole"


def test_an_under_resolved_smoothing_term_is_warned():
    """The two-pole's sag term is sqrt(b) h ~ 0.46 mm long on the 2 mm layer at nu 0.49; the
    built-in cylinder's springs are ~0.86 mm across, so it warns, with the length to aim for; the
    Pade's single term (~1.3 h) does not."""
    scene = load_scene("cylinder-layer", {"cartilage.coupling": "thin-layer", "cartilage.poissons_ratio": 0.49})
    assert not [w for w in run(scene).warnings if "smoothing length" in w]
    two_pole = run(coupled(scene, thin_layer_symbol="two-pole")).warnings
    (warning,) = [w for w in two_pole if "smoothing length" in w]
    length = np.sqrt(min(two_pole_symbol(0.49).screenings)) * scene.cartilage.thickness_mm
    size = np.sqrt(2.0 * np.median(scene.spring_area_mm2))
    assert length < size and f"length, {length:.2g} mm" in warning and f"size {size:.2g} mm" in warning


@pytest.mark.parametrize("symbol", ("pade", "two-pole"))
def test_push_back_solved_over_the_carried_forces_equals_the_formed_push_back(symbol):
    """EDEM's push-back d0 = C c of carried forces c, solved for as increments over them with the
    contact matrix's own factor (module docstring, "Carried forces"), equals the solve on the
    formed d0 = C c to round-off: forces, pose, the gap out of contact, and the deflection less
    C c; also where springs that carried a force leave the contact (c_N != 0: here the carried
    forces are those of a load 2.5 times the one applied, scaled spring by spring by 0-2, so the
    body backs off and the springs that carried little leave), and for the viscoelastic
    increment, whose set keeps every carried spring."""
    scene = coupled(make_scene(cylinder_patch(20.0, 28.0, 114.0, 40, 8), plane(lambda x, y: 1.5), [0.0, 0.0, 1500.0],
                               fixed_dofs=CYLINDER_DOFS, poissons_ratio=0.45, law="threshold"), thin_layer_symbol=symbol)
    geometry = spring_geometry(scene.spring_centroid_mm, scene.spring_normal, scene.spring_area_mm2,
                               Placement.identity(scene.reference_point_mm), RayCaster(scene.fixed.vertices_mm, scene.fixed.triangles),
                               scene.fixed_placement(0), scene.cartilage)
    cand = geometry.candidate
    rows = generalised_directions(geometry.centroid_mm[cand], geometry.normal[cand], scene.reference_point_mm)
    mesh = coupled_layer_mesh(scene)
    no_ligaments = (np.zeros((0, 6)), LinearElements(np.zeros(0), np.zeros(0)))
    dem = CoupledStep.build(mesh, geometry, scene.cartilage, np.zeros(cand.sum()), rows, *no_ligaments)
    carried = dem.solve(np.array([0.0, 0.0, 1500.0, 0.0, 0.0, 0.0]), CYLINDER_DOFS, None, 1.0).element_force_n[: cand.sum()]
    carried = carried * np.random.default_rng(7).uniform(0.0, 2.0, carried.shape)
    step = CoupledStep.build(mesh, geometry, scene.cartilage, carried, rows, *no_ligaments)
    c = step.pushback_force_n
    assert np.all(step.overlap_mm[step.candidate] == 0.0) and np.array_equal(c[step.candidate], carried)
    formed = step.layer.deflection(c)  # C c: the factorisation of H alone the solve does without
    load = np.array([0.0, 0.0, 600.0, 0.0, 0.0, 0.0])
    new = solve_thin_layer(step.directions, step.layer, step.overlap_mm, load, fixed_dofs=CYLINDER_DOFS, pushback_force_n=c)
    old = solve_thin_layer(step.directions, step.layer, formed, load, fixed_dofs=CYLINDER_DOFS)
    released = ~new.active[: c.shape[0]] & (c > 0.0)
    assert released.sum() >= 10  # the released carried forces' column (-Z_N c_N) is exercised
    scale = np.abs(old.element_force_n).max()
    # Round-off: the two paths differ by solves with differently factored matrices (H, and the
    # contact matrix), each accurate to about 1e-13 of its result on this 0.3k-vertex layer.
    np.testing.assert_allclose(new.element_force_n, old.element_force_n, rtol=0, atol=1e-10 * scale)
    assert np.array_equal(new.active, old.active)
    np.testing.assert_allclose(new.displacement, old.displacement, rtol=1e-10, atol=1e-12)
    depth = np.abs(formed).max()
    np.testing.assert_allclose(new.gap_mm, old.gap_mm, rtol=0, atol=1e-10 * depth)
    np.testing.assert_allclose(new.deflection_mm, old.deflection_mm - formed, rtol=0, atol=1e-10 * depth)
    # The viscoelastic increment (its set: the elastic one and every carried spring).
    elastic = np.concatenate([new.active[: c.shape[0]], np.zeros(0, bool)])
    args = (step.directions, step.layer)
    rest = (*no_ligaments, None, elastic, c, np.array([0, 0, 1500.0, 0, 0, 0]), load,
            (0.4, 0.3), CYLINDER_DOFS)
    u_new, f_new = thin_layer_viscoelastic_increment(*args, step.overlap_mm, *rest, pushback=True)
    u_old, f_old = thin_layer_viscoelastic_increment(*args, formed, *rest)
    np.testing.assert_allclose(u_new, u_old, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(f_new, f_old, rtol=0, atol=1e-10 * scale)


def test_a_run_on_cholmod_is_the_run_on_the_banded_factor(monkeypatch):
    """The gap law's layer over the whole surface factored by CHOLMOD (the optional extra, its bar
    lowered to take this small layer) gives the banded factor's run: the same contact sets and
    iterations, pressures and displacements within 1e-9 of their largest (round-off of two
    backward-stable factors, 1e-14 measured, through the active-set and Woodbury solves)."""
    pytest.importorskip("cvxopt")
    import edem.sparse_factors as sparse_factors

    scene = load_scene("cylinder-layer", {"cartilage.coupling": "thin-layer", "load.force_n": [[0.0, 0.0, 150.0], [0.0, 0.0, 333.0]],
                                          "load.time_s": [0.0, 1.0]})
    monkeypatch.setattr(sparse_factors, "CHOLMOD_MIN_BAND_WORK", 0.0)
    factored = []
    numeric = sparse_factors.SupernodalCholesky._numeric
    monkeypatch.setattr(sparse_factors.SupernodalCholesky, "_numeric", lambda self, entries: factored.append(1) or numeric(self, entries))
    supernodal = run(scene, "edem").steps
    assert factored  # CHOLMOD did factor
    monkeypatch.setattr(sparse_factors, "cholmod_module", lambda: None)
    banded = run(scene, "edem").steps
    for a, b in zip(supernodal, banded):
        assert np.array_equal(a.in_contact, b.in_contact) and a.iterations == b.iterations
        np.testing.assert_allclose(a.pressure_mpa, b.pressure_mpa, rtol=0.0, atol=1e-9 * b.peak_pressure_mpa)
        np.testing.assert_allclose(a.displacement_mm, b.displacement_mm, rtol=0.0, atol=1e-9 * np.abs(b.displacement_mm).max())
