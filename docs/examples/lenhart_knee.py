"""Worked example 2: a real knee with measured cartilage thickness (Lenhart 2015, OpenSim JAM).

What it shows
-------------
The tibial cartilage of an MRI-segmented knee, with its subchondral bone, pressed into the femoral
subchondral bone, which carries a uniform 2 mm layer (the femoral cartilage mesh is not public in
a usable size). Each spring's tibial thickness is measured along its ray to the tibial bone, as
OpenSim JAM does (README.md, "Measured cartilage thickness"); contact starts where the two
articular surfaces meet, and the gap law's stiffness is E' / (t_tibia + 2 mm). JAM's material:
E 10 MPa, nu 0.45. The tibia is pushed up its long axis (y) with 500, 1000 and 2000 N at the
neutral pose (translations across the plateau and rotations held), DEM, with both beds: the
independent springs (``coupling = "none"``) and the coupled thin layer (``"thin-layer"``), each at
two ray windows, h_max 8 and 10 mm.

Expected numbers (checked by tests/test_examples.py)
----------------------------------------------------
Contact area (mm^2) at 500 / 1000 / 2000 N (``EXPECTED_AREA_MM2``):

- independent springs: about 179 / 253 / 354;
- coupled thin layer: about 245 / 332 / 452 (the layer spreads the load sideways; the tibial and
  femoral layers as a sandwich, each bonded to its bone: docs/method.md, "Two layers: the sandwich").

Within 3 % (``AREA_RTOL``: the area is a sum of spring areas and moves by whole springs between
library versions and platforms; the largest spring is under 1 % of the smallest area). The
area grows with the load, and it does not move when h_max goes from 8 to 10 mm (to half a
spring's area): once the window sees where the articular surfaces meet, the gap law's contact is
set by the geometry and the measured thickness, not by h_max.

The script also prints the peak pressures and the measured tibial thickness (median, range).

Data
----
``lenhart2015-knee/`` in the data folder: ``lenhart2015-R-tibia-cartilage.stl``,
``lenhart2015-R-tibia-subchondral-bone.stl`` and ``lenhart2015-R-femur-subchondral-bone-tf20.stl``
(the femoral subchondral bone cropped to its tibiofemoral region), from the public repository
clnsmith/opensim-jam (commit fb77705, Apache 2.0; Lenhart, Kaiser, Smith, Thelen 2015, Ann Biomed
Eng 43:2675-2685). The data folder is ``--data`` or the environment variable
``EDEM_SHARED_DATA``, by default ``../shared/data`` beside the repository.

Output
------
``--out`` (default ``results/examples/lenhart-knee``): the scene (``knee.toml``),
``numbers.json`` and ``pressure.png``: the tibial plateau seen from above, coloured by the
contact pressure at 2000 N, one panel per bed.

Run: ``PYTHONPATH=. python docs/examples/lenhart_knee.py [--data DIR] [--out DIR]`` (about a minute).
"""

from __future__ import annotations

import argparse
import json
import os
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
LOADS_N = (500.0, 1000.0, 2000.0)
FEMORAL_LAYER_MM = 2.0
WINDOWS_MM = (8.0, 10.0)
BEDS = ("none", "thin-layer")
EXPECTED_AREA_MM2 = {"none": (179.0, 253.0, 354.0), "thin-layer": (245.0, 332.0, 452.0)}
AREA_RTOL = 0.03


def default_data() -> Path:
    return Path(os.environ.get("EDEM_SHARED_DATA", ROOT.parent / "shared" / "data")).resolve()


def scene_toml(knee: Path) -> str:
    forces = ", ".join(f"[0, {f:g}, 0]" for f in LOADS_N)
    return f"""[scene]
name = "lenhart-knee"
description = "Lenhart 2015 tibia (measured cartilage) against the femoral bone with a 2 mm layer (docs/examples/lenhart_knee.py)"

[geometry]
mobile = "{knee / 'lenhart2015-R-tibia-cartilage.stl'}"
mobile_bone = "{knee / 'lenhart2015-R-tibia-subchondral-bone.stl'}"
fixed = "{knee / 'lenhart2015-R-femur-subchondral-bone-tf20.stl'}"
units = "m"

[cartilage]
youngs_modulus_mpa = 10.0       # JAM's tf_contact
poissons_ratio = 0.45
law = "gap"
max_spring_length_mm = {WINDOWS_MM[0]}
fixed_thickness_mm = {FEMORAL_LAYER_MM}
coupling = "none"

[load]
time_s = [0, 1, 2]
force_n = [{forces}]            # the tibia pushed up its long axis into the femur

[constraints]
fixed_dofs = ["tx", "tz", "rx", "ry", "rz"]

[solver]
method = "dem"
"""


