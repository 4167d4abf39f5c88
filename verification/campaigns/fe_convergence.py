"""``fe-convergence``: the own mesh-convergence error of every FE reference a verdict rests on.

Every FE run the ``quick`` campaign's trust section compares against (the cartilage ankles'
two-layer FE, the threshold law's slab on the ideal ankle, the bonded cylinder layer over
thickness and at 100 N), then every other FE reference of ``quick``, ``subject``, ``cylinder-plane``,
``thin-layer``, ``two-layers``, ``ankles`` and ``viscoelastic`` (:func:`reference_points`: loads,
Poisson's ratios 0 and 0.499, layer thicknesses, toe-off, the viscoelastic step, the Kelvin-Voigt
histories the viscoelastic goal judges), each on three meshes of the FE's own mesher
(:func:`point_levels`: ``mesh_size_mm`` 2.0, 1.0 and 0.7 mm, P2 or Taylor-Hood; the 1 mm layer
on 1.0, 0.7 and 0.7 mm with 4 elements through it; quick's viscoelastic slab in its own P1; the
Kelvin-Voigt histories on :data:`VISCOELASTIC_LEVELS`; the two-layer cylinder on four,
:data:`TWO_LAYER_CYLINDER_LEVELS`, each mesh's error from the finest three that contain it),
plus the P1 run ``quick`` uses at 1.0 mm where P1 does not lock. Every reference is one of its
point's meshes (the campaigns use the 1.0 mm level, ``thin-layer``'s base sweep the 0.7 mm one).
The analysis gives, per point and quantity, the three values, the observed order, the Richardson
extrapolation and each mesh's estimated error (verification.fe_convergence), with each mesh's
DOFs, wall time and peak memory. ``edem verify fe-convergence --refresh-reference`` stores the
estimates in ``verification/references/fe_convergence.json``, where the other campaigns' FE
references find their errors (:func:`verification.fe_convergence.fe_relative_error`).

The mesher refines M's triangles by midpoint subdivision (powers of 2 in plane) and sets the
layers through the thickness to ceil(thickness / size): the three meshes are not one uniform
refinement, so each is represented by its DOFs (h ~ N^(-1/3), the usual representative size;
N^(-1/2) for three meshes of one number of elements through the layers, refined in plane only)
and the order is solved for the unequal ratios.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

from verification.analyses import run_analysis
from verification.campaign_model import Analysis, Campaign, Case
from verification.fe_comparison import FE_TABLE_COLUMNS, fe_comparison_case
from verification.fe_convergence import FE_VALUE_METRICS, fe_values
from verification.verdicts import INVARIANT, Basis

#: the mesh sizes of the study (mm), coarsest first; today's references are the 1.0 mm level. The
#: finest is 0.7 mm: M's triangles halved, 5 layers on the ankles (268k-419k DOFs, 5-8 min and
#: 4-8 GB each by LU); 0.5 mm (438k-579k DOFs) took the campaign past two hours on 2 shared cores
LEVELS_MM = (2.0, 1.0, 0.7)
#: the finest solves first, the points quick's ankle answer rests on ahead (the cartilage ankles' two-layer FE), then the threshold law's row and the base layer
PRIORITY = ("ideal-cartilage-nu0.42", "subject-cartilage-nu0.42", "slab-F333-nu0.42", "layer-F333-nu0.42-t2")
#: wall time with 2 jobs on 2 cores, nothing cached: an estimate from the measured cases (docs/campaigns.md):
#: quick's twelve points about 75 min (twelve 0.7 mm solves of about 8 min on a quiet core over two
#: jobs, plus 28 meshes of 2.0 and 1.0 mm); the 30 points added on 2026-11-26 took 2 h 10 min on two
#: processes at load 2-4, the six left then (Taylor-Hood and subject-like 0.7 mm solves) about 20-40
#: min each; at load 9-14 a 0.7 mm solve took over 40 min. The two-layer ankles (three loads a run) by the
#: Krylov path, one job at load 4-5 (2026-11-28): the ideal ankle at nu 0.42 190 / 260 / 1368 s (2.0 / 1.0 /
#: 0.7 mm; about 100 / 140 / 690 s of CPU; 0.7 / 0.9 / 3.2 GB), the subject-like one 121 / 184 / 1133 s (0.7 mm: 662k
#: DOFs, 3.0 GB); the ideal ankle at nu 0.49 (Taylor-Hood) 211 / 229 / 1456 s (0.7 mm: 753k DOFs, 4.7 GB)
#: The stored study (2026-11-28, 62 points): the 20 points estimated that day by the Krylov path took 5.1 h of wall
#: time, one solve at a time at load 2-5 (the two-layer cylinder's eight 0.35 mm solves 5-9 min and 7-10 GB each, so
#: never two at once); the 42 older points 10.6 h by LU at load 2-14, which the Krylov path takes in about a half to a
#: third of that at their sizes: about 9 h, two jobs gaining little where memory allows only one. The cylinder layer's
#: six Kelvin-Voigt histories on M's triangles quartered (2026-11-28 night): 847-1871 s each, 2.6 GB, 2-4 jobs on 2 cores.
EXPECTED_TIME_S = 37400.0
#: what the study found on the subject-like ankle (issue 24, item 3), measured 2026-11-26 (docs/campaigns.md)
FINDINGS = (
    "Subject-like ankle (issue 24, item 3): the FE's raw peak at 1.0 mm is not converged: refining in plane lowers it 22 % (1.913 -> 1.499 MPa; "
    "Richardson: 1.0 mm is 39 % above the extrapolated 1.37 MPa). It is one node at the rim of the slab's hole under the smaller plafond depression "
    "(peak / p98 = 1.92; 1.05 on the ideal ankle). Halving the springs leaves the beds' peaks unchanged (0.756 MPa): not a spring-size effect. "
    "On the p98 (converging, 5.9 % at 1.0 mm) the beds are 14-22 % low and the threshold law's area 15 % too large (every candidate loaded, where the "
    "FE lets the thickest columns unload): a model error of the law that no coupled bed removes. The raw peak is not a metric this geometry can judge a bed on.",
)
#: the beds compared with the finest FE on the subject-like ankle and the ideal ankle (issue 24, item 3):
#: (suffix, overrides, what); they reuse the finest level's FE run
BEDS = (("dem", {}, "independent springs"), ("dem-pade", {"cartilage.coupling": "thin-layer"}, "coupled thin layer, Pade"),
        ("dem-two-pole", {"cartilage.coupling": "thin-layer", "cartilage.thin_layer_symbol": "two-pole"}, "coupled thin layer, two-pole"))
BED_POINTS = ("subject-standing", "slab-F333-nu0.42")
CHECK = {"force_residual_rel": 1e-6}
CHECK_BASIS = {"force_residual_rel": Basis(INVARIANT, "the FE solve balances the load to 1e-6 (fem_reference's force-balance check)")}


#: the levels of a layer no thicker than this (mm): at 2.0 and 1.0 mm its mesh is the same (one
#: element through it, M's own triangles), so the study takes 1.0 mm, 0.7 mm (triangles halved, 2
#: elements through it) and 0.7 mm with 4 elements through it; the last step refines only through
#: the layer, so the estimate mostly falls back to the largest difference between the meshes
THIN_LAYER_MM = 1.0
SCENE_TWO_LAYER_CYLINDER = "cylinder-two-layers"
THIN_LAYER_LEVELS = ({"mesh_size_mm": 1.0, "degree": 2}, {"mesh_size_mm": 0.7, "degree": 2}, {"mesh_size_mm": 0.7, "degree": 2, "layers_through_thickness": 4})


#: the levels of the two-layer cylinder (scene cylinder-two-layers, layers of 0.5-1.5 mm): M's own
#: 0.94 mm triangles with one and with two element layers in each cartilage layer, then the
#: triangles halved (0.47 mm) and halved again (0.24 mm) with two; the campaign (two-layers) uses
#: the third, 0.7 mm with two, so its error comes from the finest three, a uniform in-plane
#: refinement (verification.fe_convergence.level_estimates), and the first three alone, where one
#: step refines through the layers and one in plane, estimated it only as their largest difference.
#: P2: 64k, 107k, 419k, 1.66M DOFs, the finest 4.5-8 min and 7.1-7.2 GB by the Krylov path;
#: Taylor-Hood: 68k, 112k, 441k, 1.75M, the finest 8-9 min and 9.9-10.1 GB (load 2-4, 2026-11-28)
TWO_LAYER_CYLINDER_LEVELS = ({"mesh_size_mm": 1.0, "degree": 2, "layers_through_thickness": 1},
                             {"mesh_size_mm": 1.0, "degree": 2, "layers_through_thickness": 2},
                             {"mesh_size_mm": 0.7, "degree": 2, "layers_through_thickness": 2},
                             {"mesh_size_mm": 0.35, "degree": 2, "layers_through_thickness": 2})


#: the levels of a Kelvin-Voigt layer's history (the viscoelastic campaign's goal), every time point,
#: by FE side. The cylinder layer (fe-layer, 2 mm): M's own 0.97 mm triangles, halved (0.7 mm) and
#: quartered (0.35 mm), each with 2 P2 elements through it (53k / 210k / 832k DOFs): a uniform
#: in-plane refinement, what moves the early creep (the regularised peak at tau/2 by 11-13 % per
#: halving, order about 1: the patch's edge advancing into the layer; 4 elements through it instead
#: of 2 moved it by 1-1.5 %, not in these errors: docs/campaigns.md); the campaign uses the finest.
#: The cartilage ankle (fe-two-layer): the elastic ankles' levels
#: (:data:`LEVELS_MM`: M's own triangles with one and two elements through each layer, then the triangles
#: halved), the campaign on the finest: on M's own triangles the talus slid 9.3 um antero-posteriorly at
#: tau/4 under the vertical step (0.6 um on the triangles halved), 27 % of its displacement
VISCOELASTIC_LEVELS = {
    "fe-layer": ({"mesh_size_mm": 1.0, "degree": 2, "layers_through_thickness": 2}, {"mesh_size_mm": 0.7, "degree": 2, "layers_through_thickness": 2},
                 {"mesh_size_mm": 0.35, "degree": 2, "layers_through_thickness": 2}),
    "fe-two-layer": tuple({"mesh_size_mm": size, "degree": 2} for size in LEVELS_MM),
}


def point_levels(source: Case) -> list[dict[str, Any]]:
    """The FE options of a point, coarsest first (three; four for the two-layer cylinder):
    :data:`LEVELS_MM` at P2 (Taylor-Hood from nu 0.49, the FE's own choice),
    :data:`THIN_LAYER_LEVELS` for a layer of at most
    :data:`THIN_LAYER_MM`, :data:`TWO_LAYER_CYLINDER_LEVELS` for the two-layer cylinder, or
    :data:`VISCOELASTIC_LEVELS` for a Kelvin-Voigt layer's history. A viscoelastic slab keeps its
    own element (quick's is P1 at nu 0.42, where P1 does not lock): each of its levels is a whole
    creep history, and P2 at 0.7 mm would be seven solves of 10-45 min."""
    viscoelastic = any(key.startswith("viscoelastic.") for key in source.overrides)
    if viscoelastic and source.sides[-1] in VISCOELASTIC_LEVELS:
        return [dict(options) for options in VISCOELASTIC_LEVELS[source.sides[-1]]]
    if source.scene == SCENE_TWO_LAYER_CYLINDER:
        return [dict(options) for options in TWO_LAYER_CYLINDER_LEVELS]
    if source.sides[-1] == "fe-layer" and _layer_thickness_mm(source) <= THIN_LAYER_MM:
        return [dict(options) for options in THIN_LAYER_LEVELS]
    degree = int(source.options.get("degree", 2)) if viscoelastic else 2
    return [{"mesh_size_mm": size, "degree": degree} for size in LEVELS_MM]


def _layer_thickness_mm(case: Case) -> float:
    from edem.scene import read_scene_toml, resolve_scene_path

    if "cartilage.thickness_mm" in case.overrides:
        return float(case.overrides["cartilage.thickness_mm"])
    return float(read_scene_toml(resolve_scene_path(case.scene))["cartilage"]["thickness_mm"])


def _cost_rank(case: Case) -> int:
    """How dear a point's finest mesh is, for the order of the runs (measured 2026-11-26 at load
    2-4, docs/campaigns.md): the 2 mm layer (0.7 mm: 0.3M DOFs, 1-15 min), the 1 mm layer (0.38M
    with 4 elements through it, 5-8 min), the ideal ankle (0.4M, 5-20 min), the 3 mm layer
    (0.46M, 14-20 min), the subject-like ankle (0.53M, 14-30 min); then (2026-11-28) the two-layer
    cylinder (0.7 mm: 0.44M, 4-5 min by the Krylov path; 0.35 mm: 1.7M, 5-9 min and 7-10 GB) and
    the two-layer ankles (0.7M, three loads each: by the Krylov path 23 min and 3.2 GB on
    the ideal ankle at nu 0.42, load 4-5)."""
    if any(key.startswith("viscoelastic.") for key in case.overrides) and case.sides[-1] in VISCOELASTIC_LEVELS:
        return 7  # a whole creep history per level
    if case.sides[-1] == "fe-two-layer":
        return 5 if case.scene == SCENE_TWO_LAYER_CYLINDER else 6
    if case.scene != "cylinder-layer":
        return 2 if case.scene == "ideal-standing" else 4
    return {2.0: 0, 1.0: 1, 3.0: 3}[float(case.overrides.get("cartilage.thickness_mm", 2.0))]


def quick_points() -> list[tuple[str, Case]]:
    """(point name, the quick campaign's case) for every FE reference of quick's trust section:
    one per FE run (the beds of an ankle and nu share one, verification.sides.side_inputs), named
    by its first case without its bed words."""
    from verification.campaigns.quick import trust_cases

    points, seen = [], set()
    for case in trust_cases():
        key = _point_key(case)
        if key not in seen:
            seen.add(key)
            points.append((_BED_WORDS.sub("", case.name), case))
    return points


def study_points() -> list[tuple[str, Case]]:
    """Every point of the study: :func:`quick_points`, then :func:`reference_points`."""
    quick = quick_points()
    return quick + reference_points({_point_key(case) for _, case in quick})


#: the words of a case name that name its bed or its discrete side, not its FE run
_BED_WORDS = re.compile(r"-(coupled|two-pole|springs|sandwich|lumped|lumping|dem-vs-fe|edem-vs-fe)(?=-|$)")


def _point_key(case: Case) -> str:
    """The FE run a point studies, whatever the mesh (its key at the 1.0 mm level)."""
    from verification.fe_convergence import fe_key

    return fe_key(case.scene, case.sides[-1], dict(case.overrides), {"mesh_size_mm": 1.0, "degree": 2})


def reference_points(covered: set[str]) -> list[tuple[str, Case]]:
    """(point name, case) for each FE run of the ``quick``, ``subject``, ``cylinder-plane``,
    ``thin-layer``, ``two-layers``, ``ankles`` and ``viscoelastic`` (its goal's) campaigns not in ``covered`` (point keys, :func:`_point_key`) whose options
    are one of its study levels (:func:`point_levels`), named by the first case using it without
    its bed words. A reference at other options would have no study: it stays "FE error
    unknown" (tests/verification/test_fe_convergence_study.py checks that none is left)."""
    from verification.campaigns.ankles import campaign as ankles
    from verification.campaigns.cylinder_plane import campaign as cylinder_plane
    from verification.campaigns.quick import campaign as quick
    from verification.campaigns.subject import campaign as subject
    from verification.campaigns.thin_layer import campaign as thin_layer
    from verification.campaigns.two_layers import GOAL_NUS, SCENE
    from verification.campaigns.two_layers import campaign as two_layers
    from verification.campaigns.viscoelastic import GOAL_MODELS
    from verification.campaigns.viscoelastic import campaign as viscoelastic

    def studied(case: Case, campaign_of: Any) -> bool:
        if campaign_of is viscoelastic:  # the goal's models (the time-step sweep on the thesis's ankle is reported)
            return case.name.split("-")[0] in GOAL_MODELS
        # the two-layer cylinder: the goal's nus (the others are reported)
        return case.scene != SCENE or float(case.overrides["cartilage.poissons_ratio"]) in GOAL_NUS

    points, seen = [], set(covered)
    for campaign_of in (quick, subject, cylinder_plane, thin_layer, two_layers, ankles, viscoelastic):
        for case in campaign_of().cases:
            if len(case.sides) < 2 or not case.sides[-1].startswith("fe-") or dict(case.options) not in point_levels(case) or not studied(case, campaign_of):
                continue
            key = _point_key(case)
            if key not in seen:
                seen.add(key)
                points.append((_BED_WORDS.sub("", case.name), case))
    return points


def _fe_case(name: str, source: Case, options: dict, what: str) -> Case:
    side = source.sides[-1]
    return Case(
        name,
        f"{what}: the FE reference of quick's {source.name} ({side}) {options}",
        source.scene,
        (side,),
        FE_VALUE_METRICS + ("force_residual_rel",),
        dict(CHECK),
        overrides=dict(source.overrides),
        options=dict(options),
        basis=dict(CHECK_BASIS),
    )


def campaign() -> Campaign:
    cases, points, all_points = [], [], study_points()
    for point, source in all_points:
        names, levels = [], point_levels(source)
        for options in levels:
            layers = options.get("layers_through_thickness")
            name = f"{point}-h{options['mesh_size_mm']:g}" + (f"-L{layers}" if layers else "")
            cases.append(_fe_case(name, source, options, f"mesh level {options['mesh_size_mm']:g} mm" + (f", {layers} layers" if layers else "")))
            names.append(name)
        extra = None
        if source.options.get("degree") == 1 and dict(source.options) not in levels:  # quick's own P1 reference, judged against the study's extrapolation
            extra = f"{point}-P1-h{source.options['mesh_size_mm']:g}"
            cases.append(_fe_case(extra, source, dict(source.options), "quick's P1 reference"))
        points.append({"point": point, "levels": names, "extra": extra, "source_case": source.name, "scene": source.scene,
                       "side": source.sides[-1], "overrides": dict(source.overrides), "source_options": dict(source.options)})
    beds = []
    for point, source in all_points:
        if point not in BED_POINTS:
            continue
        finest = {"mesh_size_mm": LEVELS_MM[-1], "degree": 2}
        for suffix, extra_overrides, what in BEDS:
            beds.append(fe_comparison_case(f"{point}-{suffix}-vs-h{LEVELS_MM[-1]:g}", f"{point}: DEM ({what}) against the finest FE ({LEVELS_MM[-1]:g} mm)",
                                           source.scene, ("dem", source.sides[-1]), overrides={**source.overrides, **extra_overrides}, options=finest, maps=False))
    # the points item 3 of issue 24 rests on complete first, then every point's cheap meshes, then
    # the other points' finest meshes (on 2 shared cores each takes 10-40 min): a campaign cut
    # short still has whole points; the other campaigns' points after quick's, cheapest first,
    # each point's meshes together
    rank = {p: k for k, p in enumerate(PRIORITY)}
    quick = {p for p, _ in quick_points()}
    cost = {p: (_cost_rank(source), k) for k, (p, source) in enumerate(all_points)}

    def order(case: Case) -> tuple:
        point = case.name.rsplit("-h", 1)[0].removesuffix("-P1")
        if point not in quick:
            return (True, *cost[point], -case.options["mesh_size_mm"])
        fine = case.options["mesh_size_mm"] < 1.0
        return (False, rank.get(point, len(rank)) >= 2, fine, rank.get(point, len(rank)), -case.options["mesh_size_mm"])

    cases.sort(key=order)
    analysis = Analysis("fe-convergence", "FE mesh convergence: observed order and Richardson error of each compared quantity, with each mesh's cost",
                        "fe-convergence", tuple(c.name for c in cases), {"points": points, "findings": list(FINDINGS)})
    bed_table = Analysis("beds-vs-finest-fe", "The beds against the finest FE (0.7 mm) on the subject-like and the ideal ankle (issue 24, item 3). Reported, no verdict",
                         "table", tuple(c.name for c in beds), {"columns": FE_TABLE_COLUMNS})
    return Campaign(
        "fe-convergence",
        "The FE reference's own error: each FE point of quick on three meshes (2.0, 1.0, 0.7 mm), observed order, Richardson error, cost; "
        "--refresh-reference stores the errors for the other campaigns.",
        tuple(cases[:8]) + tuple(beds) + tuple(cases[8:]),
        (),
        (analysis, bed_table),
    )


def summary_from_cached_cases(out_dir: str | Path) -> dict[str, Any]:
    """An ``fe-convergence`` summary (its analyses) from the finished cases of a campaign
    directory, without running the others: for a study cut short (each finest mesh takes 10-40
    min on two shared cores), the points whose meshes all finished, each FE run's values
    measured again from its result directory (:func:`verification.fe_convergence.fe_values`).
    Cases whose record is missing are "case not run" to the analysis."""
    study = campaign()
    rows = {}
    for case in study.cases:
        file = Path(out_dir) / "cases" / case.name / "metrics.json"
        if not file.exists():
            continue
        record = json.loads(file.read_text(encoding="utf-8"))
        if record.get("case", {}).get("options") != json.loads(json.dumps(case.options)):
            continue  # another definition of the case
        metrics = dict(record["metrics"])
        fe_dirs = sorted((Path(out_dir) / "cases" / case.name).glob("a-fe-*"))
        if len(case.sides) == 1 and fe_dirs:  # the FE run's values as this code measures them (a definition added since it ran)
            metrics.update(fe_values(fe_dirs[0]))
        rows[case.name] = {"name": case.name, "sides": record["sides"], "metrics": metrics, "options": case.options, "scene": case.scene,
                           "overrides": case.overrides, "params": case.params, "status": record.get("status", "ran"), "out_dir": str(out_dir),
                           "result_dirs": [f"cases/{case.name}/{s['result_dir']}" for s in record["sides"] if s.get("result_dir")]}
    return {"campaign": study.name, "analyses": [run_analysis(a, rows) for a in study.analyses]}
