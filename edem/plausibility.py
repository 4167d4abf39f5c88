"""A new user's likely mistakes, said before they become a plausible-looking exit 0 (docs/conventions.md#plausibility-checks).

Small pure checks, each with one call site: a modulus or a load outside physiological ranges
(units mixed up), `[load]` bodies that contradict `[opensim]`, a motion in degrees read as
radians, bodies that look swapped, warnings repeated at many time points, and the Python
warning class that carries the run's warnings to `edem.solve`'s caller.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from geometries.errors import InputError

if TYPE_CHECKING:
    from edem.loads import LoadSeries
    from geometries.surface import TriangleSurface

#: Young's moduli of articular cartilage in the literature lie between about 0.1 MPa (equilibrium)
#: and 100 MPa (instantaneous); bone is 1e3-2e4 MPa. Above 1e4 MPa the number is most likely Pa
#: (cartilage in Pa is 1e5-1e8), below 0.05 MPa most likely GPa (cartilage up to 50 MPa, in GPa).
MODULUS_LOOKS_LIKE_PA_MPA = 1e4
MODULUS_LOOKS_LIKE_GPA_MPA = 0.05
#: Joint contact loads of weight-bearing activities: 0.5 to about 10 body weights (a peak of 3-6
#: in the ankle during walking), for adults of 40-150 kg (400-1500 N): about 200 N to 15 kN.
#: Below 20 N the peak reads like kN or body weights (0.2-15); from 20 to 200 N like a mass in kg
#: (an adult's 40-150 kg); above 2e4 N (over 13 body weights of 150 kg) like mN or a scale applied twice.
LOAD_LOOKS_LIKE_KN_N = 20.0
LOAD_LOOKS_LIKE_KG_N = 200.0
LOAD_TOO_LARGE_N = 2e4
#: A mean unit normal shorter than this says nothing about where F lies (a closed or wrapped mesh).
MEAN_NORMAL_MIN = 0.3


class EdemWarning(UserWarning):
    """A run's warning (the lines `edem run` prints and `summary.json` lists) raised by `edem.solve`."""


def modulus_warning(youngs_modulus_mpa: float) -> list[str]:
    """A cartilage modulus outside 0.05-1e4 MPa, with the unit it looks like."""
    if youngs_modulus_mpa > MODULUS_LOOKS_LIKE_PA_MPA:
        return [f"[cartilage] youngs_modulus_mpa = {youngs_modulus_mpa:g} MPa looks like Pa (cartilage is 0.1-100 MPa, "
                f"bone up to 2e4): if it is Pa, write {youngs_modulus_mpa / 1e6:g}"]
    if youngs_modulus_mpa < MODULUS_LOOKS_LIKE_GPA_MPA:
        return [f"[cartilage] youngs_modulus_mpa = {youngs_modulus_mpa:g} MPa looks like GPa (cartilage is 0.1-100 MPa): "
                f"if it is GPa, write {youngs_modulus_mpa * 1e3:g}"]
    return []


def load_magnitude_warning(force_n: np.ndarray, is_history: bool) -> list[str]:
    """The peak of a load history (a file or a time_s series) outside 20 N - 20 kN, with the unit
    it looks like. A single static load is taken as written (verification cases press with 1 N)."""
    if not is_history:
        return []
    peak = float(np.linalg.norm(force_n, axis=1).max())
    if peak < LOAD_LOOKS_LIKE_KN_N:
        return [f"the load peaks at {peak:.4g} N, while a loaded joint carries 200 N to 15 kN: it looks like kN or body "
                "weights ([load] force_scale = 1000 for kN, or the body weight in N)"]
    if peak < LOAD_LOOKS_LIKE_KG_N:
        return [f"the load peaks at {peak:.4g} N, less than a third of an adult's body weight, while a loaded joint "
                "carries 200 N to 15 kN: it looks like a mass in kg ([load] force_scale = 9.81)"]
    if peak > LOAD_TOO_LARGE_N:
        return [f"the load peaks at {peak:.4g} N, over 13 body weights of a 150 kg adult: it looks like mN or a scale "
                "applied twice (check [load] force_scale and the file's units)"]
    return []


def swapped_bodies_warning(normals: np.ndarray, areas_mm2: np.ndarray, force_n: np.ndarray) -> list[str]:
    """The load pulls M away from F at every loaded time point (over a fifth of the peak): the
    bodies or the load's sign look swapped. F lies along M's area-weighted mean normal; a
    surface whose normals cancel (a closed bone) says nothing."""
    mean = (normals * areas_mm2[:, None]).sum(axis=0) / max(float(areas_mm2.sum()), 1e-300)
    if np.linalg.norm(mean) < MEAN_NORMAL_MIN:
        return []
    magnitude = np.linalg.norm(force_n, axis=1)
    loaded = magnitude > 0.2 * magnitude.max()
    if not loaded.any():
        return []
    cosine = force_n[loaded] @ (mean / np.linalg.norm(mean)) / magnitude[loaded]
    if cosine.max() >= -0.5:
        return []
    return [f"the load pulls the mobile body away from the fixed one at every loaded time point (its direction makes "
            f"at least {math.degrees(math.acos(cosine.max())):.0f} deg with the mobile surface's mean normal, which "
            "points to F): the bodies look swapped (M carries the springs and is pressed into F) or the load is the "
            "joint's reaction on M (a JointReaction on [load] mobile_body is negated: check mobile_body and fixed_body)"]


