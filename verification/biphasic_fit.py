"""Kelvin-Voigt EDEM fitted to the biphasic FE's creep of the cylinder layer (docs/campaigns.md#biphasic-fit).

``python -m verification.biphasic_fit [--out DIR] [--mesh-size MM] [--refine MM] [--reuse]``

Real cartilage creeps by interstitial fluid flow; EDEM's viscoelastic bed by one dashpot per spring
(a single relaxation time tau). This script measures what that costs on the ``viscoelastic``
campaign's cylinder scene (``cylinder-layer``: R 20 mm, a bonded 2 mm layer, a rigid plane):

1. the biphasic FE (``[fe] material = "biphasic"``, :mod:`fem_reference.biphasic_contact`; the
   layer model, Taylor-Hood, BDF2; the layer's contact face drains where it is out of contact, its
   cut edges drain, its bonded face does not) under a step of :data:`LOAD_N` held to :data:`TIMES_S`'s
   end (:data:`TIMES_S`: from 1 s on, every sqrt 2, through the consolidation);
2. viscoelastic EDEM with the coupled thin layer and the creeping contact set (the campaign's
   ``coupled`` bed, ``[viscoelastic]``), the same drained matrix (E, nu) and the same time points;
   its single tau fitted by least squares to the FE's displacement history (scipy
   ``least_squares`` on log tau: every time point weighs the same, so every decade of the creep
   weighs alike on this geometric grid);
3. the fitted EDEM's error against the FE at every instant, in displacement, regularised peak and
   contact area (both on M, :func:`verification.metrics.compare_result_dirs`), its worst and when;
4. with ``--refine``, the FE again on a finer mesh and the largest difference between the two
   levels over time (the FE's own mesh error at the level used, at least that large).

Result directories go under ``--out`` (``fe-mesh<size>``, ``edem-<contact set>-tau<tau>``);
``--reuse`` keeps FE directories already there, unchecked against this script's inputs. The FE
dominates the cost: about 4-5 min at 2.0 mm; the fit is 36 EDEM runs in 25 s.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np

SCENE = "cylinder-layer"
#: the drained matrix: the scene's Young's modulus, a cartilage-like drained Poisson's ratio
#: (0-0.1, fem_reference.biphasic; the campaign's 0.42 is a Kelvin-Voigt bed's, not a drained one)
POISSONS_RATIO = 0.1
#: N: the drained equilibrium compresses the layer by 0.27 mm (14 %), as 333 N at nu 0.42 (13 %)
LOAD_N = 200.0
#: mm^4/(N s): cartilage's about 1e-15 m^4/(N s); H_A k = 10.6e-3 mm^2/s, h^2 / (H_A k) = 377 s
PERMEABILITY_MM4_PER_N_S = 1e-3
#: 0, then 1 s to 16384 s every sqrt 2 (to the microsecond; BDF2's step ratio must stay below 1 + sqrt 2)
TIMES_S = [0.0] + [round(2.0 ** (k / 2), 6) for k in range(29)]
MESH_SIZE_MM = 2.0
METRICS = (("displacement", "displacement_rel_error", "displacement_a_mm", "displacement_b_mm"),
           ("regularised peak", "regularised_peak_pressure_rel_error", "regularised_peak_pressure_a_mpa", "regularised_peak_pressure_b_mpa"),
           ("contact area", "contact_area_rel_error", "contact_area_a_mm2", "contact_area_b_mm2"))


def load_overrides() -> dict[str, Any]:
    """The step history and the drained matrix (both sides); the bone moves along z only (the FE
    fixes ty, which frictionless contact on the cylinder's line cannot hold)."""
    return {"cartilage.poissons_ratio": POISSONS_RATIO, "load.time_s": TIMES_S, "constraints.fixed_dofs": ["tx", "ty", "rx", "ry", "rz"],
            "load.force_n": [[0.0, 0.0, 0.0]] + [[0.0, 0.0, LOAD_N]] * (len(TIMES_S) - 1)}


def fe_overrides() -> dict[str, Any]:
    return {**load_overrides(), "fe.material": "biphasic", "biphasic.permeability_mm4_per_n_s": PERMEABILITY_MM4_PER_N_S}


#: ``[viscoelastic]`` of each contact set of the coupled bed (the viscoelastic campaign's BEDS)
CONTACT_SETS = {"frozen": {"viscoelastic.contact_set": "frozen", "viscoelastic.integrator": "exact"},
                "creeping": {"viscoelastic.contact_set": "creeping", "viscoelastic.integrator": "bdf2"}}
#: the fitted bed's contact set by default: the viscoelastic campaign's (creeping)
CONTACT_SET = "creeping"


def edem_overrides(tau_s: float, contact_set: str = CONTACT_SET) -> dict[str, Any]:
    """The campaign's coupled bed with relaxation time tau and ``contact_set`` (:data:`CONTACT_SETS`)."""
    return {**load_overrides(), "cartilage.coupling": "thin-layer", "viscoelastic.relaxation_time_s": float(tau_s),
            **CONTACT_SETS[contact_set]}


def _run(side: str, overrides: dict[str, Any], out: Path, options: dict[str, Any] | None = None) -> Path:
    import shutil

    from verification.sides import run_side
    from verification.status import OK

    if (out / "summary.json").exists():  # this script's own result of an earlier run: replaced
        shutil.rmtree(out)
    outcome = run_side(side, SCENE, overrides, out, options)
    if outcome.status != OK:
        raise SystemExit(f"biphasic_fit: the {side} side {outcome.status}: {outcome.message}")
    return Path(outcome.result_dir)


def run_fe(out: Path, mesh_size_mm: float, reuse: bool) -> Path:
    target = out / f"fe-mesh{mesh_size_mm:g}"
    if reuse and (target / "summary.json").exists():
        return target
    return _run("fe-layer", fe_overrides(), target, {"mesh_size_mm": mesh_size_mm, "degree": 2})


def edem_displacement_mm(tau_s: float, contact_set: str = CONTACT_SET) -> np.ndarray:
    """EDEM's displacement of G along z at every time point (no result directory: the fit's inner loop)."""
    from edem.scene import load_scene
    from edem.solver import run

    result = run(load_scene(SCENE, edem_overrides(tau_s, contact_set)), "edem")
    return np.array([s.displacement_mm[2] for s in result.steps])


def fit_tau(time_s: np.ndarray, fe_disp_mm: np.ndarray, contact_set: str = CONTACT_SET) -> tuple[float, float]:
    """(tau in s, rms residual in mm): least squares of EDEM's displacement on the FE's over the
    loaded time points, on log tau, from the time the FE creeps 63 % of the way from its first
    loaded value to its last."""
    from scipy.optimize import least_squares

    loaded = time_s > 0
    u = fe_disp_mm[loaded]
    start = float(np.interp(u[0] + (1 - math.exp(-1)) * (u[-1] - u[0]), u, time_s[loaded]))
    fit = least_squares(lambda x: edem_displacement_mm(math.exp(x[0]), contact_set)[loaded] - u, [math.log(start)], diff_step=1e-3, xtol=1e-6)
    return math.exp(fit.x[0]), float(np.sqrt(np.mean(fit.fun**2)))


def error_table(comparison: dict[str, Any], tau_s: float) -> tuple[list[str], dict[str, tuple[float, float]]]:
    """Lines of the error over time, and per metric its worst (error, time)."""
    lines = [f"{'t (s)':>9} {'t/tau':>7} | " + " | ".join(f"{name:^30}" for name, *_ in METRICS),
             f"{'':>9} {'':>7} | " + " | ".join(f"{'FE':>9} {'EDEM':>9} {'error':>8}" for _ in METRICS)]
    worst = {name: (0.0, math.nan) for name, *_ in METRICS}
    for entry in comparison["per_time"]:
        t = entry["time_b_s"]
        if entry["load_n"] == 0.0:
            continue
        cells = []
        for name, key, a, b in METRICS:
            fe, ed = entry[b], entry[a]
            fe, ed = (fe[2], ed[2]) if isinstance(fe, list) else (fe, ed)
            err = float(entry[key])  # signed: EDEM above the FE is positive
            if abs(err) > abs(worst[name][0]):
                worst[name] = (err, t)
            cells.append(f"{fe:9.4g} {ed:9.4g} {100 * err:7.1f}%")
        lines.append(f"{t:9.4g} {t / tau_s:7.3g} | " + " | ".join(cells))
    return lines, worst


def mesh_difference(coarse: Path, fine: Path) -> dict[str, tuple[float, float, float]]:
    """Per metric the largest |coarse - fine| / fine over the loaded time points, when, and the
    difference at the last time point (the equilibrium)."""
    from verification.metrics import compare_result_dirs

    loaded = [e for e in compare_result_dirs(coarse, fine)["per_time"] if e["load_n"] > 0]
    out = {}
    for name, key, *_ in METRICS:
        e = max(loaded, key=lambda e: abs(e[key]))
        out[name] = (abs(float(e[key])), e["time_b_s"], abs(float(loaded[-1][key])))
    return out


def main(argv: list[str] | None = None) -> int:
    from verification.metrics import compare_result_dirs

    parser = argparse.ArgumentParser(prog="python -m verification.biphasic_fit", description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("results/biphasic-fit"), help="result directories (default results/biphasic-fit)")
    parser.add_argument("--mesh-size", type=float, default=MESH_SIZE_MM, help=f"the FE's element size in mm (default {MESH_SIZE_MM:g})")
    parser.add_argument("--refine", type=float, default=None,
                        help="also the FE at this element size, for its mesh error (the layer model puts ceil(2 mm / size) cells "
                             "through the layer and subdivides M's triangles only below their mean edge, 0.97 mm here)")
    parser.add_argument("--contact-set", choices=tuple(CONTACT_SETS), default=CONTACT_SET,
                        help=f"the Kelvin-Voigt bed's contact set (default {CONTACT_SET}; frozen: the thesis's increment)")
    parser.add_argument("--reuse", action="store_true", help="keep FE result directories already in --out (not checked against the inputs)")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)

    fe_dir = run_fe(args.out, args.mesh_size, args.reuse)
    from edem.resultdir import read_result_dir

    fe = read_result_dir(fe_dir)
    time_s = np.asarray(fe.time_s, dtype=float)
    tau, rms = fit_tau(time_s, np.asarray(fe.timeseries["disp_z_mm"], dtype=float), args.contact_set)
    edem_dir = _run("edem", edem_overrides(tau, args.contact_set), args.out / f"edem-{args.contact_set}-tau{tau:.4g}")
    comparison = compare_result_dirs(edem_dir, fe_dir)
    lines, worst = error_table(comparison, tau)
    from edem.scene import load_scene

    youngs = load_scene(SCENE).cartilage.youngs_modulus_mpa
    print(f"biphasic FE (layer model, TH, {args.mesh_size:g} mm, BDF2; E {youngs:g} MPa, "
          f"nu {POISSONS_RATIO:g}, k {PERMEABILITY_MM4_PER_N_S:g} mm^4/(N s), {LOAD_N:g} N step) against Kelvin-Voigt EDEM "
          f"(coupled layer, {args.contact_set} contact set) with the fitted tau = {tau:.4g} s (rms displacement residual {rms:.3g} mm)")
    print("\n".join(lines))
    for name, (err, t) in worst.items():
        print(f"worst {name} error: {100 * err:.1f} % at t = {t:.4g} s ({t / tau:.3g} tau)")
    name, (err, t) = max(worst.items(), key=lambda kv: abs(kv[1][0]))
    print(f"worst over the history: {100 * err:.1f} % ({name}) at t = {t:.4g} s ({t / tau:.3g} tau)")
    if args.refine is not None:
        fine = run_fe(args.out, args.refine, args.reuse)
        for name, (diff, t, last) in mesh_difference(fe_dir, fine).items():
            print(f"FE mesh {args.mesh_size:g} mm against {args.refine:g} mm: {name} differs by at most {100 * diff:.2f} % "
                  f"(t = {t:.4g} s), {100 * last:.2f} % at the last time point")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
