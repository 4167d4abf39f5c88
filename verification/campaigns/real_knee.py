"""``real-knee``: DEM against the FE on a real tibiofemoral joint (docs/campaigns.md#real-knee-dem-against-the-fe-on-a-real-knee).

The public Lenhart 2015 knee of OpenSim JAM (``edem verify real-knee --data FOLDER``; the folder's
README gives the source and licence, nothing of it is in this repository): the tibial cartilage
(M) with its subchondral bone, measured thickness (:mod:`edem.thickness`), pressed up the tibial
long axis (y) into the femur at the model's neutral pose by 500, 1000 and 2000 N (translations
across the plateau and rotations fixed, as the knee test of item 4 does); JAM's tf_contact
material, E 10 MPa, nu 0.45, gap law.

The femoral cartilage mesh is not public in a usable size, so the femur is its subchondral bone
with a uniform 2 mm layer. Both sides model that layer the same way: **rigid**, the femoral
articular surface being the bone offset by 2 mm along its vertex normals
(:func:`geometries.cartilage_solids.offset_surface`), with ``fixed_thickness_mm = 0``: the springs
carry the tibial layer only, k = E' / t_M, and the FE bonds the measured tibial cartilage solid
to a rigid tibial bone against that rigid surface (:mod:`fem_reference.models`, layer model).
Folding a compliant 2 mm femoral layer into the springs (E' / (t_M + t_F)) would have no FE twin
here: the FE would need a second deformable body.

Preparation (:func:`prepare_inputs`, into ``<out>/inputs``): the meshes in mm; the tibial
cartilage kept where its triangle centroids lie within :data:`CROP_MM` of the femoral articular
surface's vertices (the contact at 2000 N reaches an initial gap of about 0.7 mm: the kept rim is
twice that away; the same cropped surface serves both sides). Cases: each bed (independent
springs, coupled thin layer) at each load against the FE layer on each mesh of :data:`FE_LEVELS`;
the analysis ``band`` judges each against the issue's goal (15 %) only where the FE's own mesh
error (the changes of its refinements) is below it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from geometries.errors import InputError
from verification.campaign_model import Analysis, Campaign, Figure
from verification.fe_comparison import ERROR_PANELS, FE_VALUE_COLUMNS, fe_comparison_case

#: wall time with 2 jobs on 2 cores, nothing cached (measured: 484 s at load 15-20,
#: docs/campaigns.md#real-knee-dem-against-the-fe-on-a-real-knee)
EXPECTED_TIME_S = 500.0

#: the public files the campaign reads from ``--data`` (docs/campaigns.md#real-knee-dem-against-the-fe-on-a-real-knee)
DATA_FILES = {
    "tibia_cartilage": "lenhart2015-R-tibia-cartilage.stl",
    "tibia_bone": "lenhart2015-R-tibia-subchondral-bone.stl",
    "femur_bone": "lenhart2015-R-femur-subchondral-bone-tf20.stl",
}
#: the meshes' units (OpenSim JAM's geometry is in metres)
DATA_UNITS = "m"
#: the femoral layer taken as rigid (mm): the femoral articular surface is its bone offset by it
FEMORAL_LAYER_MM = 2.0
#: tibial cartilage kept within this distance of the femoral articular surface (mm; module docstring)
CROP_MM = 1.5
LOADS_N = (500.0, 1000.0, 2000.0)
#: JAM's tf_contact material
YOUNGS_MODULUS_MPA, POISSONS_RATIO = 10.0, 0.45
#: the FE meshes: P2 on the native surface (0.74 mm mean edge) with one element through the
#: cartilage (base), then the elements halved through the thickness (two) and, separately, in the
#: plane (the surface subdivided once, 0.37 mm); halving both at once (366k DOFs) needs an
#: estimated 3.6 GB, more than this shared 2-core machine had free. The analysis adds the two
#: refinements' changes (verification.analyses.fe_band_analysis).
FE_LEVELS = (
    ("L0", {"mesh_size_mm": 1.0, "degree": 2, "layers_through_thickness": 1}),
    ("L1", {"mesh_size_mm": 1.0, "degree": 2, "layers_through_thickness": 2}),
    ("L2", {"mesh_size_mm": 0.5, "degree": 2, "layers_through_thickness": 1}),
)
BEDS = {"springs": ({}, "independent springs"), "coupled": ({"cartilage.coupling": "thin-layer"}, "coupled thin layer")}
GOAL_REL = 0.15
SCENE_NAME = "real-knee.toml"
#: the same knee with the femoral layer deformable: the femoral bone as F with a uniform
#: FEMORAL_LAYER_MM layer (``fixed_thickness_mm``), both layers in the springs (the coupled
#: layer's sandwich) and in the FE (the two-layer model)
TWO_LAYER_SCENE_NAME = "real-knee-two-layers.toml"
#: the beds against the two-layer FE: the coupled layer (the scene's default, the sandwich of the
#: two layers) and the independent springs (the two layers in series)
TWO_LAYER_BEDS = {"springs-2L": ({"cartilage.coupling": "none"}, "independent springs"),
                  "coupled-2L": ({"cartilage.coupling": "thin-layer"}, "coupled layer, sandwich")}
QUANTITIES = (
    ("displacement (mm)", "a_at_b_displacement_norm_mm", "b_displacement_norm_mm"),
    ("peak pressure (MPa)", "a_at_b_peak_pressure_mpa", "b_peak_pressure_mpa"),
    ("contact area (mm^2)", "a_at_b_mean_contact_area_mm2", "b_mean_contact_area_mm2"),
)


def data_files(data: Path | str | None) -> dict[str, Path]:
    """The data folder's files by role; InputError naming ``--data`` or the missing file."""
    if data is None:
        raise InputError("the real-knee campaign needs the public Lenhart knee data", key="--data",
                         expected="the folder with " + ", ".join(DATA_FILES.values()) + " (docs/campaigns.md#real-knee-dem-against-the-fe-on-a-real-knee says where they come from)")
    folder = Path(data)
    files = {role: folder / name for role, name in DATA_FILES.items()}
    missing = [path for path in files.values() if not path.is_file()]
    if missing:
        raise InputError(f"{len(missing)} of the knee's files are missing", file=str(missing[0]), key="--data",
                         expected="the folder with " + ", ".join(DATA_FILES.values()))
    return files


