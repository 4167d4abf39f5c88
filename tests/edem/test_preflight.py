"""The geometry pre-flight (edem.preflight, docs/method.md#9-geometry-pre-flight-and-spring-resolution):
what the springs see before any solve, and the refusals it gives instead of a misleading one."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from support import grid_plate, make_scene, paraboloid

from edem.cli import main
from geometries.errors import SolverError
from edem.mechanics import DOF_NAMES
from edem.results import write_results
from edem.solver import run
from geometries.surface import TriangleSurface

GAIT2392 = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "opensim-gait2392"


def half_covered_plates(**options):
    """A 20 x 20 mm plate (200 springs, normals +z) under a plate 2 mm above that covers its x > 0 half."""
    mobile = grid_plate(20, 20, 10)
    cover = grid_plate(10, 24, 5, z_mm=2.0, facing_up=False)
    fixed = TriangleSurface(cover.vertices_mm + [5.0, 0.0, 0.0], cover.triangles)
    settings = {"law": "gap", "thickness_mm": 2.5, "max_spring_length_mm": 3.5, **options}
    return make_scene(mobile, fixed, [0.0, 0.0, 100.0], fixed_dofs=("tx", "ty", "rx", "ry", "rz"), method="dem", **settings)


def test_preflight_measures_the_gap_and_the_covered_share_of_the_springs(tmp_path):
    """Closest distance = the plates' 2 mm gap; the share in the window = the covered half, exactly
    (the cover's edge runs along the plate's grid lines); written to summary.json."""
    result = run(half_covered_plates())
    report = result.preflight
    assert report.time_point == 0
    assert report.closest_distance_mm == pytest.approx(2.0, abs=1e-9)
    assert report.shortest_ray_mm == pytest.approx(2.0, abs=1e-9)
    assert (report.n_springs, report.n_in_window) == (200, 100)
    assert report.share_in_window == pytest.approx(0.5, abs=1e-12)
    assert report.spring_size_mm == pytest.approx(np.sqrt(2.0), rel=1e-12)  # right triangles of 2 x 2 mm
    assert report.median_edge_mm == pytest.approx(2.0, rel=1e-12)
    assert report.patch_radius_mm is None  # flat on flat: no curvature, no Winkler patch
    write_results(result, tmp_path / "out")
    written = json.loads((tmp_path / "out" / "summary.json").read_text())["preflight"]
    assert written["closest_distance_mm"] == pytest.approx(2.0, abs=1e-9)
    assert written["share_in_window"] == pytest.approx(0.5, abs=1e-12)
    assert written["patch_radius_mm"] is None


def out_of_reach_scene(window_mm: float = 3.5, fixed_dofs=("tx", "ty", "rz")):
    """8 coarse springs (a 20 x 20 mm plate of 2 x 2 cells) under a paraboloid (R = 6 mm) whose apex
    sits 3 mm above one spring: with h_max = 3.5 mm only that spring is in reach (its neighbours'
    gaps are 3 + 3.3^2 / 12 > 3.9 mm)."""
    mobile = grid_plate(20, 20, 2)
    apex = mobile.centroids_mm[0]
    fixed = paraboloid(6.0, apex + [0.0, 0.0, 3.0], 30.0, 60)
    return make_scene(mobile, fixed, [0.0, 0.0, 100.0], max_spring_length_mm=window_mm, fixed_dofs=fixed_dofs, method="dem")


def test_springs_out_of_reach_are_refused_with_the_gap_and_the_window_to_set():
    """One spring in reach cannot restrain tz, rx, ry: refused with the 3 mm gap and a window that
    reaches enough springs, never "fix these DOFs" (the DOFs are restrained by springs further out)."""
    with pytest.raises(SolverError) as refused:
        run(out_of_reach_scene())
    message = str(refused.value)
    assert "1 of 8 springs" in message and "restrain tz, rx, ry" in message
    assert "3 mm apart at their closest" in message
    assert "max_spring_length_mm = " in message and "thickness_mm = 3" in message
    assert "fix these DOFs" not in message
    # The window it advises is enough: the same scene with it solves.
    advised = float(message.split("A window of ")[1].split(" mm")[0])
    solved = run(out_of_reach_scene(window_mm=advised))
    assert solved.steps[0].force_residual_n < 1e-6 * 100.0


def test_no_spring_in_reach_is_refused_with_the_gap():
    """h_max = 1 mm under a plate 2 mm away: no candidate, and the message says how far the bodies are."""
    with pytest.raises(SolverError) as refused:
        run(half_covered_plates(max_spring_length_mm=1.0, thickness_mm=None, law="threshold"))
    message = str(refused.value)
    assert "no spring is a candidate" in message and "2 mm apart at their closest" in message
    assert "A window of 2.1 mm would reach 100 springs" in message  # the covered half, 5 % beyond the 2 mm gap


def test_dofs_no_spring_could_restrain_still_name_the_constraints():
    """Plates restrain no in-plane slide at any reach: that is the constraints' matter, and the
    solver's advice (fix these DOFs) stands."""
    with pytest.raises(SolverError, match="fix these DOFs"):
        run(out_of_reach_scene(window_mm=30.0, fixed_dofs=()))


