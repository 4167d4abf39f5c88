"""Worked example 1: a real gait's ankle load, from OpenSim to the contact over stance.

What it shows
-------------
OpenSim's gait2392 model of subject01 walking (public data, see below) goes through OpenSim's own
static optimisation and JointReaction analyses (OpenSim's Python API, about 15 s). The reaction of
the ankle joint on the talus, expressed in the tibia, then drives the built-in ideal ankle with
its cartilage (a cylindrical talar bone, R 20 mm, and an incongruent concave tibial plafond, each
under its layer, the articular surfaces touching at zero load) over the right stance (0.62 to
1.40 s, 48 rows), with the IK ankle angle turning the tibia about the talar axis, EDEM, no
ligaments (so only the contact and the constraints carry the load).

The scene reads the ``.sto`` exactly as OpenSim wrote it: ``axes = "opensim"`` (OpenSim's x
anterior, y up, z right onto the scene's x right, y anterior, z up), ``mobile_body = "talus_r"``
(the columns are the load the joint applies on the talus, so the load pressing the talus into
the tibia is minus them: README.md, "From an OpenSim model") and ``fixed_body = "tibia_r"`` (the
columns are in the tibia's axes and turn with it).

Cartilage: a talar layer of 1.3 mm and a tibial layer of 1.4 mm at their centres, tapered to 0 at
their margins (``[geometry] talar_cartilage_mm``, ``tibial_cartilage_mm`` of the built-in ankle,
whose bones the thickness is measured to: docs/method.md#measured-cartilage-thickness), the linear
gap law on the two layers in series, the coupled thin layer (the built-in scenes' default bed:
the sandwich of the two layers), E 10.35 MPa, nu 0.42 (the thesis's values). The talus carries
the builder's 3046 springs (0.63 mm across); the script prints their size and the pre-flight's
count of springs in the expected contact patch (about 480). With ``SPRING_SPACING_MM = 0.5``
(edges of at most 0.5 mm, 15.7k springs) the peak contact area moves by 0.4 % and the peak
pressure by 0.2 %.

This set-up replaces one on bone surfaces without cartilage driven by the same reaction, whose
springs passed through the bones at nearly every time point: such a run is refused now (exit 2,
docs/method.md#1-two-rigid-bones-and-a-bed-of-springs), and a joint's contact needs the cartilage
it has.

Expected numbers (checked by tests/test_examples.py)
----------------------------------------------------
- the reaction on the talus peaks at about 4 kN (``EXPECTED_PEAK_REACTION_N``, within 15 %);
- every instant whose reaction exceeds 1 kN (``LOADED_N``) is in contact (area > 0);
- along the DOFs left free (ty, tz: anterior and superior in the talus), the contact resultant
  equals minus the reaction turned into the scene, to 1e-6 of the peak load (EDEM balances each
  step to round-off).

The constraints hold the rest: frictionless layers on cylinders about the ankle axis carry no
load along that axis, so the reaction's component along it goes to the ``tx`` constraint and
its moments to the fixed rotations (``edem`` warns about these); the concave plafond carries the
antero-posterior shear (up to about 220 N). The script also prints the peak contact area and
peak pressure: 696 mm^2 and 8.3 MPa near 81 % stance (2026-11-28; reported, not asserted), the
area 469-696 mm^2 over the instants above 1 kN, as the patch spreads over the plafond's 30 mm.

Data
----
``opensim-gait2392/`` in the data folder: ``subject01_simbody.osim``, ``subject01_walk1_ik.mot``,
``subject01_walk1_grf.mot`` and ``subject01_walk1_grf.xml`` from the public repository
opensim-org/opensim-models (commit 20a888b, ``Pipelines/Gait2392_Simbody``; CC BY 3.0 per the
models' credits). The data folder is ``--data`` or the environment variable ``EDEM_SHARED_DATA``,
by default ``../shared/data`` beside the repository.

Output
------
``--out`` (default ``results/examples/gait2392-ankle``): OpenSim's files (``opensim/``), the
scene (``ankle.toml``), the result directory of the run (``run/``) and ``stance.png``: the
reaction, the contact resultant, the contact area and the peak pressure over stance.

Run: ``PYTHONPATH=. python docs/examples/gait2392_ankle.py [--data DIR] [--out DIR]``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
STANCE_S = (0.62, 1.40)  # right heel strike to right toe off in subject01_walk1 (from the GRF)
LOWPASS_HZ = 6.0  # the IK low-pass filter of OpenSim's gait tutorials
TALAR_CARTILAGE_MM = 1.3
TIBIAL_CARTILAGE_MM = 1.4
#: [cartilage] coupling: the built-in ankle scenes' default bed, the coupled thin layer
COUPLING = "thin-layer"
#: [geometry] spring_spacing_mm (mm): the longest spring triangle edge (None: the mesh's own triangles)
SPRING_SPACING_MM: float | None = None
LOADED_N = 1000.0
EXPECTED_PEAK_REACTION_N = 4000.0
PELVIS_COORDINATES = ("pelvis_tx", "pelvis_ty", "pelvis_tz", "pelvis_tilt", "pelvis_list", "pelvis_rotation")
REACTION_PREFIX = "ankle_r_on_talus_r_in_tibia_r"


def default_data() -> Path:
    return Path(os.environ.get("EDEM_SHARED_DATA", ROOT.parent / "shared" / "data")).resolve()


def _analyze(osim, name: str, analysis, model: Path, data: Path, out: Path, external_loads: Path) -> None:
    """One OpenSim AnalyzeTool over the stance, run from its setup file as OpenSim's own tools do."""
    tool = osim.AnalyzeTool()
    tool.setName(name)
    tool.setModelFilename(str(model))
    tool.setCoordinatesFileName(str(data / "subject01_walk1_ik.mot"))
    tool.setLowpassCutoffFrequency(LOWPASS_HZ)
    tool.setInitialTime(STANCE_S[0])
    tool.setFinalTime(STANCE_S[1])
    tool.setResultsDir(str(out))
    tool.setExternalLoadsFileName(str(external_loads))
    analysis.setStartTime(STANCE_S[0])
    analysis.setEndTime(STANCE_S[1])
    tool.updAnalysisSet().cloneAndAppend(analysis)
    setup = out / f"{name}_setup.xml"
    tool.printToXML(str(setup))
    osim.AnalyzeTool(str(setup)).run()