def _write_mm(path: Path, vertices_mm: np.ndarray, triangles: np.ndarray) -> None:
    from geometries.mesh_files import write_surface
    from geometries.surface import TriangleSurface

    write_surface(path, TriangleSurface(np.asarray(vertices_mm, float), np.asarray(triangles, np.int64)))


def prepare_inputs(data: Path | str, work: Path | str) -> Path:
    """Write the campaign's meshes (mm, VTP) and scene into ``work``; return the scene's path.

    The femoral articular surface (bone + :data:`FEMORAL_LAYER_MM`), the tibial cartilage cropped
    to :data:`CROP_MM` of it, and the tibial bone (module docstring)."""
    from scipy.spatial import cKDTree

    from geometries.cartilage_solids import offset_surface
    from geometries.repair import orient_towards, prepare_surface

    files = data_files(data)
    work = Path(work)
    work.mkdir(parents=True, exist_ok=True)
    tibia = prepare_surface(files["tibia_cartilage"], units=DATA_UNITS, key="--data", name="tibia cartilage")
    bone = prepare_surface(files["tibia_bone"], units=DATA_UNITS, key="--data", name="tibia bone")
    femur = orient_towards(prepare_surface(files["femur_bone"], units=DATA_UNITS, key="--data", name="femur bone"),
                           tibia.vertices_mm, key="--data", near_mm=10.0)
    articular = offset_surface(femur, FEMORAL_LAYER_MM)
    distance, _ = cKDTree(articular.vertices_mm).query(tibia.centroids_mm)
    kept = tibia.triangles[distance <= CROP_MM]
    if not len(kept):
        raise InputError(f"no tibial cartilage within {CROP_MM:g} mm of the femur", file=str(files["tibia_cartilage"]), key="--data",
                         expected="the Lenhart 2015 meshes in their model frame (femur and tibia at the neutral pose)")
    used = np.unique(kept)
    remap = np.full(len(tibia.vertices_mm), -1, np.int64)
    remap[used] = np.arange(used.size)
    _write_mm(work / "tibia-cartilage.vtp", tibia.vertices_mm[used], remap[kept])
    _write_mm(work / "tibia-bone.vtp", bone.vertices_mm, bone.triangles)
    _write_mm(work / "femur-articular.vtp", articular.vertices_mm, articular.triangles)
    _write_mm(work / "femur-bone.vtp", femur.vertices_mm, femur.triangles)
    (work / TWO_LAYER_SCENE_NAME).write_text(f"""[scene]
name = "real-knee-two-layers"
description = "Lenhart 2015 knee (OpenSim JAM): tibial cartilage with its bone (measured thickness) against the femoral bone with a deformable uniform {FEMORAL_LAYER_MM:g} mm layer; tibia cropped to {CROP_MM:g} mm of the femoral articular surface"

[geometry]
mobile = "tibia-cartilage.vtp"
mobile_bone = "tibia-bone.vtp"
fixed = "femur-bone.vtp"

[cartilage]
youngs_modulus_mpa = {YOUNGS_MODULUS_MPA}
poissons_ratio = {POISSONS_RATIO}
law = "gap"
max_spring_length_mm = 8.0
fixed_thickness_mm = {FEMORAL_LAYER_MM}
coupling = "thin-layer"

[load]
force_n = [0.0, {LOADS_N[0]}, 0.0]

[constraints]
fixed_dofs = ["tx", "tz", "rx", "ry", "rz"]
""", encoding="utf-8")
    scene = work / SCENE_NAME
    scene.write_text(f"""[scene]
name = "real-knee"
description = "Lenhart 2015 knee (OpenSim JAM): tibial cartilage with its bone (measured thickness) against the femoral bone + a rigid {FEMORAL_LAYER_MM:g} mm layer; tibia cropped to {CROP_MM:g} mm of the femur"

[geometry]
mobile = "tibia-cartilage.vtp"
mobile_bone = "tibia-bone.vtp"
fixed = "femur-articular.vtp"

[cartilage]
youngs_modulus_mpa = {YOUNGS_MODULUS_MPA}
poissons_ratio = {POISSONS_RATIO}
law = "gap"
max_spring_length_mm = 8.0
fixed_thickness_mm = 0.0

[load]
force_n = [0.0, {LOADS_N[0]}, 0.0]

[constraints]
fixed_dofs = ["tx", "tz", "rx", "ry", "rz"]
""", encoding="utf-8")
    return scene


