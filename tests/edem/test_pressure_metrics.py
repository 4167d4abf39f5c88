"""The regularised peak pressure (edem.pressure_metrics): the mean over a 1 mm^2 disc converges
under mesh refinement where the raw peak does not (a singular rim, a one-node spike), on nodal
(FE) and spring (cell) fields alike, and summary.json states it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from edem.pressure_metrics import (MAX_QUADRATURE_POINTS, PEAK_DISC_AREA_MM2, DiscMeans, RegularisedPeaks, check_quadrature_size,
                                   disc_mean_pressure_mpa, largest_regularised_peak_mpa, pressure_bound_mpa, quadrature_size,
                                   regularised_peak_pressure_mpa, surface_regularised_peak_mpa)
from geometries.errors import InputError
from edem.resultdir import SurfaceFrame

RADIUS_MM = math.sqrt(PEAK_DISC_AREA_MM2 / math.pi)


def square_mesh(side_mm: float, h_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """A flat square [0, side]^2 of right triangles of leg h, points (n, 3) and triangles (m, 3)."""
    n = int(round(side_mm / h_mm))
    x = np.linspace(0.0, side_mm, n + 1)
    xx, yy = np.meshgrid(x, x, indexing="ij")
    points = np.column_stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)])
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    return points, np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])


@pytest.mark.parametrize("at_points", [True, False])
def test_uniform_field_is_its_own_regularised_peak(at_points):
    """The mean of a constant over any disc is the constant: exact on any mesh, to round-off."""
    points, triangles = square_mesh(6.0, 0.7)
    pressure = np.full(len(points) if at_points else len(triangles), 2.5)
    assert regularised_peak_pressure_mpa(points, triangles, pressure, at_points=at_points) == pytest.approx(2.5, rel=1e-12)


@pytest.mark.parametrize("at_points", [True, False])
def test_one_node_spike_leaves_the_regularised_peak_converging_while_the_raw_peak_stays(at_points):
    """A field of 1 MPa with one spike of 10 MPa at the centre (a node of the FE, a spring of the
    bed): the raw peak is 11 MPa on every mesh, while the spike adds to a 1 mm^2 disc's mean its
    10 MPa x its support's integral (a node's hat function: h^2; one triangle: h^2 / 2) over the
    disc's area: O(h^2), to 0 as the mesh is refined."""
    for h in (0.4, 0.2, 0.1):
        points, triangles = square_mesh(4.0, h)
        if at_points:
            pressure = np.ones(len(points))
            pressure[np.argmin(np.linalg.norm(points[:, :2] - 2.0, axis=1))] += 10.0
        else:
            pressure = np.ones(len(triangles))
            pressure[np.argmin(np.linalg.norm(points[triangles].mean(axis=1)[:, :2] - 2.0, axis=1))] += 10.0
        support = h * h if at_points else h * h / 2.0
        assert float(pressure.max()) == 11.0
        excess = regularised_peak_pressure_mpa(points, triangles, pressure, at_points=at_points) - 1.0
        # the quadrature (points a third of the radius apart) counts the disc's area to 3 % (measured 2.5 %)
        assert excess == pytest.approx(10.0 * support / PEAK_DISC_AREA_MM2, rel=0.03)


def test_singular_rim_regularised_peak_converges_to_the_disc_mean_while_the_raw_peak_grows():
    """p = r^-1/2 about a point (an integrable singularity, as at a sharp contact edge): its mean
    over a disc of radius R is (4/3) R^-1/2 exactly. Sampled at the nodes (cut off at h/4 from
    the singular point, off the mesh's nodes), the raw peak grows as h^-1/2 while the regularised
    peak converges to the closed form."""
    exact = 4.0 / 3.0 / math.sqrt(RADIUS_MM)
    errors, raw = [], []
    for h in (0.5, 0.25, 0.125):
        points, triangles = square_mesh(10.0, h)
        r = np.linalg.norm(points[:, :2] - np.array([5.0 + 0.37 * h, 5.0 + 0.21 * h]), axis=1)
        pressure = 1.0 / np.sqrt(np.maximum(r, h / 4.0))
        raw.append(float(pressure.max()))
        errors.append(abs(regularised_peak_pressure_mpa(points, triangles, pressure, at_points=True) - exact) / exact)
    assert raw[0] < raw[1] < raw[2] and raw[2] / raw[0] == pytest.approx(2.0, rel=0.01)  # ~ h^-1/2 at the node nearest the point
    assert errors[0] > errors[1] > errors[2]
    # P1 interpolation of r^-1/2 loses O(h^1/2) of the disc's integral near the singular point:
    # measured 11 %, 2.9 %, 0.37 % at h = 0.5, 0.25, 0.125
    assert errors[2] < 0.01


