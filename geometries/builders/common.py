"""What every builder shares: the result types, the parameter specifications and their
validation (errors name the key ``geometry.<param>``), and the pieces of the ankle builders
(rotation about y, ligament placement) (docs/method.md#8-built-in-geometries)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from geometries.errors import InputError
from geometries.surface import TriangleSurface


# --------------------------------------------------------------------------------------------
# result types
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LigamentAttachment:
    """A ligament as a straight line from a point on the talus (M) to a point on tibia/fibula (F).

    The fibula is taken as rigidly attached to the tibia (one fixed body). The rest length is not
    stored: the solver takes the distance at the neutral pose, so every ligament is slack (zero
    force) at the neutral pose and only pulls when stretched.
    """

    name: str
    mobile_point_mm: np.ndarray
    fixed_point_mm: np.ndarray


@dataclass(frozen=True)
class BuiltGeometry:
    """Result of a builder: both surfaces, the ankle axis, ligaments, description, parameters."""

    mobile: TriangleSurface
    fixed: TriangleSurface
    reference_point_mm: np.ndarray | None  # None = centroid of the mobile surface
    ankle_axis_point_mm: np.ndarray
    ankle_axis_direction: np.ndarray
    ligaments: tuple[LigamentAttachment, ...]
    description: str  # what it represents, where its numbers come from
    parameters: dict = field(default_factory=dict)  # the resolved parameters (defaults filled in)
    # With articular cartilage (docs/method.md#8-built-in-geometries): mobile and fixed above are the
    # articular surfaces and these the subchondral bones under them, read as a scene's bone meshes
    # (docs/method.md#measured-cartilage-thickness); None: mobile and fixed are the bones.
    mobile_bone: TriangleSurface | None = None
    fixed_bone: TriangleSurface | None = None
    contact_point_mm: np.ndarray | None = None  # where the articular surfaces touch at zero load (on M)


# --------------------------------------------------------------------------------------------
# parameter validation
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Param:
    """Specification of one builder parameter (type, range) for validation and documentation."""

    kind: str  # "float" | "int" | "bool" | "seed" | "float_or_none" | "pairs" | "floats"
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False  # lo excluded
    length: int | None = None  # for "pairs" / "floats"

    def describe(self) -> str:
        base = {
            "float": "a number",
            "float_or_none": "a number",
            "int": "an integer",
            "bool": "true or false",
            "seed": "an integer seed",
            "pairs": f"a list of {self.length} [x_mm, y_mm] pairs",
            "floats": f"a list of {self.length} numbers",
        }[self.kind]
        if self.lo is not None or self.hi is not None:
            lo = "-inf" if self.lo is None else f"{self.lo:g}"
            hi = "inf" if self.hi is None else f"{self.hi:g}"
            base += f" in {'(' if self.lo_open else '['}{lo}, {hi}]"
        return base


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(
        v, (bool, np.bool_))


def _check_value(builder: str, name: str, spec: Param, value: Any) -> Any:
    try:
        return _checked_value(builder, name, spec, value)
    except OverflowError:  # an integer such as 10**400 has no float64 value
        raise InputError(f"{builder}: an integer too large for a float64", key=f"geometry.{name}",
                         expected=spec.describe()) from None


def _checked_value(builder: str, name: str, spec: Param, value: Any) -> Any:
    key = f"geometry.{name}"

    def bad(problem: str) -> InputError:
        return InputError(f"{builder}: {problem}", key=key, expected=spec.describe())

    def in_range(x: float) -> bool:
        if spec.lo is not None and (x < spec.lo or (spec.lo_open and x <= spec.lo)):
            return False
        if spec.hi is not None and x > spec.hi:
            return False
        return True

    if spec.kind == "bool":
        if not isinstance(value, (bool, np.bool_)):
            raise bad(f"wrong type {type(value).__name__}")
        return bool(value)
    if spec.kind in ("int", "seed"):
        if spec.kind == "seed" and value is None:
            return None
        if not isinstance(value, (int, np.integer)) or isinstance(value, (bool, np.bool_)):
            raise bad(f"wrong type {type(value).__name__}")
        if not in_range(float(value)):
            raise bad(f"value {value} out of range")
        return int(value)
    if spec.kind in ("float", "float_or_none"):
        if spec.kind == "float_or_none" and value is None:
            return None
        if not _is_number(value):
            raise bad(f"wrong type {type(value).__name__}")
        x = float(value)
        if not math.isfinite(x) or not in_range(x):
            raise bad(f"value {value} out of range")
        return x
    if spec.kind == "floats":
        try:
            arr = [float(v) for v in value] if not isinstance(value, (str, bytes)) else None
        except TypeError:
            arr = None
        if arr is None or any(not _is_number(v) for v in value) or len(arr) != spec.length:
            raise bad("wrong type or length")
        if not all(math.isfinite(x) and in_range(x) for x in arr):
            raise bad(f"value {value} out of range")
        return tuple(arr)
    if spec.kind == "pairs":
        if value is None:
            return None
        ok = not isinstance(value, (str, bytes)) and hasattr(value, "__len__")
        if ok and len(value) == spec.length:
            out = []
            for pair in value:
                if (isinstance(pair, (str, bytes)) or not hasattr(pair, "__len__") or len(pair) != 2
                        or not all(_is_number(v) and math.isfinite(float(v)) for v in pair)):
                    ok = False
                    break
                out.append((float(pair[0]), float(pair[1])))
            if ok:
                return tuple(out)
        raise bad("wrong type or length")
    raise AssertionError(spec.kind)  # pragma: no cover


def validate_parameters(builder: str, specs: dict[str, Param], given: dict[str, Any]) -> dict[str, Any]:
    unknown = sorted(set(given) - set(specs))
    if unknown:
        raise InputError(
            f"unknown parameter '{unknown[0]}' for geometry builder '{builder}'",
            key=f"geometry.{unknown[0]}",
            expected="one of " + ", ".join(specs),
        )
    return {k: _check_value(builder, k, specs[k], v) for k, v in given.items()}


def mode_parameters(builder: str, checked: dict[str, Any], thesis_defaults: dict[str, Any], cartilage_defaults: dict[str, Any]) -> dict[str, Any]:
    """An ankle builder's parameters for its mode (docs/method.md#8-built-in-geometries):
    ``checked["cartilage"]`` picks the bones with cartilage or the thesis's geometry; a parameter
    only the other mode has is refused when given (None: not given) and dropped, and this
    mode's unset ones take their defaults."""
    cartilage = checked["cartilage"]
    own, other = (cartilage_defaults, thesis_defaults) if cartilage else (thesis_defaults, cartilage_defaults)
    out = dict(checked)
    for name in other:
        if name in own:
            continue
        if out.pop(name, None) is not None:
            raise InputError(
                f"{builder}: {name} is a parameter of the {'thesis geometry (cartilage = false)' if cartilage else 'bones with cartilage (cartilage = true)'}",
                key=f"geometry.{name}",
                expected=(f"no {name} with cartilage = true (the tibia is placed so that the articular surfaces touch)" if cartilage
                          else f"cartilage = true for {name}, or no {name} for the thesis geometry"),
            )
    for name, default in own.items():
        if out.get(name) is None:
            out[name] = default
    return out