def case_name(bed: str, load_n: float, level: str) -> str:
    return f"{bed}-F{load_n:g}-{level}"


def campaign(scene: str = SCENE_NAME, two_layer_scene: str = TWO_LAYER_SCENE_NAME) -> Campaign:
    """The campaign on the prepared scenes (:func:`prepare_inputs`); without them the cases name
    :data:`SCENE_NAME` and :data:`TWO_LAYER_SCENE_NAME` (listed, not runnable: ``edem verify``
    prepares them from ``--data``)."""
    cases = []
    for bed, (overrides, what) in BEDS.items():
        for load in LOADS_N:
            for level, options in FE_LEVELS:
                cases.append(fe_comparison_case(
                    case_name(bed, load, level),
                    f"Lenhart knee, {what}, {load:g} N up the tibia; FE layer (measured tibial cartilage, rigid femur + 2 mm) "
                    f"P2 at {options['mesh_size_mm']:g} mm, {options['layers_through_thickness']} element(s) through the cartilage",
                    scene, ("dem", "fe-layer"), overrides={"load.force_n": [0.0, load, 0.0], **overrides}, options=options,
                    params={"load_n": load}, maps=(load == LOADS_N[-1] and level == "L1"),
                ))
    rigid = tuple(c.name for c in cases)
    for bed, (overrides, what) in TWO_LAYER_BEDS.items():
        for load in LOADS_N:
            for level, options in FE_LEVELS:
                cases.append(fe_comparison_case(
                    case_name(bed, load, level),
                    f"Lenhart knee, both layers deformable, {what}, {load:g} N up the tibia; FE two-layer (measured tibial cartilage, femur + a deformable 2 mm layer) "
                    f"P2 at {options['mesh_size_mm']:g} mm, {options['layers_through_thickness']} element(s) through each layer",
                    two_layer_scene, ("dem", "fe-two-layer"), overrides={"load.force_n": [0.0, load, 0.0], **overrides}, options=options,
                    params={"load_n": load}, maps=(bed == "coupled-2L" and load == LOADS_N[-1] and level == "L1"),
                ))
    for load in LOADS_N:
        for level, options in FE_LEVELS:
            cases.append(fe_comparison_case(
                case_name("lumping", load, level),
                f"Lenhart knee, {load:g} N: the FE of one layer of the summed thickness (tibial + 2 mm) on the tibial bone against the femoral bone (lumped) "
                f"against the two-layer FE; P2 at {options['mesh_size_mm']:g} mm, {options['layers_through_thickness']} element(s) through each layer",
                two_layer_scene, ("fe-lumped", "fe-two-layer"), overrides={"load.force_n": [0.0, load, 0.0]}, options=options,
                params={"load_n": load}, maps=False))
    points = tuple((f"{bed} {load:g} N", tuple(case_name(bed, load, level) for level, _ in FE_LEVELS)) for bed in (*BEDS, *TWO_LAYER_BEDS) for load in LOADS_N)
    # the femoral layer's compliance: the two-layer FE against the rigid femur's (each FE value on the three meshes)
    compliance = tuple((f"{load:g} N {level}", case_name("coupled-2L", load, level), case_name("coupled", load, level)) for load in LOADS_N for level, _ in FE_LEVELS)
    lumping = tuple(case_name("lumping", load, level) for load in LOADS_N for level, _ in FE_LEVELS)
    analyses = (
        Analysis("band", f"DEM against the FE on the real knee, rigid femur and (-2L) both layers deformable: goal {GOAL_REL:.0%}, judged where the FE's mesh error is below it",
                 "fe-band", tuple(c.name for c in cases if c.name not in lumping), {"points": points, "quantities": QUANTITIES, "goal": GOAL_REL}),
        Analysis("femoral-compliance", "What the femoral layer's compliance changes: the FE with both layers deformable against the FE with the femur rigid, "
                                       "(two layers - rigid femur) / rigid femur, on each mesh", "pairs", tuple(n for _, a, b in compliance for n in (a, b)),
                 {"pairs": compliance, "quantities": tuple((q, b, b) for q, _, b in QUANTITIES)}),
        Analysis("lumping", "The lumping error on the knee: one layer of the summed thickness on the tibial bone against the two-layer FE, signed (lumped - two layers) / two layers",
                 "table", lumping, {"columns": FE_VALUE_COLUMNS}),
        # (the FE's own error is the band's, from this campaign's own meshes: the fe-convergence
        # study, whose columns would read "unknown" here, does not hold the knee)
        Analysis("table", "DEM against the FE, every case (the FE's own error: the band above)", "table", tuple(c.name for c in cases if c.name not in lumping),
                 {"columns": FE_VALUE_COLUMNS}),
    )
    # the errors against the FE refined through the thickness (L1: every load fits in memory)
    series = tuple((what, tuple(case_name(bed, load, "L1") for load in LOADS_N)) for bed, (_, what) in BEDS.items()) + tuple(
        (f"{what}, both layers deformable", tuple(case_name(bed, load, "L1") for load in LOADS_N)) for bed, (_, what) in TWO_LAYER_BEDS.items())
    figures = (Figure("errors-vs-load", f"Lenhart knee: errors of the two beds against the FE (two elements through the cartilage) vs the load; dashed: the {GOAL_REL:.0%} goal",
                      "sweep", tuple(n for _, group in series for n in group), x="load_n", y=ERROR_PANELS, logy=True, series=series,
                      lines=tuple((m, GOAL_REL, f"goal {GOAL_REL:.0%}") for m in ERROR_PANELS[:3])),)
    return Campaign(
        "real-knee",
        "the Lenhart MRI knee (edem verify real-knee --data FOLDER): DEM springs and coupled layer vs the FE on measured cartilage, 500-2000 N",
        tuple(cases), figures, analyses,
    )


def with_data(data: Path | str | None, work: Path | str) -> Campaign:
    """The campaign on ``data`` (the Lenhart knee folder), its inputs prepared in ``work``."""
    scene = prepare_inputs(data, work)
    return campaign(str(scene), str(scene.with_name(TWO_LAYER_SCENE_NAME)))