def ankle_reaction(data: Path, out: Path) -> Path:
    """Static optimisation, then JointReaction of ``ankle_r`` on the talus (child) in the tibia
    (parent), over the stance: the ReactionLoads .sto OpenSim wrote. The subject01 model carries
    no reserve actuators: residual actuators on the six pelvis coordinates are added, as in
    OpenSim's gait tutorials."""
    import opensim as osim

    osim.Logger.removeFileSink()  # no opensim.log in the working directory
    osim.Logger.setLevelString("warn")
    out.mkdir(parents=True, exist_ok=True)
    model = osim.Model(str(data / "subject01_simbody.osim"))
    for name in PELVIS_COORDINATES:
        actuator = osim.CoordinateActuator(name)
        actuator.setName(f"residual_{name}")
        actuator.setOptimalForce(1.0)
        actuator.setMinControl(-math.inf)
        actuator.setMaxControl(math.inf)
        model.addForce(actuator)
    model.finalizeConnections()
    model_file = out / "subject01_residuals.osim"
    model.printToXML(str(model_file))
    grf = data / "subject01_walk1_grf.xml"
    _analyze(osim, "so", osim.StaticOptimization(), model_file, data, out, grf)
    reaction = osim.JointReaction()
    reaction.setName("JointReaction")
    for setter, value in ((reaction.setJointNames, "ankle_r"), (reaction.setOnBody, "child"), (reaction.setInFrame, "parent")):
        names = osim.ArrayStr()
        names.append(value)
        setter(names)
    reaction.setForcesFileName(str(out / "so_StaticOptimization_force.sto"))
    _analyze(osim, "jr", reaction, model_file, data, out, grf)
    return out / "jr_JointReaction_ReactionLoads.sto"


