"""The campaign runner: parallel run, cache keyed by the inputs (instant re-run), metrics.json,
verdicts and exit status, FE sides reported unavailable (never faked), and the Dask path."""

from __future__ import annotations

import concurrent.futures
import json
import os
import shutil
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest

import verification.runner as runner
import verification.sides as sides
from edem.atomic_dirs import manifest_problems, write_manifest
from edem.cli import main
from geometries.extras import EXTRA_OF_MODULE
from verification.campaigns import SCENES_DIR, Campaign, Case, Expect, get_campaign
from verification.metrics import COMPARISON_METRICS
from verification.runner import case_key, run_campaign
from verification.verdicts import CLOSED_FORM, MODEL_BAND, Basis

EXACT = {m: Basis(CLOSED_FORM, "test: exact") for m in COMPARISON_METRICS}
BAND = {m: Basis(MODEL_BAND, "test: a declared band") for m in COMPARISON_METRICS}


def tiny_campaign(**changes) -> Campaign:
    """Two tiny cases: DEM plates against p = F/A, and a load pulling the plates apart (refused)."""
    quick = get_campaign("quick")
    plates = quick.case("flat-plates-dem")
    pull = quick.case("pull-apart")
    for name, value in changes.items():
        plates = Case(**{**plates.__dict__, name: value})
    return Campaign("tiny", "two tiny cases", (plates, pull))


def file_mtimes(root: Path) -> dict[str, int]:
    return {str(p.relative_to(root)): p.stat().st_mtime_ns for p in root.rglob("*") if p.is_file() and p.suffix in (".vtp", ".csv", ".pvd")}


def test_campaign_end_to_end_then_cache_hit(tmp_path):
    out = tmp_path / "tiny"
    first = run_campaign(tiny_campaign(), out, jobs=2, report=False)
    assert first["computed"] == 2 and first["exit_status"] == 0
    assert first["counts"]["verified"] == 1 and first["counts"]["refused as declared"] == 1 and first["outcomes"] == {"converges": 1, "refused": 1}

    data = json.loads((out / "metrics.json").read_text())
    plates = next(r for r in data["cases"] if r["name"] == "flat-plates-dem")
    assert set(plates["metrics"]) == set(COMPARISON_METRICS)
    assert all(v["verdict"] == "met" and v["tolerance"] == 1e-9 and v["kind"] == "closed-form" and v["reason"] for v in plates["verdicts"].values())
    assert plates["wall_time_s"] > 0 and [s["side"] for s in plates["sides"]] == ["dem", "closed-form:flat-plates"]
    for rel in plates["result_dirs"]:
        assert (out / rel / "pressure.pvd").is_file() and (out / rel / "summary.json").is_file()
    case_json = json.loads((out / "cases" / "flat-plates-dem" / "metrics.json").read_text())
    assert case_json["key"] == case_key(tiny_campaign().cases[0])
    assert case_json["status"] == "verified" and case_json["verdicts"]["displacement_rel_error"]["verdict"] == "met"
    pull = next(r for r in data["cases"] if r["name"] == "pull-apart")
    assert pull["outcome"] == "refused" and "no equilibrium" in pull["sides"][0]["message"]

    before = file_mtimes(out / "cases")
    seen = []
    start = time.perf_counter()
    second = run_campaign(tiny_campaign(), out, jobs=2, report=False, on_case=lambda name, cached: seen.append(cached))
    assert time.perf_counter() - start < 2.0
    assert second["computed"] == 0 and second["cached"] == 2 and seen == [True, True]
    assert file_mtimes(out / "cases") == before  # nothing rewritten
    assert [r["metrics"] for r in second["cases"]] == [r["metrics"] for r in first["cases"]]
    # a cached case keeps the wall time of the run that computed it (not the re-read's)
    assert [r["wall_time_s"] for r in second["cases"]] == [r["wall_time_s"] for r in first["cases"]]
    assert second["cases_wall_time_s"] == first["cases_wall_time_s"] and all(r["cached"] for r in second["cases"])


