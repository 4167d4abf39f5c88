"""The project's own import graph, read from the source with ``ast``, and digests of module sources.

A campaign case's cache key hashes the source of the modules that compute it: the modules its
sides name (:func:`verification.sides.side_modules`) and everything they import, at module top
or inside functions (:func:`dependency_closure`). Editing a module outside that set (another
campaign, a report) leaves the case's cached results valid.
"""

from __future__ import annotations

import ast
import hashlib
from collections.abc import Iterable
from functools import lru_cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: the project's packages, lowest layer first
PACKAGES = ("geometries", "edem", "fem_reference", "verification", "reports")


def module_files(root: Path = ROOT) -> dict[str, Path]:
    """Dotted module name -> file of every module of the packages (``pkg`` for pkg/__init__.py)."""
    out = {}
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            parts = path.relative_to(root).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def imported_modules(name: str, path: Path, known: set[str]) -> set[str]:
    """The project modules module ``name`` (file ``path``) imports, anywhere in the file.

    ``from pkg import sub`` counts as importing ``pkg.sub`` when that is a module of ``known``;
    ``from mod import function`` as importing ``mod``.
    """
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                source = ".".join(parts[: len(parts) - (node.level - 1)] + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            targets = [source] + [f"{source}.{alias.name}" for alias in node.names]
        else:
            continue
        for target in targets:
            if target.split(".")[0] not in PACKAGES:
                continue
            while target not in known and "." in target:  # a name inside a module: that module
                target = target.rpartition(".")[0]
            if target in known and target != name:
                found.add(target)
    return found


def import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    """Module -> the project modules it imports."""
    files = module_files(root)
    return {name: imported_modules(name, path, set(files)) for name, path in files.items()}


def dependency_closure(roots: Iterable[str], graph: dict[str, set[str]]) -> set[str]:
    """``roots`` and every module they import, directly or not (a package root: all its modules)."""
    todo = [m for root in roots for m in graph if m == root or m.startswith(root + ".")]
    seen: set[str] = set()
    while todo:
        module = todo.pop()
        if module not in seen:
            seen.add(module)
            todo.extend(graph.get(module, ()))
    return seen


@lru_cache(maxsize=None)
def source_digest(modules: tuple[str, ...], root: Path = ROOT) -> str:
    """sha256 over the names and source of ``modules`` (a package name: all its modules)."""
    files = module_files(root)
    chosen = sorted({m for name in modules for m in files if m == name or m.startswith(name + ".")})
    digest = hashlib.sha256()
    for module in chosen:
        digest.update(module.encode())
        digest.update(files[module].read_bytes())
    return digest.hexdigest()


@lru_cache(maxsize=None)
def closure_digest(roots: tuple[str, ...], root: Path = ROOT) -> str:
    """:func:`source_digest` of ``roots`` and everything they import."""
    return source_digest(tuple(sorted(dependency_closure(roots, import_graph(root)))), root)
