"""Tests of edem/loads.py: scene [load] / [kinematics] tables, data files, stance table (docs/method.md#2-edem-the-time-dependent-incremental-method, docs/references.md#the-thesiss-figures, README.md#scene-files)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from geometries.errors import InputError
from edem.loads import (
    JointKinematics,
    LoadSeries,
    angle_series_from_table,
    load_series_from_table,
    resample_pchip,
    thesis_stance_table,
)

JR = "ankle_r_on_talus_r_in_ground"  # OpenSim JointReaction column prefix


@pytest.fixture
def scene(tmp_path: Path) -> Path:
    path = tmp_path / "scene.toml"
    path.write_text("[scene]\nname = 'test'\n")
    return path


def write_jointreaction_sto(path: Path, rows: np.ndarray, prefixes: tuple[str, ...] = (JR,)) -> Path:
    """An OpenSim JointReaction ReactionLoads .sto in OpenSim's layout (moments in N·m, positions in m)."""
    names = ["time"]
    for p in prefixes:
        names += [f"{p}_{c}" for c in ("fx", "fy", "fz", "mx", "my", "mz", "px", "py", "pz")]
    lines = [
        "JointReaction_ReactionLoads",
        "version=1",
        f"nRows={rows.shape[0]}",
        f"nColumns={len(names)}",
        "inDegrees=no",
        "endheader",
        "\t".join(names),
    ]
    for row in rows:
        lines.append("\t".join(f"{v:20.8f}" for v in row))
    path.write_text("\n".join(lines) + "\n")
    return path


def write_ik_mot(path: Path, time_s: np.ndarray, angle: np.ndarray, in_degrees: bool) -> Path:
    """An OpenSim 4 inverse-kinematics .mot (header as written by STOFileAdapter)."""
    lines = [
        "Coordinates",
        "version=1",
        f"nRows={time_s.size}",
        "nColumns=3",
        f"inDegrees={'yes' if in_degrees else 'no'}",
        "",
        "Units are S.I. units (second, meters, Newtons, ...)",
        "If the header above contains a line with 'inDegrees', this indicates whether rotational "
        "values are in degrees (yes) or radians (no).",
        "",
        "endheader",
        "time\tpelvis_tilt\tankle_angle_r",
    ]
    for t, a in zip(time_s, angle):
        lines.append(f"\t{t:.8f}\t{0.1:.8f}\t{a:.12f}")
    path.write_text("\n".join(lines) + "\n")
    return path


def jointreaction_rows(n: int = 4) -> np.ndarray:
    time = np.linspace(0.0, 0.3, n)
    cols = [time]
    for k in range(9):
        cols.append((k + 1) * 10.0 + time * 100.0)
    return np.column_stack(cols)


# --------------------------------------------------------------------------- [load] forms


def test_static_table_round_trips_to_one_point_at_t0(scene):
    load = load_series_from_table({"force_n": [1, 2, 333], "moment_nmm": [4.0, 5.0, 6.0]}, scene)
    assert isinstance(load, LoadSeries)
    np.testing.assert_array_equal(load.time_s, [0.0])
    np.testing.assert_array_equal(load.force_n, [[1.0, 2.0, 333.0]])
    np.testing.assert_array_equal(load.moment_nmm, [[4.0, 5.0, 6.0]])
    assert load.force_n.dtype == np.float64


def test_static_without_moment_has_zero_moment(scene):
    load = load_series_from_table({"force_n": [0, 0, 333]}, scene)
    np.testing.assert_array_equal(load.moment_nmm, np.zeros((1, 3)))


def test_inline_series_round_trips(scene):
    table = {
        "time_s": [0.0, 0.01, 0.02],
        "force_n": [[0, 0, 100], [0, 1, 200], [2, 0, 300.5]],
        "moment_nmm": [[1, 2, 3], [4, 5, 6], [7, 8, 9]],
    }
    load = load_series_from_table(table, scene)
    np.testing.assert_array_equal(load.time_s, table["time_s"])
    np.testing.assert_array_equal(load.force_n, table["force_n"])
    np.testing.assert_array_equal(load.moment_nmm, table["moment_nmm"])