def test_cache_counts_executions_and_tolerance_changes_need_no_rerun(tmp_path, monkeypatch):
    calls = []
    real = runner.execute_case

    def counting(case, *args):
        calls.append(case.name)
        return real(case, *args)

    monkeypatch.setattr(runner, "execute_case", counting)
    out = tmp_path / "tiny"
    run_campaign(tiny_campaign(), out, jobs=1, report=False)
    assert sorted(calls) == ["flat-plates-dem", "pull-apart"]
    calls.clear()
    strict = tiny_campaign(tolerance={**{m: 1e-9 for m in COMPARISON_METRICS}, "displacement_rel_error": 0.0, "pressure_l2_rel_error": -1.0})
    judged = run_campaign(strict, out, jobs=1, report=False)
    assert calls == []  # the tolerance is judged, not hashed
    row = next(r for r in judged["cases"] if r["name"] == "flat-plates-dem")
    assert row["status"] == "failed" and judged["exit_status"] == 1
    assert row["verdicts"]["pressure_l2_rel_error"]["verdict"] == "fail"
    assert "pressure_l2_rel_error" in runner.format_summary(judged)
    rerun = run_campaign(tiny_campaign(overrides={"load.force_n": [0.0, 0.0, 200.0]}), out, jobs=1, report=False)
    assert calls == ["flat-plates-dem"] and rerun["exit_status"] == 0


def test_case_key_follows_scene_file_and_mesh_contents(tmp_path):
    from geometries.mesh_files import write_surface
    from support import grid_plate, plane

    write_surface(tmp_path / "talus.stl", grid_plate(10, 10, 4))
    write_surface(tmp_path / "tibia.stl", plane(lambda x, y: 2.0, size_mm=20.0))
    scene = tmp_path / "mesh.toml"
    scene.write_text(
        '[geometry]\nmobile = "talus.stl"\nfixed = "tibia.stl"\n[cartilage]\nyoungs_modulus_mpa = 10.0\npoissons_ratio = 0.4\n'
        '[load]\nforce_n = [0.0, 0.0, 10.0]\n[constraints]\nfixed_dofs = ["tx", "ty", "rx", "ry", "rz"]\n',
        encoding="utf-8",
    )
    case = Case("mesh", "mesh files", str(scene), ("dem",), ("non_finite_outputs",))
    key = case_key(case)
    assert case_key(case) == key
    write_surface(tmp_path / "tibia.stl", plane(lambda x, y: 2.5, size_mm=20.0))
    key_mesh = case_key(case)
    assert key_mesh != key
    scene.write_text(scene.read_text().replace("10.0]", "11.0]"), encoding="utf-8")
    assert case_key(case) != key_mesh
    assert case_key(Case("mesh", "mesh files", str(scene), ("edem",), ("non_finite_outputs",))) != case_key(case)


def test_source_digest_covers_the_solver_package():
    digest = runner._source_digest(("edem",))
    assert len(digest) == 64 and digest != runner._source_digest(("geometries",))


def test_fe_side_is_reported_unavailable_not_faked(tmp_path, monkeypatch):
    monkeypatch.setattr(sides, "fe_availability", lambda *entry_point: "FE reference not available: test")
    fe_case = Case("vs-fe", "DEM against the FE slab", "flat-plates.toml", ("dem", "fe-slab"), COMPARISON_METRICS, {m: 0.1 for m in COMPARISON_METRICS}, basis=BAND)
    summary = run_campaign(Campaign("fe", "FE", (fe_case,)), tmp_path / "fe", jobs=1, report=False)
    row = summary["cases"][0]
    assert row["status"] == "unavailable" and summary["exit_status"] == 0
    assert row["sides"][1]["message"] == "FE reference not available: test" and row["metrics"] == {}
    assert "FE reference not available" in runner.format_summary(summary)
    again = run_campaign(Campaign("fe", "FE", (fe_case,)), tmp_path / "fe", jobs=1, report=False)
    assert again["computed"] == 1  # unavailable outcomes are not cached


def test_fe_availability_needs_run_scene(monkeypatch):
    import importlib.util

    import fem_reference

    if importlib.util.find_spec("dolfinx") is None:
        assert "dolfinx" in sides.fe_availability()
        return
    monkeypatch.delattr(fem_reference, "run_scene", raising=False)
    assert "fem_reference.run_scene" in sides.fe_availability()


