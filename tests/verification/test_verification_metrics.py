"""The comparison metrics (docs/method.md#7-comparison-metrics): hand-computed relative errors, exact surface sampling, two result directories."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from edem.atomic_dirs import write_manifest
from edem.pressure_metrics import regularised_peak_pressure_mpa
from edem.resultdir import non_finite_count, read_result_dir, write_surface_frame
from edem.results import TIMESERIES_COLUMNS, write_pvd
from verification.metrics import (
    against_cycle_peak,
    COMPARISON_METRICS,
    compare_result_dirs,
    contact_area_error,
    displacement_error,
    format_metrics_table,
    l2_relative_error,
    mean_pressure_error,
    peak_pressure_error,
    project_onto_surface,
    relative_error,
    sample_cells_onto,
    sample_onto,
    unloading_branch,
)


# ---------------------------------------------------------------------------------------------
# Scalar errors (hand-computed values)


def test_relative_errors_of_scalars_keep_their_sign():
    # (a - b) / |b|: above the reference positive, below it negative
    assert peak_pressure_error(2.5, 2.0) == pytest.approx(0.25)
    assert mean_pressure_error(0.9, 1.2) == pytest.approx(-0.25)
    assert contact_area_error(450.0, 500.0) == pytest.approx(-0.1)
    assert peak_pressure_error(-1.0, -2.0) == pytest.approx(0.5)  # |b| in the denominator: -1 is above -2
    assert relative_error(-3.0, 2.0) == pytest.approx(2.5)  # the norm of a difference (vectors): unsigned


def test_displacement_error_is_norm_of_difference_over_norm_of_reference_signed_by_which_moves_more():
    # |(1, 2, 2) - (1, 2, 0)| / |(1, 2, 0)| = 2 / sqrt(5); a moves farther than b: positive
    assert displacement_error(np.array([1.0, 2.0, 2.0]), np.array([1.0, 2.0, 0.0])) == pytest.approx(2.0 / math.sqrt(5.0))
    # the bed moving 43 % less than the FE reads -43 %, not +43 %
    assert displacement_error(np.array([0.0, 0.0, 0.057]), np.array([0.0, 0.0, 0.1])) == pytest.approx(-0.43)


def test_zero_reference_gives_zero_or_infinity_never_nan():
    assert relative_error(0.0, 0.0) == 0.0
    assert relative_error(np.zeros(3), np.zeros(3)) == 0.0
    assert relative_error(1e-9, 0.0) == math.inf
    assert l2_relative_error(np.zeros(4), np.zeros(4)) == 0.0
    assert l2_relative_error(np.ones(4), np.zeros(4)) == math.inf


def test_l2_relative_error_weighted_hand_value():
    # sqrt( (1*0^2 + 3*1^2) / (1*1^2 + 3*1^2) ) = sqrt(3/4)
    assert l2_relative_error(np.array([1.0, 2.0]), np.array([1.0, 1.0]), np.array([1.0, 3.0])) == pytest.approx(math.sqrt(0.75))
    # unweighted: sqrt((0.01 + 0.04) / (1 + 4))
    assert l2_relative_error(np.array([1.1, 1.8]), np.array([1.0, 2.0])) == pytest.approx(math.sqrt(0.05 / 5.0))


# ---------------------------------------------------------------------------------------------
# Projection and sampling


def wavy_surface(n: int = 14, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """A curved triangulated surface z = 0.6 sin(x) cos(0.8 y) on a jittered grid."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.linspace(-3, 3, n + 1), np.linspace(-2, 2, n + 1), indexing="ij")
    x = x + rng.uniform(-0.05, 0.05, x.shape)
    y = y + rng.uniform(-0.05, 0.05, y.shape)
    points = np.column_stack([x.ravel(), y.ravel(), 0.6 * np.sin(x.ravel()) * np.cos(0.8 * y.ravel())])
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    return points, np.vstack([np.column_stack([a, b, c]), np.column_stack([a, c, d])])


def random_points_on(points: np.ndarray, triangles: np.ndarray, n: int, seed: int = 7) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    tri = rng.integers(0, len(triangles), n)
    w = rng.dirichlet(np.ones(3), n)
    return np.einsum("ij,ijk->ik", w, points[triangles[tri]]), tri