def test_load_series_arrays_are_read_only(scene):
    load = load_series_from_table({"force_n": [0, 0, 333]}, scene)
    with pytest.raises(ValueError):
        load.force_n[0, 0] = 1.0


def test_force_scale_scales_force_only(scene):
    load = load_series_from_table({"force_n": [1, 2, 3], "moment_nmm": [1, 1, 1], "force_scale": 2.5}, scene)
    np.testing.assert_array_equal(load.force_n, [[2.5, 5.0, 7.5]])
    np.testing.assert_array_equal(load.moment_nmm, [[1.0, 1.0, 1.0]])


def test_time_range_selects_rows_inclusive(scene):
    table = {"time_s": [0.0, 1.0, 2.0, 3.0], "force_n": [[0, 0, k] for k in range(4)], "time_range_s": [1.0, 2.0]}
    load = load_series_from_table(table, scene)
    np.testing.assert_array_equal(load.time_s, [1.0, 2.0])
    np.testing.assert_array_equal(load.force_n[:, 2], [1.0, 2.0])


# --------------------------------------------------------------------------- CSV


def test_csv_default_columns_read_with_moments(scene):
    (scene.parent / "load.csv").write_text(
        "time_s,force_x_n,force_y_n,force_z_n,moment_x_nmm,moment_y_nmm,moment_z_nmm\n"
        "0.0,1,2,3,10,20,30\n"
        "0.5,4,5,6,40,50,60\n"
    )
    load = load_series_from_table({"file": "load.csv"}, scene)
    np.testing.assert_array_equal(load.time_s, [0.0, 0.5])
    np.testing.assert_array_equal(load.force_n, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(load.moment_nmm, [[10, 20, 30], [40, 50, 60]])  # CSV moments are N·mm


def test_csv_default_columns_without_moments_give_zero_moment(scene):
    (scene.parent / "load.csv").write_text("time_s, force_x_n, force_y_n, force_z_n\n0, 0, 0, 333\n")
    load = load_series_from_table({"file": "load.csv"}, scene)
    np.testing.assert_array_equal(load.force_n, [[0, 0, 333]])
    np.testing.assert_array_equal(load.moment_nmm, np.zeros((1, 3)))


def test_csv_custom_columns_with_negation(scene):
    sub = scene.parent / "data"
    sub.mkdir()
    (sub / "gait.csv").write_text("t,a,b,c,m1,m2,m3\n0,1,2,3,7,8,9\n1,4,5,6,7,8,9\n")
    table = {
        "file": "data/gait.csv",
        "time_column": "t",
        "force_columns": ["c", "-a", "b"],
        "moment_columns": ["-m3", "m1", "m2"],
    }
    load = load_series_from_table(table, scene)
    np.testing.assert_array_equal(load.time_s, [0.0, 1.0])
    np.testing.assert_array_equal(load.force_n, [[3, -1, 2], [6, -4, 5]])
    np.testing.assert_array_equal(load.moment_nmm, [[-9, 7, 8], [-9, 7, 8]])


# --------------------------------------------------------------------------- OpenSim JointReaction


def test_sto_jointreaction_on_the_mobile_body_is_negated_and_moments_converted_nm_to_nmm(scene):
    """On the mobile body (talus_r), in ground, axes kept: the joint's load on M negated (what
    presses M into F, by M's equilibrium), moments N m -> N mm and negated about the same point,
    the joint centre (px, py, pz) m -> mm as the point the moment is about."""
    rows = jointreaction_rows()
    write_jointreaction_sto(scene.parent / "jr.sto", rows)
    load = load_series_from_table({"file": "jr.sto", "axes": "same", "mobile_body": "talus_r"}, scene)
    np.testing.assert_allclose(load.time_s, rows[:, 0])
    np.testing.assert_allclose(load.force_n, -rows[:, 1:4])
    np.testing.assert_allclose(load.moment_nmm, -rows[:, 4:7] * 1000.0)
    np.testing.assert_allclose(load.point_mm, rows[:, 7:10] * 1000.0)
    assert load.frame == "global"


def test_sto_jointreaction_axes_are_never_guessed(scene):
    """OpenSim's x anterior, y up, z right taken as the scene's slid the talus 9 mm: now refused
    until `axes` says how they map."""
    write_jointreaction_sto(scene.parent / "jr.sto", jointreaction_rows())
    with pytest.raises(InputError, match=r"x anterior, y up, z right.*not guessed.*axes = \"opensim\""):
        load_series_from_table({"file": "jr.sto", "mobile_body": "talus_r"}, scene)
    with pytest.raises(InputError, match=r"mobile_body = \"talus_r\""):
        load_series_from_table({"file": "jr.sto", "axes": "opensim"}, scene)


def test_opensim_axes_preset_maps_anterior_up_right_onto_scene_right_anterior_up(scene):
    """axes = "opensim": scene (x right, y anterior, z up) = OpenSim (z, x, y) for force, moment
    and the joint centre; a proper rotation, so moment = r x F keeps its form."""
    rows = jointreaction_rows()
    write_jointreaction_sto(scene.parent / "jr.sto", rows)
    load = load_series_from_table({"file": "jr.sto", "axes": "opensim", "mobile_body": "talus_r"}, scene)
    fx, fy, fz, mx, my, mz, px, py, pz = (rows[:, k] for k in range(1, 10))
    np.testing.assert_allclose(load.force_n, -np.column_stack([fz, fx, fy]))  # on M: negated
    np.testing.assert_allclose(load.moment_nmm, -1000.0 * np.column_stack([mz, mx, my]))
    np.testing.assert_allclose(load.point_mm, 1000.0 * np.column_stack([pz, px, py]))
    f, r = np.array([1.0, 2.0, 3.0]), np.array([-4.0, 0.5, 2.0])
    from edem.joint_reaction import axes_matrix

    a = axes_matrix("opensim")
    np.testing.assert_allclose(np.cross(a @ r, a @ f), a @ np.cross(r, f), atol=1e-12)


@pytest.mark.parametrize("axes", [["x", "y", "-z"], ["x", "x", "z"], ["x", "y", "w"], "zxy"])
def test_axes_that_are_not_a_rotation_are_refused(scene, axes):
    with pytest.raises(InputError) as info:
        load_series_from_table({"force_n": [0, 0, 1], "axes": axes}, scene)
    assert info.value.key == "load.axes" and "opensim" in info.value.expected


def test_jointreaction_on_the_fixed_body_is_used_as_is_and_turns_with_it(scene):
    """ankle_r_on_tibia_r_in_tibia_r: the joint's load on the tibia (F), in the tibia's frame, is
    what M transmits to F (sign +1), and the components turn with F (frame "fixed")."""
    rows = jointreaction_rows()
    prefix = "ankle_r_on_tibia_r_in_tibia_r"
    write_jointreaction_sto(scene.parent / "jr.sto", rows, prefixes=(prefix,))
    table = {"file": "jr.sto", "axes": "same", "mobile_body": "talus_r", "fixed_body": "tibia_r"}
    load = load_series_from_table(table, scene)
    np.testing.assert_allclose(load.force_n, rows[:, 1:4])
    np.testing.assert_allclose(load.moment_nmm, 1000.0 * rows[:, 4:7])
    np.testing.assert_allclose(load.point_mm, 1000.0 * rows[:, 7:10])
    assert load.frame == "fixed"
    with pytest.raises(InputError, match="expressed in the fixed frame"):
        load_series_from_table({**table, "frame": "global"}, scene)
    with pytest.raises(InputError, match="neither mobile_body"):
        load_series_from_table({**table, "fixed_body": "femur_r"}, scene)


def test_sto_moment_unit_nmm_keeps_values(scene):
    rows = jointreaction_rows()
    write_jointreaction_sto(scene.parent / "jr.sto", rows)
    load = load_series_from_table({"file": "jr.sto", "moment_unit": "nmm", "axes": "same", "mobile_body": "talus_r"}, scene)
    np.testing.assert_allclose(load.moment_nmm, -rows[:, 4:7])  # on M: negated, not scaled


def test_sto_negated_column_mapping_onto_scene_axes(scene):
    # OpenSim X anterior, Y superior, Z right -> scene (x = right, y = posterior, z = superior)
    rows = jointreaction_rows()
    write_jointreaction_sto(scene.parent / "jr.sto", rows)
    table = {
        "file": "jr.sto",
        "force_columns": [f"{JR}_fz", f"-{JR}_fx", f"{JR}_fy"],
        "moment_columns": [f"{JR}_mz", f"-{JR}_mx", f"{JR}_my"],
    }
    load = load_series_from_table(table, scene)
    fx, fy, fz, mx, my, mz = (rows[:, k] for k in range(1, 7))
    np.testing.assert_allclose(load.force_n, np.column_stack([fz, -fx, fy]))
    np.testing.assert_allclose(load.moment_nmm, 1000.0 * np.column_stack([mz, -mx, my]))


def test_sto_two_jointreaction_triples_is_an_error_listing_candidates(scene):
    rows = np.column_stack([jointreaction_rows(), jointreaction_rows()[:, 1:]])
    write_jointreaction_sto(scene.parent / "jr.sto", rows, prefixes=(JR, "knee_r_on_tibia_r_in_ground"))
    with pytest.raises(InputError) as info:
        load_series_from_table({"file": "jr.sto"}, scene)
    msg = str(info.value)
    assert f"{JR}_fx" in msg and "knee_r_on_tibia_r_in_ground_fz" in msg and "force_columns" in msg


# --------------------------------------------------------------------------- [kinematics]


def test_kinematics_mot_in_degrees(scene):
    t = np.linspace(0.0, 0.64, 65)
    angle_deg = 10.0 * np.sin(t)
    write_ik_mot(scene.parent / "ik.mot", t, angle_deg, in_degrees=True)
    kin = angle_series_from_table(
        {"axis_point_mm": [1, 2, 3], "axis_direction": [0, 2, 0], "file": "ik.mot", "angle_column": "ankle_angle_r"},
        scene, t,
    )
    assert isinstance(kin, JointKinematics)
    np.testing.assert_allclose(kin.angle_rad, np.deg2rad(angle_deg), atol=1e-12)
    np.testing.assert_array_equal(kin.axis_point_mm, [1, 2, 3])
    np.testing.assert_array_equal(kin.axis_direction, [0, 1, 0])  # normalised


def test_kinematics_mot_in_radians(scene):
    t = np.array([0.0, 0.1, 0.2])
    angle_rad = np.array([0.0, 0.1, -0.2])
    write_ik_mot(scene.parent / "ik.mot", t, angle_rad, in_degrees=False)
    kin = angle_series_from_table(
        {"axis_point_mm": [0, 0, 0], "axis_direction": [1, 0, 0], "file": "ik.mot", "angle_column": "-ankle_angle_r"},
        scene, t,
    )
    np.testing.assert_allclose(kin.angle_rad, -angle_rad, atol=1e-12)


def test_kinematics_interpolation_onto_load_times_exact_for_linear_angle(scene):
    file_t = np.array([0.0, 0.3, 0.5, 1.0])
    write_ik_mot(scene.parent / "ik.mot", file_t, 2.0 + 7.0 * file_t, in_degrees=True)
    load_t = np.array([0.0, 0.05, 0.42, 0.77, 1.0])
    kin = angle_series_from_table(
        {"axis_point_mm": [0, 0, 0], "axis_direction": [0, 0, 1], "file": "ik.mot", "angle_column": "ankle_angle_r"},
        scene, load_t,
    )
    np.testing.assert_allclose(np.rad2deg(kin.angle_rad), 2.0 + 7.0 * load_t, rtol=1e-12)


def test_kinematics_load_times_outside_file_range_is_an_error(scene):
    write_ik_mot(scene.parent / "ik.mot", np.array([0.0, 1.0]), np.array([0.0, 1.0]), in_degrees=True)
    with pytest.raises(InputError, match="outside"):
        angle_series_from_table(
            {"axis_point_mm": [0, 0, 0], "axis_direction": [0, 0, 1], "file": "ik.mot", "angle_column": "ankle_angle_r"},
            scene, np.array([0.5, 1.5]),
        )


def test_kinematics_inline_angles_per_point_or_single_value(scene):
    base = {"axis_point_mm": [0, 0, 0], "axis_direction": [0, 1, 0]}
    t = np.array([0.0, 1.0])
    kin = angle_series_from_table({**base, "angle_deg": [0.0, 5.0]}, scene, t)
    np.testing.assert_allclose(kin.angle_rad, np.deg2rad([0.0, 5.0]))
    for single in (16.31, [16.31]):
        kin = angle_series_from_table({**base, "angle_deg": single}, scene, t)
        np.testing.assert_allclose(kin.angle_rad, np.deg2rad([16.31, 16.31]))
    with pytest.raises(InputError) as info:
        angle_series_from_table({**base, "angle_deg": [0.0, 1.0, 2.0]}, scene, t)
    assert info.value.key == "kinematics.angle_deg"


def test_kinematics_zero_axis_is_an_error(scene):
    with pytest.raises(InputError) as info:
        angle_series_from_table({"axis_point_mm": [0, 0, 0], "axis_direction": [0, 0, 0], "angle_deg": 0.0},
                                scene, np.zeros(1))
    assert info.value.key == "kinematics.axis_direction"


def test_kinematics_unknown_key_is_an_error(scene):
    with pytest.raises(InputError, match="axis_dir"):
        angle_series_from_table({"axis_point_mm": [0, 0, 0], "axis_dir": [0, 0, 1], "angle_deg": 0.0},
                                scene, np.zeros(1))


# --------------------------------------------------------------------------- stance (docs/references.md#the-thesiss-figures)


def test_thesis_stance_table_is_the_published_numbers():
    table = thesis_stance_table()
    np.testing.assert_array_equal(table.percent_stance, [12, 20, 55, 69, 78, 87, 92])
    np.testing.assert_array_equal(table.angle_deg, [-0.57, 5.37, 10.7, 12.92, 16.31, 17.1, 15.1])
    assert table.force_si_n[4] == 4078.26 and table.force_ml_n[0] == 13.64 and table.force_pa_n[1] == 143.87


def test_pchip_passes_exactly_through_the_seven_points_and_never_overshoots():
    table = thesis_stance_table()
    x = table.percent_stance
    values = np.column_stack([table.angle_deg, table.force_ml_n, table.force_pa_n, table.force_si_n])
    np.testing.assert_allclose(resample_pchip(x, values, x), values, rtol=1e-13, atol=1e-12)
    dense = np.linspace(x[0], x[-1], 2001)
    out = resample_pchip(x, values, dense)
    for k in range(len(x) - 1):
        inside = (dense >= x[k]) & (dense <= x[k + 1])
        lo = np.minimum(values[k], values[k + 1])
        hi = np.maximum(values[k], values[k + 1])
        assert np.all(out[inside] >= lo - 1e-9) and np.all(out[inside] <= hi + 1e-9)
        # monotone between monotone points
        step = np.diff(out[inside], axis=0) * np.sign(values[k + 1] - values[k])
        assert np.all(step >= -1e-9)


# --------------------------------------------------------------------------- errors


def test_unknown_load_key_is_named_with_allowed_keys(scene):
    with pytest.raises(InputError) as info:
        load_series_from_table({"force_n": [0, 0, 1], "forces": [1, 2, 3]}, scene)
    err = info.value
    assert err.file == str(scene) and err.key == "load.forces"
    assert "forces" in str(err) and "force_n" in err.expected and "time_range_s" in err.expected


@pytest.mark.parametrize(
    "table,key",
    [
        ({"force_n": [0, 333]}, "load.force_n"),
        ({"force_n": [0, 0, 333], "moment_nmm": [1, 2]}, "load.moment_nmm"),
        ({"time_s": [0, 1], "force_n": [[0, 0, 1], [0, 1]]}, "load.force_n"),
        ({"time_s": [0, 1], "force_n": [[0, 0, 1]]}, "load.force_n"),
        ({"force_n": [0, "0", 333]}, "load.force_n"),
        ({"force_n": [0, 0, 1], "force_scale": "2"}, "load.force_scale"),
        ({"force_n": [0, 0, float("nan")]}, "load.force_n"),
    ],
)
def test_wrong_types_and_triple_lengths_name_key_and_shape(scene, table, key):
    with pytest.raises(InputError) as info:
        load_series_from_table(table, scene)
    assert info.value.key == key and info.value.expected


def test_non_increasing_inline_time_is_an_error(scene):
    with pytest.raises(InputError) as info:
        load_series_from_table({"time_s": [0.0, 1.0, 1.0], "force_n": [[0, 0, 1]] * 3}, scene)
    assert info.value.key == "load.time_s" and "increas" in info.value.expected


def test_non_increasing_file_time_is_an_error(scene):
    (scene.parent / "load.csv").write_text("time_s,force_x_n,force_y_n,force_z_n\n0,0,0,1\n0.2,0,0,1\n0.1,0,0,1\n")
    with pytest.raises(InputError, match="line 4"):
        load_series_from_table({"file": "load.csv"}, scene)


@pytest.mark.parametrize("bad", ["nan", "inf", "-inf"])
def test_non_finite_value_in_file_is_an_error(scene, bad):
    rows = jointreaction_rows(3)
    path = write_jointreaction_sto(scene.parent / "jr.sto", rows)
    text = path.read_text().splitlines()
    fields = text[-1].split("\t")
    fields[2] = bad  # the _fy column of the last row
    text[-1] = "\t".join(fields)
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(InputError) as info:
        load_series_from_table({"file": "jr.sto", "axes": "same", "mobile_body": "talus_r"}, scene)
    assert info.value.file == str(path) and f"{JR}_fy" in str(info.value) and "finite" in info.value.expected


def test_missing_file_is_an_error(scene):
    with pytest.raises(InputError) as info:
        load_series_from_table({"file": "nowhere.csv"}, scene)
    assert info.value.file == str(scene) and info.value.key == "load.file" and "nowhere.csv" in str(info.value)


def test_missing_column_lists_available_columns(scene):
    (scene.parent / "load.csv").write_text("time_s,fx,fy,fz\n0,0,0,1\n")
    with pytest.raises(InputError) as info:
        load_series_from_table({"file": "load.csv", "force_columns": ["fx", "fy", "f_z"]}, scene)
    msg = str(info.value)
    assert "'f_z'" in msg and "time_s, fx, fy, fz" in msg and info.value.key == "load.force_columns"


def test_file_and_force_n_together_is_an_error(scene):
    (scene.parent / "load.csv").write_text("time_s,force_x_n,force_y_n,force_z_n\n0,0,0,1\n")
    with pytest.raises(InputError, match="both"):
        load_series_from_table({"file": "load.csv", "force_n": [0, 0, 1]}, scene)


def test_column_keys_without_file_are_an_error(scene):
    with pytest.raises(InputError) as info:
        load_series_from_table({"force_n": [0, 0, 1], "force_columns": ["a", "b", "c"]}, scene)
    assert info.value.key == "load.force_columns"


def test_empty_time_range_is_an_error(scene):
    with pytest.raises(InputError) as info:
        load_series_from_table({"force_n": [0, 0, 1], "time_range_s": [1.0, 2.0]}, scene)
    assert info.value.key == "load.time_range_s"


# --------------------------------------------------------------------------- conversions that overflow


def test_moment_finite_in_n_m_but_infinite_in_n_mm_names_file_column_and_line(scene):
    """-1e308 N m is a finite number in the file and -inf after N m -> N mm (x 1000): refused as
    bad input naming the .sto, the column and the line, not left to fail as non-finite later."""
    rows = jointreaction_rows(3)
    rows[1, 4] = -1e308  # the _mx column of the second data row (file line 9: 6 header lines, the names, row 1)
    path = write_jointreaction_sto(scene.parent / "jr.sto", rows)
    with pytest.raises(InputError) as info:
        load_series_from_table({"file": "jr.sto", "axes": "same", "mobile_body": "talus_r"}, scene)
    message = str(info.value)
    assert info.value.file == str(path) and info.value.key == "load.file"
    assert f"column '{JR}_mx'" in message and "line 9" in message and "N m -> N mm" in message
    # the largest moment that stays finite in N mm is accepted: the limit is the conversion's
    rows[1, 4] = -np.finfo(float).max / 1000.0
    write_jointreaction_sto(scene.parent / "jr.sto", rows)
    load = load_series_from_table({"file": "jr.sto", "axes": "same", "mobile_body": "talus_r"}, scene)
    assert np.isfinite(load.moment_nmm).all()


def test_joint_centre_finite_in_m_but_infinite_in_mm_names_its_column(scene):
    rows = jointreaction_rows(3)
    rows[2, 7] = 1e306  # _px of the last row, m
    write_jointreaction_sto(scene.parent / "jr.sto", rows)
    with pytest.raises(InputError) as info:
        load_series_from_table({"file": "jr.sto", "axes": "same", "mobile_body": "talus_r"}, scene)
    assert f"column '{JR}_px'" in str(info.value) and "line 10" in str(info.value) and "m -> mm" in str(info.value)


def test_force_scale_that_overflows_names_the_force_it_overflows(scene):
    """force_scale multiplies finite forces: from a file the column and line are named, inline the
    entry of force_n; the key is force_scale either way."""
    write_jointreaction_sto(scene.parent / "jr.sto", jointreaction_rows(3))
    with pytest.raises(InputError) as info:
        load_series_from_table({"file": "jr.sto", "axes": "same", "mobile_body": "talus_r", "force_scale": 1e307}, scene)
    assert info.value.key == "load.force_scale" and f"column '{JR}_fy'" in str(info.value) and "line 8" in str(info.value)
    with pytest.raises(InputError) as info:
        load_series_from_table({"time_s": [0.0, 1.0], "force_n": [[0, 0, 1], [0, 0, 1e300]], "force_scale": 1e10}, scene)
    assert info.value.key == "load.force_scale" and "force_n[1][2]" in str(info.value)


def test_max_step_s_between_values_whose_difference_overflows_is_refused(scene):
    """Linear interpolation between -1.7e308 and 1.7e308 needs their difference, which is not a
    float: the step is named (key max_step_s), no infinity reaches the solver."""
    table = {"time_s": [0.0, 1.0], "force_n": [[0, 0, -1.7e308], [0, 0, 1.7e308]], "max_step_s": 0.25}
    with pytest.raises(InputError) as info:
        load_series_from_table(table, scene)
    assert info.value.key == "load.max_step_s" and "t = 0 s and t = 1 s" in str(info.value)
