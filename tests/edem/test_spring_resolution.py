"""Spring resolution (`[geometry] spring_spacing_mm`, docs/method.md#9-geometry-pre-flight-and-spring-resolution):
a coarse spring-bearing surface resampled finer converges to the closed form of a rigid
paraboloid on a Winkler bed."""

from __future__ import annotations

import math

import numpy as np
import pytest
from support import grid_plate, paraboloid

from edem.preflight import PATCH_MIN_SPRINGS, winkler_patch
from edem.scene import Scene, load_scene
from edem.solver import run
from geometries.mesh_files import write_surface
from geometries.surface import TriangleSurface
from geometries.vtk_ops import subdivide_to_spacing

# Paraboloid of radius R over a bed of thickness t (gap law p = E' (t - h) / t, nu = 0 so E' = E),
# pressed by F: a = 4.0 mm, d = 0.40 mm (20 % strain), p0 = 2.0 MPa (winkler_patch).
RADIUS_MM, THICKNESS_MM, MODULUS_MPA, FORCE_N, HALF_WIDTH_MM = 20.0, 2.0, 10.0, 50.0, 8.0
SPACINGS_MM = [None, 8.0, 4.0, 2.0, 1.0, 0.5, 0.25]


def test_winkler_closed_form_balances_the_load_it_was_solved_for():
    """winkler_patch: F = int_0^a E'/t (d - r^2 / 2R) 2 pi r dr, summed numerically, gives F back."""
    approach, radius, peak = winkler_patch(FORCE_N, MODULUS_MPA, THICKNESS_MM, RADIUS_MM)
    r = np.linspace(0.0, radius, 200_001)
    pressure = MODULUS_MPA / THICKNESS_MM * (approach - r**2 / (2.0 * RADIUS_MM))
    force = float(np.sum(0.5 * (pressure[1:] * r[1:] + pressure[:-1] * r[:-1]) * np.diff(r)) * 2.0 * math.pi)
    assert force == pytest.approx(FORCE_N, rel=1e-9)  # trapezoid on a quadratic-times-r integrand: error ~ 1e-11
    assert pressure[0] == pytest.approx(peak, rel=1e-12)
    assert pressure[-1] == pytest.approx(0.0, abs=1e-12)


def test_subdivision_keeps_the_surface_and_bounds_every_edge():
    """Resampling only splits edges: the area, the area centroid and every triangle's normal stay,
    and no edge is longer than the spacing."""
    coarse = grid_plate(16, 10, 1)
    tilted = TriangleSurface(coarse.vertices_mm @ np.array([[1, 0, 0], [0, 0.8, 0.6], [0, -0.6, 0.8]]).T, coarse.triangles)
    fine = subdivide_to_spacing(tilted, 0.7)
    v, t = fine.vertices_mm, fine.triangles
    assert np.linalg.norm(v[t] - v[np.roll(t, 1, axis=1)], axis=2).max() <= 0.7
    assert fine.areas_mm2.sum() == pytest.approx(tilted.areas_mm2.sum(), rel=1e-12)
    centroid = (fine.centroids_mm * fine.areas_mm2[:, None]).sum(axis=0) / fine.areas_mm2.sum()
    assert centroid == pytest.approx((tilted.centroids_mm * tilted.areas_mm2[:, None]).sum(axis=0) / tilted.areas_mm2.sum(), abs=1e-12)
    assert np.allclose(fine.unit_normals, tilted.unit_normals[0], atol=1e-12)


def paraboloid_on_plate(spacing_mm: float | None) -> Scene:
    """A 16 x 16 mm plate of two triangles (the springs, normals +z), resampled to the spacing,
    under a finely meshed paraboloid that touches the bed's surface at the plate's centre."""
    plate = grid_plate(2 * HALF_WIDTH_MM, 2 * HALF_WIDTH_MM, 1)
    # 0.1 mm facets: the paraboloid's chordal error e^2 / (8 R) = 6e-5 mm, 1.6e-4 of the approach
    rigid = paraboloid(RADIUS_MM, (0.0, 0.0, THICKNESS_MM), 10.0, 200)
    return Scene.from_arrays(plate.vertices_mm, plate.triangles, rigid.vertices_mm, rigid.triangles, [0.0, 0.0, FORCE_N],
                             youngs_modulus_mpa=MODULUS_MPA, poissons_ratio=0.0, law="gap", thickness_mm=THICKNESS_MM,
                             fixed_dofs=("tx", "ty", "rx", "ry", "rz"), method="dem", spring_spacing_mm=spacing_mm)


