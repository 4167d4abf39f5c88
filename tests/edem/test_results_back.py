"""Results back to OpenSim and ParaView: timeseries.sto read by opensim.TimeSeriesTable, the
joint's pose, the contact resultant, centre of pressure and ligament tensions in the time
series, and the fixed body written per time step."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest
from support import grid_plate, make_scene, plane

from edem.loads import LoadSeries
from edem.resultdir import read_surface_frame, read_timeseries_csv
from edem.results import write_results
from edem.scene import load_scene
from edem.solver import run


def test_sto_round_trips_through_opensim_timeseriestable(tmp_path):
    """Every timeseries.csv column comes back from opensim.TimeSeriesTable under its name, time as
    the index, values exact (repr)."""
    osim = pytest.importorskip("opensim")
    out = write_results(run(load_scene("ideal-toe-off")), tmp_path / "r")
    csv_columns = read_timeseries_csv(out / "timeseries.csv")
    table = osim.TimeSeriesTable(str(out / "timeseries.sto"))
    labels = list(table.getColumnLabels())
    assert labels == [c for c in csv_columns if c != "time_s"]
    np.testing.assert_array_equal(np.array(table.getIndependentColumn()), csv_columns["time_s"])
    for label in labels:
        np.testing.assert_array_equal(table.getDependentColumn(label).to_numpy(), csv_columns[label])


def test_contact_resultant_balances_the_load_and_its_centre_of_pressure_is_the_load_point(tmp_path):
    """Plates, free rotations, no ligaments: sum p A n equals the applied force, its moment about
    G the applied moment, and the centre of pressure sits where the load's line of action meets
    the plate (x = -M_y / F_z, y = M_x / F_z with G at the origin)."""
    force, moment = np.array([0.0, 0.0, 400.0]), np.array([800.0, -1200.0, 0.0])
    scene = make_scene(grid_plate(20, 20, 10), plane(lambda x, y: 2.0, size_mm=30.0), force, moment_nmm=moment,
                       fixed_dofs=("tx", "ty", "rz"), reference_point_mm=np.zeros(3))
    series = read_timeseries_csv(write_results(run(scene, "dem"), tmp_path / "r") / "timeseries.csv")
    contact_force = np.array([series[f"contact_force_{c}_n"][0] for c in "xyz"])
    contact_moment = np.array([series[f"contact_moment_{c}_nmm"][0] for c in "xyz"])
    # the solver balances to 1e-10 of the force scale (1e-8 N here); the csv keeps every digit
    np.testing.assert_allclose(contact_force, force, atol=1e-8)
    np.testing.assert_allclose(contact_moment, moment, atol=1e-8 * 20.0)
    cop = np.array([series[f"cop_{c}_mm"][0] for c in "xyz"])
    np.testing.assert_allclose(cop, [-moment[1] / force[2], moment[0] / force[2], 0.0], atol=1e-9)


def test_ligament_tensions_and_joint_angle_are_columns(tmp_path):
    scene = load_scene("ideal-toe-off")
    result = run(scene)
    series = read_timeseries_csv(write_results(result, tmp_path / "r") / "timeseries.csv")
    np.testing.assert_allclose(series["joint_angle_deg"], np.degrees(scene.kinematics.angle_rad), rtol=1e-12)
    for i, ligament in enumerate(scene.ligaments):
        np.testing.assert_allclose(series[f"ligament_{ligament.name}_n"], [max(s.ligament_force_n[i], 0.0) for s in result.steps])


def test_fixed_body_is_written_at_every_time_step(tmp_path):
    """fixed.pvd lists one fixed_NNNN.vtp per time point, each the fixed body at that time's pose
    (the stance turns the tibia from -3 to 10 deg): ParaView shows the true relative pose."""
    scene = load_scene("ideal-stance")
    result = run(scene)
    out = write_results(result, tmp_path / "r")
    entries = [(float(d.get("timestep")), d.get("file")) for d in ET.parse(out / "fixed.pvd").getroot().iter("DataSet")]
    assert len(entries) == len(scene.load.time_s)
    for k in (0, 40, 64):
        assert entries[k][0] == scene.load.time_s[k]
        frame = read_surface_frame(out / entries[k][1])
        np.testing.assert_allclose(frame.points_mm, scene.fixed_placement(k).points(scene.fixed.vertices_mm), atol=1e-9)
    first, last = (read_surface_frame(out / entries[k][1]).points_mm for k in (0, 64))
    assert np.abs(first - last).max() > 1.0  # 13 deg apart: millimetres at the plafond


def test_opensim_coordinates_are_columns(tmp_path):
    pytest.importorskip("opensim")
    from opensim_fixtures import build_model, write_motion

    build_model(tmp_path)
    write_motion(tmp_path / "walk.mot", [0.0, 1.0], [0.0, 6.0], [0.0, 0.001])
    (tmp_path / "s.toml").write_text(
        '[opensim]\nmodel = "two_body_ankle.osim"\nmobile_body = "talus"\nfixed_body = "tibia"\nmotion = "walk.mot"\n'
        "[cartilage]\nyoungs_modulus_mpa = 10.35\npoissons_ratio = 0.42\n"
        "[load]\ntime_s = [0.0, 1.0]\nforce_n = [[0.0, 300.0, 0.0], [0.0, 300.0, 0.0]]\n"
        '[constraints]\nfixed_dofs = ["tz", "rx", "ry"]\n',
        encoding="utf-8",
    )
    series = read_timeseries_csv(write_results(run(load_scene(tmp_path / "s.toml")), tmp_path / "r") / "timeseries.csv")
    np.testing.assert_allclose(series["coord_ankle_angle"], np.radians([0.0, 6.0]), rtol=1e-9)
    np.testing.assert_allclose(series["coord_ankle_slide"], [0.0, 0.001], rtol=1e-9)
