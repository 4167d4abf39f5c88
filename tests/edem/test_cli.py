"""`edem run` end to end: the result directory (docs/result-format.md), the built-in scenes and bad input (exit 2)."""

from __future__ import annotations

import csv
import json
import math
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from support import grid_plate, plane

from edem.cli import main
from edem.results import TIMESERIES_COLUMNS
from edem.scene import load_scene
from edem.scene import builtin_scene_names, load_scene
from geometries.mesh_files import write_surface

SUMMARY_KEYS = {
    "scene",
    "method",
    "steps",
    "n_springs",
    "wall_time_s",
    "setup_time_s",
    "peak_pressure_mpa",
    "max_contact_area_mm2",
    "final_displacement_mm",
    "max_force_residual_n",
    "warnings",
}


def write_plates_scene(tmp_path: Path, extra: str = "", cartilage: str = "", load: str = "force_n = [0.0, 0.0, 400.0]") -> Path:
    """Two STL plates 2 mm apart and a scene file pointing at them."""
    write_surface(tmp_path / "talus.stl", grid_plate(20, 20, 10))
    write_surface(tmp_path / "tibia.stl", plane(lambda x, y: 2.0, size_mm=30.0))
    scene = tmp_path / "plates.toml"
    scene.write_text(
        f"""[scene]
name = "plates"
[geometry]
mobile = "talus.stl"
fixed = "tibia.stl"
[cartilage]
youngs_modulus_mpa = 10.35
poissons_ratio = 0.42
{cartilage}
[load]
{load}
[constraints]
fixed_dofs = ["tx", "ty", "rz"]
{extra}
""",
        encoding="utf-8",
    )
    return scene


