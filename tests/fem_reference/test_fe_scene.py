"""`edem fe SCENE`: the FE reference of a whole scene (fem_reference.run_scene), docs/method.md#6-the-fe-reference-and-its-discrete-twins and 9.

Closed forms on the flat plates (slab and layer models), the result directory (docs/result-format.md), the ideal
ankle on a coarse mesh, time point selection, free rotations and bad input. Coarse meshes: each
case runs in a few seconds on 2 cores.
"""

from __future__ import annotations

import csv
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("dolfinx_solver")

from fe_cases import report  # noqa: E402

from edem.cli import main  # noqa: E402
from edem.results import TIMESERIES_COLUMNS  # noqa: E402
from fem_reference import closed_forms as cf  # noqa: E402

pytestmark = pytest.mark.fe

ROOT = Path(__file__).resolve().parents[2]
PLATES = str(ROOT / "verification" / "scenes" / "flat-plates.toml")  # 20 x 20 mm, gap 2, 400 N
E, NU = 10.35, 0.42
SUMMARY_KEYS = {"scene", "method", "steps", "n_dofs", "wall_time_s", "peak_pressure_mpa",
                "max_contact_area_mm2", "final_displacement_mm", "max_force_residual_n",
                "warnings", "contact_area_definition", "element", "mesh_size_mm",
                "newton_iterations", "max_nominal_strain"}
VTP_ARRAYS = {"pressure_mpa", "spring_length_mm", "in_contact"}


def edem_fe(out: Path, scene: str, *args: str) -> dict:
    """Run `edem fe` in-process; return summary.json."""
    rc = main(["fe", scene, "--out", str(out), *args])
    assert rc == 0
    return json.loads((out / "summary.json").read_text())


def timeseries(out: Path) -> tuple[list[str], list[dict[str, float]]]:
    with open(out / "timeseries.csv", newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], [dict(zip(rows[0], map(float, r))) for r in rows[1:]]


def frame(out: Path, step: int = 0):
    from edem.resultdir import read_surface_frame

    return read_surface_frame(out / f"pressure_{step:04d}.vtp")


def plates_scene(tmp_path: Path, *, law: str = "threshold", thickness: float | None = None,
                 time_s: list[float] | None = None, forces: list[float] | None = None,
                 gap: float = 2.0, nu: float = NU, n_per_side: int = 10,
                 fixed: str = '["tx", "ty", "rx", "ry", "rz"]', moment: str | None = None,
                 fe: str = "") -> str:
    """A flat-plates scene file (the builtin flat_plates geometry)."""
    cart = f'law = "{law}"\n' + (f"thickness_mm = {thickness}\n" if thickness else "")
    if time_s is None:
        load = "force_n = [0.0, 0.0, 400.0]\n"
    else:
        load = (f"time_s = {time_s}\nforce_n = "
                + str([[0.0, 0.0, f] for f in forces]) + "\n")
    if moment:
        load += f"moment_nmm = {moment}\n"
    path = tmp_path / "plates.toml"
    path.write_text(f"""[scene]
name = "plates"
[geometry]
builtin = "flat_plates"
width_mm = 20.0
depth_mm = 20.0
gap_mm = {gap}
n_per_side = {n_per_side}
[cartilage]
youngs_modulus_mpa = {E}
poissons_ratio = {nu}
max_spring_length_mm = 3.5
{cart}
[load]
{load}
[constraints]
fixed_dofs = {fixed}
{fe}
""", encoding="utf-8")
    return str(path)


# --------------------------------------------------------------------------------------------
# slab model on the flat plates: closed forms
# --------------------------------------------------------------------------------------------


def test_flat_plates_nu0_is_exact_uniaxial_strain(tmp_path):
    """Closed form: at nu = 0 the free-sided slab is in uniaxial strain (no Poisson coupling),
    so p = F / A at every node and d = (F / A) h / E exactly (P1 reproduces the linear field)."""
    out = tmp_path / "fe"
    s = edem_fe(out, PLATES, "--degree", "1", "--mesh-size", "1.0",
                "--set", "cartilage.poissons_ratio=0.0")
    p = frame(out).point_data["pressure_mpa"]
    d = s["final_displacement_mm"][2]
    report("flat plates nu=0", d=d, d_exact=2.0 / E, p_min=p.min(), p_max=p.max(),
           n_dofs=s["n_dofs"], wall_s=s["wall_time_s"])
    assert np.allclose(p, 1.0, rtol=1e-9)
    assert d == pytest.approx(1.0 * 2.0 / E, rel=1e-9)
    assert s["max_contact_area_mm2"] == pytest.approx(400.0, rel=1e-9)
    assert (s["linear_solver"], s["krylov_iterations"]) == (["direct"], 0)
    assert s["newton_iterations_per_time_point"] == [s["newton_iterations"]]
    assert s["krylov_iterations_per_newton_step"] == [[]]


