"""What makes a result directory reproducible: the resolved scene, the overrides, the software
version and the source revision (docs/result-format.md).

:func:`record_provenance` is called by every producer of a scene's result directory (``edem run``,
``edem fe``, the campaign sides) after the directory is written. It adds

* ``scene.toml``: the scene after every override, with the files it reads (meshes, load and
  kinematics files) as absolute paths and its name kept, so ``edem run DIR/scene.toml`` (or
  ``edem fe``) reproduces the run exactly; FE settings given outside the scene go into its
  ``[fe]`` table;
* to ``summary.json``: ``overrides`` (the dotted keys and values applied), ``scene_source`` (the
  scene argument as given), ``software_version`` and ``source_revision``.
"""

from __future__ import annotations

import importlib.metadata
import json
import subprocess
import tomllib
from functools import lru_cache
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
SCENE_FILE = "scene.toml"
#: scene keys that name files, relative to the scene file: (section, key)
FILE_KEYS = (("geometry", "mobile"), ("geometry", "fixed"), ("load", "file"), ("kinematics", "file"))


def software_version() -> str:
    """The installed ``edem`` package version ("unknown" when it is not installed)."""
    try:
        return importlib.metadata.version("edem")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


@lru_cache(maxsize=1)
def source_revision() -> str:
    """The git commit of the source tree (``-dirty`` when it has uncommitted changes), or "unknown"."""
    def git(*args: str) -> str:
        return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True, check=True, timeout=20).stdout.strip()

    try:
        commit = git("rev-parse", "HEAD")
        dirty = git("status", "--porcelain", "--untracked-files=no", "--", "edem", "geometries", "fem_reference", "verification", "reports")
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return commit + ("-dirty" if dirty else "") if commit else "unknown"


def resolved_scene(scene_ref: str | Path, overrides: dict[str, Any] | None = None, fe_settings: dict[str, Any] | None = None,
                   method: str | None = None) -> dict[str, Any]:
    """The scene's TOML data after ``overrides``, file paths made absolute, its name pinned.

    ``fe_settings`` (model, mesh_size_mm, degree) are written into ``[fe]``, ``method`` (a
    ``--method`` given on the command line) into ``[solver]``. Overrides must
    already be plain dotted keys (``verification.sides.expand_array_overrides`` expands the
    ``array[*].key`` form).
    """
    from edem.scene import apply_overrides, resolve_scene_path

    path = resolve_scene_path(scene_ref)
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    if overrides:
        apply_overrides(data, dict(overrides))
    meta = data.setdefault("scene", {})
    meta.setdefault("name", path.stem)  # the resolved file is called scene.toml: keep the scene's own name
    for section, key in FILE_KEYS:
        value = data.get(section, {}).get(key) if isinstance(data.get(section), dict) else None
        if isinstance(value, str):
            data[section][key] = str((path.parent / value).resolve())
    if method:
        data.setdefault("solver", {})["method"] = method
    if fe_settings:
        data.setdefault("fe", {}).update({k: v for k, v in fe_settings.items() if v is not None})
    return data


def record_provenance(out_dir: str | Path, scene_ref: str | Path, overrides: dict[str, Any] | None = None,
                      fe_settings: dict[str, Any] | None = None, method: str | None = None) -> None:
    """Write ``scene.toml`` into a result directory and the provenance keys into its summary.json
    (arguments as :func:`resolved_scene`)."""
    import tomli_w

    out = Path(out_dir)
    (out / SCENE_FILE).write_text(tomli_w.dumps(resolved_scene(scene_ref, overrides, fe_settings, method)), encoding="utf-8")
    path = out / "summary.json"
    summary = json.loads(path.read_text(encoding="utf-8"))
    summary.update(
        overrides=dict(overrides or {}),
        scene_source=str(scene_ref),
        software_version=software_version(),
        source_revision=source_revision(),
    )
    path.write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