def test_a_load_the_constraints_carry_entirely_is_refused():
    """All six DOFs fixed under 100 N: the contact would see none of it (0 MPa with exit 0 before)."""
    plates = make_scene(grid_plate(20, 20, 10), grid_plate(24, 24, 6, z_mm=2.0, facing_up=False), [0.0, 0.0, 100.0],
                        fixed_dofs=DOF_NAMES)
    with pytest.raises(SolverError, match="constraints carry all of it"):
        run(plates)


@pytest.mark.opensim
def test_gait2392_display_meshes_are_refused_with_their_gap(tmp_path, capsys):
    """The public gait2392 talus and tibia display meshes (no cartilage) with the README's 3.5 mm
    window: exit 2 naming the gap in mm and the thickness and window to set, not "fix these DOFs"."""
    if not GAIT2392.is_dir():
        pytest.skip("../shared/data/opensim-gait2392 is not here")
    pytest.importorskip("opensim")
    scene = tmp_path / "gait2392-ankle.toml"
    scene.write_text(
        f"""[opensim]
model = "{(GAIT2392 / 'subject01_simbody.osim').resolve()}"
mobile_body = "talus_r"
fixed_body = "tibia_r"
fixed_meshes = ["tibia_r.vtp"]
motion = "{(GAIT2392 / 'subject01_walk1_ik.mot').resolve()}"
[cartilage]
youngs_modulus_mpa = 10.35
poissons_ratio = 0.42
max_spring_length_mm = 3.5
[load]
time_s = [0.8, 0.9]
force_n = [[0, 700, 0], [0, 700, 0]]
""",
        encoding="utf-8",
    )
    assert main(["run", str(scene), "--out", str(tmp_path / "out")]) == 2
    message = capsys.readouterr().err
    assert "1 of 194 springs" in message
    # 1.70 mm: the dense check (both meshes subdivided to 0.3 mm, vertex to vertex) gives 1.705 mm
    assert "1.7 mm apart at their closest" in message
    assert 'law = "gap" with thickness_mm' in message and "max_spring_length_mm = " in message
    assert "fix these DOFs" not in message


def test_edem_run_prints_the_preflight_and_writes_it(tmp_path, capsys):
    """`edem run` prints the pre-flight's figures and summary.json holds the same."""
    from geometries.mesh_files import write_surface

    write_surface(tmp_path / "plate.stl", grid_plate(20, 20, 10))
    write_surface(tmp_path / "cover.stl", grid_plate(24, 24, 6, z_mm=2.0, facing_up=False))
    (tmp_path / "plates.toml").write_text(
        """[geometry]
mobile = "plate.stl"
fixed = "cover.stl"
[cartilage]
youngs_modulus_mpa = 10.35
poissons_ratio = 0.42
[load]
force_n = [0.0, 0.0, 400.0]
[constraints]
fixed_dofs = ["tx", "ty", "rz"]
""",
        encoding="utf-8",
    )
    assert main(["run", str(tmp_path / "plates.toml"), "--out", str(tmp_path / "out")]) == 0
    printed = capsys.readouterr().out
    assert "closest distance between the surfaces 2 mm" in printed
    assert "200 of 200 springs, 100 % of the spring-bearing area" in printed
    written = json.loads((tmp_path / "out" / "summary.json").read_text())["preflight"]
    assert (written["n_in_window"], written["closest_distance_mm"]) == (200, pytest.approx(2.0, abs=1e-9))