def test_forced_krylov_path_keeps_the_uniaxial_strain_closed_form(tmp_path):
    """`--linear-solver iterative` (docs/method.md, section 6) solves the same flat plates as the
    LU: p = F / A at every node and d = (F / A) h / E at nu = 0. Tolerance: Newton stops at 1e-10
    of its first residual, measured on the assembled residual whatever the inner solves' forcing
    term, within condition x 1e-10 of the discrete solution (condition number of the Jacobian
    212 on this mesh, scipy svds), plus the discrete solution's 1e-9 of the LU test above;
    summary.json says which solver ran and its iterations, per Newton step of each time point."""
    out = tmp_path / "fe"
    s = edem_fe(out, PLATES, "--degree", "1", "--mesh-size", "1.0", "--linear-solver", "iterative",
                "--set", "cartilage.poissons_ratio=0.0")
    p = frame(out).point_data["pressure_mpa"]
    report("flat plates nu=0, Krylov", d=s["final_displacement_mm"][2], krylov=s["krylov_iterations"],
           per_step=s["krylov_iterations_per_newton_step"])
    assert s["linear_solver"] == ["iterative"] and s["krylov_iterations"] > 0
    assert s["newton_iterations_per_time_point"] == [s["newton_iterations"]]
    (per_step,) = s["krylov_iterations_per_newton_step"]
    assert len(per_step) == s["newton_iterations"] and sum(per_step) == s["krylov_iterations"]
    rtol = 212 * 1e-10 + 1e-9
    assert np.allclose(p, 1.0, rtol=rtol, atol=0.0)
    assert s["final_displacement_mm"][2] == pytest.approx(1.0 * 2.0 / E, rel=rtol)


def test_flat_plates_slab_confined_interior_and_result_directory(tmp_path):
    """Closed form (confined compression, p = E' d / h) in the interior of a thin free-sided slab
    (20 x 20 mm, h = 0.5 mm, nu = 0.42): the free edges relax within a few h, so more than 12 h
    from them the pressure is uniform (within 1 %) and equals E' d / h (0.5 %). Honest
    tolerance against the plate averages: the edges carry less, so the interior pressure is
    about 6 % above F / A and d about 6 % above (F / A) h / E' (both checked within 8 %).
    Invariants: force residual < 1e-6 relative; the docs/result-format.md layout (summary keys, the exact
    timeseries columns, pressure.pvd, one .vtp with point and cell arrays, fixed.vtp)."""
    out = tmp_path / "fe"
    s = edem_fe(out, PLATES, "--degree", "1", "--mesh-size", "0.5",
                "--set", "geometry.gap_mm=0.5")
    h, load, area = 0.5, 400.0, 400.0
    e_conf = cf.confined_modulus(E, NU)
    f = frame(out)
    x, p = f.points_mm, f.point_data["pressure_mpa"]
    inner = (np.abs(x[:, 0]) <= 10.0 - 12 * h) & (np.abs(x[:, 1]) <= 10.0 - 12 * h)
    d = s["final_displacement_mm"][2]
    p_closed = cf.confined_compression_pressure(E, NU, h, d)
    spread = p[inner].max() / p[inner].min() - 1.0
    report("flat plates slab h=0.5", d=d, d_avg=load / area * h / e_conf, p_closed=p_closed,
           p_inner=[p[inner].min(), p[inner].max()], spread=spread, n_dofs=s["n_dofs"],
           wall_s=s["wall_time_s"], residual=s["max_force_residual_n"])
    assert inner.sum() > 50
    assert spread < 0.01
    assert np.allclose(p[inner], p_closed, rtol=0.005)
    assert p[inner].mean() == pytest.approx(load / area, rel=0.08)
    assert p[inner].mean() > load / area  # the free edges carry less than the average
    assert d == pytest.approx(load / area * h / e_conf, rel=0.08)
    assert s["max_force_residual_n"] < 1e-6 * load
    assert s["final_displacement_mm"][:2] == [0.0, 0.0]

    # result directory (docs/result-format.md)
    assert SUMMARY_KEYS <= set(s)
    assert s["method"] == "fe-slab" and s["steps"] == 1 and s["element"] == "P1"
    assert s["mesh_size_mm"] == 0.5 and s["scene"] == "flat-plates"
    assert s["max_contact_area_on_mobile_mm2"] == pytest.approx(s["max_contact_area_mm2"])
    assert s["contact_area_on_mobile_mm2"] == [s["max_contact_area_on_mobile_mm2"]]  # per time point
    header, rows = timeseries(out)
    assert tuple(header) == TIMESERIES_COLUMNS
    assert len(rows) == 1 and rows[0]["force_z_n"] == load
    assert rows[0]["disp_z_mm"] == pytest.approx(d, rel=1e-12)
    assert rows[0]["iterations"] == s["newton_iterations"] >= 1
    assert rows[0]["mean_pressure_mpa"] == pytest.approx(load / rows[0]["contact_area_mm2"],
                                                         rel=1e-6)
    assert [rows[0][c] for c in ("rot_x_rad", "rot_y_rad", "rot_z_rad")] == [0, 0, 0]
    assert (out / "pressure.pvd").read_text().count("pressure_0000.vtp") == 1
    assert (out / "fixed.vtp").is_file()
    assert VTP_ARRAYS <= set(f.point_data) and VTP_ARRAYS <= set(f.cell_data)
    assert np.allclose(f.point_data["spring_length_mm"], h, rtol=1e-9)  # slab thickness
    assert np.allclose(f.points_mm[:, 2], h)  # the contact face lies on F
    for arrays in (f.point_data, f.cell_data):
        assert all(np.all(np.isfinite(v)) for v in arrays.values())
    assert f.cell_data["pressure_mpa"] == pytest.approx(
        f.point_data["pressure_mpa"][f.triangles].mean(axis=1))