def test_sample_onto_is_exact_for_a_linear_field_on_a_curved_surface():
    """Barycentric interpolation reproduces f(p) = a . p + c at points of the surface (P1 exactness)."""
    points, triangles = wavy_surface()
    a, c = np.array([0.7, -1.3, 2.1]), 0.4
    dst, _ = random_points_on(points, triangles, 500)
    sampled = sample_onto(points, triangles, points @ a + c, dst)
    np.testing.assert_allclose(sampled, dst @ a + c, rtol=0, atol=1e-12)
    # several fields at once (n_vertices, m)
    both = sample_onto(points, triangles, np.column_stack([points @ a + c, points[:, 2]]), dst)
    np.testing.assert_allclose(both[:, 1], dst[:, 2], atol=1e-12)


def test_projection_of_points_on_the_surface_is_the_point_itself():
    points, triangles = wavy_surface()
    dst, _ = random_points_on(points, triangles, 300, seed=11)
    proj = project_onto_surface(points, triangles, dst)
    assert proj.distance_mm.max() < 1e-12
    np.testing.assert_allclose(proj.point_mm, dst, atol=1e-12)
    assert np.all(proj.barycentric >= -1e-12) and np.allclose(proj.barycentric.sum(axis=1), 1.0)


def test_projection_onto_a_flat_plate_matches_hand_geometry():
    """Plate [0, 2] x [0, 1] at z = 0: above it the foot is (x, y, 0); outside, the nearest edge or corner."""
    points = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0], [2, 1, 0]], float)
    triangles = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]])
    dst = np.array([[0.3, 0.6, 0.7], [1.5, 0.2, -2.0], [2.0 + 3.0, 0.5, 4.0], [-1.0, -1.0, 0.0]])
    proj = project_onto_surface(points, triangles, dst)
    np.testing.assert_allclose(proj.distance_mm, [0.7, 2.0, 5.0, math.sqrt(2.0)], atol=1e-14)
    np.testing.assert_allclose(proj.point_mm, [[0.3, 0.6, 0.0], [1.5, 0.2, 0.0], [2.0, 0.5, 0.0], [0.0, 0.0, 0.0]], atol=1e-14)


def test_projection_is_not_misled_by_nearby_centroids_of_small_triangles():
    """The closest triangle is a large one whose centroid is far away: candidates must widen until certified."""
    big = np.array([[0, 0, 0], [100, 0, 0], [0, 100, 0]], float)
    rng = np.random.default_rng(0)
    small_centres = np.column_stack([rng.uniform(85, 95, 40), rng.uniform(0, 10, 40), np.full(40, 1.0)])
    small = small_centres[:, None, :] + np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]])  # (40, 3, 3)
    points = np.vstack([big, small.reshape(-1, 3)])
    triangles = np.vstack([[0, 1, 2], 3 + np.arange(120).reshape(40, 3)])
    dst = np.array([[90.0, 5.0, 0.0], [88.0, 3.0, -0.2]])
    proj = project_onto_surface(points, triangles, dst)
    np.testing.assert_array_equal(proj.triangle, [0, 0])
    np.testing.assert_allclose(proj.distance_mm, [0.0, 0.2], atol=1e-12)


def test_projection_distance_is_never_beaten_by_dense_samples_of_the_surface():
    """Exactness off the surface: no point of a dense sampling of every triangle is closer."""
    points, triangles = wavy_surface(n=6)
    rng = np.random.default_rng(5)
    dst = rng.uniform([-3, -2, -1], [3, 2, 1], (60, 3))
    proj = project_onto_surface(points, triangles, dst, candidates=1)
    s, t = np.meshgrid(np.linspace(0, 1, 25), np.linspace(0, 1, 25))
    keep = s + t <= 1
    w = np.column_stack([1 - s[keep] - t[keep], s[keep], t[keep]])
    samples = np.einsum("sj,tjk->tsk", w, points[triangles]).reshape(-1, 3)
    dense = np.sqrt(((dst[:, None, :] - samples[None]) ** 2).sum(axis=2)).min(axis=1)
    assert np.all(proj.distance_mm <= dense + 1e-12)
    assert np.all(dense - proj.distance_mm < 0.05)  # the sampling is within 0.05 of the true minimum


