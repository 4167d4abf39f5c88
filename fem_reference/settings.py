"""The resolved settings of an FE reference run: model, element, degree, mesh size, layers.

:func:`resolve_settings` takes the arguments first, then the scene's ``[fe]`` table, then the
defaults below. Callers that take the arguments from elsewhere (the command line) pass
``argument_keys`` so that errors name what the user typed.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from edem.laws import LAWS
from fem_reference.biphasic import TIME_SCHEMES as BIPHASIC_TIME_SCHEMES
from fem_reference.biphasic_contact import COUNTER_SURFACES, DEFAULT_COUNTER_SURFACE
from fem_reference.models import FE_MODELS, fixed_has_cartilage
from fem_reference.problem import LINEAR_SOLVERS
from fem_reference.viscoelastic import DEFAULT_TIME_SCHEME, TIME_SCHEMES
from geometries.errors import InputError

ELEMENTS = ("auto", "P1", "P2", "TH")

#: Default degree and mesh sizes (mm), chosen on the ideal ankle for 2 cores (fem_reference.scene_run).
DEFAULT_DEGREE = 2
DEFAULT_MESH_SIZE_MM = {1: 0.5, 2: 1.0}
#: Nearly incompressible cartilage: Taylor-Hood (P2-P1 u-p) by default from this Poisson's ratio.
TAYLOR_HOOD_FROM_NU = 0.49
#: The FE's materials (``[fe] material``): what the cartilage continuum is
MATERIALS = {
    "elastic": "linear elastic; with [viscoelastic] the Kelvin-Voigt continuum",
    "biphasic": "linear biphasic (a drained matrix, the [cartilage] Young's modulus and Poisson's ratio, and "
                "interstitial fluid, [biphasic]), Taylor-Hood",
}

#: the models whose one deformable layer can be biphasic (against a rigid F)
BIPHASIC_MODELS = ("layer", "slab")


@dataclass(frozen=True)
class BiphasicSettings:
    """The scene's ``[biphasic]`` (:mod:`fem_reference.biphasic_contact`)."""

    permeability_mm4_per_n_s: float
    counter_surface: str = DEFAULT_COUNTER_SURFACE


@dataclass(frozen=True)
class FESettings:
    """The resolved FE settings of a run (from the arguments, then the scene's [fe] table, then
    the defaults)."""

    model: str  # a name of fem_reference.models.FE_MODELS
    element: str  # P1 | P2 | TH
    degree: int
    mesh_size_mm: float
    layers_through_thickness: int | None
    # Kelvin-Voigt scenes ([viscoelastic]): fem_reference.viscoelastic.TIME_SCHEMES
    time_scheme: str = DEFAULT_TIME_SCHEME
    # the inner linear solve, a key of fem_reference.problem.LINEAR_SOLVERS
    linear_solver: str = "auto"
    # [fe] material = "biphasic": the scene's [biphasic] (None: elastic)
    biphasic: BiphasicSettings | None = None
    # the surface refined further to this size where the contact can reach (None: mesh_size_mm everywhere)
    contact_mesh_size_mm: float | None = None

    @property
    def method(self) -> str:
        return f"fe-{self.model}"