def scene_toml(reaction: Path, ik_motion: Path) -> str:
    spacing = "" if SPRING_SPACING_MM is None else f"spring_spacing_mm = {SPRING_SPACING_MM}\n"
    return f"""[scene]
name = "gait2392-ideal-ankle"
description = "subject01's right stance: OpenSim SO + JointReaction on the ideal ankle with cartilage (docs/examples/gait2392_ankle.py)"

[geometry]
builtin = "ideal_ankle"             # talar and tibial bones under their cartilage, the articular surfaces touching
talar_cartilage_mm = {TALAR_CARTILAGE_MM}
tibial_cartilage_mm = {TIBIAL_CARTILAGE_MM}
{spacing}
[cartilage]
youngs_modulus_mpa = 10.35
poissons_ratio = 0.42
law = "gap"                         # the two layers in series, thickness measured to the builder's bones
coupling = "{COUPLING}"
max_spring_length_mm = 3.5

[load]
file = "{reaction}"
axes = "opensim"
mobile_body = "talus_r"
fixed_body = "tibia_r"

[kinematics]
file = "{ik_motion}"
angle_column = "ankle_angle_r"
axis_point_mm = [0.0, 0.0, -20.0]   # the talar dome's axis
axis_direction = [-1.0, 0.0, 0.0]   # dorsiflexion carries the tibia anteriorly

[constraints]
# frictionless layers on cylinders about the ankle axis: nothing resists the load along that axis
# (tx) or the moments about it and the others; the concave plafond takes the antero-posterior shear
fixed_dofs = ["tx", "rx", "ry", "rz"]

[solver]
method = "edem"
"""


