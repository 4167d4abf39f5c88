"""Scene files (README.md#scene-files): TOML -> a validated, immutable Scene.

Every section but geometry, cartilage and load is optional and its absence switches the feature
off. Bad input raises InputError naming the file, the key and what was expected.
"""

from __future__ import annotations

import pickle
import tomllib
import warnings
from dataclasses import dataclass, replace
from functools import cached_property, lru_cache
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from edem.beds import DEFAULT_COUPLING, bed_keys, read_bed
from geometries.errors import InputError
from edem.joint_reaction import transfer_moment
from edem.laws import LAWS
from edem.loads import JointKinematics, LoadSeries, angle_series_from_table, load_series_from_table
from edem.mechanics import DOF_NAMES, rotation_matrix
from edem.opensim_model import BodyPoses
from edem.plausibility import scene_warnings
from edem.springs import Cartilage, Ligament, Placement
from edem.viscoelastic import CONTACT_SETS, DEFAULT_CONTACT_SET, integrator_problem
from edem.thickness import CARTILAGE_KEYS, GEOMETRY_KEYS, array_layers, scene_layers, uses_layers
from edem.tables import SceneTable, not_utf8
from geometries.builders import build_geometry
from geometries.mesh_files import MAX_COORDINATE_MM
from geometries.surface import TriangleSurface


SECTIONS = {
    "scene": {"name", "description"},
    "geometry": None,  # builtin parameters are checked by the builder
    "cartilage": {
        "youngs_modulus_mpa",
        "poissons_ratio",
        "law",
        "max_spring_length_mm",
        "thickness_mm",
        "shear_modulus_mpa",
        *CARTILAGE_KEYS,  # measured thickness (edem.thickness)
    },  # and the beds' keys (edem.beds.bed_keys: coupling and each bed's own)
    "load": None,  # checked by edem.loads
    "kinematics": None,  # checked by edem.loads
    "constraints": {"fixed_dofs"},
    "ligaments": {"name", "mobile_point_mm", "fixed_point_mm", "youngs_modulus_mpa", "area_mm2", "rest_length_mm"},
    "viscoelastic": {"relaxation_time_s", "contact_set", "integrator", "allow_unstable"},
    "solver": {"method", "allow_bone_overlap"},
    "fe": {"model", "mesh_size_mm", "degree", "element", "layers_through_thickness", "contact_mesh_size_mm", "time_scheme", "material"},
    "biphasic": {"permeability_mm4_per_n_s", "counter_surface"},  # the FE's (fem_reference.settings.biphasic_settings)
    "opensim": None,  # checked by edem.opensim_model
}
FILE_GEOMETRY_KEYS = {"mobile", "fixed", "units", "reference_point_mm", "spring_spacing_mm", *GEOMETRY_KEYS}


@dataclass(frozen=True)
class Viscoelastic:
    """Kelvin-Voigt springs, damping = tau * stiffness (docs/method.md#4-viscoelastic-edem-thesis-chapter-6, eq. 6.13).

    ``contact_set``: how a time point decides the contact (:data:`edem.viscoelastic.CONTACT_SETS`:
    "creeping", each spring's creeping compression, or "frozen", the thesis's increment);
    ``integrator``: one of that contact set's (None: its default, "bdf2" or "exact"). InputError
    naming the key for an integrator of the other set.
    """

    relaxation_time_s: float
    integrator: str | None = None  # creeping: bdf2 | backward-euler; frozen: exact | rk2
    allow_unstable: bool = False  # run RK2 beyond dt > 2 tau (with a warning) instead of refusing
    contact_set: str = DEFAULT_CONTACT_SET

    def __post_init__(self) -> None:
        if self.contact_set not in CONTACT_SETS:
            raise InputError(f"unknown contact set {self.contact_set!r}", key="viscoelastic.contact_set", expected=" or ".join(CONTACT_SETS))
        if self.integrator is None:
            object.__setattr__(self, "integrator", CONTACT_SETS[self.contact_set].integrators[0])
        problem = integrator_problem(self.contact_set, self.integrator)
        if problem:
            raise InputError(problem, key="viscoelastic.integrator", expected=" or ".join(CONTACT_SETS[self.contact_set].integrators))


def _read_only(array: np.ndarray) -> np.ndarray:
    array.flags.writeable = False
    return array


