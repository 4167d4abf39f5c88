"""Pictures of the built-in scenes' geometry (``edem scenes --render``)."""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path

import numpy as np

from edem.raycast import RayCaster
from edem.scene import load_scene, resolve_scene_path
from geometries.builders import build_geometry
from geometries.render import render_geometry_png


def render_scene_pngs(names: list[str], target: str | Path) -> list[Path]:
    """PNG of each built-in scene's geometry in ``target/<scene>.png``: springs coloured by their
    length at the first time point, the tibia (and the ligaments' tibial ends) where that time
    point puts them."""
    out = Path(target)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name in names:
        table = tomllib.loads(resolve_scene_path(name).read_text(encoding="utf-8"))["geometry"]
        built = build_geometry(table["builtin"], {k: v for k, v in table.items() if k not in ("builtin", "reference_point_mm")})
        scene = load_scene(name)
        rotation, translation = scene.fixed_placement(0).affine()
        hits = RayCaster(scene.fixed.vertices_mm, scene.fixed.triangles).cast(
            scene.mobile.centroids_mm, scene.mobile.unit_normals, scene.cartilage.max_spring_length_mm, rotation, translation
        )
        placed = dataclasses.replace(
            built,
            fixed=dataclasses.replace(built.fixed, vertices_mm=built.fixed.vertices_mm @ rotation.T + translation),
            ligaments=tuple(dataclasses.replace(lig, fixed_point_mm=rotation @ lig.fixed_point_mm + translation) for lig in built.ligaments),
        )
        lengths = np.where(np.isfinite(hits.spring_length_mm), hits.spring_length_mm, np.nan)
        written.append(render_geometry_png(placed, out / f"{name}.png", lengths, scene.cartilage.max_spring_length_mm, title=name))
    return written