def test_summary_json_states_the_regularised_peak_of_its_maps(tmp_path):
    """write_result_dir fills regularised_peak_pressure_mpa (the largest over the maps) and its
    definition for every producer; the raw peak keeps its own key."""
    from edem.resultdir import Frame, SurfaceFrame, read_result_dir, timeseries_row, write_result_dir

    points, triangles = square_mesh(4.0, 0.4)
    frames, rows = [], []
    for k, level in enumerate((1.0, 3.0)):
        pressure = np.full(len(triangles), level)
        pressure[0] = 50.0  # a one-spring spike: the raw peak
        frames.append(Frame(k, float(k), SurfaceFrame(points, triangles, {}, {"pressure_mpa": pressure})))
        rows.append(timeseries_row(k, float(k), np.array([0.0, 0.0, 1.0]), 50.0, level, 16.0, np.zeros(3), np.zeros(3), 1, 0.0))
    summary = {"scene": "s", "method": "dem", "steps": 2, "wall_time_s": 0.0, "peak_pressure_mpa": 50.0, "max_contact_area_mm2": 16.0,
               "final_displacement_mm": [0.0, 0.0, 0.0], "max_force_residual_n": 0.0, "warnings": []}
    written = read_result_dir(write_result_dir(tmp_path / "r", summary, rows, frames)).summary
    expected = regularised_peak_pressure_mpa(points, triangles, frames[1].surface.cell_data["pressure_mpa"], at_points=False)
    assert written["regularised_peak_pressure_mpa"] == expected and 3.0 < expected < 50.0
    assert written["peak_pressure_mpa"] == 50.0 and "1 mm^2" in written["regularised_peak_pressure_definition"]


def paraboloid_fields(points: np.ndarray, triangles: np.ndarray, at_points: bool) -> list[np.ndarray]:
    """Contact-like fields on the square [0, 8]^2: p = p0 (1 - r^2 / a^2)+ about a few centres,
    contact radii a several disc radii wide (a paraboloid pressed on a plane; the last one
    reaching over the edge), a flat-topped one (no bound can rule a loaded disc out) and one
    without contact."""
    where = points if at_points else points[triangles].mean(axis=1)
    fields = []
    for centre, a, p0 in (((4.0, 4.0), 3.0, 3.0), ((3.0, 5.0), 2.5, 7.0), ((6.5, 2.0), 3.5, 1.0)):
        r2 = ((where[:, :2] - centre) ** 2).sum(axis=1)
        fields.append(np.maximum(p0 * (1.0 - r2 / a**2), 0.0))
    fields.append(np.where(((where[:, :2] - 4.0) ** 2).sum(axis=1) < 3.0**2, 2.0, 0.0))
    fields.append(np.zeros(len(where)))
    return fields


@pytest.mark.parametrize("at_points", [True, False])
def test_averaging_built_once_gives_exactly_the_per_call_values(at_points):
    """A run builds the disc averaging once for its surface and applies it to every time point's
    field: each disc's sum runs over the same quadrature points in the same order as a call for
    that field alone, so every disc mean and the peak are the same floats, whatever was
    evaluated or bounded before."""
    points, triangles = square_mesh(8.0, 0.4)
    discs = DiscMeans(points, triangles, at_points=at_points)
    for pressure in paraboloid_fields(points, triangles, at_points) * 2:  # twice: the second pass after the first's
        centres, mean = discs.means(pressure)
        centres_mm, mean_alone = disc_mean_pressure_mpa(points, triangles, pressure, at_points=at_points)
        np.testing.assert_array_equal(discs.centres_mm(centres), centres_mm)
        np.testing.assert_array_equal(mean, mean_alone)
        assert discs.peak(pressure) == regularised_peak_pressure_mpa(points, triangles, pressure, at_points=at_points) == mean.max(initial=0.0)


@pytest.mark.parametrize("at_points", [True, False])
def test_chunked_and_bounded_peak_equals_the_largest_of_all_disc_means(at_points):
    """The peak evaluated in chunks of discs, largest bound first (the largest value of the
    triangles whose centroids lie in the 27 cells around a centre), each chunk by an averaging
    built for its discs only, stopping where the bound falls below the best mean, is the largest
    of all the disc means exactly. Every disc whose bound reaches the peak is evaluated; on a
    peaked field some are ruled out (measured 41-61 % evaluated on this 8 mm square, where a
    bound reaches 2.7 mm around its centre), on a flat-topped one (every bound equal to the top)
    none is."""
    points, triangles = square_mesh(8.0, 0.25)
    fields = paraboloid_fields(points, triangles, at_points)
    for pressure, pruned in zip(fields, (True, True, True, False, False)):
        full = disc_mean_pressure_mpa(points, triangles, pressure, at_points=at_points)[1]
        discs = DiscMeans(points, triangles, at_points=at_points, chunk_pairs=2000)
        peak = discs.peak(pressure)
        assert peak == full.max(initial=0.0)
        bound = discs._bounds(pressure, discs.loaded_centres(pressure))
        assert np.all(full <= bound + 1e-6 * np.abs(pressure).max(initial=0.0))  # (the rounding margin of DiscMeans.peak)
        assert discs.rows_evaluated >= int((bound + 1e-6 * np.abs(pressure).max(initial=0.0) >= peak).sum())
        if pruned:
            assert discs.rows_evaluated < len(full)
        else:
            assert discs.rows_evaluated == len(full)


