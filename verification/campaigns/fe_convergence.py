"""``fe-convergence``: the FE reference's own mesh-convergence error at the quick campaign's FE points.

Every FE run the ``quick`` campaign's trust section compares against (the ideal ankle's slab over
Poisson's ratio, the bonded cylinder layer over thickness and at 100 N, the subject-like ankle
standing) on three meshes of the FE's own mesher (``mesh_size_mm`` 2.0, 1.0 and 0.7 mm, P2 or
Taylor-Hood; the finest solved by LU), plus the P1
run ``quick`` uses at 1.0 mm where P1 does not lock. The analysis gives, per point and quantity,
the three values, the observed order, the Richardson extrapolation and each mesh's estimated
error (verification.fe_convergence), with each mesh's DOFs, wall time and peak memory.
``edem verify fe-convergence --refresh-reference`` stores the estimates in
``verification/references/fe_convergence.json``, where the other campaigns' FE references find
their errors (:func:`verification.fe_convergence.fe_relative_error`).

The mesher refines M's triangles by midpoint subdivision (powers of 2 in plane) and sets the
layers through the thickness to ceil(thickness / size): the three meshes are not one uniform
refinement, so each is represented by its DOFs (h ~ N^(-1/3), the usual representative size)
and the order is solved for the unequal ratios.
"""

from __future__ import annotations

from verification.campaign_model import Analysis, Campaign, Case
from verification.fe_convergence import FE_VALUE_METRICS
from verification.verdicts import INVARIANT, Basis

#: the mesh sizes of the study (mm), coarsest first; today's references are the 1.0 mm level. The
#: finest is 0.7 mm: M's triangles halved, 5 layers on the ankles (268k-419k DOFs, 5-8 min and
#: 4-8 GB each by LU); 0.5 mm (438k-579k DOFs) took the campaign past two hours on 2 shared cores
LEVELS_MM = (2.0, 1.0, 0.7)
#: the finest solves first, the subject and the base point ahead (item 3 of issue 24 rests on them)
PRIORITY = ("subject-standing", "slab-F333-nu0.42", "slab-F333-nu0.49", "layer-F333-nu0.42-t2")
#: wall time with 2 jobs on 2 cores, nothing cached: see docs/campaigns.md (the finest meshes dominate)
EXPECTED_TIME_S = 3600.0
CHECK = {"force_residual_rel": 1e-6}
CHECK_BASIS = {"force_residual_rel": Basis(INVARIANT, "the FE solve balances the load to 1e-6 (fem_reference's force-balance check)")}


def study_points() -> list[tuple[str, Case]]:
    """(point name, the quick campaign's case) for every FE reference of quick's trust section."""
    from verification.campaigns.quick import trust_cases

    return [(case.name.replace("-dem-vs-fe", ""), case) for case in trust_cases()]


def _fe_case(name: str, source: Case, options: dict, what: str) -> Case:
    side = source.sides[-1]
    return Case(
        name,
        f"{what}: the FE reference of quick's {source.name} ({side}) {options}",
        source.scene,
        (side,),
        FE_VALUE_METRICS + ("force_residual_rel",),
        dict(CHECK),
        overrides=dict(source.overrides),
        options=dict(options),
        basis=dict(CHECK_BASIS),
    )


def campaign() -> Campaign:
    cases, points = [], []
    for point, source in study_points():
        names = []
        for size in LEVELS_MM:
            name = f"{point}-h{size:g}"
            cases.append(_fe_case(name, source, {"mesh_size_mm": size, "degree": 2}, f"mesh level {size:g} mm"))
            names.append(name)
        extra = None
        if source.options.get("degree") == 1:  # quick's own P1 reference, judged against the study's extrapolation
            extra = f"{point}-P1-h{source.options['mesh_size_mm']:g}"
            cases.append(_fe_case(extra, source, dict(source.options), "quick's P1 reference"))
        points.append({"point": point, "levels": names, "extra": extra, "source_case": source.name, "scene": source.scene,
                       "side": source.sides[-1], "overrides": dict(source.overrides), "source_options": dict(source.options)})
    # the slowest (finest) solves first: two jobs finish together rather than one long tail
    rank = {p: k for k, p in enumerate(PRIORITY)}
    cases.sort(key=lambda c: (c.options["mesh_size_mm"] >= 1.0, rank.get(c.name.rsplit("-", 1)[0], len(rank))))
    analysis = Analysis("fe-convergence", "FE mesh convergence: observed order and Richardson error of each compared quantity, with each mesh's cost",
                        "fe-convergence", tuple(c.name for c in cases), {"points": points})
    return Campaign(
        "fe-convergence",
        "The FE reference's own error: each FE point of quick on three meshes (2.0, 1.0, 0.7 mm), observed order, Richardson error, cost; "
        "--refresh-reference stores the errors for the other campaigns.",
        tuple(cases),
        (),
        (analysis,),
    )