def reaction_in_scene(reaction: Path, angle_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The reaction on the talus as OpenSim's own reader gives it: time (s) and the force (N)
    turned into the scene's axes (OpenSim -> scene axes, then the tibia's turn by the ankle angle
    about -x)."""
    import opensim as osim

    table = osim.TimeSeriesTable(str(reaction))
    time_s = np.array(table.getIndependentColumn())
    force = np.column_stack([table.getDependentColumn(f"{REACTION_PREFIX}_f{c}").to_numpy() for c in "xyz"])
    force = force[:, [2, 0, 1]]  # OpenSim (x anterior, y up, z right) -> scene (x right, y anterior, z up)
    c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
    turned = np.column_stack([force[:, 0], c * force[:, 1] + s * force[:, 2], -s * force[:, 1] + c * force[:, 2]])
    return time_s, turned


def spring_size_mm(scene) -> float:
    return float(np.sqrt(scene.spring_area_mm2.mean()))


def plot(path: Path, stance_pct: np.ndarray, reaction_n: np.ndarray, contact_n: np.ndarray, area_mm2: np.ndarray,
         peak_mpa: np.ndarray) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(7, 8), sharex=True)
    axes[0].plot(stance_pct, np.linalg.norm(reaction_n, axis=1), "k-", label="|JointReaction| on the talus (OpenSim)")
    axes[0].plot(stance_pct, -reaction_n[:, 2], "k:", label="minus the reaction, superior")
    axes[0].plot(stance_pct, contact_n[:, 2], "C0--", label="contact resultant, superior (EDEM)")
    axes[0].plot(stance_pct, -reaction_n[:, 1], "C1:", label="minus the reaction, anterior")
    axes[0].plot(stance_pct, contact_n[:, 1], "C1--", label="contact resultant, anterior (EDEM)")
    axes[0].set_ylabel("force (N)")
    axes[0].legend(fontsize=8)
    axes[1].plot(stance_pct, area_mm2, "C2")
    axes[1].set_ylabel("contact area (mm$^2$)")
    axes[2].plot(stance_pct, peak_mpa, "C3")
    axes[2].set_ylabel("peak pressure (MPa)")
    axes[2].set_xlabel("right stance (%)")
    fig.suptitle("gait2392 subject01, right stance: OpenSim reaction -> ideal ankle with cartilage (EDEM)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _absolute(text: str) -> Path:
    """A command-line path made absolute: the scene files (and OpenSim's setup files) written
    under --out resolve their paths from their own folder, not from the working directory."""
    return Path(text).resolve()


def main(argv: list[str] | None = None) -> dict:
    """Run the example; return the measured numbers (also written to ``OUT/numbers.json``)."""
    import edem
    from edem.resultdir import read_timeseries_csv

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=_absolute, default=default_data(), help="the public data folder (holds opensim-gait2392/)")
    parser.add_argument("--out", type=_absolute, default=ROOT / "results" / "examples" / "gait2392-ankle")
    args = parser.parse_args(argv)
    data = args.data / "opensim-gait2392"
    args.out.mkdir(parents=True, exist_ok=True)

    start = time.perf_counter()
    reaction = ankle_reaction(data, args.out / "opensim")
    opensim_s = time.perf_counter() - start

    scene_file = args.out / "ankle.toml"
    scene_file.write_text(scene_toml(reaction, data / "subject01_walk1_ik.mot"), encoding="utf-8")
    scene = edem.load_scene(scene_file)
    start = time.perf_counter()
    run = edem.solve(scene)
    edem_s = time.perf_counter() - start
    edem.write_results(run, args.out / "run", overwrite=True)

    series = read_timeseries_csv(args.out / "run" / "timeseries.csv")
    time_s, reaction_n = reaction_in_scene(reaction, series["joint_angle_deg"])
    contact_n = np.column_stack([series[f"contact_force_{c}_n"] for c in "xyz"])
    area, peak = series["contact_area_mm2"], series["peak_pressure_mpa"]
    magnitude = np.linalg.norm(reaction_n, axis=1)
    loaded = magnitude > LOADED_N
    pressing = -reaction_n
    numbers = {
        "rows": int(len(time_s)),
        "times_match": bool(np.allclose(series["time_s"], time_s)),
        "loaded_rows": int(loaded.sum()),
        "loaded_rows_in_contact": int((area[loaded] > 0).sum()),
        "peak_reaction_n": float(magnitude.max()),
        "max_balance_error_n": float(np.abs(contact_n[:, 1:] - pressing[:, 1:]).max()),
        "peak_contact_area_mm2": float(area.max()),
        "peak_pressure_mpa": float(peak.max()),
        "spring_size_mm": spring_size_mm(scene),
        "springs": int(scene.spring_area_mm2.shape[0]),
        "springs_in_patch": run.preflight.patch_springs,
        "cartilage_mm": [TALAR_CARTILAGE_MM, TIBIAL_CARTILAGE_MM],
        "opensim_s": opensim_s,
        "edem_s": edem_s,
    }
    stance_pct = 100.0 * (time_s - time_s[0]) / (time_s[-1] - time_s[0])
    plot(args.out / "stance.png", stance_pct, reaction_n, contact_n, area, peak)
    (args.out / "numbers.json").write_text(json.dumps(numbers, indent=2), encoding="utf-8")
    print(f"cartilage: talar {TALAR_CARTILAGE_MM} mm + tibial {TIBIAL_CARTILAGE_MM} mm; {numbers['springs']} springs, "
          f"spring size {numbers['spring_size_mm']:.2f} mm (spring_spacing_mm: {SPRING_SPACING_MM}), "
          f"about {numbers['springs_in_patch'] or 0:.0f} springs in the pre-flight's expected contact patch")
    print(f"reaction peak {numbers['peak_reaction_n']:.0f} N; {numbers['loaded_rows_in_contact']} of {numbers['loaded_rows']} "
          f"instants over {LOADED_N:.0f} N in contact; contact - (-reaction) on ty, tz: {numbers['max_balance_error_n']:.2e} N")
    print(f"peak contact area {numbers['peak_contact_area_mm2']:.0f} mm^2, peak pressure {numbers['peak_pressure_mpa']:.2f} MPa")
    print(f"OpenSim {opensim_s:.1f} s, EDEM {edem_s:.1f} s; picture {args.out / 'stance.png'}")
    return numbers


if __name__ == "__main__":
    main()