def test_run_writes_the_spec9_result_directory(tmp_path):
    """summary.json keys, timeseries.csv columns and a pvd whose vtp files carry the cell arrays.

    Flat plates, 200 N then 400 N over 400 mm^2: p = F/A = 1 MPa at the end, in every file.
    """
    scene = write_plates_scene(tmp_path, load="time_s = [0.0, 1.0]\nforce_n = [[0.0, 0.0, 200.0], [0.0, 0.0, 400.0]]")
    out = tmp_path / "out"
    assert main(["run", str(scene), "--method", "edem", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert SUMMARY_KEYS <= set(summary)
    assert summary["steps"] == 2 and summary["n_springs"] == 200
    assert summary["peak_pressure_mpa"] == pytest.approx(1.0, rel=1e-9)
    assert summary["max_contact_area_mm2"] == pytest.approx(400.0, rel=1e-12)
    with open(out / "timeseries.csv", newline="") as f:
        rows = list(csv.reader(f))
    assert tuple(rows[0][: len(TIMESERIES_COLUMNS)]) == TIMESERIES_COLUMNS  # then the run's extra columns
    assert len(rows) == 3 and all(math.isfinite(float(x)) for row in rows[1:] for x in row)
    # Uniform pressure on the plate: the centre of pressure is the plate's centroid (x, y); the
    # plate only moves along z. 1e-9 mm: round-off of sums over 200 springs of ~10 mm values is ~1e-14.
    plate = load_scene(scene)
    centroid = (plate.spring_centroid_mm * plate.spring_area_mm2[:, None]).sum(axis=0) / plate.spring_area_mm2.sum()
    cop = [float(rows[2][rows[0].index(f"cop_{x}_mm")]) for x in "xy"]
    assert cop == pytest.approx(centroid[:2], abs=1e-9)
    assert float(rows[2][TIMESERIES_COLUMNS.index("mean_pressure_mpa")]) == pytest.approx(1.0, rel=1e-9)

    files = [d.get("file") for d in ET.parse(out / "pressure.pvd").getroot().iter("DataSet")]
    assert len(files) == 2
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

    reader = vtkXMLPolyDataReader()
    reader.SetFileName(str(out / files[1]))
    reader.Update()
    cells = reader.GetOutput().GetCellData()
    pressure = vtk_to_numpy(cells.GetArray("pressure_mpa"))
    np.testing.assert_allclose(pressure, 1.0, rtol=1e-9)
    # EDEM redid the geometry after the first step: the springs are shorter by its displacement.
    first_disp = float(rows[1][TIMESERIES_COLUMNS.index("disp_z_mm")])
    np.testing.assert_allclose(vtk_to_numpy(cells.GetArray("spring_length_mm")), 2.0 - first_disp, rtol=1e-9)
    assert vtk_to_numpy(cells.GetArray("in_contact")).all()


def test_python_dash_m_edem_runs(tmp_path):
    """`python -m edem` is the same program as the console script."""
    scene = write_plates_scene(tmp_path)
    done = subprocess.run([sys.executable, "-m", "edem", "run", str(scene), "--out", str(tmp_path / "o")], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert "peak pressure 1 MPa" in done.stdout


@pytest.mark.parametrize("name", builtin_scene_names())
def test_every_builtin_scene_runs(name, tmp_path):
    """Each built-in scene runs through `edem run` and balances its load at every time point."""
    assert main(["run", name, "--out", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    scene = load_scene(name)
    assert summary["n_springs"] == scene.spring_area_mm2.size
    assert summary["max_force_residual_n"] <= 1e-8 * (1.0 + float(np.abs(scene.load.force_n).max()))


def test_stance_scenes_carry_the_interpolated_table():
    """The stance arrays in the scene files are the PCHIP series of edem.stance (to their 4 decimals)."""
    from edem.stance import stance_series

    time_s, angle_deg, force_n = stance_series()
    for name in ("ideal-stance", "subject-stance"):
        scene = load_scene(name)
        np.testing.assert_allclose(scene.load.time_s, time_s, atol=1e-4)
        np.testing.assert_allclose(scene.load.force_n, force_n, atol=1e-4)
        np.testing.assert_allclose(np.degrees(scene.kinematics.angle_rad), angle_deg, atol=1e-4)


BAD_INPUT = [
    ("malformed TOML", dict(extra="[solver\nmethod = 1"), "malformed TOML"),
    ("unknown key", dict(cartilage="stiffness = 3"), "cartilage.stiffness"),
    ("wrong type", dict(cartilage='max_spring_length_mm = "long"'), "cartilage.max_spring_length_mm"),
    ("nu = 0.5", dict(cartilage="poissons_ratio_x = 0"), "cartilage.poissons_ratio_x"),
    ("h_max <= 0", dict(cartilage="max_spring_length_mm = 0.0"), "cartilage.max_spring_length_mm"),
    ("NaN load", dict(load="force_n = [0.0, 0.0, nan]"), "load.force_n"),
    ("inf load", dict(load="force_n = [0.0, inf, 1.0]"), "load.force_n"),
    ("unknown law", dict(cartilage='law = "hertz"'), "cartilage.law"),
    ("gap law without thickness", dict(cartilage='law = "gap"'), "cartilage.thickness_mm"),
    ("unknown DOF", dict(extra='[solver]\nmethod = "edem"\n[viscoelastic]\nrelaxation_time_s = -1.0'), "viscoelastic.relaxation_time_s"),
]


@pytest.mark.parametrize("label,parts,key", BAD_INPUT, ids=[b[0] for b in BAD_INPUT])
def test_bad_input_exits_2_naming_file_and_key(label, parts, key, tmp_path, capsys):
    """Bad scene input: exit status 2, one message naming the file and the key, no traceback."""
    scene = write_plates_scene(tmp_path, **parts)
    assert main(["run", str(scene), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert str(scene) in err and key in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "value,expected", [("0.5", "(-1, 0.5)"), ("-1.0", "(-1, 0.5)"), ("0.7", "(-1, 0.5)")], ids=["0.5", "-1", "0.7"]
)
def test_poissons_ratio_out_of_range(value, expected, tmp_path, capsys):
    """nu >= 0.5 or <= -1 is refused (E' would be infinite or negative)."""
    scene = write_plates_scene(tmp_path)
    scene.write_text(scene.read_text().replace("poissons_ratio = 0.42", f"poissons_ratio = {value}"))
    assert main(["run", str(scene)]) == 2
    err = capsys.readouterr().err
    assert "cartilage.poissons_ratio" in err and expected in err


def test_youngs_modulus_must_be_positive(tmp_path, capsys):
    scene = write_plates_scene(tmp_path)
    scene.write_text(scene.read_text().replace("youngs_modulus_mpa = 10.35", "youngs_modulus_mpa = 0"))
    assert main(["run", str(scene)]) == 2
    assert "cartilage.youngs_modulus_mpa" in capsys.readouterr().err


def test_missing_mesh_file(tmp_path, capsys):
    scene = write_plates_scene(tmp_path)
    (tmp_path / "tibia.stl").unlink()
    assert main(["run", str(scene)]) == 2
    err = capsys.readouterr().err
    assert "tibia.stl" in err and "geometry.fixed" in err


def test_mesh_without_triangles(tmp_path, capsys):
    scene = write_plates_scene(tmp_path)
    (tmp_path / "talus.stl").write_text("solid empty\nendsolid empty\n")
    assert main(["run", str(scene)]) == 2
    assert "geometry.mobile" in capsys.readouterr().err


def test_bodies_too_far_apart(tmp_path, capsys):
    scene = write_plates_scene(tmp_path)
    write_surface(tmp_path / "tibia.stl", plane(lambda x, y: 500.0, size_mm=30.0))
    assert main(["run", str(scene)]) == 2
    assert "far apart" in capsys.readouterr().err


def test_load_pulling_apart_ends_with_a_clear_status(tmp_path, capsys):
    """A load pulling the bodies apart: exit 2 with 'no equilibrium', and no result files."""
    scene = write_plates_scene(tmp_path, load="force_n = [0.0, 0.0, -400.0]")
    assert main(["run", str(scene), "--out", str(tmp_path / "o")]) == 2
    assert "pulls the bodies apart" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_sto_moment_that_overflows_in_n_mm_exits_2_naming_file_column_and_line(tmp_path, capsys):
    """An OpenSim JointReaction .sto whose moment, -1e308 N m, is finite in the file but not in
    N mm: exit 2 naming the file, the column and the line (it ended in a traceback)."""
    names = ["time"] + [f"ankle_r_on_talus_r_in_ground_{c}" for c in ("fx", "fy", "fz", "mx", "my", "mz")]
    rows = [[0.0, 0.0, 0.0, -400.0, 0.0, 0.0, 0.0], [0.1, 0.0, 0.0, -400.0, -1e308, 0.0, 0.0]]
    (tmp_path / "jr.sto").write_text("\n".join(["JointReaction_ReactionLoads", "version=1", "nRows=2", "nColumns=7", "inDegrees=no",
                                                "endheader", "\t".join(names)] + ["\t".join(repr(v) for v in row) for row in rows]) + "\n")
    scene = write_plates_scene(tmp_path, load='file = "jr.sto"\naxes = "same"\nmobile_body = "talus_r"')
    assert main(["run", str(scene), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert str(tmp_path / "jr.sto") in err and "ankle_r_on_talus_r_in_ground_mx" in err and "line 9" in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()


def test_mesh_whose_regularised_peak_would_not_fit_in_memory_exits_2_before_the_solve(tmp_path, capsys):
    """Eight triangles 1 m across (a joint-sized mesh, 1.98 m diagonal) need 2.2e8 quadrature points for the regularised peak of the
    result (n^2 sub-triangles, n = edge / (radius / 3)): refused before the solve, naming the
    mesh and the size it can hold, not after it in a MemoryError."""
    from edem.pressure_metrics import MAX_QUADRATURE_POINTS

    scene = write_plates_scene(tmp_path)
    write_surface(tmp_path / "talus.stl", grid_plate(1400, 1400, 2))
    assert main(["run", str(scene), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "talus.stl" in err and "geometry.mobile" in err and f"{MAX_QUADRATURE_POINTS:,}" in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()


def test_bones_through_each_other_exit_2_naming_the_time_points_unless_allowed(tmp_path, capsys):
    """Plates 2 mm apart (threshold law: the springs are the gap) pressed 3 and 3.2 mm together at
    time points 1 and 2 (d = F h / (E' A)): the bones pass through each other there, exit 2 naming
    those time points and the share of the springs in contact (all of them), no result; with
    [solver] allow_bone_overlap the run is kept, warned."""
    e_conf = 10.35 * (1 - 0.42) / ((1 + 0.42) * (1 - 2 * 0.42))
    forces = [[0.0, 0.0, 400.0]] + [[0.0, 0.0, d * e_conf * 400.0 / 2.0] for d in (3.0, 3.2)]
    scene = write_plates_scene(tmp_path, load=f"time_s = [0.0, 1.0, 2.0]\nforce_n = {forces}")
    assert main(["run", str(scene), "--method", "dem", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "bones pass through each other" in err and "at 2 of 3 time points (k = 1-2; t = 1-2 s)" in err
    assert "100 % of those in contact" in err and "[solver] allow_bone_overlap = true" in err
    assert not (tmp_path / "o").exists()
    assert main(["run", str(scene), "--method", "dem", "--out", str(tmp_path / "kept"), "--set", "solver.allow_bone_overlap=true"]) == 0
    warnings = json.loads((tmp_path / "kept" / "summary.json").read_text())["warnings"]
    assert any("at 2 time points (k = 1-2" in w and "compressed past their length" in w for w in warnings)


def test_unknown_builtin_scene(capsys):
    assert main(["run", "no-such-scene"]) == 2
    assert "ideal-standing" in capsys.readouterr().err


def test_set_overrides_a_scene_value(tmp_path):
    """--set changes a value before validation: 800 N instead of 400 N doubles p = F/A."""
    scene = write_plates_scene(tmp_path)
    assert main(["run", str(scene), "--out", str(tmp_path / "o"), "--set", "load.force_n=[0.0, 0.0, 800.0]"]) == 0
    assert json.loads((tmp_path / "o" / "summary.json").read_text())["peak_pressure_mpa"] == pytest.approx(2.0, rel=1e-9)


def test_plot_draws_one_curve_per_result_directory(tmp_path):
    """`edem plot` reads timeseries.csv (with the derived disp_norm_mm) and writes a non-blank PNG."""
    from reports.plots import read_timeseries

    scene = write_plates_scene(tmp_path, load="time_s = [0.0, 1.0]\nforce_n = [[0.0, 0.0, 200.0], [0.0, 0.0, 400.0]]")
    for method in ("edem", "dem"):
        assert main(["run", str(scene), "--method", method, "--out", str(tmp_path / method)]) == 0
    series = read_timeseries(tmp_path / "edem")
    np.testing.assert_allclose(series["disp_norm_mm"], np.abs(series["disp_z_mm"]), rtol=1e-12)
    out = tmp_path / "fig.png"
    assert main(["plot", str(tmp_path / "edem"), str(tmp_path / "dem"), "--column", "disp_z_mm", "--out", str(out)]) == 0
    import matplotlib.image

    assert matplotlib.image.imread(out).std() > 0


def test_summary_and_report_line_name_the_bed_the_run_used(tmp_path, capsys):
    """The built-in standing scene's default bed is the coupled layer and one --set gives the
    springs: summary.json and the one-line report say which ran (the two runs differ, so the key is
    not decoration: the coupled layer carries the same 333 N with a larger displacement)."""
    runs = {}
    for name, extra in (("default", []), ("springs", ["--set", "cartilage.coupling=none"])):
        out = tmp_path / name
        assert main(["run", "ideal-standing", "--out", str(out), *extra]) == 0
        runs[name] = (json.loads((out / "summary.json").read_text()), capsys.readouterr().out)
    (coupled, coupled_line), (springs, springs_line) = runs["default"], runs["springs"]
    assert (coupled["coupling"], coupled["thin_layer_symbol"], coupled["thin_layer_smoothing_resolution"]) == ("thin-layer", "pade", 0.0)
    assert "coupled layer (pade)" in coupled_line
    assert (springs["coupling"], springs["thin_layer_symbol"], springs["thin_layer_smoothing_resolution"]) == ("none", None, None)
    assert "independent springs" in springs_line
    assert coupled["final_displacement_mm"][2] > springs["final_displacement_mm"][2]
