"""Run by test_fe_mpi.py under mpiexec: small Nitsche (P2, TH), VI and two-layer solves, JSON on rank 0."""

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from fe_cases import MATERIAL, hertz_mesh, hertz_problem, world  # noqa: E402

from fem_reference import (  # noqa: E402
    FEContactProblem,
    RigidPlane,
    solve_contact,
    solve_contact_vi,
)
from fem_reference import meshes  # noqa: E402

comm = world()
out = {}
hc = 0.25
msh = hertz_mesh(comm, hc, size_far=2.5)
for element in ("P2", "TH"):
    r = solve_contact(hertz_problem(msh, hc, element=element))
    out[element] = [r.bone_displacement_mm[2], r.peak_pressure_mpa, r.contact_area_mm2,
                    r.relative_force_residual, len(r.contact_pressure_mpa), r.n_dofs]
slab = meshes.box_slab(comm, 10.0, 10.0, 2.0, (6, 6, 3), confined=False)
prob = FEContactProblem(mesh=slab, obstacle=RigidPlane((0, 0, 2.0), (0, 0, -1.0)),
                        force_n=(0, 0, 100.0), element="P1", **MATERIAL)
for name, f in (("nitsche", solve_contact), ("vi", solve_contact_vi)):
    r = f(prob)
    out[name] = [r.bone_displacement_mm[2], r.peak_pressure_mpa, r.contact_area_mm2,
                 r.relative_force_residual, len(r.contact_pressure_mpa), r.n_dofs]
# two deformable layers (fem_reference.two_body): F's face gathered on every rank, P across ranks
from fem_reference import FEMesh, Roller, DeformableCounterpart  # noqa: E402

for name, solid, force in (
        ("two-layer stack", meshes.two_layer_stack(10.0, 8.0, 2.0, 1.0, (5, 4), (2, 1), gap=0.05), (0.0, 0.0, -120.0)),
        ("two cylinders", meshes.mirrored_pair(meshes.hertz_cylinder(
            comm, radius=20.0, slice_thickness=0.4, size_contact=0.4, size_far=4.0, fine_radius=1.5, coarse_radius=15.0,
            contact_extent=5.0)), (0.0, 0.0, -0.1))):
    mesh, cell_tags, facet_tags = solid.to_dolfinx(comm)
    r = solve_contact(FEContactProblem(mesh=FEMesh(mesh, facet_tags, cell_tags), obstacle=DeformableCounterpart.from_solid(solid, 5.0, 0.3),
                                       force_n=force, element="P2", rollers=(Roller(4, "x"), Roller(5, "y")), **MATERIAL))
    out[name] = [r.bone_displacement_mm[2], r.peak_pressure_mpa, r.contact_area_mm2,
                 r.relative_force_residual, len(r.contact_pressure_mpa), r.n_dofs]
if comm.rank == 0:
    print("RESULT " + json.dumps(out))
