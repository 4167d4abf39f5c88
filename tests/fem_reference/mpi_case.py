"""Run by test_fe_mpi.py under mpiexec: small Nitsche (P2, TH) and VI solves, JSON on rank 0."""

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
if comm.rank == 0:
    print("RESULT " + json.dumps(out))
