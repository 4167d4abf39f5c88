"""Result directories that are never partial, stale or mixed.

A result directory is written into a temporary sibling (``.<name>.tmp-<host>-<pid>-<random>``),
sealed with ``manifest.json`` (every file with its size and sha256, and the run id), flushed to
disk (fsync of every file and directory, all issued together) and only then renamed into place.
A writer hands each file over whole (:class:`ResultFiles`), hashed from the bytes written: the
manifest reads back only files written otherwise. A campaign's case
results, a cache that is verified before use and re-run when it does not verify, skip the flush
(``durable=False``): under the I/O of other processes it cost more than the rest of the write,
and a power cut can then leave a sealed directory whose files did not reach the disk, which its
manifest refuses like any other damage. An existing result
is replaced only when the caller says so (``overwrite``), and it stays untouched until the
rename: a crash, a kill or a full disk before that point leaves the previous result as it was
and at most a hidden temporary sibling, which the next write of that result removes. Readers verify the manifest (:func:`verify_manifest`): a
missing, changed or extra file (two runs mixed in one directory) is refused.

Output paths are checked before any solve (:func:`check_out_dir`): a path that is a file or
lies under one, a name too long for the file system, a directory that cannot be written (read-
only file system, permissions) and an existing result without ``overwrite`` are refused with
:class:`geometries.errors.InputError` (exit status 2). :func:`default_out_dir` keeps the default
output under the results root whatever the scene's name, and gives runs with ``--set``
overrides their own directory.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import hashlib
import json
import os
import re
import secrets
import shutil
import socket
import tempfile
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from geometries.errors import InputError

MANIFEST_NAME = "manifest.json"
MANIFEST_FORMAT = 1
#: Host tag of the temporary siblings: only this host's dead writers' siblings are removed.
_HOST = hashlib.sha256(socket.gethostname().encode()).hexdigest()[:8]
#: Bytes the temporary sibling's name adds to the result's name (".", ".tmp-", host, pid, 16 hex).
_SIBLING_EXTRA = 48
#: Name prefix of the write probes check_out_dir makes and removes at once (never content of a directory).
_PROBE_PREFIX = ".probe-"
_CHUNK = 1 << 20
#: threads hashing and flushing a result's files (the waits overlap; the hashing releases the GIL)
_SYNC_THREADS = 16


def _safe_name(text: str) -> str:
    """A single path component made of [A-Za-z0-9_.-], never "", "." or ".." (no leading dot)."""
    name = re.sub(r"[^A-Za-z0-9_.-]+", "-", text).strip("-.")
    return name or "scene"


def default_out_dir(root: str | Path, *parts: str, overrides: dict[str, Any] | None = None) -> Path:
    """``root/<part>-<part>...`` made of safe characters, plus ``-set-<hash>`` with overrides.

    ``parts`` (e.g. the scene name and the method) become one path component each stripped of
    separators and leading dots, so a scene named "../.." or "/etc" stays under ``root``. Runs
    with ``overrides`` (the ``--set`` values) get a suffix from a hash of them, so they never
    share a directory with the plain run or with other overrides.
    """
    name = "-".join(_safe_name(p) for p in parts)
    if overrides:
        digest = hashlib.sha256(json.dumps(overrides, sort_keys=True, default=str).encode()).hexdigest()
        name += f"-set-{digest[:10]}"
    return Path(root) / name


def _name_max(directory: Path) -> int:
    try:
        return os.pathconf(directory, "PC_NAME_MAX")
    except (OSError, ValueError):
        return 255


def _existing_ancestor(path: Path) -> Path:
    """The nearest ancestor of ``path`` (or itself) that exists; refuses one that is a file."""
    probe = path
    while not os.path.lexists(probe):
        probe = probe.parent
    if not probe.is_dir():
        where = "is a file, not a directory" if probe == path else f"lies under {probe}, which is a file"
        raise InputError(f"output {where}", file=path, key="--out", expected="a directory path")
    return probe


def is_result_dir(path: str | Path) -> bool:
    return (Path(path) / MANIFEST_NAME).is_file()


def check_out_dir(out: str | Path, *, overwrite: bool = False, reuse_if: tuple[str, ...] = ()) -> Path:
    """Refuse, before any computing, an output directory the result could not be written to.

    Creates the missing parent directories and a probe directory beside ``out`` (removed again)
    so that read-only file systems and permissions are found now, not after the solve.
    ``overwrite``: an existing result directory (one with a manifest) may be replaced; a non-
    empty directory that is not a result is never replaced. ``reuse_if``: the directory is kept
    and written into (a campaign's cache directory) when it is new, empty or holds one of these
    entries (e.g. "cases"). Returns the absolute path.
    """
    reuse = bool(reuse_if)
    out = Path(os.path.abspath(out))
    ancestor = _existing_ancestor(out)
    limit = _name_max(ancestor)
    for part in out.relative_to(ancestor).parts:
        if len(part.encode()) > limit:
            raise InputError(f"the name '{part[:40]}...' has {len(part.encode())} bytes", file=out, key="--out",
                             expected=f"names of at most {limit} bytes on this file system")
    if len(out.name.encode()) + _SIBLING_EXTRA > limit:
        raise InputError(f"the name has {len(out.name.encode())} bytes", file=out, key="--out",
                         expected=f"at most {limit - _SIBLING_EXTRA} bytes (room for the temporary sibling written first)")
    # another command's write probe (created and removed within microseconds) does not make the
    # directory "not empty": two campaigns started together would otherwise refuse for it
    entries = [p for p in out.iterdir() if not p.name.startswith(_PROBE_PREFIX)] if out.is_dir() else []
    if entries and reuse and not any(os.path.lexists(out / name) for name in reuse_if):
        raise InputError(f"the directory exists and holds no '{reuse_if[0]}' of an earlier run; it is never written into",
                         file=out, key="--out", expected="a new or empty directory, or one this command wrote")
    if entries and not reuse:
        if not is_result_dir(out):
            raise InputError("the directory exists and is not a result directory (no manifest.json); it is never replaced",
                             file=out, key="--out", expected="a new or empty directory")
        if not overwrite:
            raise InputError("a result exists here already", file=out, key="--out",
                             expected="--overwrite to replace it, or another --out")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        probe = tempfile.mkdtemp(prefix=_PROBE_PREFIX, dir=out.parent)
        os.rmdir(probe)
        if reuse:
            out.mkdir(exist_ok=True)
            probe = tempfile.mkdtemp(prefix=_PROBE_PREFIX, dir=out)
            os.rmdir(probe)
    except OSError as exc:
        raise InputError(f"cannot write here: {exc.strerror or exc}", file=out, key="--out",
                         expected="a writable directory (not a read-only file system)") from None
    return out


# ---------------------------------------------------------------------------------------------
# Manifest


def _sha256(path: Path, *, sync: bool = False) -> str:
    """sha256 of a file; with ``sync``, also flush it to disk (it is open anyway)."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(_CHUNK):
            digest.update(chunk)
        if sync:
            os.fsync(f.fileno())
    return digest.hexdigest()


def _fsync_file(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _listed_files(root: Path) -> list[str]:
    """Every file under ``root`` but manifests, as sorted relative POSIX paths (by os.walk: the
    directory entries say what is a file, where Path.rglob and is_file stat each one, 40x slower)."""
    listed = []
    for directory, _, files in os.walk(root):
        prefix = Path(directory).relative_to(root).as_posix() + "/"
        listed += [name if prefix == "./" else prefix + name for name in files if name != MANIFEST_NAME]
    return sorted(listed)


def write_manifest(root: str | Path, run_id: str | None = None, *, durable: bool = True,
                   known: dict[str, dict[str, Any]] | None = None) -> dict[str, Any]:
    """Seal ``root``: manifest.json lists every file (relative path, bytes, sha256) and the run id.

    ``durable``: every file and directory is fsynced on the way, so a sealed directory is on disk.
    ``known``: entries of files hashed from the bytes written (:attr:`ResultFiles.entries`); the
    other files are read back and hashed here.
    """
    from concurrent.futures import ThreadPoolExecutor

    root = Path(root)
    known = known or {}

    def entry(rel: str) -> dict[str, Any]:
        if rel not in known:
            return {"bytes": (root / rel).stat().st_size, "sha256": _sha256(root / rel, sync=durable)}
        if durable:
            _fsync_file(root / rel)
        return known[rel]

    listed = _listed_files(root)
    # fsyncs issued together: the file system commits them in a few journal transactions, where
    # one after the other each waited for its own (the 140 files of a 65-point run, 2026-11-28:
    # 0.63-0.68 s -> 0.03-0.07 s). Issued as each file is written instead, they cost more: more,
    # smaller commits (measured 2026-11-28 on the stance at 3k and 13k springs, load 3: the
    # writer 20-30 % slower, wall and CPU).
    with ThreadPoolExecutor(max_workers=_SYNC_THREADS) as pool:
        files = dict(zip(listed, pool.map(entry, listed)))
    manifest = {"format": MANIFEST_FORMAT, "run_id": run_id or uuid.uuid4().hex, "files": files}
    tmp = root / (MANIFEST_NAME + ".tmp")
    with open(tmp, "w", encoding="utf-8") as f:
        f.write(json.dumps(manifest, indent=1) + "\n")
        f.flush()
        if durable:
            os.fsync(f.fileno())
    os.replace(tmp, root / MANIFEST_NAME)
    if durable:
        for directory in {root} | {(root / rel).parent for rel in files}:
            _fsync_dir(directory)
    return manifest


def manifest_problems(root: str | Path) -> list[str]:
    """What does not match the manifest of ``root`` (empty when it verifies)."""
    root = Path(root)
    try:
        manifest = json.loads((root / MANIFEST_NAME).read_text(encoding="utf-8"))
        files = manifest["files"]
    except FileNotFoundError:
        return ["no manifest.json (the write did not finish, or an old layout)"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        return [f"unreadable manifest.json ({exc})"]
    problems = []
    present = set(_listed_files(root))
    for rel in sorted(present - set(files)):
        problems.append(f"{rel} is not in the manifest (left by another run)")
    for rel, entry in files.items():
        path = root / rel
        if rel not in present:
            problems.append(f"{rel} is missing")
        elif path.stat().st_size != entry.get("bytes"):
            problems.append(f"{rel} has {path.stat().st_size} bytes, the manifest says {entry.get('bytes')}")
        elif _sha256(path) != entry.get("sha256"):
            problems.append(f"{rel} was changed after the run (sha256 differs)")
    return problems


def verify_manifest(root: str | Path) -> str:
    """The run id of ``root``; InputError naming the directory and what differs otherwise."""
    problems = manifest_problems(root)
    if problems:
        more = f" (and {len(problems) - 3} more)" if len(problems) > 3 else ""
        raise InputError("incomplete, changed or mixed result directory: " + "; ".join(problems[:3]) + more,
                         file=root, expected="a directory as one run wrote it (manifest.json verifies)")
    return json.loads((Path(root) / MANIFEST_NAME).read_text(encoding="utf-8"))["run_id"]


# ---------------------------------------------------------------------------------------------
# Atomic write


class ResultWriteError(InputError):
    """Writing a result failed (disk full, I/O error...): exit status 2 like bad input, but a
    campaign records it as a crash to run again, never as the case's refusal."""


def _write_error(out: Path, exc: OSError) -> ResultWriteError:
    full = exc.errno in (errno.ENOSPC, errno.EDQUOT)
    problem = "the disk is full" if full else f"cannot write the result ({exc.strerror or exc})"
    return ResultWriteError(f"{problem}; nothing was written there and a previous result is unchanged", file=out,
                            expected="free space and a writable directory" if full else "a writable directory")


def _sibling(out: Path, kind: str) -> Path:
    """``.<name>.<kind>-<host>-<pid>-<random>``: hidden, and traceable to the process writing it."""
    return out.parent / f".{out.name}.{kind}-{_HOST}-{os.getpid()}-{secrets.token_hex(8)}"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_siblings(out: str | Path) -> list[str]:
    """Remove the temporary siblings of ``out`` left by writers of this host that were killed
    (their pid no longer exists); returns their names. Live writers' siblings are kept."""
    out = Path(os.path.abspath(out))
    pattern = re.compile(rf"^\.{re.escape(out.name)}\.(tmp|old)-{_HOST}-(\d+)-[0-9a-f]{{16}}$")
    removed = []
    with contextlib.suppress(OSError):
        for entry in out.parent.iterdir():
            match = pattern.match(entry.name)
            if match and not _alive(int(match.group(2))):
                shutil.rmtree(entry, ignore_errors=True)
                removed.append(entry.name)
    return removed


def _write_file(path: Path, data: bytes) -> None:
    """Write a new file (never over one: a name given twice is an error)."""
    with open(path, "xb") as f:
        f.write(data)


class ResultFiles:
    """The files of a result directory being written (:func:`atomic_result_dir`): each is
    given whole to :meth:`write`, which writes it and takes its manifest entry (size, sha256)
    from the bytes written, so that the manifest reads nothing back (:attr:`entries`; the
    flush to disk comes with the manifest, all files together)."""

    def __init__(self, root: Path) -> None:
        self.root = root
        #: manifest entries of the files written, by name relative to the root
        self.entries: dict[str, dict[str, Any]] = {}

    def write(self, name: str, data: str | bytes) -> None:
        """Write file ``name`` (relative to :attr:`root`) with ``data`` (text as UTF-8)."""
        content = data.encode("utf-8") if isinstance(data, str) else bytes(data)
        _write_file(self.root / name, content)
        self.entries[name] = {"bytes": len(content), "sha256": hashlib.sha256(content).hexdigest()}


@contextlib.contextmanager
def atomic_result_dir(out: str | Path, *, overwrite: bool = False, run_id: str | None = None,
                      durable: bool = True) -> Iterator[ResultFiles]:
    """Yield the :class:`ResultFiles` of a temporary sibling of ``out``; seal it and rename it
    to ``out`` on exit.

    Files are written through :meth:`ResultFiles.write` or directly into its ``root`` (those are
    read back and hashed by the manifest). ``durable=False`` skips the fsyncs (module docstring:
    for verified caches only); the write stays atomic and sealed.

    An existing ``out`` is replaced only with ``overwrite`` and only when it is a result
    directory or empty; it stays whole until the rename (an atomic exchange where the file
    system has one). An exception inside the block removes the temporary sibling and leaves
    ``out`` as it was; OSError (disk full, read-only, ...) becomes ResultWriteError (an
    InputError: exit status 2) with a message. Siblings of killed earlier writers are removed.
    """
    out = Path(os.path.abspath(out))
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        remove_stale_siblings(out)
        tmp = _sibling(out, "tmp")
        tmp.mkdir()  # not mkdtemp: the result gets the umask's permissions, not 0700
    except OSError as exc:
        raise _write_error(out, exc) from None
    files = ResultFiles(tmp)
    try:
        yield files
        write_manifest(tmp, run_id, durable=durable, known=files.entries)
        _replace(tmp, out, overwrite, durable)
    except OSError as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        raise _write_error(out, exc) from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _exchange(a: Path, b: Path) -> bool:
    """Swap two directories in one atomic step (Linux renameat2 RENAME_EXCHANGE); False if unsupported."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    at_fdcwd, rename_exchange = -100, 2
    if renameat2(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP):
        return False  # a file system without exchange: fall back to two renames
    raise OSError(code, os.strerror(code), str(b))


def _replace(tmp: Path, out: Path, overwrite: bool, durable: bool = True) -> None:
    if os.path.lexists(out):
        if out.is_dir() and not any(out.iterdir()):
            out.rmdir()
        elif not overwrite or not is_result_dir(out):
            raise InputError("a result exists here already" if is_result_dir(out) else "exists and is not a result directory",
                             file=out, expected="--overwrite to replace a result directory, or another --out")
        elif _exchange(tmp, out):  # the old result is now at tmp: never a moment without a result
            if durable:
                _fsync_dir(out.parent)
            shutil.rmtree(tmp, ignore_errors=True)
            return
        else:
            old = _sibling(out, "old")
            os.rename(out, old)
            os.rename(tmp, out)
            if durable:
                _fsync_dir(out.parent)
            shutil.rmtree(old, ignore_errors=True)
            return
    os.rename(tmp, out)
    if durable:
        _fsync_dir(out.parent)