def test_closest_distance_is_measured_once_per_pair_of_surfaces_and_again_when_one_moves(monkeypatch):
    """Runs on the same two surfaces (a campaign grid varying the cartilage) share the measured
    closest distance; a fixed body 0.5 mm higher is measured again and gives the plates' gap
    plus 0.5 mm exactly (the 2 mm of the first scene is the plates' z offset)."""
    import edem.preflight as preflight_module

    measured = []
    original = preflight_module.closest_distance_mm

    def counting(*arrays):
        measured.append(1)
        return original(*arrays)

    monkeypatch.setattr(preflight_module, "closest_distance_mm", counting)
    monkeypatch.setattr(preflight_module, "_CLOSEST", type(preflight_module._CLOSEST)())
    first = run(half_covered_plates(max_spring_length_mm=3.5)).preflight
    again = run(half_covered_plates(max_spring_length_mm=4.0)).preflight  # another window, the same surfaces
    assert len(measured) == 1
    assert again.closest_distance_mm == first.closest_distance_mm == pytest.approx(2.0, abs=1e-9)
    scene = half_covered_plates()
    raised = TriangleSurface(scene.fixed.vertices_mm + [0.0, 0.0, 0.5], scene.fixed.triangles)
    moved = make_scene(scene.mobile, raised, [0.0, 0.0, 100.0], fixed_dofs=("tx", "ty", "rx", "ry", "rz"), method="dem",
                       law="gap", thickness_mm=2.5, max_spring_length_mm=3.5)
    # 1e-9 mm: as above, far above the round-off of mm coordinates (1e-15) and far below the 0.5 mm move
    assert run(moved).preflight.closest_distance_mm == pytest.approx(2.5, abs=1e-9)
    assert len(measured) == 2


def _counting_casts(monkeypatch):
    """The number of ray casts against F (every spring's rays at one pose) made from now on."""
    from edem.raycast import RayCaster

    casts = []
    original = RayCaster.cast_rays

    def counting(self, *args, **kwargs):
        casts.append(1)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(RayCaster, "cast_rays", counting)
    return casts


def test_the_first_time_point_is_cast_once_for_the_preflight_and_the_first_step(monkeypatch):
    """A run of n time points casts n + 1 times: once per time point (the pre-flight checks time
    point 0 on the first step's cast) and once across the whole scene for the gap field. The
    pre-flight's figures are those it measures on its own cast."""
    from edem.preflight import preflight

    scene = half_covered_plates()
    scene = make_scene(scene.mobile, scene.fixed, np.array([[0.0, 0.0, 50.0], [0.0, 0.0, 100.0], [0.0, 0.0, 80.0]]),
                       time_s=np.array([0.0, 1.0, 2.0]), fixed_dofs=("tx", "ty", "rx", "ry", "rz"), law="gap", thickness_mm=2.5,
                       method="edem")
    casts = _counting_casts(monkeypatch)
    result = run(scene)
    assert len(casts) == len(result.steps) + 1 == 4
    assert result.preflight.time_point == 0
    from edem.raycast import RayCaster

    caster = RayCaster(scene.fixed.vertices_mm, scene.fixed.triangles)
    rays = caster.prepare(scene.spring_centroid_mm, scene.spring_normal)
    alone = preflight(scene, scene.applied_loads(), scene.fixed_placement, caster, rays)
    assert alone.as_dict() == result.preflight.as_dict()
    assert (alone.n_in_window, alone.time_point) == (100, 0)


def test_a_preflight_of_a_later_first_load_casts_at_that_time_point(monkeypatch):
    """Unloaded at time point 0, the pre-flight checks the first loaded one, which no step has cast
    before it: n + 2 casts, and the report names that time point."""
    scene = half_covered_plates()
    scene = make_scene(scene.mobile, scene.fixed, np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 100.0]]), time_s=np.array([0.0, 1.0]),
                       fixed_dofs=("tx", "ty", "rx", "ry", "rz"), law="gap", thickness_mm=2.5, method="edem")
    casts = _counting_casts(monkeypatch)
    result = run(scene)
    assert result.preflight.time_point == 1
    assert len(casts) == len(result.steps) + 2 == 4


def test_median_edge_is_the_median_of_every_triangle_edge_length_bit_for_bit():
    """Corner by corner (no norm over a last axis of 3): the same numbers as the norm of the edge
    vectors, on a mesh with edges of many lengths and an even and an odd count of edges."""
    from edem.preflight import _median_edge_mm

    rng = np.random.default_rng(11)
    vertices = rng.normal(size=(400, 3)) * rng.uniform(0.1, 10.0, size=(400, 1))
    for count in (301, 300):
        triangles = rng.integers(0, 400, size=(count, 3))
        expected = np.median(np.linalg.norm(vertices[triangles] - vertices[np.roll(triangles, 1, axis=1)], axis=2))
        assert _median_edge_mm(vertices, triangles) == float(expected)