# --------------------------------------------------------------------------------------------
# layer model with an initial gap; time points
# --------------------------------------------------------------------------------------------


def test_layer_contact_only_after_the_gap_closes(tmp_path):
    """Closed form (nu = 0, uniaxial strain): a t = 1.5 mm layer under a plane 2 mm above the
    plate starts 0.5 mm apart; contact needs the gap closed first, d = gap + (F / A) t / E at
    each load (40 and 400 N), so d(F) extrapolates to the gap at F = 0, not to 0. The two time
    points share the mesh (the second is warm-started). spring_length_mm = t + gap = 2 mm."""
    scene = plates_scene(tmp_path, law="gap", thickness=1.5, nu=0.0, time_s=[0.0, 1.0],
                         forces=[40.0, 400.0])
    out = tmp_path / "fe"
    s = edem_fe(out, scene, "--degree", "1", "--mesh-size", "1.0")
    assert s["method"] == "fe-layer"
    _, rows = timeseries(out)
    d = np.array([r["disp_z_mm"] for r in rows])
    f = np.array([r["force_z_n"] for r in rows])
    expected = 0.5 + f / 400.0 * 1.5 / E
    slope = (d[1] - d[0]) / (f[1] - f[0])
    report("layer with a gap", d=d, expected=expected, intercept=d[0] - slope * f[0],
           newton=[r["iterations"] for r in rows], n_dofs=s["n_dofs"])
    assert np.allclose(d, expected, rtol=1e-8)
    assert d[0] - slope * f[0] == pytest.approx(0.5, rel=1e-8)
    assert all(r["contact_area_mm2"] == pytest.approx(400.0) for r in rows)
    assert s["max_force_residual_n"] < 1e-6 * 400.0
    for k in (0, 1):
        fr = frame(out, k)
        assert np.allclose(fr.point_data["gap_mm"], 0.5, atol=1e-12)
        assert np.allclose(fr.point_data["spring_length_mm"], 2.0, atol=1e-12)
        assert np.allclose(fr.point_data["pressure_mpa"], f[k] / 400.0, rtol=1e-8)