@dataclass(frozen=True, eq=False)
class Scene:
    """Everything one run needs, validated. Springs: one per non-degenerate mobile triangle."""

    name: str
    description: str
    source: str
    mobile: TriangleSurface
    fixed: TriangleSurface
    reference_point_mm: np.ndarray
    cartilage: Cartilage
    load: LoadSeries
    kinematics: JointKinematics | Any | None = None  # or edem.opensim_model.BodyPoses (F's pose per time point)
    fixed_dofs: tuple[str, ...] = ()
    ligaments: tuple[Ligament, ...] = ()
    viscoelastic: Viscoelastic | None = None
    method: str = "edem"
    fe: dict | None = None
    # [solver] allow_bone_overlap: a result whose springs are compressed past their layer (the bones
    # through each other) is kept with a warning instead of refused (stability studies)
    allow_bone_overlap: bool = False
    biphasic: dict | None = None  # the FE's biphasic cartilage ([fe] material = "biphasic"); EDEM does not read it
    warnings: tuple[str, ...] = ()

    # The springs' arrays are formed once per scene (a run reads them, and every RunResult's
    # n_springs) and handed out read-only: a scene is immutable.
    @cached_property
    def spring_triangle(self) -> np.ndarray:
        """Index of the mobile triangle that carries each spring (degenerate ones carry none)."""
        return _read_only(np.flatnonzero(self.mobile.areas_mm2 > 0.0))

    @cached_property
    def spring_centroid_mm(self) -> np.ndarray:
        return _read_only(self.mobile.centroids_mm[self.spring_triangle])

    @cached_property
    def spring_normal(self) -> np.ndarray:
        return _read_only(self.mobile.unit_normals[self.spring_triangle])

    @cached_property
    def spring_area_mm2(self) -> np.ndarray:
        return _read_only(self.mobile.areas_mm2[self.spring_triangle])

    # What a time point means: where F is and what load acts on M (the DEM/EDEM run, the FE
    # reference and the renders all ask the scene).
    def fixed_placement(self, step: int) -> Placement:
        """Pose of F at time point ``step``: the joint angle about the scene's axis (docs/method.md#2-edem-the-time-dependent-incremental-method
        step 1), the pose an OpenSim model gives it at the motion's coordinates, or the identity
        without kinematics."""
        kin = self.kinematics
        if kin is None:
            return Placement.identity()
        if isinstance(kin, BodyPoses):  # F's full pose from an OpenSim model
            return Placement(kin.rotation[step], kin.translation_mm[step], np.zeros(3))
        rotation = rotation_matrix(kin.axis_direction * kin.angle_rad[step])
        return Placement(rotation, np.zeros(3), kin.axis_point_mm)

    def applied_loads(self) -> np.ndarray:
        """(n_times, 6) force (N) and moment about G (N mm) on M per time point, in global axes
        (turned with F for ``load.frame = "fixed"``).

        A moment given about another point (``load.point_mm``, e.g. a JointReaction's joint centre,
        placed with F for frame = "fixed") is moved to G: M_G = M_P + (P - G) x F.
        """
        load = self.load
        force, moment, point = load.force_n, load.moment_nmm, load.point_mm
        if load.frame == "fixed" and self.kinematics is not None:
            placements = [self.fixed_placement(k) for k in range(len(load.time_s))]
            rotations = [p.rotation for p in placements]
            force = np.einsum("kij,kj->ki", rotations, force)
            moment = np.einsum("kij,kj->ki", rotations, moment)
            if point is not None:
                point = np.array([p.points(x[None])[0] for p, x in zip(placements, point)])
        if point is not None:
            moment = transfer_moment(moment, force, point, self.reference_point_mm)
        return np.hstack([force, moment])

    def fixed_cell_data(self) -> dict[str, np.ndarray]:
        """Cell data of the fixed body in the result directory: with measured thickness, F's
        layer per triangle (``thickness_mm``, mm); otherwise none."""
        layers = self.cartilage.layers
        return {} if layers is None else {"thickness_mm": layers.fixed.thickness_mm}

    @classmethod
    def from_arrays(
        cls,
        mobile_vertices_mm: np.ndarray,
        mobile_triangles: np.ndarray,
        fixed_vertices_mm: np.ndarray,
        fixed_triangles: np.ndarray,
        force_n: np.ndarray,
        *,
        youngs_modulus_mpa: float,
        poissons_ratio: float,
        time_s: np.ndarray | None = None,
        moment_nmm: np.ndarray | None = None,
        load_frame: str = "global",
        law: str = "threshold",
        max_spring_length_mm: float | None = None,
        thickness_mm: float | None = None,
        shear_modulus_mpa: float = 0.0,
        coupling: str = DEFAULT_COUPLING,
        fixed_dofs: tuple[str, ...] = (),
        reference_point_mm: np.ndarray | None = None,
        kinematics: JointKinematics | None = None,
        ligaments: tuple[Ligament, ...] = (),
        viscoelastic: Viscoelastic | None = None,
        method: str = "edem",
        allow_bone_overlap: bool = False,
        name: str = "scene",
        description: str = "",
        mobile_bone: tuple[np.ndarray, np.ndarray] | None = None,
        fixed_bone: tuple[np.ndarray, np.ndarray] | None = None,
        mobile_thickness_mm: float | None = None,
        fixed_thickness_mm: float | None = None,
        spring_spacing_mm: float | None = None,
        **bed_settings: Any,
    ) -> Scene:
        """A scene from meshes and loads already in memory (no TOML file, no mesh cleaning).

        Parameters
        ----------
        mobile_vertices_mm, fixed_vertices_mm : (n_vertices, 3) float, mm
            Vertices of the mobile body M (it moves; its triangles carry the springs) and of the
            fixed body F.
        mobile_triangles, fixed_triangles : (n_triangles, 3) int
            Vertex indices; the right-hand-rule normals of each body point towards the other.
        force_n : (3,) or (n_times, 3) float, N
            Load on M per time point.
        youngs_modulus_mpa, poissons_ratio : float
            The cartilage (MPa; -1 < nu < 0.5).
        time_s : (n_times,) float, s, optional
            Strictly increasing times; default 0, 1, 2, ...
        moment_nmm : (3,) or (n_times, 3) float, N mm, optional
            Moment about the reference point; default zero.
        load_frame : {"global", "fixed"}
            Axes of the load components: global, or the fixed body's (they turn with
            ``kinematics``), as ``[load] frame``.
        law : str
            A contact law of :data:`edem.laws.LAWS` (``threshold``, ``gap``, ``gap-log``).
        max_spring_length_mm : float, optional
            h_max, the ray window; default the law's (3.5 mm, or twice the thickness).
        thickness_mm : float, optional
            Undeformed combined cartilage thickness (the gap laws need it).
        shear_modulus_mpa : float
            Shear spring modulus (0: frictionless).
        coupling : str
            The bed, a key of :data:`edem.beds.BEDS` (as ``[cartilage] coupling``); default
            :data:`edem.beds.DEFAULT_COUPLING`, the independent springs.
        fixed_dofs : tuple of str
            Fixed DOFs of M among tx, ty, tz, rx, ry, rz.
        reference_point_mm : (3,) float, optional
            G, the point M's rotations and moments refer to; default the area-weighted centroid
            of M's triangles.
        kinematics, ligaments, viscoelastic, method, allow_bone_overlap, name, description
            As the scene file's ``[kinematics]``, ``[[ligaments]]``, ``[viscoelastic]``,
            ``[solver] method`` and ``allow_bone_overlap`` and ``[scene]``.
        mobile_bone, fixed_bone : (vertices (m, 3) mm, triangles (k, 3) int), optional
            Subchondral bone under M's / F's surface: that side's cartilage thickness is measured
            (docs/method.md#measured-cartilage-thickness); with either, or a per-side thickness,
            ``thickness_mm`` is not given and the gap laws need ``max_spring_length_mm``.
        mobile_thickness_mm, fixed_thickness_mm : float, optional
            Uniform layer of a side without a bone (its surface is then its bone), or where the
            bone is not found below a side with one.
        spring_spacing_mm : float, optional
            Resample M so that no spring triangle has an edge longer than this (mm), as
            ``[geometry] spring_spacing_mm``; default: one spring per given triangle.
        **bed_settings
            The bed's own keys, as ``[cartilage]``'s (:attr:`edem.beds.Bed.Keys`); e.g. for the
            coupled layer ``thin_layer_symbol`` (a name of :data:`edem.layer_symbols.LAYER_SYMBOLS`,
            default ``"pade"``) and ``thin_layer_smoothing_resolution`` (cells of the coarse
            smoothing space per smoothing length; default 0, the springs' own mesh). None: not given.

        Returns
        -------
        Scene

        Raises
        ------
        InputError
            A value or shape that does not fit, naming the argument (the cartilage arguments are
            checked as the scene file's ``[cartilage]``, by :func:`cartilage_from_table`).
        """
        source = "<arrays>"

        def surface(vertices: np.ndarray, triangles: np.ndarray, what: str) -> TriangleSurface:
            v = np.asarray(vertices, dtype=np.float64)
            t = np.asarray(triangles)
            if v.ndim != 2 or v.shape[1] != 3 or not np.isfinite(v).all():
                raise InputError(f"shape {v.shape} or non-finite values", file=source, key=f"{what}_vertices_mm", expected="(n, 3) finite floats in mm")
            if t.ndim != 2 or t.shape[1] != 3 or t.shape[0] == 0 or not np.issubdtype(t.dtype, np.integer) or t.min() < 0 or t.max() >= len(v):
                raise InputError(f"shape {t.shape} or indices outside the {len(v)} vertices", file=source, key=f"{what}_triangles", expected="(m, 3) integer vertex indices")
            return TriangleSurface(v, t.astype(np.int64), name=what, source=source)

        mobile = surface(mobile_vertices_mm, mobile_triangles, "mobile")
        fixed = surface(fixed_vertices_mm, fixed_triangles, "fixed")
        if spring_spacing_mm is not None:
            if not spring_spacing_mm > 0:
                raise InputError(f"spring_spacing_mm = {spring_spacing_mm!r}", file=source, key="spring_spacing_mm", expected="a spacing in mm > 0")
            from geometries.vtk_ops import subdivide_to_spacing

            mobile = subdivide_to_spacing(mobile, float(spring_spacing_mm), key="spring_spacing_mm")
        given = {
            "youngs_modulus_mpa": youngs_modulus_mpa, "poissons_ratio": poissons_ratio, "law": law, "max_spring_length_mm": max_spring_length_mm,
            "thickness_mm": thickness_mm, "shear_modulus_mpa": shear_modulus_mpa, "coupling": coupling, **bed_settings,
        }
        # numpy scalars as the plain numbers a TOML table holds; None: not given
        bones, uniform = {"mobile": mobile_bone, "fixed": fixed_bone}, {"mobile": mobile_thickness_mm, "fixed": fixed_thickness_mm}
        layered = any(v is not None for v in (*bones.values(), *uniform.values()))
        cartilage = cartilage_from_table({k: v.item() if isinstance(v, np.generic) else v for k, v in given.items() if v is not None}, source, "", layered)
        unknown = [d for d in fixed_dofs if d not in DOF_NAMES]
        if unknown:
            raise InputError(f"unknown DOF(s) {', '.join(unknown)}", file=source, key="fixed_dofs", expected="a subset of " + ", ".join(DOF_NAMES))
        force = np.atleast_2d(np.asarray(force_n, dtype=np.float64))
        times = np.arange(len(force), dtype=np.float64) if time_s is None else np.asarray(time_s, dtype=np.float64)
        moment = np.zeros_like(force) if moment_nmm is None else np.atleast_2d(np.asarray(moment_nmm, dtype=np.float64))
        try:
            load = LoadSeries(times, force, moment, frame=load_frame)
        except ValueError as exc:
            raise InputError(str(exc), file=source, key="force_n, moment_nmm, time_s, load_frame", expected="one finite row of 3 per time point") from None
        if reference_point_mm is None:
            areas = mobile.areas_mm2
            reference_point_mm = (mobile.centroids_mm * areas[:, None]).sum(axis=0) / areas.sum()
        notes: list[str] = []
        if layered:
            layers = array_layers(mobile, fixed, np.flatnonzero(mobile.areas_mm2 > 0.0), bones, uniform, cartilage.max_spring_length_mm, notes)
            cartilage = replace(cartilage, layers=layers)
        return cls(
            name=name,
            description=description,
            source=source,
            mobile=mobile,
            fixed=fixed,
            reference_point_mm=np.asarray(reference_point_mm, dtype=np.float64),
            cartilage=cartilage,
            load=load,
            kinematics=kinematics,
            fixed_dofs=tuple(fixed_dofs),
            ligaments=tuple(ligaments),
            viscoelastic=viscoelastic,
            method=method,
            allow_bone_overlap=bool(allow_bone_overlap),
            warnings=tuple(notes),
        )