def plot(path: Path, runs: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.tri import Triangulation

    fig, axes = plt.subplots(1, len(runs), figsize=(5 * len(runs), 4.5), sharey=True)
    vmax = max(run.steps[-1].peak_pressure_mpa for run in runs.values())
    for ax, (bed, run) in zip(axes, runs.items()):
        scene, step = run.scene, run.steps[-1]
        pressure = np.zeros(scene.mobile.triangles.shape[0])
        pressure[scene.spring_triangle] = step.pressure_mpa
        v = scene.mobile.vertices_mm
        # seen from above (down the tibia's long axis y): lateral z to the right, anterior x up
        image = ax.tripcolor(Triangulation(v[:, 2], v[:, 0], scene.mobile.triangles), facecolors=pressure,
                             cmap="viridis", vmin=0.0, vmax=vmax)
        ax.set_aspect("equal")
        ax.set_title(f"{bed}: {step.contact_area_mm2:.0f} mm$^2$, peak {step.peak_pressure_mpa:.1f} MPa")
        ax.set_xlabel("z, lateral (mm)")
    axes[0].set_ylabel("x, anterior (mm)")
    fig.colorbar(image, ax=list(axes), label="contact pressure (MPa)")
    fig.suptitle(f"Lenhart knee, tibial cartilage at {LOADS_N[-1]:.0f} N (measured thickness + {FEMORAL_LAYER_MM} mm femoral layer)")
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _absolute(text: str) -> Path:
    """A command-line path made absolute: the scene files (and OpenSim's setup files) written
    under --out resolve their paths from their own folder, not from the working directory."""
    return Path(text).resolve()


def main(argv: list[str] | None = None) -> dict:
    """Run the example; return the measured numbers (also written to ``OUT/numbers.json``)."""
    import edem

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=_absolute, default=default_data(), help="the public data folder (holds lenhart2015-knee/)")
    parser.add_argument("--out", type=_absolute, default=ROOT / "results" / "examples" / "lenhart-knee")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    scene_file = args.out / "knee.toml"
    scene_file.write_text(scene_toml(args.data / "lenhart2015-knee"), encoding="utf-8")

    numbers: dict = {"loads_n": list(LOADS_N), "warnings": []}
    at_first_window = {}
    for bed in BEDS:
        for h_max in WINDOWS_MM:
            start = time.perf_counter()
            with warnings.catch_warnings(record=True) as caught:  # the same notes for every run: said once below
                warnings.simplefilter("always", edem.EdemWarning)
                run = edem.solve(edem.load_scene(scene_file, {"cartilage.coupling": bed, "cartilage.max_spring_length_mm": h_max}))
            numbers["warnings"] += [str(w.message) for w in caught if str(w.message) not in numbers["warnings"]]
            key = f"{bed}/h_max={h_max:g}"
            numbers[key] = {
                "area_mm2": [s.contact_area_mm2 for s in run.steps],
                "peak_pressure_mpa": [s.peak_pressure_mpa for s in run.steps],
                "wall_time_s": time.perf_counter() - start,
            }
            print(f"{key:22s} area " + " / ".join(f"{a:.0f}" for a in numbers[key]["area_mm2"]) + " mm^2, peak "
                  + " / ".join(f"{p:.2f}" for p in numbers[key]["peak_pressure_mpa"]) + f" MPa ({numbers[key]['wall_time_s']:.1f} s)")
            if h_max == WINDOWS_MM[0]:
                at_first_window[bed] = run
    for message in numbers["warnings"]:
        print(f"warning: {message}")
    first = at_first_window[BEDS[0]]
    numbers["largest_spring_mm2"] = float(first.scene.spring_area_mm2.max())
    numbers["cartilage_thickness"] = first.summary()["cartilage_thickness"]
    tibia = numbers["cartilage_thickness"]["mobile"]
    print(f"tibial cartilage measured: median {tibia['median_mm']:.2f} mm, {tibia['min_mm']:.2f} to {tibia['max_mm']:.2f} mm "
          f"({100 * tibia['measured_area_share']:.0f} % of its area above the bone); femoral layer {FEMORAL_LAYER_MM} mm")
    plot(args.out / "pressure.png", at_first_window)
    (args.out / "numbers.json").write_text(json.dumps(numbers, indent=2), encoding="utf-8")
    print(f"picture {args.out / 'pressure.png'}")
    return numbers


if __name__ == "__main__":
    main()