def test_refining_where_the_contact_reaches_gives_what_refining_everywhere_gives(tmp_path):
    """[fe] contact_mesh_size_mm (fem_reference.models.contact_refinement): the cylinder layer
    (10 mm long, 111 N: the scene's line load; P2, two elements through the layer) on M's own
    triangles (1.0 mm), halved everywhere, and halved only where the contact can reach
    (red-green around it). Away from the contact the bonded layer carries almost no load, so the
    graded mesh must recover what the halving changes: its regularised peak and area within 1 %
    of that change from the halved mesh's (the option's purpose, not a measured value), with
    fewer DOFs. (The displacement, which the halving moves by 0.04 % at P2, is left out.)"""
    common = ("--set", "fe.layers_through_thickness=2", "--set", "geometry.width_mm=10.0", "--set", "load.force_n=[0.0, 0.0, 111.0]")
    runs = {name: edem_fe(tmp_path / name, "cylinder-layer", *common, *args) for name, args in (
        ("coarse", ("--mesh-size", "1.0")), ("halved", ("--mesh-size", "0.5")),
        ("graded", ("--mesh-size", "1.0", "--contact-mesh-size", "0.5")))}
    keys = ("regularised_peak_pressure_mpa", "contact_area_on_mobile_mm2")

    def value(run: dict, key: str) -> float:
        return float(np.ravel(run[key])[-1])

    report("graded mesh", **{f"{name}_{key}": value(run, key) for name, run in runs.items() for key in keys},
           dofs=[run["n_dofs"] for run in runs.values()])
    for key in keys:
        change = value(runs["halved"], key) - value(runs["coarse"], key)
        assert abs(change) > 1e-3 * abs(value(runs["halved"], key))  # the halving moves it: the check can fail
        assert abs(value(runs["graded"], key) - value(runs["halved"], key)) <= 0.01 * abs(change)
    assert runs["coarse"]["n_dofs"] < runs["graded"]["n_dofs"] < runs["halved"]["n_dofs"]
    assert runs["graded"]["contact_mesh_size_mm"] == 0.5


def test_a_contact_beyond_the_refined_region_is_warned(tmp_path):
    """The refined region is where the contact can reach at the first pose: within half the 2 mm
    layer (1 mm) of the closest approach. At 333 N the approach is 0.25 mm: the contact stays
    inside, no warning. At 4190 N it is 1.4 mm, past that reach: the run warns at that time
    point, naming both sizes."""
    s = edem_fe(tmp_path / "fe", "cylinder-layer", "--degree", "1", "--mesh-size", "1.0", "--contact-mesh-size", "0.5",
                "--set", "load.time_s=[0.0, 1.0]", "--set", "load.force_n=[[0.0, 0.0, 333.0], [0.0, 0.0, 4190.0]]")
    beyond = [w for w in s["warnings"] if "beyond the region refined to 0.5 mm" in w]
    assert len(beyond) == 1 and "time point 1" in beyond[0] and "time point 0" not in beyond[0] and "the mesh there is 1 mm" in beyond[0]
    _, rows = timeseries(tmp_path / "fe")
    assert rows[0]["disp_z_mm"] < 1.0 < rows[1]["disp_z_mm"]


def test_steps_pick_time_points(tmp_path):
    """Invariant: --steps solves only the chosen time points, each as an independent static
    solve: the rows and .vtp files are those time points, and their answers are the closed form
    of each load (nu = 0: d = (F / A) h / E, proportional to F). The FE settings come from the
    scene's [fe] table."""
    scene = plates_scene(tmp_path, time_s=[0.0, 1.0, 2.0, 3.0],
                         forces=[100.0, 200.0, 300.0, 400.0], nu=0.0,
                         fe='[fe]\nmodel = "slab"\nmesh_size_mm = 2.0\ndegree = 1\n')
    out = tmp_path / "fe"
    s = edem_fe(out, scene, "--steps", "1,3")  # settings from the scene's [fe] table
    assert s["element"] == "P1" and s["mesh_size_mm"] == 2.0 and s["method"] == "fe-slab"
    _, rows = timeseries(out)
    assert [int(r["step"]) for r in rows] == [1, 3]
    assert [r["time_s"] for r in rows] == [1.0, 3.0]
    assert [r["force_z_n"] for r in rows] == [200.0, 400.0]
    assert s["steps"] == 2 and s["time_points"] == [1, 3]
    names = sorted(p.name for p in out.glob("pressure_*.vtp"))
    assert names == ["pressure_0001.vtp", "pressure_0003.vtp"]
    pvd = (out / "pressure.pvd").read_text()
    assert 'timestep="1.0"' in pvd and 'timestep="3.0"' in pvd
    d = [r["disp_z_mm"] for r in rows]
    assert d[1] == pytest.approx(2.0 * d[0], rel=1e-9)
    assert d[1] == pytest.approx(2.0 / E, rel=1e-9)

    out2 = tmp_path / "fe2"
    edem_fe(out2, scene, "--steps", "0:4:2")
    _, rows2 = timeseries(out2)
    assert [int(r["step"]) for r in rows2] == [0, 2]


# --------------------------------------------------------------------------------------------
# free rotations
# --------------------------------------------------------------------------------------------


