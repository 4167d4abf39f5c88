"""Worked example 3 (notebook style): meshes made in numpy, ``edem.Scene.from_arrays``, and the
Winkler closed form.

What it shows
-------------
A rigid paraboloid (radius of curvature R = 50 mm) pressed by 50, 100 and 200 N into a flat plate
with a bonded cartilage layer of thickness t (the linear gap law, E 10 MPa, nu 0.3), built from
numpy arrays with :meth:`edem.Scene.from_arrays` (no file), solved by DEM with both beds:
independent springs (``coupling="none"``) and the coupled thin layer (``"thin-layer"``). The
plate carries the springs (mobile body M, pushed up by the load); the paraboloid is the fixed body
F, its apex touching the layer at no load. Each ``# %%`` cell runs on its own in an editor that
knows them (VS Code, Spyder, Jupytext).

Closed form (elastic foundation, gap law; E' = E (1 - nu) / ((1 + nu)(1 - 2 nu)), the confined
modulus): an approach d gives p(r) = E' (d - r^2 / (2 R)) / t inside the contact radius
a = sqrt(2 R d), so F = pi E' R d^2 / t, d = sqrt(F t / (pi E' R)), peak p0 = E' d / t.

Expected numbers (checked by tests/test_examples.py)
----------------------------------------------------
- independent springs, t = 2 mm: d = 0.217 / 0.308 / 0.435 mm, a = 4.66 / 5.55 / 6.59 mm,
  peak 1.46 / 2.07 / 2.93 MPa at 50 / 100 / 200 N (and t = 0.5 mm). The springs match the closed
  form to the discretisation of 0.4 mm springs: measured within 0.2 % (d), 0.5 % (peak) and 0.7 %
  (area against pi a^2); asserted within 1 %, 1 % and 2 % (``TOLERANCE``: twice to five times
  that), far below the 15 % by which a Hertzian answer (F ~ d^1.5) would differ over this load
  range;
- the coupled thin layer is the bonded layer, whose long-wave limit is the same foundation: its
  approach exceeds the closed form by about 1 % at t = 2 mm (t/a 0.3-0.43) and by a third of
  that at t = 0.5 mm (t/a 0.11-0.15), so its departure shrinks with t/a; asserted: at every load
  the t = 0.5 mm departure is under 0.6 of the t = 2 mm one (the t/a ratio is 0.35);
- with both beds the contact pressures sum to the load (1e-9: the solver's balance).

Data: none (the meshes are made here). Output: ``--out`` (default
``results/examples/paraboloid``): ``numbers.json`` and ``pressure.png``, the pressure against the
radius at 200 N for both beds with the closed form.

Run: ``PYTHONPATH=. python docs/examples/paraboloid_from_arrays.py [--out DIR]`` (about a minute:
the coupled layer's solves take most of it).
"""

# %% Imports and the problem
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import edem

ROOT = Path(__file__).resolve().parents[2]
RADIUS_MM = 50.0
YOUNGS_MODULUS_MPA = 10.0
POISSONS_RATIO = 0.3
LOADS_N = np.array([50.0, 100.0, 200.0])
THICKNESSES_MM = (2.0, 0.5)
SPRING_SIZE_MM = 0.4  # the plate's grid spacing
TOLERANCE = {"approach": 0.01, "peak": 0.01, "area": 0.02}
CONFINED_MPA = YOUNGS_MODULUS_MPA * (1 - POISSONS_RATIO) / ((1 + POISSONS_RATIO) * (1 - 2 * POISSONS_RATIO))