def cartilage_from_table(table: dict[str, Any], file: str | Path, section: str = "cartilage", layered: bool = False) -> Cartilage:
    """The cartilage, checked: the one validator of ``[cartilage]`` (:func:`load_scene`) and of
    :meth:`Scene.from_arrays`'s cartilage arguments.

    Parameters
    ----------
    table : dict
        The keys of ``SECTIONS["cartilage"]`` and of the beds (:func:`edem.beds.bed_keys`;
        README.md#scene-files) to TOML values.
    file : str or Path
        The scene file (or ``"<arrays>"``), named in the errors.
    section : str
        Prefix of the keys named in the errors (``"cartilage"``; ``""``: the bare argument names).
    layered : bool
        The scene gives per-side layers (:mod:`edem.thickness`): they replace ``thickness_mm``,
        and the gap laws' window has no default.

    Returns
    -------
    Cartilage
        With the law's default ray window h_max (mm) where none is given; ``coupling`` picks the
        bed (:data:`edem.beds.BEDS`), which refuses what it cannot take (:meth:`edem.beds.Bed.check`).

    Raises
    ------
    InputError
        Naming the file, the key and what was expected.
    """
    cart = SceneTable(table, file, section, (*SECTIONS["cartilage"], *bed_keys()))
    law = cart.string("law", "threshold", tuple(LAWS))
    spring_law = LAWS[law]
    thickness = cart.optional_number("thickness_mm", positive=True, what="the undeformed cartilage thickness in mm (> 0)")
    if layered and thickness is not None:
        raise cart.error("thickness_mm", "per-side layers replace thickness_mm",
                         "no thickness_mm with a bone mesh, a per-side thickness or a built-in ankle's cartilage (geometry.cartilage = false: the thesis's geometry without it)")
    if spring_law.needs_thickness and thickness is None and not layered:
        raise cart.error("thickness_mm", f"the '{law}' law needs the undeformed thickness", "a thickness in mm > 0")
    # Beyond a kilometre the ray window is no longer a length on a joint (and its float32 reach overflows).
    window = cart.number("max_spring_length_mm", None if layered and spring_law.needs_thickness else spring_law.default_window_mm(thickness),
                         positive=True, high=MAX_COORDINATE_MM, what=f"h_max in mm (> 0 and < {MAX_COORDINATE_MM:g})"
                         + ("; with per-side layers it has no default" if layered else ""))
    if spring_law.needs_thickness and thickness is not None and window < thickness:
        raise cart.error(
            "max_spring_length_mm",
            f"the ray window h_max = {window:g} mm is shorter than the thickness {thickness:g} mm",
            f"h_max >= thickness_mm for the {law} law (springs beyond h_max are not seen)",
        )
    bed, own_keys = read_bed(cart)
    cartilage = Cartilage(
        coupling=bed.coupling,
        bed_keys=own_keys,
        youngs_modulus_mpa=cart.number("youngs_modulus_mpa", positive=True, what="Young's modulus in MPa (> 0)"),
        poissons_ratio=cart.number("poissons_ratio", low=-1.0, high=0.5, what="Poisson's ratio in (-1, 0.5)"),
        law=law,
        max_spring_length_mm=window,
        thickness_mm=thickness,
        shear_modulus_mpa=cart.number("shear_modulus_mpa", 0.0, nonnegative=True, what="a shear modulus in MPa (>= 0)"),
    )
    bed.check(cartilage, cart)
    return cartilage