def test_free_rotations_balance_a_moment_like_the_springs(tmp_path):
    """Invariant and closed form: with rx, ry free, a moment M_x = 500 N mm on the plate
    (eccentricity 1.25 mm, inside the kern: the whole plate stays in contact; nu = 0: each column
    of cartilage is close to an independent spring, E / h per unit area) tilts it by
    theta = M h / (E I),
    I = 20^4 / 12 mm^4, as the DEM springs do (within 2 %: the shear coupling between columns
    of height h = 0.5 mm is small); force and moment balance to 1e-6."""
    scene = plates_scene(tmp_path, gap=0.5, nu=0.0, fixed='["tx", "ty", "rz"]',
                         moment="[500.0, 0.0, 0.0]")
    out = tmp_path / "fe"
    s = edem_fe(out, scene, "--degree", "1", "--mesh-size", "1.0")
    theta = 500.0 * 0.5 / (E * 20.0**4 / 12.0)
    rot = s["final_rotation_rad"]
    _, rows = timeseries(out)
    report("free rotations", rotation=rot, theta=theta, d=s["final_displacement_mm"],
           moment_residual=s["max_moment_residual_nmm"], force_residual=s["max_force_residual_n"])
    assert rot[0] == pytest.approx(theta, rel=0.02)
    assert abs(rot[1]) < 0.01 * theta and rot[2] == 0.0  # the mesh diagonals: not exactly 0
    assert rows[0]["rot_x_rad"] == pytest.approx(rot[0])
    assert s["final_displacement_mm"][2] == pytest.approx(0.5 / E, rel=0.02)
    assert s["max_force_residual_n"] < 1e-6 * 400.0
    assert s["max_moment_residual_nmm"] < 1e-6 * 500.0

    from edem.scene import load_scene
    from edem.solver import run

    dem = run(load_scene(scene), "dem").steps[0]
    assert rot[0] == pytest.approx(dem.rotation_rad[0], rel=0.02)


# --------------------------------------------------------------------------------------------
# the ideal ankle (coarse)
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("model", ["slab", "layer"])
def test_ideal_standing_coarse_runs_and_balances_the_load(tmp_path, model):
    """Invariant: the ideal ankle in standing (333 N) runs on a coarse P1 mesh with both models
    and the contact carries the vertical load (residual < 1e-6 relative); the medio-lateral
    component (the plafond is tilted 2 deg) goes to the fixed tx. Frictionless contact on the
    flat plafond cannot resist ty: the FE fixes it with a warning (no load along it). The slab
    stands on the DEM's candidate springs (463.4 mm^2 of M, all in contact in the DEM): the FE
    contact area mapped onto M is at most that, and above 80 % of it (the thick slab edges lift
    off); on the contact face itself (the columns fan out) it is larger. Layer: t = 1 mm (the
    plafond is 1.01 to 1.99 mm above the dome top): strained beyond 10 %, with a warning."""
    out = tmp_path / model
    # the thesis's ankle (no cartilage, threshold law): the scene's default, two measured layers, has no FE twin yet
    args = ["--model", model, "--degree", "1", "--mesh-size", "1.0", "--set", "geometry.cartilage=false", "--set", "cartilage.law=threshold"]
    if model == "layer":
        args += ["--set", "cartilage.thickness_mm=1.0"]
    s = edem_fe(out, "ideal-standing", *args)
    _, rows = timeseries(out)
    report(f"ideal standing {model}", d=s["final_displacement_mm"], peak=s["peak_pressure_mpa"],
           area=s["max_contact_area_mm2"], n_dofs=s["n_dofs"], wall_s=s["wall_time_s"],
           newton=s["newton_iterations"], warnings=len(s["warnings"]))
    assert s["max_force_residual_n"] < 1e-6 * 333.0
    assert s["final_displacement_mm"][0] == 0.0 and s["final_displacement_mm"][1] == 0.0
    assert s["final_displacement_mm"][2] > 0.0
    assert any("ty" in w and "fixed in the FE" in w for w in s["warnings"])
    assert any("ligament" in w for w in s["warnings"])
    assert rows[0]["mean_pressure_mpa"] * rows[0]["contact_area_mm2"] == pytest.approx(
        333.0 / np.cos(np.radians(2.0)), rel=1e-3)
    f = frame(out)
    assert VTP_ARRAYS <= set(f.point_data) and VTP_ARRAYS <= set(f.cell_data)
    if model == "slab":
        assert 0.8 * 463.4 < s["max_contact_area_on_mobile_mm2"] <= 463.4
        assert s["max_contact_area_mm2"] > s["max_contact_area_on_mobile_mm2"]
        assert np.allclose(f.point_data["gap_mm"], 0.0, atol=1e-9)  # touching F everywhere
        # each contact point's column stands on the talar cylinder (R 20 mm, axis x at z = -20)
        on_m = f.point_data["mobile_point_mm"]
        assert np.allclose(np.hypot(on_m[:, 1], on_m[:, 2] + 20.0), 20.0, rtol=1e-6)
        # columns fan out: the force per area of M exceeds the traction on F
        assert np.all(f.point_data["pressure_on_mobile_mpa"] >= f.point_data["pressure_mpa"])
        # one FE solution, one judged peak: summary.json's regularised peak is the campaigns' (b's
        # force per area of M on M, edem.pressure_metrics); the raw peak on M is the campaigns'
        # b_peak_pressure_mpa, named apart from the contact face's raw peak
        from edem.pressure_metrics import regularised_peak_pressure_mpa
        from edem.resultdir import read_result_dir
        from verification.metrics import series_on_mobile
        assert s["regularised_peak_pressure_mpa"] == regularised_peak_pressure_mpa(
            on_m, f.triangles, f.point_data["pressure_on_mobile_mpa"], at_points=True)
        assert s["peak_pressure_on_mobile_mpa"] == float(series_on_mobile(read_result_dir(out))["peak_pressure_mpa"][0])
        assert s["peak_pressure_on_mobile_mpa"] > s["peak_pressure_mpa"]
    else:
        assert any("nominal strain" in w for w in s["warnings"])


