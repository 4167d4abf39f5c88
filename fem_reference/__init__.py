"""FEniCSx (dolfinx) reference models: linear-elastic frictionless contact with force control.

Importing this package does not import dolfinx; the solvers import the FE stack on first use
(:func:`fem_reference.fe_stack.fe_modules`).

* :mod:`fem_reference.problem`: :class:`FEContactProblem` (mesh source, material, element,
  obstacle, load, free translations, rollers, Nitsche and solver options) and
  :class:`FEContactResult`; obstacles :class:`RigidPlane`, :class:`RigidCylinder`,
  :class:`RigidSurface` (triangulated; gap along the nearest triangle's normal), and a deformable
  F, :class:`DeformableCounterpart` (F's own elastic layer in the same mesh).
* :mod:`fem_reference.contact`: :func:`solve_contact` (Nitsche, force control by a bordered
  semi-smooth Newton in PETSc SNES; P1, P2, Taylor-Hood); its inner linear solve (MUMPS LU or
  Krylov: GAMG, Taylor-Hood field split) is :mod:`fem_reference.krylov`, the set-up it shares
  with the cross-check :mod:`fem_reference.contact_setup`; against a deformable F
  (two layers in frictionless contact) the set-up and the assembly of :mod:`fem_reference.two_body`.
* :mod:`fem_reference.contact_vi`: :func:`solve_contact_vi` (variational-inequality cross-check,
  P1, axis-aligned plane).
* :mod:`fem_reference.scene_run`: :func:`run_scene`, the FE reference of a whole scene (every
  time point, the result directory of ``edem fe``); its models (slab, layer, two-layer) are
  :data:`fem_reference.models.FE_MODELS`, its settings :mod:`fem_reference.settings` and how it
  steps through time (elastic, Kelvin-Voigt) :mod:`fem_reference.time_stepping`.
* :mod:`fem_reference.biphasic`: the linear biphasic (Biot, mixed u-p Taylor-Hood) FE of cartilage
  that creeps by fluid flow, stepped by backward Euler or BDF2 (:class:`~fem_reference.biphasic.BiphasicFE`).
* :mod:`fem_reference.closed_forms`: Hertz line contact, confined compression (elastic, Kelvin-Voigt,
  biphasic), observed orders.
* :mod:`fem_reference.meshes`: small tagged verification meshes (slab, Hertz block, cylinder
  layer; two layers: a stack, two Hertz cylinders, a cylinder layer on a flat one). Facet tags:
  1 bonded, 2 contact, 3 free, 4/5/6 zero x/y/z displacement; F's layer 11 bonded, 12 contact.

Units: mm, N, MPa.
"""

from . import two_body  # noqa: F401  (registers the solver of two deformable layers with solve_contact)
from .contact import solve_contact
from .contact_vi import solve_contact_vi
from .problem import (
    DeformableCounterpart,
    FEContactProblem,
    FEContactResult,
    FEConvergenceError,
    FEMesh,
    NitscheParameters,
    RigidCylinder,
    RigidPlane,
    RigidSurface,
    Roller,
    SolverOptions,
)
from .scene_run import FERunResult, FEStepResult, run_scene
from .settings import FESettings


__all__ = [
    "FEContactProblem", "FEContactResult", "FEConvergenceError", "FEMesh", "NitscheParameters",
    "RigidCylinder", "RigidPlane", "RigidSurface", "Roller", "SolverOptions", "solve_contact", "DeformableCounterpart",
    "solve_contact_vi", "run_scene", "FERunResult", "FEStepResult", "FESettings",
]