def test_a_model_added_to_the_fe_registry_is_a_side_and_the_registry_needs_no_fe_extra(tmp_path):
    """The ``fe-<model>`` sides are built from fem_reference.models.FE_MODELS: a model registered
    there (a stand-in subclass, before verification.sides is imported) is a side with no edit to
    verification.sides. On the core install (every extra blocked, as tests/geometries/test_extras.py
    does) the registry and the sides import without dolfinx or gmsh, and the new side is reported
    unavailable, naming dolfinx, instead of failing."""
    code = (
        f"import json, sys; sys.modules.update(dict.fromkeys({sorted(EXTRA_OF_MODULE)!r}))\n"
        "from fem_reference.models import FE_MODELS, LayerModel\n"
        "class StandInModel(LayerModel):\n"
        "    name = 'stand-in'\n"
        "FE_MODELS['stand-in'] = StandInModel()\n"
        "import verification.sides as sides\n"
        "outcome = sides.run_side('fe-stand-in', 'flat-plates.toml', {}, 'out')\n"
        "print(json.dumps({'fe_model_sides': [s for s in sides.SIDES if s.removeprefix('fe-') in FE_MODELS],\n"
        "                  'status': outcome.status, 'message': outcome.message}))\n"
    )
    root = Path(__file__).resolve().parents[2]
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env={**os.environ, "PYTHONPATH": str(root)},
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]  # an import of a blocked extra is an ImportError here
    out = json.loads(done.stdout.splitlines()[-1])
    assert out["fe_model_sides"][-1] == "fe-stand-in" and {"fe-slab", "fe-layer"} <= set(out["fe_model_sides"])
    assert out["status"] == "unavailable" and "dolfinx" in out["message"]


def test_fe_side_calls_run_scene_and_compares_nodal_pressure(tmp_path, monkeypatch):
    """The FE plumbing with a stand-in for fem_reference.run_scene (a test double: it writes the
    FE layout, nodal pressure F/A on a surface 2 mm above the plate) and the metrics read it."""
    import fem_reference

    from edem.resultdir import write_surface_frame
    from edem.results import write_pvd

    calls = {}

    def stand_in(scene, model, out_dir, mesh_size_mm=None, degree=None, layers_through_thickness=None, provenance=None):
        calls.update(model=model, mesh_size_mm=mesh_size_mm, degree=degree, layers=layers_through_thickness,
                     recorded=tomllib.loads(provenance.scene_toml)["fe"])
        src = Path(tmp_path / "dem-copy")
        shutil.copytree(src, out_dir)
        points = scene.mobile.vertices_mm + np.array([0.0, 0.0, 2.0])
        p = np.full(len(points), 1.0)
        write_surface_frame(Path(out_dir) / "pressure_0000.vtp", points, scene.mobile.triangles, {"pressure_mpa": p}, {"pressure_mpa": np.full(scene.mobile.n_triangles, 5.0)})
        write_pvd(Path(out_dir) / "pressure.pvd", [(0.0, "pressure_0000.vtp")])
        write_manifest(out_dir)  # a stand-in FE writer seals its directory like the real one

    from edem.results import write_results
    from edem.scene import load_scene
    from edem.solver import run

    write_results(run(load_scene(SCENES_DIR / "flat-plates.toml"), "dem"), tmp_path / "dem-copy")
    monkeypatch.setattr(fem_reference, "run_scene", stand_in, raising=False)
    monkeypatch.setattr(sides, "fe_availability", lambda: None)
    case = Case("vs-fe", "DEM against FE", "flat-plates.toml", ("dem", "fe-layer"), COMPARISON_METRICS, {m: 1e-9 for m in COMPARISON_METRICS}, options={"mesh_size_mm": 0.5, "degree": 2, "layers_through_thickness": 3}, basis=EXACT)
    summary = run_campaign(Campaign("fe", "FE", (case,)), tmp_path / "fe", jobs=1, report=False)
    settings = {"mesh_size_mm": 0.5, "degree": 2}
    assert calls == {"model": "layer", **settings, "layers": 3, "recorded": {"model": "layer", **settings, "layers_through_thickness": 3}}
    row = summary["cases"][0]
    assert row["status"] == "verified", row["verdicts"]
    assert row["metrics"]["pressure_l2_rel_error"] < 1e-12  # point data (1 MPa) used, not the cells (5 MPa)


def _fe_stand_in(tmp_path, monkeypatch, calls: list) -> None:
    """fem_reference.run_scene replaced by a stand-in (a test double: DEM's result directory,
    sealed like the real FE's) that records what each call received."""
    import fem_reference

    from edem.results import write_results
    from edem.scene import load_scene
    from edem.solver import run

    def stand_in(scene, model, out_dir, mesh_size_mm=None, degree=None, provenance=None):
        calls.append({"model": model, "mesh_size_mm": mesh_size_mm, "coupling": scene.cartilage.coupling, "overrides": provenance.summary_keys["overrides"]})
        write_results(run(scene, "dem"), out_dir)

    monkeypatch.setattr(fem_reference, "run_scene", stand_in, raising=False)
    monkeypatch.setattr(sides, "fe_availability", lambda: None)