# %% Meshes in numpy
def grid(half_width_mm: float, spacing_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """A square grid in the plane z = 0, two triangles per cell, normals +z: vertices (n, 3) mm
    and triangles (m, 3)."""
    n = int(round(2 * half_width_mm / spacing_mm))
    x, y = np.meshgrid(np.linspace(-half_width_mm, half_width_mm, n + 1), np.linspace(-half_width_mm, half_width_mm, n + 1), indexing="ij")
    vertices = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    i = np.arange(x.size).reshape(x.shape)
    a, b, c, d = i[:-1, :-1].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel(), i[:-1, 1:].ravel()
    return vertices, np.vstack([np.column_stack([a, b, c]), np.column_stack([a, c, d])])


def paraboloid_scene(thickness_mm: float, coupling: str) -> edem.Scene:
    """The plate (M, springs up) under the paraboloid (F, apex at z = t, normals down)."""
    plate_vertices, plate_triangles = grid(12.0, SPRING_SIZE_MM)
    cap_vertices, cap_triangles = grid(13.0, 0.25)  # finer than the springs: its chords err by 1e-4 mm
    cap_vertices[:, 2] = thickness_mm + (cap_vertices[:, 0] ** 2 + cap_vertices[:, 1] ** 2) / (2 * RADIUS_MM)
    force = np.column_stack([np.zeros_like(LOADS_N), np.zeros_like(LOADS_N), LOADS_N])
    return edem.Scene.from_arrays(
        plate_vertices, plate_triangles, cap_vertices, cap_triangles[:, ::-1], force,
        youngs_modulus_mpa=YOUNGS_MODULUS_MPA, poissons_ratio=POISSONS_RATIO, law="gap", thickness_mm=thickness_mm,
        max_spring_length_mm=thickness_mm + 3.0, coupling=coupling, fixed_dofs=("tx", "ty", "rx", "ry", "rz"),
        method="dem", name=f"paraboloid-t{thickness_mm:g}-{coupling}",
    )


# %% The closed form
def winkler(force_n: np.ndarray, thickness_mm: float) -> dict[str, np.ndarray]:
    approach = np.sqrt(force_n * thickness_mm / (np.pi * CONFINED_MPA * RADIUS_MM))
    radius = np.sqrt(2 * RADIUS_MM * approach)
    return {"approach_mm": approach, "radius_mm": radius, "area_mm2": np.pi * radius**2, "peak_mpa": CONFINED_MPA * approach / thickness_mm}


# %% Solve both beds and compare
def solve_case(thickness_mm: float, coupling: str) -> tuple[edem.RunResult, dict]:
    start = time.perf_counter()
    run = edem.solve(paraboloid_scene(thickness_mm, coupling), method="dem")
    wall_s = time.perf_counter() - start
    closed = winkler(LOADS_N, thickness_mm)
    area = run.scene.spring_area_mm2
    measured = {
        "approach_mm": [float(s.displacement_mm[2]) for s in run.steps],
        "area_mm2": [s.contact_area_mm2 for s in run.steps],
        "peak_mpa": [s.peak_pressure_mpa for s in run.steps],
        "pressure_sum_n": [float((s.pressure_mpa * area).sum()) for s in run.steps],
    }
    numbers = {**measured, **{f"closed_{k}": v.tolist() for k, v in closed.items()},
               **{f"{k}_ratio": (np.array(measured[k]) / closed[k]).tolist() for k in ("approach_mm", "area_mm2", "peak_mpa")},
               "wall_time_s": wall_s}
    return run, numbers


def plot(path: Path, runs: dict[str, edem.RunResult], thickness_mm: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for (bed, run), style in zip(runs.items(), ("C0.", "C1x")):
        r = np.hypot(*run.scene.spring_centroid_mm[:, :2].T)
        near = r < 9.0
        ax.plot(r[near], run.steps[-1].pressure_mpa[near], style, ms=2, label=f"DEM, {bed}")
    closed = winkler(LOADS_N[-1:], thickness_mm)
    r = np.linspace(0.0, 9.0, 200)
    ax.plot(r, np.maximum(CONFINED_MPA * (closed["approach_mm"][0] - r**2 / (2 * RADIUS_MM)) / thickness_mm, 0.0), "k-",
            label="closed form (elastic foundation)")
    ax.set_xlabel("radius (mm)")
    ax.set_ylabel("contact pressure (MPa)")
    ax.set_title(f"paraboloid R {RADIUS_MM:g} mm on a {thickness_mm:g} mm layer, {LOADS_N[-1]:g} N")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


# %% Run it all
def main(argv: list[str] | None = None) -> dict:
    """Run the example; return the measured numbers (also written to ``OUT/numbers.json``)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "examples" / "paraboloid")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    numbers: dict = {"loads_n": LOADS_N.tolist()}
    for thickness in THICKNESSES_MM:
        runs = {}
        for coupling in ("none", "thin-layer"):
            runs[coupling], case = solve_case(thickness, coupling)
            numbers[f"t={thickness:g}/{coupling}"] = case
            print(f"t = {thickness:g} mm, {coupling:10s}: approach / closed form "
                  + " ".join(f"{x:.4f}" for x in case["approach_mm_ratio"]) + ", area / pi a^2 "
                  + " ".join(f"{x:.4f}" for x in case["area_mm2_ratio"]) + ", peak / p0 "
                  + " ".join(f"{x:.4f}" for x in case["peak_mpa_ratio"]) + f" ({case['wall_time_s']:.1f} s)")
        if thickness == THICKNESSES_MM[0]:
            plot(args.out / "pressure.png", runs, thickness)
            closed = winkler(LOADS_N, thickness)
            print(f"closed form, t = {thickness:g} mm: d " + " / ".join(f"{x:.3f}" for x in closed["approach_mm"]) + " mm, a "
                  + " / ".join(f"{x:.2f}" for x in closed["radius_mm"]) + " mm, p0 " + " / ".join(f"{x:.2f}" for x in closed["peak_mpa"]) + " MPa")
    (args.out / "numbers.json").write_text(json.dumps(numbers, indent=2), encoding="utf-8")
    print(f"picture {args.out / 'pressure.png'}")
    return numbers


if __name__ == "__main__":
    main()