def resolve_settings(scene: Any, *, model: str | None = None, mesh_size_mm: float | None = None,
                     degree: int | None = None, element: str | None = None,
                     layers_through_thickness: int | None = None, time_scheme: str | None = None,
                     linear_solver: str | None = None, contact_mesh_size_mm: float | None = None,
                     argument_keys: Mapping[str, str] | None = None) -> FESettings:
    """Arguments first, then the scene's ``[fe]`` table, then the defaults.

    model: default the FE twin of the scene's contact law (:mod:`edem.laws`: threshold -> slab,
    gap laws -> layer, or two-layer when F has cartilage of its own).
    element: "auto" (default) is P1 for degree 1 and P2 for degree 2, and Taylor-Hood (P2-P1 u-p,
    degree 2) when nu >= 0.49 unless the degree is given as 1 (P1 then locks: the core warns).
    mesh_size_mm: default :data:`DEFAULT_MESH_SIZE_MM` of the degree.
    contact_mesh_size_mm: a finer size where the contact can reach (the models built on M's layer,
    :func:`fem_reference.models.contact_refinement`); default None, ``mesh_size_mm`` everywhere.
    time_scheme: the implicit scheme of a viscoelastic or biphasic scene (:mod:`fem_reference.viscoelastic`,
    :mod:`fem_reference.biphasic`), default BDF2.
    The scene's ``[fe] material`` (:data:`MATERIALS`, default elastic): "biphasic" takes its
    ``[biphasic]`` table (:func:`biphasic_settings`) and Taylor-Hood.
    linear_solver: the inner linear solve (:data:`fem_reference.problem.LINEAR_SOLVERS`), default
    "auto" (Krylov from 20,000 unknowns for P2 and Taylor-Hood, or where the LU does not fit in memory, direct below).
    argument_keys: how errors name an argument given here (default: its parameter name).
    """
    fe = dict(scene.fe or {})
    file = scene.source
    names = dict(argument_keys or {})

    def pick(arg: Any, key: str) -> tuple[Any, str]:
        if arg is not None:
            return arg, names.get(key, key)
        return fe.get(key), f"fe.{key}"

    value, key = pick(model, "model")
    if value is None:
        value = LAWS[scene.cartilage.law].fe_twin
        if value == "layer" and fixed_has_cartilage(scene):
            value = "two-layer"  # cartilage on both bones: both layers deformable
    if value not in FE_MODELS:
        raise InputError(f"unknown FE model {value!r}", file=file, key=key,
                         expected=" or ".join(f"{m.name} ({m.what})" for m in FE_MODELS.values()))
    fe_model = FE_MODELS[str(value)]

    deg, deg_key = pick(degree, "degree")
    if deg is not None and (isinstance(deg, bool) or deg not in (1, 2)):
        raise InputError(f"{deg!r} is not an element degree", file=file, key=deg_key,
                         expected="1 or 2")
    el, el_key = pick(element, "element")
    if el is None:
        el = "auto"
    if el not in ELEMENTS:
        raise InputError(f"unknown element {el!r}", file=file, key=el_key,
                         expected="auto, P1, P2 or TH (Taylor-Hood P2-P1)")
    material = fe.get("material", "elastic")
    if material not in MATERIALS:
        raise InputError(f"unknown FE material {material!r}", file=file, key="fe.material",
                         expected=" or ".join(f'"{m}" ({what})' for m, what in MATERIALS.items()))
    biphasic_table = biphasic_settings(scene) if material == "biphasic" else None
    if biphasic_table is not None and fe_model.name not in BIPHASIC_MODELS:
        raise InputError(f"the FE {fe_model.name} model has no biphasic layer (only the layer and slab models, one layer on M)", file=file, key="fe.material",
                         expected=f'[fe] material = "elastic", or the {" or ".join(BIPHASIC_MODELS)} model with "biphasic"')
    if biphasic_table is not None:  # displacement and pore pressure: Taylor-Hood
        if el not in ("auto", "TH"):
            raise InputError(f"element {el} cannot carry the fluid pressure", file=file, key=el_key,
                             expected='TH (or auto) with [fe] material = "biphasic"')
        el = "TH"
    nu = float(scene.cartilage.poissons_ratio)
    if el == "auto":
        d = DEFAULT_DEGREE if deg is None else int(deg)
        if nu >= TAYLOR_HOOD_FROM_NU and deg is None:
            el = "TH"
        else:
            el = "P1" if d == 1 else ("TH" if nu >= TAYLOR_HOOD_FROM_NU else "P2")
    el_degree = 1 if el == "P1" else 2
    if deg is not None and int(deg) != el_degree:
        raise InputError(f"element {el} has degree {el_degree}, not {deg}", file=file,
                         key=deg_key, expected=f"degree {el_degree} with element {el}")

    size, size_key = pick(mesh_size_mm, "mesh_size_mm")
    if size is None:
        size = DEFAULT_MESH_SIZE_MM[el_degree]
    if isinstance(size, bool) or not isinstance(size, (int, float)) or not (
            math.isfinite(size) and size > 0):
        raise InputError(f"{size!r} is not a mesh size", file=file, key=size_key,
                         expected="a length in mm > 0")
    fine, fine_key = pick(contact_mesh_size_mm, "contact_mesh_size_mm")
    if fine is not None and (isinstance(fine, bool) or not isinstance(fine, (int, float)) or not (
            math.isfinite(fine) and 0 < fine < size)):
        raise InputError(f"{fine!r} is not a contact mesh size", file=file, key=fine_key,
                         expected=f"a length in mm > 0 and below the mesh size, {size:g} mm")
    if fine is not None and fe_model.name == "slab":
        raise InputError("the FE slab is built under the threshold law's candidates, all in contact: it has no region to refine",
                         file=file, key=fine_key, expected="no contact mesh size (or the layer, two-layer or lumped model)")
    layers, layers_key = pick(layers_through_thickness, "layers_through_thickness")
    if layers is not None and (isinstance(layers, bool) or not isinstance(layers, int)
                               or layers < 1):
        raise InputError(f"{layers!r} is not a number of layers", file=file, key=layers_key,
                         expected="an integer >= 1")
    layered = scene.cartilage.layers
    if layered is None and fe_model.name == "lumped":
        raise InputError("the FE lumped model sums the two sides' layers: the scene has one combined thickness_mm",
                         file=file, key="cartilage.thickness_mm",
                         expected="per-side layers (cartilage.mobile_thickness_mm and fixed_thickness_mm, or bone meshes), or the layer model")
    if layered is not None and fe_model.name not in ("layer", "two-layer", "lumped"):
        # (measured thickness, edem.thickness): the slab fills the gap, whatever the bone says
        raise InputError(f"the FE {fe_model.name} model does not take measured or per-side cartilage thickness",
                         file=file, key="geometry.mobile_bone, geometry.fixed_bone, geometry.cartilage, cartilage.mobile_thickness_mm, cartilage.fixed_thickness_mm",
                         expected="the layer, two-layer or lumped model (--model layer / two-layer / lumped), or one combined thickness_mm (a built-in ankle without "
                                  "its cartilage: geometry.cartilage = false, the thesis's geometry)")
    fixed_key = "geometry.fixed_bone" if layered is not None and layered.fixed.has_bone else "cartilage.fixed_thickness_mm"
    if fe_model.name == "layer" and fixed_has_cartilage(scene):
        # the layer model bonds M's cartilage to M and takes F rigid: a layer on F would be left out
        raise InputError("the FE layer model takes the fixed body rigid: it has no cartilage on it",
                         file=file, key=fixed_key,
                         expected="the two-layer model (--model two-layer: both layers deformable), the lumped model (--model lumped: "
                                  "both layers summed into one on M, F's bone rigid), or fixed_thickness_mm = 0 and "
                                  "no fixed_bone (give F's articular surface as [geometry] fixed, e.g. its bone offset by its layer; "
                                  "the springs then model the same rigid F)")
    if fe_model.name == "two-layer" and not fixed_has_cartilage(scene):
        raise InputError("the FE two-layer model needs cartilage on the fixed body", file=file, key=fixed_key,
                         expected="cartilage.fixed_thickness_mm > 0 or a [geometry] fixed_bone (or the layer model, --model layer)")
    if fe_model.needs_thickness and scene.cartilage.thickness_mm is None and layered is None:
        raise InputError(f"the FE {fe_model.name} model needs the undeformed cartilage thickness",
                         file=file, key="cartilage.thickness_mm",
                         expected="a thickness in mm > 0 (or the slab model)")
    scheme, scheme_key = pick(time_scheme, "time_scheme")
    scheme = DEFAULT_TIME_SCHEME if scheme is None else scheme
    if scheme not in TIME_SCHEMES:
        raise InputError(f"unknown time scheme {scheme!r}", file=file, key=scheme_key,
                         expected=" or ".join(TIME_SCHEMES) + " (the viscoelastic FE's implicit scheme)")
    if biphasic_table is not None and scheme not in BIPHASIC_TIME_SCHEMES:
        raise InputError(f"the biphasic FE has no {scheme} scheme", file=file, key=scheme_key,
                         expected=" or ".join(BIPHASIC_TIME_SCHEMES) + " (the trapezoid leaves a step load's finest pressure "
                                  "modes undamped: docs/method.md#the-biphasic-anchor)")
    solver, solver_key = pick(linear_solver, "linear_solver")
    solver = "auto" if solver is None else solver
    if solver not in LINEAR_SOLVERS:
        raise InputError(f"unknown linear solver {solver!r}", file=file, key=solver_key,
                         expected="; ".join(f"{k} ({v})" for k, v in LINEAR_SOLVERS.items()))
    return FESettings(fe_model.name, el, el_degree, float(size), layers, scheme, solver, biphasic_table,
                      None if fine is None else float(fine))


def biphasic_settings(scene: Any) -> BiphasicSettings:
    """The scene's ``[biphasic]`` table, validated (InputError naming the file and key)."""
    file = scene.source
    table = scene.biphasic
    if table is None:
        raise InputError('[fe] material = "biphasic" needs the fluid\'s properties', file=file, key="biphasic",
                         expected="a [biphasic] table with permeability_mm4_per_n_s (README.md#scene-files)")
    k = table.get("permeability_mm4_per_n_s")
    if isinstance(k, bool) or not isinstance(k, (int, float)) or not (math.isfinite(k) and k > 0):
        raise InputError(f"{k!r} is not a permeability", file=file, key="biphasic.permeability_mm4_per_n_s",
                         expected="the permeability k in mm^4/(N s), > 0 (cartilage: about 1e-3, i.e. 1e-15 m^4/(N s))")
    surface = table.get("counter_surface", DEFAULT_COUNTER_SURFACE)
    if surface not in COUNTER_SURFACES:
        raise InputError(f"unknown counter-surface {surface!r}", file=file, key="biphasic.counter_surface",
                         expected=" or ".join(f'"{c}" ({what})' for c, what in COUNTER_SURFACES.items()))
    return BiphasicSettings(float(k), str(surface))