def test_cases_giving_the_fe_the_same_inputs_share_one_fe_run(tmp_path, monkeypatch):
    calls = []
    _fe_stand_in(tmp_path, monkeypatch, calls)
    sanity = {m: 10.0 for m in COMPARISON_METRICS}
    basis = {m: Basis(MODEL_BAND, "test") for m in COMPARISON_METRICS}

    def case(name, overrides, options=None):
        return Case(name, "DEM vs FE", "flat-plates.toml", ("dem", "fe-layer"), COMPARISON_METRICS, sanity, overrides=overrides,
                    options=options or {"mesh_size_mm": 1.0}, basis=basis)

    springs = case("springs", {"cartilage.poissons_ratio": 0.49})
    coupled = case("coupled", {"cartilage.poissons_ratio": 0.49, "cartilage.coupling": "thin-layer"})
    assert runner.side_key(springs, 1) == runner.side_key(coupled, 1) and runner.side_key(springs, 0) is None
    assert runner.case_key(springs) != runner.case_key(coupled)
    out = tmp_path / "share"
    first = run_campaign(Campaign("share", "", (springs, coupled)), out, jobs=1, report=False)
    # one FE run, without the key only the discrete bed reads
    assert len(calls) == 1 and calls[0]["coupling"] == "none" and calls[0]["overrides"] == {"cartilage.poissons_ratio": 0.49}
    rows = {r["name"]: r for r in first["cases"]}
    fe = [rows[n]["sides"][1] for n in ("springs", "coupled")]
    assert fe[0]["shared"] == fe[1]["shared"] and [f["reused"] for f in fe] == [False, True]
    assert fe[0]["wall_time_s"] == fe[1]["wall_time_s"]  # the run's own cost, not the copy's
    for name in rows:  # each case holds its own copy, verifying by its manifest
        assert not manifest_problems(out / "cases" / name / rows[name]["sides"][1]["result_dir"])

    # an FE input that differs (the load; an FE option) runs the FE again, once each
    calls.clear()
    loaded = case("loaded", {"cartilage.poissons_ratio": 0.49, "load.force_n": [0.0, 0.0, 800.0]})
    finer = case("finer", {"cartilage.poissons_ratio": 0.49}, {"mesh_size_mm": 0.5})
    frames = case("frames", {"cartilage.poissons_ratio": 0.49}, {"mesh_size_mm": 1.0, "frames": "peak"})  # a DEM-only option
    run_campaign(Campaign("share", "", (springs, coupled, loaded, finer, frames)), out, jobs=1, report=False)
    assert sorted((c["mesh_size_mm"], c["overrides"].get("load.force_n", [0, 0, 0])[2]) for c in calls) == [(0.5, 0), (1.0, 800.0)]

    # the store outlives the cases: a case run again finds its FE there; a damaged entry runs again
    calls.clear()
    shutil.rmtree(out / "cases" / "springs")
    run_campaign(Campaign("share", "", (springs, coupled)), out, jobs=1, report=False)
    assert calls == []
    entry = out / "sides" / fe[0]["shared"] / "result"
    with open(entry / "summary.json", "a", encoding="utf-8") as f:
        f.write(" ")
    shutil.rmtree(out / "cases" / "springs")
    run_campaign(Campaign("share", "", (springs, coupled)), out, jobs=1, report=False)
    assert len(calls) == 1 and not manifest_problems(entry)


