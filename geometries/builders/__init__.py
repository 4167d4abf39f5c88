"""Built-in geometries of the ankle contact problem (docs/method.md#8-built-in-geometries; thesis sections 4.2.2 and 4.3.3).

Every builder is a plain function with keyword parameters and documented defaults; it returns a
:class:`BuiltGeometry` (the mobile surface M = talus, the fixed surface F = tibia, the ankle axis,
ligament attachment points, a description and the resolved parameters; the ankles with
``cartilage = true``, their default, also the subchondral bones under M and F, which are then the
articular surfaces). ``build_geometry(name,
params)`` is the entry point used by scene files: it looks the builder up by name, validates the
parameters (unknown names, types, ranges) and raises :class:`geometries.errors.InputError` naming the
key ``geometry.<param>``.

Coordinate convention (all builders, mm):
    x = medio-lateral (the ankle axis / talar cylinder axis; +x lateral, -x medial),
    y = posterior -> anterior, z = inferior -> superior.
    The talar dome top is at z = 0 and the talar cylinder axis runs along x through (0, 0, -R).
Normals (right-hand rule on the triangles): mobile normals point out of the talus towards the
tibia; fixed normals point out of the tibia towards the talus (the plafond faces down, the medial
malleolus faces laterally).

Meshing: the curved surfaces (ideal talar cylinder patch, subject-like talus and tibia) are meshed
with gmsh (imported only inside the functions that mesh; a plate or hemisphere scene never loads
it). Meshing is deterministic: one thread, Frontal-Delaunay (algorithm 6), fixed random seed and
random factor; the same parameters give identical arrays. The icosphere hemispheres and the flat
and tilted plates are exact subdivisions / structured grids built with plain numpy (no mesher is
needed for them).

One module per builder (:mod:`.ideal_ankle`, :mod:`.subject_ankle`, :mod:`.hemispheres`,
:mod:`.flat_plates`, :mod:`.tilted_plane`); what they share is in :mod:`.common` and
:mod:`.gmsh_session`. This module holds the registry, the parameter validation entry point
and the per-process cache of built geometries.
"""

from __future__ import annotations

import collections
import copy
import inspect
import json
import warnings
from collections.abc import Callable
from typing import Any

from geometries.builders.common import BuiltGeometry, LigamentAttachment, Param, validate_parameters
from geometries.builders.flat_plates import PLATE_PARAMS, flat_plates
from geometries.builders.hemispheres import HEMISPHERE_PARAMS, hemispheres, icosphere
from geometries.builders.ideal_ankle import IDEAL_ANKLE_PARAMS, ideal_ankle, ideal_candidate_fraction
from geometries.builders.subject_ankle import (SUBJECT_CARTILAGE_ONLY, SUBJECT_DEPRESSION_RANGES, SUBJECT_PARAMS, SUBJECT_RANGES,
                                               SUBJECT_THESIS_ONLY, subject_ankle)
from geometries.builders.tilted_plane import TILTED_PARAMS, tilted_plane
from geometries.errors import InputError

__all__ = [
    "BuiltGeometry",
    "LigamentAttachment",
    "build_geometry",
    "builder_names",
    "builds_bones",
    "ideal_ankle",
    "hemispheres",
    "flat_plates",
    "tilted_plane",
    "subject_ankle",
    "SUBJECT_RANGES",
    "SUBJECT_DEPRESSION_RANGES",
    "SUBJECT_THESIS_ONLY",
    "SUBJECT_CARTILAGE_ONLY",
    "PLATE_PARAMS",
    "icosphere",
    "ideal_candidate_fraction",
    "builder_defaults",
    "clear_geometry_cache",
    "BUILT_CACHE_SIZE",
]

# --------------------------------------------------------------------------------------------
# registry
# --------------------------------------------------------------------------------------------

_BUILDERS: dict[str, tuple[Callable[..., BuiltGeometry], dict[str, Param]]] = {
    "ideal_ankle": (ideal_ankle, IDEAL_ANKLE_PARAMS),
    "hemispheres": (hemispheres, HEMISPHERE_PARAMS),
    "subject_ankle": (subject_ankle, SUBJECT_PARAMS),
    "flat_plates": (flat_plates, PLATE_PARAMS),
    "tilted_plane": (tilted_plane, TILTED_PARAMS),
}