# --------------------------------------------------------------------------------------------
# bad input: exit status 2, one message, no traceback
# --------------------------------------------------------------------------------------------


def test_layer_without_thickness_exits_2(capsys):
    """docs/result-format.md: the layer model needs cartilage.thickness_mm; the message names the key."""
    assert main(["fe", PLATES, "--model", "layer", "--out", "/nonexistent/never"]) == 2
    err = capsys.readouterr().err
    assert "cartilage.thickness_mm" in err and "Traceback" not in err


@pytest.mark.parametrize("model, message, key", [
    ("slab", "does not take measured or per-side cartilage thickness", "geometry.mobile_bone"),
    ("layer", "takes the fixed body rigid", "cartilage.fixed_thickness_mm"),
])
def test_fe_refuses_per_side_layers_it_cannot_model_naming_the_key(capsys, model, message, key):
    """docs/method.md#the-fe-layer-on-measured-thickness: the slab fills the gap whatever the
    layers say, and the layer model bonds M's cartilage to M with F rigid: a layer on F would be
    left out. Both exit 2 naming the key."""
    sets = ["--set", "cartilage.mobile_thickness_mm=1.0", "--set", "cartilage.fixed_thickness_mm=1.0"]
    assert main(["fe", PLATES, "--model", model, "--out", "/nonexistent/never", *sets]) == 2
    err = capsys.readouterr().err
    assert message in err and key in err and "Traceback" not in err


@pytest.mark.parametrize("args, key", [
    (["--steps", "7"], "--steps"),
    (["--steps", "a-b"], "--steps"),
    (["--set", "fe.degree=3"], "fe.degree"),
    (["--set", "fe.model=shell"], "fe.model"),
    (["--set", "fe.element=P2", "--degree", "1"], "--degree"),
    (["--mesh-size", "-1"], "--mesh-size"),
    (["--contact-mesh-size", "-1"], "--contact-mesh-size"),
    (["--contact-mesh-size", "0.5"], "--contact-mesh-size"),  # the slab: every candidate is in contact, nothing to refine
    (["--mesh-size", "1", "--contact-mesh-size", "1"], "--contact-mesh-size"),  # not finer than the mesh
    (["--set", 'fe.time_scheme="rk4"'], "fe.time_scheme"),
    (["--linear-solver", "cholesky"], "--linear-solver"),
    (["--set", 'fe.linear_solver="lu"'], "fe.linear_solver"),
    (["--set", 'fe.material="poroelastic"'], "fe.material"),
    (["--set", 'fe.material="biphasic"'], "biphasic"),  # no [biphasic] table
    (["--set", 'fe.material="biphasic"', "--set", "biphasic.permeability_mm4_per_n_s=-1"], "biphasic.permeability_mm4_per_n_s"),
    (["--set", 'fe.material="biphasic"', "--set", "biphasic.permeability_mm4_per_n_s=1e-3",
      "--set", 'biphasic.counter_surface="sponge"'], "biphasic.counter_surface"),
    (["--set", 'fe.material="biphasic"', "--set", "biphasic.permeability_mm4_per_n_s=1e-3", "--set", 'fe.element="P2"'], "fe.element"),
    (["--set", 'fe.material="biphasic"', "--set", "biphasic.permeability_mm4_per_n_s=1e-3",
      "--set", 'fe.time_scheme="trapezoidal"'], "fe.time_scheme"),
    (["--set", 'fe.material="biphasic"', "--set", "biphasic.permeability_mm4_per_n_s=1e-3", "--model", "lumped"], "fe.material"),
])
def test_bad_fe_input_exits_2(capsys, args, key):
    """docs/result-format.md: bad FE settings exit 2 with a message naming the key; nothing is solved."""
    assert main(["fe", PLATES, "--out", "/nonexistent/never", *args]) == 2
    err = capsys.readouterr().err
    assert key in err and "Traceback" not in err