def test_two_workers_wanting_one_fe_run_compute_it_once(tmp_path, monkeypatch):
    """Two cases with the same FE side key executed at the same time (threads: each opens the
    entry's lock file itself, so the flock excludes them as it does two worker processes): one
    computes the entry, the other waits and copies it."""
    from edem.results import write_results
    from edem.scene import load_scene
    from edem.solver import run

    calls = []

    def slow_fe(scene_ref, overrides, out_dir, options):
        calls.append(scene_ref)
        time.sleep(0.5)  # long enough for the other thread to reach the lock
        write_results(run(load_scene(scene_ref, overrides), "dem"), out_dir)

    slow_fe.shared = True
    monkeypatch.setitem(sides.SIDES, "fe-layer", slow_fe)
    base = dict(scene="flat-plates.toml", sides=("dem", "fe-layer"), metrics=COMPARISON_METRICS, overrides={})
    cases = [Case(name, "", **base) for name in ("one", "two")]
    out = tmp_path / "race"
    todo = [(c, out / "cases" / c.name, runner.case_key(c), tuple(runner.side_key(c, i) for i in range(2))) for c in cases]
    assert todo[0][3] == todo[1][3] and todo[0][3][1] is not None
    with concurrent.futures.ThreadPoolExecutor(2) as pool:
        records = list(pool.map(lambda t: runner.execute_case(t[0], str(t[1]), t[2], t[3]), todo))
    assert len(calls) == 1 and sorted(r["sides"][1]["reused"] for r in records) == [False, True]
    assert all(r["sides"][1]["status"] == "ok" for r in records)


def test_a_crashing_side_is_an_error_with_exit_status_1(tmp_path, monkeypatch):
    def broken(*args):
        raise RuntimeError("boom")

    monkeypatch.setitem(sides.SIDES, "dem", broken)
    summary = run_campaign(tiny_campaign(), tmp_path / "crash", jobs=1, report=False)
    assert summary["counts"]["error"] == 2 and summary["exit_status"] == 1
    assert "boom" in summary["cases"][0]["sides"][0]["message"]
    assert "crashed" in runner.format_summary(summary)


def test_cli_verify_exit_status_follows_the_verdicts(tmp_path, monkeypatch, capsys):
    tiny, failing = tiny_campaign(), tiny_campaign(tolerance={m: -1.0 for m in COMPARISON_METRICS})
    monkeypatch.setattr("verification.campaigns.campaigns", lambda: {"tiny": tiny, "tiny-failing": failing})
    assert main(["verify", "tiny", "--out", str(tmp_path / "ok"), "--jobs", "1"]) == 0
    out = capsys.readouterr().out
    assert "1 verified, 1 refused as declared" in out and f"report: {tmp_path / 'ok' / 'report.html'}" in out
    assert main(["verify", "tiny-failing", "--out", str(tmp_path / "bad"), "--jobs", "1"]) == 1
    out = capsys.readouterr().out
    assert "flat-plates-dem" in out and "peak_pressure_rel_error" in out
    assert main(["verify", "tiny", "--out", str(tmp_path / "ok"), "--jobs", "0"]) == 2


def test_cli_compare_prints_the_table_and_writes_metrics_json(tmp_path, capsys):
    from edem.results import write_results
    from edem.scene import load_scene
    from edem.solver import run
    from verification.closed_forms import solve_closed_form, write_closed_form_results

    scene, solution = solve_closed_form("tilted-plane", str(SCENES_DIR / "tilted-plane.toml"))
    a = write_results(run(scene, "dem"), tmp_path / "dem")
    b = write_closed_form_results(scene, solution, tmp_path / "cf")
    assert main(["compare", str(a), str(b), "--out", str(tmp_path / "cmp")]) == 0
    out = capsys.readouterr().out
    assert "regularised peak (MPa)" in out and "raw peak (MPa)" in out and "pressure field (L2)" in out
    data = json.loads((tmp_path / "cmp" / "metrics.json").read_text())
    assert set(data["metrics"]) == set(COMPARISON_METRICS) and abs(data["metrics"]["displacement_rel_error"]) < 1e-3
    assert main(["compare", str(tmp_path / "nothing"), str(b)]) == 2


def test_dask_scheduler_runs_the_cases(tmp_path):
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=1, processes=False, threads_per_worker=2, dashboard_address=None) as cluster:
        summary = run_campaign(tiny_campaign(), tmp_path / "dask", scheduler=cluster.scheduler_address, report=False)
    assert summary["computed"] == 2 and summary["exit_status"] == 0 and summary["scheduler"] == cluster.scheduler_address
    assert all(Path(tmp_path / "dask" / rel / "summary.json").is_file() for r in summary["cases"] for rel in r["result_dirs"])
    cached = run_campaign(tiny_campaign(), tmp_path / "dask", jobs=1, report=False)
    assert cached["cached"] == 2  # the same cache, whoever computed it


def test_dask_with_worker_processes(tmp_path):
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=1, processes=True, threads_per_worker=1, dashboard_address=None) as cluster:
        summary = run_campaign(tiny_campaign(), tmp_path / "dask", scheduler=cluster.scheduler_address, report=False)
    assert summary["computed"] == 2 and summary["exit_status"] == 0