def test_paraboloid_on_a_spring_bed_converges_to_the_winkler_closed_form_as_the_spacing_shrinks():
    """Approach, peak pressure and contact area against a = sqrt(2 R d), F = pi E' R d^2 / t,
    p0 = E' d / t, from two springs down to a 0.25 mm spacing; the pre-flight's patch estimate
    too, and the warning below about 50 springs in the patch."""
    approach, radius, peak = winkler_patch(FORCE_N, MODULUS_MPA, THICKNESS_MM, RADIUS_MM)
    area = math.pi * radius**2
    table = []
    for spacing in SPACINGS_MM:
        result = run(paraboloid_on_plate(spacing))
        step = result.steps[0]
        in_patch = int(step.in_contact.sum())
        warned = any("contact patch holds only" in w and f"{in_patch} springs" in w for w in result.warnings)
        assert warned == (in_patch < PATCH_MIN_SPRINGS)
        if spacing is not None:
            assert result.preflight.median_edge_mm <= spacing
        table.append((spacing, result.n_springs, in_patch, step.displacement_mm[2] / approach - 1, step.peak_pressure_mpa / peak - 1,
                      step.contact_area_mm2 / area - 1, result.preflight))
    print("\nspacing_mm springs in_patch approach_err peak_err area_err")
    for spacing, n, in_patch, e_d, e_p, e_a, _ in table:
        print(f"{spacing!s:>10} {n:7d} {in_patch:8d} {e_d:+12.4%} {e_p:+9.4%} {e_a:+9.4%}")
    peak_errors = [abs(row[4]) for row in table]
    area_errors = [abs(row[5]) for row in table]
    # The peak spring sits within a spacing s of the axis: its pressure is low by at most
    # E' s^2 / (2 R t), i.e. (s / a)^2 of p0, which shrinks with every halving.
    assert all(finer < coarser for coarser, finer in zip(peak_errors, peak_errors[1:]))
    # The area counts whole springs across the patch's rim: never worse on a finer bed.
    assert all(finer <= coarser + 1e-12 for coarser, finer in zip(area_errors, area_errors[1:]))
    assert area_errors[0] > 1.0 and peak_errors[0] > 0.5  # two springs: the coarse answer is far off
    s, finest = SPACINGS_MM[-1], table[-1]
    # Bounds at the finest spacing: the peak spring's offset from the axis, (s / a)^2 (0.4 %); the
    # rim band of one spring's width, 2 s / a (12.5 %) for the area; the midpoint rule over the
    # patch, whose integrand is linear in each spring but kinked at the rim, (s / a)^2 for F and
    # so for d (0.4 %).
    assert abs(finest[4]) < (s / radius) ** 2
    assert abs(finest[5]) < 2 * s / radius
    assert abs(finest[3]) < (s / radius) ** 2
    # The pre-flight's Winkler estimate from the measured gap: R from the gap's curvature (exact
    # here up to the paraboloid's 1.6e-4 chordal error), so the patch radius within 1e-3.
    assert finest[6].curvature_radius_mm == pytest.approx(RADIUS_MM, rel=1e-3)
    assert finest[6].patch_radius_mm == pytest.approx(radius, rel=1e-3)


def test_spring_spacing_in_the_scene_file_resamples_the_mobile_surface(tmp_path):
    """[geometry] spring_spacing_mm: the springs of a two-triangle plate become triangles of edges <= the spacing."""
    write_surface(tmp_path / "plate.stl", grid_plate(16, 16, 1))
    write_surface(tmp_path / "dome.stl", paraboloid(RADIUS_MM, (0.0, 0.0, THICKNESS_MM), 10.0, 40))
    (tmp_path / "scene.toml").write_text(
        """[geometry]
mobile = "plate.stl"
fixed = "dome.stl"
spring_spacing_mm = 1.0
[cartilage]
youngs_modulus_mpa = 10.0
poissons_ratio = 0.0
law = "gap"
thickness_mm = 2.0
[load]
force_n = [0, 0, 50]
""",
        encoding="utf-8",
    )
    scene = load_scene(tmp_path / "scene.toml")
    v, t = scene.mobile.vertices_mm, scene.mobile.triangles
    assert scene.spring_area_mm2.size > 256  # (16 / 1)^2 cells of two triangles at the least
    assert np.linalg.norm(v[t] - v[np.roll(t, 1, axis=1)], axis=2).max() <= 1.0
    assert scene.spring_area_mm2.sum() == pytest.approx(256.0, rel=1e-12)