@pytest.mark.parametrize("depth_over_thickness", [0.5, 2.0])
def test_a_bone_pressed_through_the_cartilage_exits_2(tmp_path, capsys, depth_over_thickness):
    """Closed form at nu = 0: the slab compresses by d = (F / A) h / E. At d = h / 2 the run ends
    (exit 0); at d = 2 h the bone would have gone through the 2 mm slab (a load 1e12 times too
    large gave 7e10 mm and exit 0): exit 2 naming the depth and the thickness."""
    force = depth_over_thickness * E * 400.0  # 20 x 20 mm plates
    rc = main(["fe", PLATES, "--out", str(tmp_path / "fe"), "--degree", "1", "--mesh-size", "2",
               "--set", "cartilage.poissons_ratio=0.0", "--set", f"load.force_n=[0.0, 0.0, {force}]"])
    err = capsys.readouterr().err
    if depth_over_thickness < 1.0:
        assert rc == 0, err
    else:
        assert rc == 2 and "more than its greatest thickness 2 mm" in err and "Traceback" not in err


def test_unresisted_loaded_dof_exits_2(tmp_path, capsys):
    """No equilibrium: frictionless contact with a flat plane cannot carry a load along the
    plane (tx free, load with an x component): exit 2 naming the DOF."""
    scene = plates_scene(tmp_path, fixed='["ty", "rx", "ry", "rz"]')
    rc = main(["fe", scene, "--out", str(tmp_path / "fe"), "--degree", "1", "--mesh-size", "2",
               "--set", "load.force_n=[10.0, 0.0, 400.0]"])
    err = capsys.readouterr().err
    assert rc == 2 and "translation tx" in err and "Traceback" not in err


# --------------------------------------------------------------------------------------------
# MPI
# --------------------------------------------------------------------------------------------