def scene_warnings(youngs_modulus_mpa: float, load: LoadSeries, load_table: dict[str, Any], mobile: TriangleSurface) -> list[str]:
    """Every pre-solve plausibility warning of a scene: the modulus, the load's magnitude, its direction."""
    is_history = "file" in load_table or "time_s" in load_table
    return (modulus_warning(youngs_modulus_mpa) + load_magnitude_warning(load.force_n, is_history)
            + swapped_bodies_warning(mobile.unit_normals, mobile.areas_mm2, load.force_n))


def check_load_bodies(load_table: dict[str, Any], opensim_table: dict[str, Any], scene_file: str | Path) -> None:
    """`[load]` mobile_body / fixed_body must name the bodies `[opensim]` names (exit 2 naming the key)."""
    for key, other in (("mobile_body", "fixed_body"), ("fixed_body", "mobile_body")):
        given, model = load_table.get(key), opensim_table.get(key)
        if given is None or model is None or given == model:
            continue
        swapped = " (the two bodies look swapped)" if given == opensim_table.get(other) else ""
        raise InputError(f"[load] {key} = {given!r} but [opensim] {key} = {model!r}{swapped}", file=scene_file, key=f"load.{key}",
                         expected=f"the same body in both sections, or no {key} in [load]")


def check_motion_units(name: str, values: np.ndarray, in_degrees: bool | None, range_rad: tuple[float, float],
                       motion_file: Path, key: str) -> list[str]:
    """A rotational coordinate beyond a full turn while the motion says radians looks like degrees:
    exit 2 with the hint when the model's range for it excludes the value too (not an
    interpenetration later), a warning with the hint when the range allows it."""
    if in_degrees:
        return []
    worst = float(values[np.argmax(np.abs(values))])
    if abs(worst) <= 2.0 * math.pi:
        return []
    low, high = range_rad
    problem = (f"coordinate '{name}' reaches {worst:g} rad ({math.degrees(worst):g} deg) with inDegrees="
               f"{'no' if in_degrees is False else '(absent)'}, more than a full turn")
    expected = "inDegrees=yes in the header when the rotations are in degrees"
    if not low <= worst <= high:
        raise InputError(f"{problem} and outside the model's range [{low:g}, {high:g}] rad: the values look like degrees",
                         file=motion_file, key=key, expected=expected)
    return [f"{motion_file}: {problem}: the values look like degrees ({expected})"]


_TIME_POINT = re.compile(r"^time point (?P<k>\d+) \(t = (?P<t>[^ ),]+) s\): ")
_NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:e[+-]?\d+)?")


def merge_repeated(warnings: list[str]) -> list[str]:
    """One line per warning said at several time points: 'at N time points (k = a-b, t = ta-tb s):
    text', where a number that differs between them becomes its range ('5-120 springs'); a
    warning said several times at no time point becomes 'text (N times)'. First-seen order."""
    groups: dict[tuple[bool, tuple[str, ...]], list[tuple[str, str, str, list[str]]]] = {}
    for warning in warnings:
        match = _TIME_POINT.match(warning)
        text = warning[match.end():] if match else warning
        template = (bool(match), tuple(_NUMBER.split(text)))
        groups.setdefault(template, []).append((warning, *((match["k"], match["t"]) if match else ("", "")), _NUMBER.findall(text)))
    merged = []
    for (at_time_points, parts), said in groups.items():
        if len(said) == 1 or (not at_time_points and len({w for w, *_ in said}) > 1):
            merged.extend(w for w, *_ in said)  # alike but not the same, and at no time point: kept
            continue
        slots = [min(values, key=float) + ("" if len(set(values)) == 1 else "-" + max(values, key=float))
                 for values in zip(*(numbers for *_, numbers in said))]
        text = "".join(part + slot for part, slot in zip(parts, [*slots, ""]))
        if at_time_points:
            merged.append(f"at {len(said)} time points (k = {said[0][1]}-{said[-1][1]}, t = {said[0][2]}-{said[-1][2]} s): {text}")
        else:
            merged.append(f"{text} ({len(said)} times)")
    return merged


def emit(warnings: list[str] | tuple[str, ...]) -> None:
    """Each warning as a Python warning of class EdemWarning (the Python API's voice)."""
    import warnings as python_warnings

    for text in warnings:
        python_warnings.warn(text, EdemWarning, stacklevel=3)