# --------------------------------------------------------------------------------------------
# shared pieces
# --------------------------------------------------------------------------------------------


def ankle_geometry(radius_mm: float, mobile: TriangleSurface, fixed: TriangleSurface, ligaments: tuple[LigamentAttachment, ...],
                   description: str, parameters: dict, bones: tuple[TriangleSurface, TriangleSurface] | None = None,
                   contact_point_mm: np.ndarray | None = None) -> BuiltGeometry:
    """An ankle builder's result: the ankle axis is the talar cylinder's, along x through (0, 0,
    -R); G the centroid of M (the default); ``bones`` (talar, tibial) under the articular
    surfaces M and F when the ankle has cartilage."""
    mobile_bone, fixed_bone = bones if bones is not None else (None, None)
    return BuiltGeometry(mobile=mobile, fixed=fixed, reference_point_mm=None, ankle_axis_point_mm=np.array([0.0, 0.0, -radius_mm]),
                         ankle_axis_direction=np.array([1.0, 0.0, 0.0]), ligaments=ligaments, description=description, parameters=parameters,
                         mobile_bone=mobile_bone, fixed_bone=fixed_bone, contact_point_mm=contact_point_mm)


def lifted(ligaments: tuple[LigamentAttachment, ...], lift_mm: float) -> tuple[LigamentAttachment, ...]:
    """The ligaments with their fixed (tibial, fibular) points moved up by ``lift_mm`` with the tibia."""
    up = np.array([0.0, 0.0, lift_mm])
    return tuple(LigamentAttachment(lig.name, lig.mobile_point_mm, lig.fixed_point_mm + up) for lig in ligaments)


def rotation_about_y(angle_rad: float) -> np.ndarray:
    """Rotation about +y; a positive angle moves points with x > 0 downwards (-z)."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def ankle_ligaments(radius: float, half_width: float, medial_x: float, lateral_x: float,
               fixed_rotation: np.ndarray | None = None, pivot: np.ndarray | None = None,
               ) -> tuple[LigamentAttachment, ...]:
    """Four ankle ligaments at plausible (not measured) anatomical positions.

    Talar points lie on the medial (x = -half_width) and lateral (x = +half_width) faces of the
    talus body, below the articular dome (the dome top is z = 0, the axis at z = -R); tibial
    points lie in the medial malleolus (x = medial_x, medial of the malleolar facet), fibular
    points in the lateral malleolus (x = lateral_x). Positions scale with the talar radius R:
      ATiTL anterior tibiotalar: anterior medial malleolus -> medial talar neck (anterior-inferior)
      PTiTL posterior tibiotalar: posterior medial malleolus -> posteromedial talus
      ATFL  anterior talofibular: anterior fibular tip -> lateral talar neck, roughly horizontal
      PTFL  posterior talofibular: fibular malleolar fossa -> posterolateral talar process
    They are slack (zero force) at the neutral pose: the solver takes their neutral length as
    rest length. The fixed points move with the tibia when it is tilted (``fixed_rotation``
    about ``pivot``).
    """
    r, hw = radius, half_width

    def p(*xyz: float) -> np.ndarray:
        return np.array(xyz, dtype=np.float64)

    def f(*xyz: float) -> np.ndarray:
        x = p(*xyz)
        if fixed_rotation is not None:
            c = np.zeros(3) if pivot is None else np.asarray(pivot, dtype=np.float64)
            x = (x - c) @ fixed_rotation.T + c
        return x

    return (
        LigamentAttachment("ATiTL", p(-hw, 0.60 * r, -0.55 * r), f(medial_x, 0.30 * r, -0.25 * r)),
        LigamentAttachment("PTiTL", p(-hw, -0.60 * r, -0.60 * r),
                           f(medial_x, -0.35 * r, -0.30 * r)),
        LigamentAttachment("ATFL", p(hw, 0.65 * r, -0.60 * r), f(lateral_x, 0.05 * r, -0.75 * r)),
        LigamentAttachment("PTFL", p(hw - 3.0, -0.90 * r, -0.85 * r),
                           f(lateral_x, -0.25 * r, -0.75 * r)),
    )