def test_mpirun_two_ranks_writes_the_same_results(tmp_path):
    """Invariant: `mpirun -n 2 edem fe` does not hang, rank 0 alone writes the result directory
    and reports, the numbers equal the 1-rank run (sums across ranks), and bad input exits 2
    once on every rank."""
    exe = Path(sys.executable).with_name("mpiexec")
    mpiexec = str(exe) if exe.exists() else shutil.which("mpiexec")
    edem = Path(sys.executable).with_name("edem")
    if mpiexec is None or not edem.exists():
        pytest.skip("mpiexec or the edem console script not found")
    args = ["--degree", "1", "--mesh-size", "2.0"]
    one = edem_fe(tmp_path / "one", PLATES, *args)
    proc = subprocess.run([mpiexec, "-n", "2", str(edem), "fe", PLATES, *args, "--progress", "--out",
                           str(tmp_path / "two")], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert proc.stdout.count("results:") == 1  # one rank reports
    assert proc.stderr.count("Newton 0:") == 1  # the progress monitors run on both ranks, rank 0 writes
    two = json.loads((tmp_path / "two" / "summary.json").read_text())
    report("mpi", one=one["final_displacement_mm"], two=two["final_displacement_mm"])
    assert two["n_dofs"] == one["n_dofs"]
    assert two["final_displacement_mm"] == pytest.approx(one["final_displacement_mm"], rel=1e-9)
    assert two["peak_pressure_mpa"] == pytest.approx(one["peak_pressure_mpa"], rel=1e-9)
    assert two["max_contact_area_mm2"] == pytest.approx(one["max_contact_area_mm2"], rel=1e-9)
    bad = subprocess.run([mpiexec, "-n", "2", str(edem), "fe", PLATES, "--model", "layer",
                          "--out", str(tmp_path / "bad")], capture_output=True, text=True,
                         timeout=300)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr
    assert bad.stderr.count("cartilage.thickness_mm") == 1


def test_viscoelastic_scene_creeps_and_recovers_as_backward_euler_in_uniaxial_strain(tmp_path):
    """`edem fe` on a scene with [viscoelastic] solves the Kelvin-Voigt continuum: the flat plates
    at nu = 0 are in uniaxial strain, so each backward-Euler step is exact in space and the
    displacement is the scheme's own solution, d_n = d_el (1 - (1 + z)^-n) under the step
    (z = dt / tau) and d_n = d_{n-1} / (1 + z) once unloaded (to round-off and Newton's 1e-10);
    the pressure is F / A at every instant (the dashpots and springs share it, the plate carries
    all of it)."""
    tau, dt = 1.0, 0.5
    times = [0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0]
    forces = [0.0, 400.0, 400.0, 400.0, 400.0, 0.0, 0.0]
    scene = plates_scene(tmp_path, time_s=times, forces=forces, nu=0.0,
                         fe=f'[viscoelastic]\nrelaxation_time_s = {tau}\n[fe]\ntime_scheme = "backward-euler"')
    out = tmp_path / "fe"
    s = edem_fe(out, scene, "--degree", "1", "--mesh-size", "2.0")
    _, rows = timeseries(out)
    d = np.array([r["disp_z_mm"] for r in rows])
    d_el = 400.0 / 400.0 * 2.0 / E
    z = dt / tau
    expected = [0.0] + [d_el * (1 - (1 + z) ** -n) for n in range(1, 5)]
    expected += [expected[-1] / (1 + z), expected[-1] / (1 + z) ** 2]
    report("viscoelastic plates nu=0 (BE)", d=d, expected=expected, peak=[r["peak_pressure_mpa"] for r in rows])
    assert np.allclose(d, expected, rtol=1e-7, atol=1e-12)
    for r, f in zip(rows, forces):
        assert r["peak_pressure_mpa"] == pytest.approx(f / 400.0, rel=1e-7, abs=1e-12)
    assert s["relaxation_time_s"] == tau and s["time_scheme"] == "backward-euler"
    assert not any("viscoelastic" in w and "ignored" in w for w in s["warnings"])


BIPHASIC = '[fe]\nmaterial = "biphasic"\n[biphasic]\npermeability_mm4_per_n_s = 1e-3\n'


def test_biphasic_scene_creeps_to_the_drained_uniaxial_strain(tmp_path):
    """`edem fe` with [fe] material = "biphasic": the flat plates (drained nu = 0, the contact face
    sealed where it touches, the slab's edges drained) under a step from zero, backward Euler on
    steps doubling from 1 s. The first loaded step is a 1 s ramp: the fluid carries most of the
    load (> 50 %; measured 78 %: the bonded 20 mm wide slab bulges at its edges undrained, so its
    matrix shares the load) and the slab has moved less than half its drained approach (measured
    14 %). At 2^20 s (about 100 times the lateral consolidation time a^2 / (E k), a = 10 mm) the
    drained equilibrium is uniaxial strain, d = F h / (E A), exact in space (p = 0, a uniform
    strain): within 1e-5 (measured 1.5e-6, the transient backward Euler leaves). The creep is
    monotone (backward Euler; BDF2 on these doubling steps overshoots the equilibrium by 5.3 %, on
    steps growing by sqrt 2 by 0.9 %: docs/method.md#biphasic-contact). Unloading is refused
    naming load.force_n."""
    times = [0.0] + [2.0 ** k for k in range(21)]
    forces = [0.0] + [400.0] * 21
    scene = plates_scene(tmp_path, time_s=times, forces=forces, nu=0.0, fe=BIPHASIC.replace("[biphasic]", 'time_scheme = "backward-euler"\n[biphasic]'))
    out = tmp_path / "fe"
    s = edem_fe(out, scene, "--mesh-size", "2.0")
    _, rows = timeseries(out)
    d = np.array([r["disp_z_mm"] for r in rows])
    d_drained = 400.0 / 400.0 * 2.0 / E
    report("biphasic plates nu=0 (BE)", d=d, d_drained=d_drained, fluid=s["fluid_load_fraction"][:3])
    assert s["material"] == "biphasic" and s["element"] == "TH" and s["counter_surface"] == "impermeable"
    assert s["time_scheme"] == "backward-euler"
    assert s["fluid_load_fraction"][0] == 0.0 and s["fluid_load_fraction"][1] > 0.5
    assert d[1] < 0.5 * d_drained
    assert d[-1] == pytest.approx(d_drained, rel=1e-5)
    assert np.all(np.diff(d) > -1e-9 * d_drained)
    unload = plates_scene(tmp_path, time_s=[0.0, 1.0, 2.0], forces=[0.0, 400.0, 0.0], nu=0.0, fe=BIPHASIC)
    assert main(["fe", unload, "--out", str(tmp_path / "unload"), "--mesh-size", "2.0"]) == 2