def test_dask_workers_run_cases_on_one_blas_thread(tmp_path, monkeypatch):
    """A worker whose environment does not set OPENBLAS_NUM_THREADS (Dask's nanny sets it only
    by its default pre-spawn-environ) loads numpy with one BLAS thread per core; the campaign
    leaves it one, as edem.cli.main does for its own processes."""
    import dask

    distributed = pytest.importorskip("dask.distributed")
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"):  # an earlier nanny in this process may have set them
        monkeypatch.delenv(name, raising=False)
    with dask.config.set({"distributed.nanny.pre-spawn-environ": {}}):
        with distributed.LocalCluster(n_workers=1, processes=True, threads_per_worker=1, dashboard_address=None) as cluster, distributed.Client(cluster) as client:
            before = client.run(_blas_threads)
            summary = run_campaign(tiny_campaign(), tmp_path / "dask", scheduler=cluster.scheduler_address, report=False)
            after = client.run(_blas_threads)
    assert summary["computed"] == 2 and summary["exit_status"] == 0
    if list(before.values()) == [1]:
        pytest.skip("this machine's BLAS starts with one thread: nothing to limit")
    assert list(after.values()) == [1]


def _blas_threads() -> int:
    import numpy  # noqa: F401  (its BLAS loaded, as a campaign's first case loads it)
    from threadpoolctl import threadpool_info

    return max((p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"), default=0)


def test_declared_outcomes_are_checked_not_assumed(tmp_path):
    """A case that converges but was declared refused, a refusal with another message and a run
    without the declared warning each fail on outcome_mismatch."""
    checks = ("outcome_mismatch", "non_finite_outputs")
    tol = {"outcome_mismatch": 0.0}
    cases = (
        Case("wrongly-refused", "", "flat-plates.toml", ("dem",), checks, tol, expect=Expect("refused", "anything")),
        Case("wrong-message", "", "flat-plates.toml", ("dem",), checks, tol, {"load.force_n": [0.0, 0.0, -1.0]}, Expect("refused", "singular")),
        Case("missing-warning", "", "flat-plates.toml", ("dem",), checks, tol, expect=Expect("converges", warning="compressed past")),
        Case("right", "", "flat-plates.toml", ("dem",), checks, tol, {"load.force_n": [0.0, 0.0, -1.0]}, Expect("refused", "no equilibrium")),
    )
    summary = run_campaign(Campaign("outcomes", "", cases), tmp_path / "o", jobs=1, report=False)
    status = {r["name"]: (r["status"], r["metrics"]["outcome_mismatch"]) for r in summary["cases"]}
    assert status == {
        "wrongly-refused": ("failed", 1.0),
        "wrong-message": ("failed", 1.0),
        "missing-warning": ("failed", 1.0),
        "right": ("refused as declared", 0.0),
    }


def test_the_terminal_summary_opens_with_the_ankle_answer_before_any_flagged_metric():
    """`make demo` prints the trust analysis's sentences first, then the counts and the flagged metrics."""
    from verification.runner import format_summary
    from verification.verdicts import count_verdicts

    flagged = {"name": "slab-F333-nu0.42", "status": "flagged", "verdicts": {"contact_area_rel_error": {"verdict": "outside band", "value": 0.3, "tolerance": 0.25}},
               "sides": []}
    answer = {"name": "trust", "title": "Can I trust it for my ankle?", "kind": "trust", "status": "reported", "columns": [], "rows": [],
              "values": {"sentences": ["The default bed " + "agrees " * 30 + "at every load.", "Goal reached."]}}
    summary = {"campaign": "quick", "cases": [flagged], "counts": count_verdicts(["flagged"]), "outcomes": {"converges": 1, "refused": 0},
               "computed": 1, "cached": 0, "wall_time_s": 1.0, "analyses": [answer]}
    lines = format_summary(summary).splitlines()
    assert lines[0] == "Can I trust it for my ankle? [reported]"
    assert lines[1].startswith("- The default bed") and all(len(line) <= 110 for line in lines[:4])
    first_count = next(k for k, line in enumerate(lines) if line.startswith("quick: 1 cases"))
    assert any(line.startswith("- Goal reached.") for line in lines[:first_count])
    assert first_count < next(k for k, line in enumerate(lines) if "slab-F333-nu0.42" in line)