@lru_cache(maxsize=8)
def _parsed(text: str) -> bytes:
    """The parsed TOML of ``text``, pickled: a campaign reads one scene file several times per
    case (scene, array overrides, provenance, description) and hundreds of cases in a row."""
    return pickle.dumps(tomllib.loads(text), protocol=pickle.HIGHEST_PROTOCOL)


def read_scene_toml(path: str | Path) -> dict[str, Any]:
    """The parsed TOML of a scene file, a fresh dict each call (the caller may change it).

    InputError naming the file when it is missing, unreadable, not UTF-8 or not valid TOML.
    The file is read every time; only the parse of identical text is shared.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError("scene file not found", file=path, expected="a TOML scene file or a built-in scene name (edem scenes)") from None
    except OSError as exc:
        raise InputError(f"cannot read the scene file: {exc.strerror}", file=path) from None
    except UnicodeDecodeError as exc:
        raise InputError(not_utf8(exc), file=path, expected="a UTF-8 text file (TOML is UTF-8 by definition)") from None
    try:
        return pickle.loads(_parsed(text))
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"malformed TOML: {exc}", file=path, expected="valid TOML (https://toml.io)") from None
    except RecursionError:
        raise InputError("arrays or tables nested too deeply to read", file=path, expected="valid TOML of ordinary depth") from None


def builtin_scene_names() -> list[str]:
    return sorted(p.name[: -len(".toml")] for p in resources.files("edem.scenes").iterdir() if p.name.endswith(".toml"))


def resolve_scene_path(scene: str | Path) -> Path:
    """A scene argument is a TOML path or the name of a built-in scene."""
    path = Path(scene)
    if path.exists() or str(scene).endswith(".toml"):
        return path
    names = builtin_scene_names()
    if str(scene) in names:
        return Path(str(resources.files("edem.scenes").joinpath(f"{scene}.toml")))
    raise InputError(f"'{scene}' is neither a scene file nor a built-in scene", expected="a .toml path or one of " + ", ".join(names))


def parse_override(text: str) -> tuple[str, Any]:
    """'section.key=value' with a TOML value (a bare word is taken as a string)."""
    key, sep, value = text.partition("=")
    if not sep or "." not in key.strip():
        raise InputError(f"cannot read the override '{text}'", key="--set", expected="section.key=value, e.g. viscoelastic.relaxation_time_s=7")
    try:
        parsed = tomllib.loads(f"v = {value.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        parsed = value.strip()
    return key.strip(), parsed


def apply_overrides(data: dict[str, Any], overrides: dict[str, Any]) -> None:
    """Set dotted keys in the parsed scene, creating sections as needed."""
    for dotted, value in overrides.items():
        *sections, key = dotted.split(".")
        table = data
        for name in sections:
            table = table.setdefault(name, {})
            if not isinstance(table, dict):
                raise InputError(f"'{name}' is not a table", key=dotted, expected="a section.key path")
        table[key] = value


def load_scene(scene: str | Path, overrides: dict[str, Any] | None = None) -> Scene:
    """Read, validate and build a scene (geometry, springs, loads) from a TOML file or built-in name.

    Parameters
    ----------
    scene : str or Path
        A scene TOML file (layout in the README), or the name of a built-in scene
        (:func:`builtin_scene_names`).
    overrides : dict, optional
        Dotted keys ('cartilage.poissons_ratio') to values, set before validation (as ``--set``).

    Returns
    -------
    Scene
        Surfaces in mm (one spring per non-degenerate mobile triangle), the cartilage, the load
        history (n_times,) and the optional kinematics, constraints, ligaments, viscoelasticity.

    Raises
    ------
    InputError
        Naming the file, the key and what was expected.
    """
    path = resolve_scene_path(scene)
    data = read_scene_toml(path)
    file = str(path)
    if overrides:
        apply_overrides(data, overrides)
    unknown = sorted(set(data) - set(SECTIONS))
    if unknown:
        raise InputError(f"unknown section [{unknown[0]}]", file=file, key=unknown[0], expected="sections " + ", ".join(SECTIONS))
    from_model = "opensim" in data
    if from_model:
        data.setdefault("geometry", {})
    for section in ("geometry", "cartilage", "load"):
        if not isinstance(data.get(section), dict):
            raise InputError(f"missing section [{section}]", file=file, key=section, expected=f"a [{section}] table (README.md#scene-files)")
    notes: list[str] = []

    meta = SceneTable(data.get("scene", {}), file, "scene", SECTIONS["scene"])
    name = meta.string("name", path.stem)
    description = meta.string("description") if meta.has("description") else ""

    cartilage = cartilage_from_table(data["cartilage"], file, layered=uses_layers(data))
    load = load_series_from_table(data["load"], path)
    if from_model:
        from edem.opensim_model import model_geometry

        mobile, fixed, reference_point, kinematics, load = model_geometry(data, path, cartilage, load, notes)
        attachments, geo_description, built_bones = {}, "", None
    else:
        mobile, fixed, reference_point, attachments, geo_description, built_bones = _load_geometry(data["geometry"], path, cartilage, notes)
        kinematics = None
        if "kinematics" in data:
            kinematics = angle_series_from_table(data["kinematics"], path, load.time_s, load.given_time_s)
    description = description or geo_description
    spacing = SceneTable(data["geometry"], file, "geometry", None).optional_number(
        "spring_spacing_mm", positive=True, what="the longest spring triangle edge in mm (> 0)")
    if spacing is not None:
        from geometries.vtk_ops import subdivide_to_spacing

        mobile = subdivide_to_spacing(mobile, spacing, key="geometry.spring_spacing_mm")
    notes += scene_warnings(cartilage.youngs_modulus_mpa, load, data["load"], mobile)
    if not np.any(mobile.areas_mm2 > 0.0):
        raise InputError(
            f"the mobile surface has no triangle of non-zero area ({len(mobile.triangles)} triangles), so it carries no spring",
            file=mobile.source or file, key="geometry.mobile" if mobile.source else "geometry",
            expected="a surface mesh whose triangles have distinct corners",
        )
    layers = scene_layers(data, path, mobile, fixed, np.flatnonzero(mobile.areas_mm2 > 0.0), cartilage.max_spring_length_mm, notes, built_bones)
    if layers is not None:
        cartilage = replace(cartilage, layers=layers)

    constraints = SceneTable(data.get("constraints", {}), file, "constraints", SECTIONS["constraints"])
    fixed_dofs = constraints.table.get("fixed_dofs", [])
    if not isinstance(fixed_dofs, list) or not all(isinstance(d, str) and d in DOF_NAMES for d in fixed_dofs):
        raise InputError(f"{fixed_dofs!r} is not a list of DOF names", file=file, key="constraints.fixed_dofs", expected="a subset of " + ", ".join(DOF_NAMES))

    ligaments = tuple(_ligament(entry, i, file, attachments) for i, entry in enumerate(_table_list(data, "ligaments", file)))

    viscoelastic = None
    if "viscoelastic" in data:
        ve = SceneTable(data["viscoelastic"], file, "viscoelastic", SECTIONS["viscoelastic"])
        contact_set = ve.string("contact_set", DEFAULT_CONTACT_SET, tuple(CONTACT_SETS))
        integrators = CONTACT_SETS[contact_set].integrators
        integrator = ve.string("integrator", integrators[0], tuple(i for each in CONTACT_SETS.values() for i in each.integrators))
        problem = integrator_problem(contact_set, integrator)
        if problem:
            raise ve.error("integrator", problem, " or ".join(integrators) + f' with contact_set = "{contact_set}"')
        viscoelastic = Viscoelastic(
            relaxation_time_s=ve.number("relaxation_time_s", positive=True, what="the relaxation time tau in s (> 0)"),
            integrator=integrator,
            allow_unstable=ve.boolean("allow_unstable", False),
            contact_set=contact_set,
        )

    solver = SceneTable(data.get("solver", {}), file, "solver", SECTIONS["solver"])
    method = solver.string("method", "edem", ("edem", "dem"))
    allow_bone_overlap = solver.boolean("allow_bone_overlap", False)
    fe = data.get("fe")
    if fe is not None:
        SceneTable(fe, file, "fe", SECTIONS["fe"])
    biphasic = data.get("biphasic")
    if biphasic is not None:
        SceneTable(biphasic, file, "biphasic", SECTIONS["biphasic"])

    return Scene(
        name=name,
        description=description,
        source=file,
        mobile=mobile,
        fixed=fixed,
        reference_point_mm=reference_point,
        cartilage=cartilage,
        load=load,
        kinematics=kinematics,
        fixed_dofs=tuple(fixed_dofs),
        ligaments=ligaments,
        viscoelastic=viscoelastic,
        method=method,
        fe=fe,
        allow_bone_overlap=allow_bone_overlap,
        biphasic=biphasic,
        warnings=tuple(notes),
    )


def _table_list(data: dict[str, Any], name: str, file: str) -> list[dict[str, Any]]:
    value = data.get(name, [])
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        raise InputError(f"[{name}] must be an array of tables", file=file, key=name, expected=f"[[{name}]] entries")
    return value


def _ligament(entry: dict[str, Any], index: int, file: str, attachments: dict[str, tuple[np.ndarray, np.ndarray]]) -> Ligament:
    r = SceneTable(entry, file, f"ligaments[{index}]", SECTIONS["ligaments"])
    name = r.string("name", f"ligament-{index}")
    mobile_point = r.optional_triple("mobile_point_mm")
    fixed_point = r.optional_triple("fixed_point_mm")
    if mobile_point is None or fixed_point is None:
        if name not in attachments:
            raise InputError(
                f"ligament '{name}' has no attachment points",
                file=file,
                key=r.key("mobile_point_mm"),
                expected="mobile_point_mm and fixed_point_mm, or the name of a ligament of the built-in geometry"
                + (f" ({', '.join(attachments)})" if attachments else ""),
            )
        mobile_point = attachments[name][0] if mobile_point is None else mobile_point
        fixed_point = attachments[name][1] if fixed_point is None else fixed_point
    initial = float(np.linalg.norm(fixed_point - mobile_point))
    if initial == 0.0:
        raise InputError(f"ligament '{name}' has coincident attachment points", file=file, key=r.key("fixed_point_mm"), expected="two distinct points")
    return Ligament(
        name=name,
        mobile_point_mm=mobile_point,
        fixed_point_mm=fixed_point,
        youngs_modulus_mpa=r.number("youngs_modulus_mpa", positive=True, what="the ligament's Young's modulus in MPa (> 0)"),
        area_mm2=r.number("area_mm2", positive=True, what="the cross-section area in mm^2 (> 0)"),
        rest_length_mm=r.number("rest_length_mm", initial, positive=True, what="the slack length in mm (default: the initial distance)"),
    )


def _load_geometry(table: dict[str, Any], path: Path, cartilage: Cartilage, warnings_out: list[str]):
    """Mobile and fixed surfaces from a built-in generator or mesh files, oriented and checked,
    with the bones a built-in ankle builds under its cartilage (by side; None without them)."""
    file = str(path)
    reference_point = None
    built_bones = None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if "builtin" in table:
            from geometries.repair import check_pair_distance

            if not isinstance(table["builtin"], str):
                raise InputError(f"{table['builtin']!r} is not a builder name", file=file, key="geometry.builtin", expected="a string")
            params = {k: v for k, v in table.items() if k not in ("builtin", "reference_point_mm", "spring_spacing_mm")}
            built = build_geometry(table["builtin"], params, file=file)
            mobile, fixed = built.mobile, built.fixed
            check_pair_distance(mobile, fixed, cartilage.max_spring_length_mm, key="geometry")
            reference_point = built.reference_point_mm
            attachments = {lig.name: (lig.mobile_point_mm, lig.fixed_point_mm) for lig in built.ligaments}
            description = built.description
            if built.mobile_bone is not None:
                built_bones = {"mobile": built.mobile_bone, "fixed": built.fixed_bone}
        else:
            from geometries.repair import prepare_pair

            r = SceneTable(table, file, "geometry", FILE_GEOMETRY_KEYS)
            units = r.string("units", "mm", ("mm", "m"))
            paths = []
            for key in ("mobile", "fixed"):
                if not r.has(key):
                    raise r.error(key, f"[geometry] has neither 'builtin' nor '{key}'", 'a mesh file (STL/OBJ/PLY/VTK/VTP) or builtin = "<generator>"')
                paths.append(path.parent / r.string(key))
            mobile, fixed = prepare_pair(*paths, units=units, max_spring_length_mm=cartilage.max_spring_length_mm)
            attachments, description = {}, ""
    warnings_out.extend(str(w.message) for w in caught)
    given = SceneTable(table, file, "geometry", None).optional_triple("reference_point_mm")
    if given is not None:
        reference_point = given
    if reference_point is None:
        # Area-weighted centroid of the articular surface (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs default for G).
        areas = mobile.areas_mm2
        reference_point = (mobile.centroids_mm * areas[:, None]).sum(axis=0) / areas.sum()
    return mobile, fixed, np.asarray(reference_point, float), attachments, description, built_bones