def test_sample_cells_onto_returns_the_value_of_the_containing_triangle():
    points, triangles = wavy_surface()
    values = np.arange(len(triangles), dtype=float) * 1.5
    dst, tri = random_points_on(points, triangles, 200, seed=2)
    # keep points safely inside their triangle (away from shared edges)
    np.testing.assert_array_equal(sample_cells_onto(points, triangles, values, points[triangles].mean(axis=1)), values)
    inside = sample_cells_onto(points, triangles, values, dst)
    assert np.mean(inside == values[tri]) > 0.97  # points on shared edges may go to the neighbour


# ---------------------------------------------------------------------------------------------
# Two result directories


def plate_mesh(n: int, size_mm: float, z_mm: float) -> tuple[np.ndarray, np.ndarray]:
    x, y = np.meshgrid(np.linspace(0, size_mm, n + 1), np.linspace(0, size_mm, n + 1), indexing="ij")
    points = np.column_stack([x.ravel(), y.ravel(), np.full(x.size, z_mm)])
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    return points, np.vstack([np.column_stack([a, b, c]), np.column_stack([a, c, d])])


def write_result_dir(
    root: Path,
    rows: list[dict[str, float]],
    frames: list[tuple[np.ndarray, np.ndarray, dict | None, dict | None]],
    method: str,
    summary: dict | None = None,
) -> Path:
    """A result directory (docs/result-format.md) with the given time-series rows and surfaces
    (``summary``: extra summary.json keys)."""
    root.mkdir(parents=True)
    (root / "summary.json").write_text(json.dumps({"scene": "synthetic", "method": method, "wall_time_s": 0.5, **(summary or {})}), encoding="utf-8")
    with open(root / "timeseries.csv", "w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(TIMESERIES_COLUMNS)
        for k, row in enumerate(rows):
            writer.writerow([row.get(c, k if c == "step" else 0.0) for c in TIMESERIES_COLUMNS])
    entries = []
    for k, (points, triangles, point_data, cell_data) in enumerate(frames):
        write_surface_frame(root / f"pressure_{k:04d}.vtp", points, triangles, point_data, cell_data)
        entries.append((rows[k]["time_s"], f"pressure_{k:04d}.vtp"))
    write_pvd(root / "pressure.pvd", entries)
    write_manifest(root)  # a result directory is sealed by its writer
    return root


def linear_pressure(points: np.ndarray) -> np.ndarray:
    return 0.2 + 0.05 * points[:, 0] + 0.02 * points[:, 1]


def test_compare_result_dirs_scalars_and_fe_point_data(tmp_path):
    """a: cell pressure = f(centroid); b (FE layout): a finer surface 1.5 mm away with nodal f and
    cell data of the same name. Sampling b's point data at a's centroids reproduces f exactly (the
    L2 error vanishes); with only b's cell data it does not. Scalars: hand values, max over time."""
    pa, ta = plate_mesh(6, 10.0, 0.0)
    pb, tb = plate_mesh(17, 10.0, 1.5)
    cell_a = {"pressure_mpa": linear_pressure(pa[ta].mean(axis=1)), "in_contact": np.ones(len(ta))}
    nodal_b = {"pressure_mpa": linear_pressure(pb)}
    cell_b = {"pressure_mpa": linear_pressure(pb)[tb].mean(axis=1) + 0.1, "in_contact": np.ones(len(tb))}
    rows_a = [
        {"time_s": 0.0, "peak_pressure_mpa": 1.0, "mean_pressure_mpa": 0.5, "contact_area_mm2": 100.0, "disp_z_mm": 0.1},
        {"time_s": 1.0, "peak_pressure_mpa": 2.2, "mean_pressure_mpa": 0.9, "contact_area_mm2": 110.0, "disp_x_mm": 0.3, "disp_z_mm": 0.4},
    ]
    rows_b = [
        {"time_s": 0.0, "peak_pressure_mpa": 1.0, "mean_pressure_mpa": 0.4, "contact_area_mm2": 100.0, "disp_z_mm": 0.1},
        {"time_s": 1.0, "peak_pressure_mpa": 2.0, "mean_pressure_mpa": 1.0, "contact_area_mm2": 100.0, "disp_z_mm": 0.4},
    ]
    a = write_result_dir(tmp_path / "a", rows_a, [(pa, ta, None, cell_a)] * 2, "edem")
    b = write_result_dir(tmp_path / "b", rows_b, [(pb, tb, nodal_b, cell_b)] * 2, "fe-slab")
    result = compare_result_dirs(a, b)
    assert result["mode"] == "each time point" and len(result["per_time"]) == 2
    m = result["metrics"]
    assert m["peak_pressure_rel_error"] == pytest.approx(0.1)  # (2.2 - 2) / 2 at t = 1
    assert m["mean_pressure_rel_error"] == pytest.approx(0.25)  # (0.5 - 0.4) / 0.4 at t = 0 (larger than -0.1 at t = 1)
    assert m["contact_area_rel_error"] == pytest.approx(0.1)
    assert m["displacement_rel_error"] == pytest.approx(0.75)  # |(0.3, 0, 0)| / |(0, 0, 0.4)|
    assert m["pressure_l2_rel_error"] < 1e-13
    assert result["per_time"][0]["b_pressure_source"] == "point"
    assert result["max_projection_distance_mm"] == pytest.approx(1.5)
    assert result["wall_time_b_s"] == 0.5
    assert "pressure field (L2)" in format_metrics_table(result)

    c = write_result_dir(tmp_path / "c", rows_b, [(pb, tb, None, cell_b)] * 2, "fe-cells")
    cells_only = compare_result_dirs(a, c)
    assert cells_only["per_time"][0]["b_pressure_source"] == "cell"
    expected = l2_relative_error(cell_a["pressure_mpa"], sample_cells_onto(pb, tb, cell_b["pressure_mpa"], pa[ta].mean(axis=1)))
    assert cells_only["metrics"]["pressure_l2_rel_error"] == pytest.approx(expected) and expected > 0.05


def test_compare_uses_the_last_time_points_when_times_differ(tmp_path):
    pa, ta = plate_mesh(2, 1.0, 0.0)
    cell = {"pressure_mpa": np.full(len(ta), 2.0)}
    a = write_result_dir(tmp_path / "a", [{"time_s": 0.0, "peak_pressure_mpa": 9.0}, {"time_s": 1.0, "peak_pressure_mpa": 3.0}], [(pa, ta, None, cell)] * 2, "edem")
    b = write_result_dir(tmp_path / "b", [{"time_s": 5.0, "peak_pressure_mpa": 2.0}], [(pa, ta, None, cell)], "fe")
    result = compare_result_dirs(a, b)
    assert result["mode"] == "last time point" and len(result["per_time"]) == 1
    assert result["metrics"]["peak_pressure_rel_error"] == pytest.approx(0.5)


def test_compare_a_run_with_itself_is_zero_and_reads_edem_output(tmp_path):
    from edem.results import write_results
    from edem.scene import load_scene
    from edem.solver import run
    from verification.campaigns import SCENES_DIR

    scene = load_scene(SCENES_DIR / "flat-plates.toml", {"load.time_s": [0.0, 1.0], "load.force_n": [[0.0, 0.0, 100.0], [0.0, 0.0, 300.0]]})
    out = write_results(run(scene, "edem"), tmp_path / "run")
    result = compare_result_dirs(out, out)
    assert all(v == 0.0 for v in result["metrics"].values())
    assert result["n_common_points"] == scene.spring_area_mm2.shape[0]
    assert non_finite_count(out) == 0
    assert read_result_dir(out).frame(1).cell_data["pressure_mpa"].max() == pytest.approx(300.0 / 400.0)


def test_bad_result_directory_is_an_input_error(tmp_path):
    from geometries.errors import InputError

    with pytest.raises(InputError, match="summary.json"):
        compare_result_dirs(tmp_path, tmp_path)


def test_runs_of_the_same_mesh_are_compared_spring_by_spring(tmp_path):
    """EDEM and DEM of one scene share the springs: each is compared with itself even when the two
    poses differ (here by 3.3 mm across the plate), not with whatever triangle lies nearest."""
    points, triangles = plate_mesh(8, 10.0, 0.0)
    cells = {"pressure_mpa": linear_pressure(points[triangles].mean(axis=1))}
    row = [{"time_s": 0.0, "peak_pressure_mpa": 1.0}]
    a = write_result_dir(tmp_path / "a", row, [(points, triangles, None, cells)], "edem")
    b = write_result_dir(tmp_path / "b", row, [(points + [3.3, 0.0, 0.0], triangles, None, cells)], "dem")
    result = compare_result_dirs(a, b)
    assert result["per_time"][0]["b_pressure_source"] == "cell (same springs)"
    assert result["metrics"]["pressure_l2_rel_error"] == 0.0
    assert result["max_projection_distance_mm"] == pytest.approx(3.3)
    # a different triangulation of the same plate falls back to projection
    c = write_result_dir(tmp_path / "c", row, [(points + [3.3, 0.0, 0.0], triangles[:, [1, 2, 0]], None, cells)], "other")
    assert compare_result_dirs(a, c)["metrics"]["pressure_l2_rel_error"] > 0.01


def test_compare_at_b_time_points_when_they_are_a_subset_of_a(tmp_path):
    """An FE reference solved at some instants of a series is compared at those instants only."""
    pa, ta = plate_mesh(2, 1.0, 0.0)
    rows_a = [{"time_s": t, "peak_pressure_mpa": p, "contact_area_mm2": 1.0} for t, p in ((0.0, 1.0), (0.5, 4.0), (1.0, 9.0), (1.5, 2.0))]
    frames_a = [(pa, ta, None, {"pressure_mpa": np.full(len(ta), r["peak_pressure_mpa"])}) for r in rows_a]
    a = write_result_dir(tmp_path / "a", rows_a, frames_a, "dem")
    rows_b = [{"time_s": 0.5, "peak_pressure_mpa": 2.0, "contact_area_mm2": 1.0}, {"time_s": 1.5, "peak_pressure_mpa": 2.0, "contact_area_mm2": 1.0}]
    b = write_result_dir(tmp_path / "b", rows_b, [(pa, ta, {"pressure_mpa": np.full(len(pa), 2.0)}, None)] * 2, "fe")
    result = compare_result_dirs(a, b)
    assert result["mode"] == "b's time points"
    assert [e["time_a_s"] for e in result["per_time"]] == [0.5, 1.5]
    assert result["metrics"]["peak_pressure_rel_error"] == pytest.approx(1.0)  # (4 - 2) / 2 at t = 0.5, not 9 at t = 1
    assert result["metrics"]["pressure_l2_rel_error"] == pytest.approx(1.0)  # a's map at t = 0.5 (4) against 2


def test_fe_surface_is_sampled_at_the_spring_ends(tmp_path):
    """a: a plate at z = 0 with springs 2 mm long along +z; b: a surface at z = 2 mm carrying
    p = x (nodal). Sampled at the spring ends each spring meets b right above itself (distance 0,
    L2 exact for this linear field); at the centroids the projection would be 2 mm away."""
    pa, ta = plate_mesh(4, 4.0, 0.0)
    pb, tb = plate_mesh(8, 4.0, 2.0)
    centroid_x = pa[ta].mean(axis=1)[:, 0]
    cells = {"pressure_mpa": centroid_x, "spring_length_mm": np.full(len(ta), 2.0)}
    a = write_result_dir(tmp_path / "a", [{"time_s": 0.0, "peak_pressure_mpa": 1.0}], [(pa, ta, None, cells)], "dem")
    b = write_result_dir(tmp_path / "b", [{"time_s": 0.0, "peak_pressure_mpa": 1.0}], [(pb, tb, {"pressure_mpa": pb[:, 0]}, None)], "fe")
    result = compare_result_dirs(a, b)
    assert result["per_time"][0]["a_sampled_at"].startswith("spring ends")
    assert result["max_projection_distance_mm"] < 1e-12
    assert result["metrics"]["pressure_l2_rel_error"] < 1e-12


def test_springs_are_compared_with_the_fe_measured_on_m(tmp_path):
    """b (FE layout) carries its area and pressure on M too (a per-time-point summary list and
    pressure_on_mobile_mpa = 1.1 x its face pressure, as a layer 2 mm thick on R 20 mm: the
    columns fan out by 22/20). A spring run a (on M) is compared with those: a built to match
    the on-M values has zero errors (peak, mean = the same force over the area on M, area, field),
    whereas against the face values it would be off by 10 %. Two FE runs (both with on-M data)
    are still compared on their own surfaces."""
    fan = 1.1
    pa, ta = plate_mesh(6, 10.0, 0.0)
    pb, tb = plate_mesh(17, 10.0, 1.5)
    face = {"pressure_mpa": linear_pressure(pb), "pressure_on_mobile_mpa": fan * linear_pressure(pb)}
    row_b = {"time_s": 0.0, "peak_pressure_mpa": float(linear_pressure(pb).max()), "mean_pressure_mpa": 0.5, "contact_area_mm2": 110.0, "disp_z_mm": 0.1}
    b = write_result_dir(tmp_path / "b", [row_b], [(pb, tb, face, None)], "fe-layer", {"contact_area_on_mobile_mm2": [110.0 / fan]})
    cells_a = {"pressure_mpa": fan * linear_pressure(pa[ta].mean(axis=1))}
    # on M: same force (0.5 MPa x 110 mm^2) over 100 mm^2, the largest on-M nodal pressure
    row_a = {"time_s": 0.0, "peak_pressure_mpa": fan * float(linear_pressure(pb).max()), "mean_pressure_mpa": 0.55, "contact_area_mm2": 100.0, "disp_z_mm": 0.1}
    a = write_result_dir(tmp_path / "a", [row_a], [(pa, ta, None, cells_a)], "dem")
    result = compare_result_dirs(a, b)
    assert result["b_measured_on"].startswith("M") and "b measured on: M" in format_metrics_table(result)
    for name in set(COMPARISON_METRICS) - {"regularised_peak_pressure_rel_error"}:
        assert abs(result["metrics"][name]) < 1e-12, name  # round-off of sums of a few hundred terms
    # the regularised peak (a disc mean, not exact between a's cells and b's nodes) is b's on-M field's:
    # fan x that of the face pressure, the disc mean being linear in the field (round-off)
    face_peak = regularised_peak_pressure_mpa(pb, tb, linear_pressure(pb), at_points=True)
    assert result["per_time"][0]["regularised_peak_pressure_b_mpa"] == pytest.approx(fan * face_peak, rel=1e-12)
    fe_a = write_result_dir(tmp_path / "fe-a", [row_b], [(pb, tb, face, None)], "fe-layer", {"contact_area_on_mobile_mm2": [50.0]})
    both_fe = compare_result_dirs(fe_a, b)
    assert both_fe["b_measured_on"] == "b's own surface" and both_fe["metrics"]["contact_area_rel_error"] == 0.0


def test_field_difference_of_two_fe_runs_is_the_l2_of_their_on_m_fields(tmp_path):
    """Two FE-layout runs on different plate meshes, b's field on M linear and a's 1.03 times it:
    a's corner mean at its centroids and b's P1 interpolation there are both exact for a linear
    field, so ||p_a - p_b|| / ||p_b|| = 0.03 and, the other way round, 0.03 / 1.03 (round-off of
    sums of a few hundred terms). The face pressure (pressure_mpa) is not the field compared."""
    from verification.fe_convergence import field_difference

    pa, ta = plate_mesh(6, 10.0, 0.0)
    pb, tb = plate_mesh(17, 10.0, 0.0)
    row = {"time_s": 0.0, "peak_pressure_mpa": 1.0, "mean_pressure_mpa": 0.5, "contact_area_mm2": 100.0}
    a = write_result_dir(tmp_path / "a", [row], [(pa, ta, {"pressure_mpa": np.ones(len(pa)), "pressure_on_mobile_mpa": 1.03 * linear_pressure(pa)}, None)], "fe-slab")
    b = write_result_dir(tmp_path / "b", [row], [(pb, tb, {"pressure_mpa": np.zeros(len(pb)), "pressure_on_mobile_mpa": linear_pressure(pb)}, None)], "fe-slab")
    assert field_difference(a, b) == pytest.approx(0.03, rel=1e-12)
    assert field_difference(b, a) == pytest.approx(0.03 / 1.03, rel=1e-12)


def _cycle_entry(load_n: float, b: float, offset: float) -> dict:
    """One per-time comparison where side a is the reference b plus a constant ``offset`` in every
    scalar (and the field a uniform offset on a unit area), as compare_result_dirs writes it."""
    entry = {"load_n": load_n, "displacement_a_mm": [0.0, 0.0, -(b + offset)], "displacement_b_mm": [0.0, 0.0, -b],
             "displacement_rel_error": displacement_error(np.array([0.0, 0.0, -(b + offset)]), np.array([0.0, 0.0, -b])),
             "pressure_l2_reference_norm": b, "pressure_l2_misfit_norm": offset, "pressure_l2_rel_error": offset / b}
    for error, a_key, b_key in (("regularised_peak_pressure_rel_error", "regularised_peak_pressure_a_mpa", "regularised_peak_pressure_b_mpa"),
                                ("peak_pressure_rel_error", "peak_pressure_a_mpa", "peak_pressure_b_mpa"),
                                ("mean_pressure_rel_error", "mean_pressure_a_mpa", "mean_pressure_b_mpa"),
                                ("contact_area_rel_error", "contact_area_a_mm2", "contact_area_b_mm2")):
        entry.update({a_key: b + offset, b_key: b, error: (b + offset - b) / b})
    return entry


def test_unloading_errors_are_taken_against_the_cycle_peak_and_loading_errors_are_unchanged():
    """A load/unload cycle in which side a is the reference plus a constant offset of 0.01: on the
    loading branch every error is 0.01 / b(t) as before; on the unloading branch (the reference
    going to zero with the load) it is 0.01 over the largest b of the cycle, 0.01 / 1.0, not
    0.01 / 0.001 = 10 (the exact values of the construction)."""
    loads = [100.0, 333.0, 333.0, 33.3, 0.333]
    responses = [0.3, 0.9, 1.0, 0.1, 0.001]  # creeping to its peak while held, then unloaded
    per_time = [_cycle_entry(f, b, 0.01) for f, b in zip(loads, responses)]
    assert unloading_branch(np.array(loads)).tolist() == [False, False, False, True, True]
    out = against_cycle_peak(per_time)
    names = ("regularised_peak_pressure_rel_error", "peak_pressure_rel_error", "mean_pressure_rel_error",
             "contact_area_rel_error", "displacement_rel_error", "pressure_l2_rel_error")
    for k in range(3):
        assert out[k] == per_time[k]  # loading: untouched
        assert out[k]["contact_area_rel_error"] == pytest.approx(0.01 / responses[k], rel=1e-12)
    for k in (3, 4):
        assert out[k]["relative_to"] == "cycle peak"
        for name in names:
            assert out[k][name] == pytest.approx(0.01 / 1.0, rel=1e-12), name
    # a held load is not unloading, however the response moves
    assert not unloading_branch(np.array([333.0, 333.0 * (1 - 1e-12), 333.0])).any()


def test_unloaded_instants_before_the_first_load_are_taken_against_the_history_peak():
    """A history that starts unloaded (the viscoelastic campaign's t = 0): the reference is zero
    there, so a's rest offset of 0.01 (round-off, or a pose at rest a micron away) gave an
    infinite relative error; against the largest b of the whole history it is 0.01 / 1.0. The
    loaded instants are untouched, and a history that is never loaded keeps 0 / inf (no peak)."""
    rest = _cycle_entry(0.0, 1.0, 0.01)  # then b set to zero, a to the offset: as compare_result_dirs writes it
    for key in list(rest):
        if key.endswith("_b_mpa") or key.endswith("_b_mm2") or key == "pressure_l2_reference_norm":
            rest[key] = 0.0
        elif key.endswith("_a_mpa") or key.endswith("_a_mm2"):
            rest[key] = 0.01
    rest.update({"displacement_a_mm": [0.0, 0.0, -0.01], "displacement_b_mm": [0.0, 0.0, 0.0]})
    rest.update({key: math.inf for key in rest if key.endswith("_rel_error")})
    per_time = [rest, _cycle_entry(333.0, 0.5, 0.01), _cycle_entry(333.0, 1.0, 0.01)]
    out = against_cycle_peak(per_time)
    assert out[0]["relative_to"] == "history peak"
    for name in ("contact_area_rel_error", "regularised_peak_pressure_rel_error", "displacement_rel_error"):
        assert out[0][name] == pytest.approx(0.01 / 1.0, rel=1e-12), name
    assert out[1] == per_time[1] and out[2] == per_time[2]
    never = [{**rest, "load_n": 0.0}]
    assert against_cycle_peak(never) == never