def builder_names() -> tuple[str, ...]:
    """Names accepted by :func:`build_geometry`."""
    return tuple(_BUILDERS)


def builds_bones(name: str, params: dict[str, Any]) -> bool:
    """Whether the builder ``name`` with ``params`` builds bones under articular cartilage (the
    ankles with ``cartilage = true``, their default; docs/method.md#8-built-in-geometries). False
    for an unknown builder or a non-boolean value, which :func:`build_geometry` refuses."""
    if name not in _BUILDERS or "cartilage" not in _BUILDERS[name][1]:
        return False
    return params.get("cartilage", builder_defaults(name)["cartilage"]) is True


def builder_defaults(name: str) -> dict[str, Any]:
    """Keyword defaults of a builder (``None`` = derived at build time)."""
    func = _BUILDERS[name][0]
    return {k: v.default for k, v in inspect.signature(func).parameters.items()}


#: Built geometries kept per process, most recent last: (builder function, parameters as JSON) ->
#: (the geometry, the warnings its build emitted). A campaign worker builds the same geometry
#: for hundreds of cases (the sensitivity grid varies the cartilage, not the bones); meshing is
#: deterministic (module docstring), so a kept geometry is the one a new build would give.
_BUILT: collections.OrderedDict[tuple[Callable[..., BuiltGeometry], str], tuple[BuiltGeometry, tuple[warnings.WarningMessage, ...]]] = collections.OrderedDict()
#: geometries kept: a few (a population's subjects differ, so there the cache only misses)
BUILT_CACHE_SIZE = 4


def _cache_key(func: Callable[..., BuiltGeometry], params: dict[str, Any]) -> tuple[Callable[..., BuiltGeometry], str] | None:
    """The cache key of a build, or None for parameters with no exact JSON text (never cached).

    JSON keeps every float exactly (repr) and tells 1 from 1.0 and true from 1, so two
    parameter sets share a key only when the builder sees the same values. The function, not
    its registered name, is part of the key: a builder replaced under the same name is a miss."""
    try:
        return func, json.dumps(params, sort_keys=True, allow_nan=False)
    except (TypeError, ValueError):
        return None


def clear_geometry_cache() -> None:
    """Forget the built geometries kept by :func:`build_geometry`."""
    _BUILT.clear()


def build_geometry(name: str, params: dict, *, file: str | None = None) -> BuiltGeometry:
    """Build the named geometry with ``params`` (a scene file's ``[geometry]`` parameters).

    The last :data:`BUILT_CACHE_SIZE` geometries are kept per process: a repeated build returns
    a copy of the kept one (the caller may change it freely) and emits again the warnings the
    first build emitted, so each caller sees the same geometry and the same warnings as from a
    fresh build, without meshing again.

    Raises :class:`InputError` (with ``file`` and key ``geometry.<param>``) for an unknown
    builder, unknown parameters, wrong types or out-of-range values.
    """
    if not isinstance(name, str) or name not in _BUILDERS:
        raise InputError(
            f"unknown geometry builder '{name}'",
            file=file,
            key="geometry.builtin",
            expected="one of " + ", ".join(_BUILDERS),
        )
    func, specs = _BUILDERS[name]
    params = dict(params or {})
    try:
        validate_parameters(name, specs, params)
        key = _cache_key(func, params)
        if key is None:
            return func(**params)
        if key in _BUILT:
            _BUILT.move_to_end(key)
            kept, caught = _BUILT[key]
            built = copy.deepcopy(kept)
        else:
            with warnings.catch_warnings(record=True) as record:
                warnings.simplefilter("always")  # every warning kept, to be re-emitted on each build
                built = func(**params)
            caught = tuple(record)
            _BUILT[key] = (copy.deepcopy(built), caught)
            while len(_BUILT) > BUILT_CACHE_SIZE:
                _BUILT.popitem(last=False)
        for w in caught:  # where the builder emitted it and never deduplicated: each build reports its own
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno, source=w.source)
        return built
    except InputError as err:
        if file is not None and err.file is None:
            raise InputError(err.problem, file=file, key=err.key, expected=err.expected) from None
        raise