def test_maps_of_a_rigidly_moving_surface_share_one_averaging():
    """A discrete run's maps are M at each pose: the averaging is built once and each peak is
    the one of the map alone (the same discs: a rigid motion changes no distance; to rounding of
    the posed points, 1e-12); a surface that is not a rigid image of it gets its own."""
    from scipy.spatial.transform import Rotation

    points, triangles = square_mesh(8.0, 0.4)
    fields = paraboloid_fields(points, triangles, False)[:3]
    peaks = RegularisedPeaks()
    built = []
    for k, pressure in enumerate(fields):
        moved = points @ Rotation.from_rotvec([0.3 * k, -0.2, 0.5 * k]).as_matrix().T + [10.0 * k, -3.0, 2.0]
        value = peaks(SurfaceFrame(moved, triangles, {}, {"pressure_mpa": pressure}))
        built.append(peaks._discs)
        assert value == pytest.approx(regularised_peak_pressure_mpa(moved, triangles, pressure, at_points=False), rel=1e-12)
    assert built[0] is built[1] is built[2]
    stretched = points * [1.5, 1.0, 1.0]
    value = peaks(SurfaceFrame(stretched, triangles, {}, {"pressure_mpa": fields[0]}))
    assert peaks._discs is not built[0]
    assert value == regularised_peak_pressure_mpa(stretched, triangles, fields[0], at_points=False)


@pytest.mark.parametrize("at_points", [True, False])
def test_largest_peak_of_many_maps_measures_only_those_that_could_beat_it(at_points):
    """The largest regularised peak over a run's maps, measured from the largest bound (the map's
    largest pressure) down and stopped where the bound falls below the best, is exactly the
    largest of every map's own peak; each map's peak is at most its bound; and a history whose
    maps rise and fall measures a few of them only. Maps of equal bounds (a flat-topped field
    repeated) are all measured until one ties, and a history without contact gives 0."""
    points, triangles = square_mesh(8.0, 0.4)
    shapes = paraboloid_fields(points, triangles, at_points)
    history = [s * scale for scale in (0.2, 0.5, 0.9, 1.0, 0.7, 0.3) for s in shapes[:3]]  # a load rising and falling
    for maps in (history, [shapes[3]] * 4, [shapes[4]] * 3):
        surfaces = [SurfaceFrame(points, triangles, {"pressure_mpa": p} if at_points else {}, {} if at_points else {"pressure_mpa": p})
                    for p in maps]
        alone = [surface_regularised_peak_mpa(s) for s in surfaces]
        bounds = [pressure_bound_mpa(s) for s in surfaces]
        assert all(peak <= bound for peak, bound in zip(alone, bounds))
        asked = []
        largest = largest_regularised_peak_mpa(lambda i: asked.append(i) or surfaces[i], bounds)
        assert largest == max(alone)
        if maps is history:  # the largest field's peak (6.8 MPa) is above every other map's largest pressure (at most 6.3)
            assert asked == [int(np.argmax(bounds))]
        elif largest > 0.0:  # flat tops of 2 MPa: every bound is 2 MPa plus the rounding margin, above the peak
            assert len(asked) == len(maps)
    assert largest == 0.0


def test_a_surface_whose_quadrature_would_not_fit_is_refused_by_name():
    """Two triangles 3 km across would need ~1e9 quadrature points (n^2 sub-triangles a third of
    the disc radius across): InputError, before any array of that size exists; the count is the
    one the averaging would build (quadrature_size, exact on a small mesh)."""
    points, triangles = square_mesh(8.0, 0.4)
    assert quadrature_size(points, triangles) == DiscMeans(points, triangles, at_points=False).n_quadrature_points
    huge = np.array([[0.0, 0.0, 0.0], [3000.0, 0.0, 0.0], [3000.0, 3000.0, 0.0], [0.0, 3000.0, 0.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    assert quadrature_size(huge, faces) > MAX_QUADRATURE_POINTS
    with pytest.raises(InputError) as info:
        check_quadrature_size(huge, faces, file="big.stl", key="geometry.mobile")
    assert info.value.key == "geometry.mobile" and f"{MAX_QUADRATURE_POINTS:,}" in str(info.value)
    with pytest.raises(InputError):
        DiscMeans(huge, faces, at_points=False)
