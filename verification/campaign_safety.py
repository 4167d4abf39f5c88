"""A campaign directory under concurrency and interrupts: one writer at a time, workers that die
with their parent, Ctrl-C that stops cleanly.

* :func:`campaign_lock` holds an exclusive ``flock`` on ``OUT/.lock`` while a campaign runs; a
  second campaign on the same directory is refused at once, naming the process that holds it.
  The kernel drops the lock when its holder dies, so a killed campaign never leaves a stale one.
* :func:`init_worker` runs first in every worker process: it ignores SIGINT (the parent owns
  Ctrl-C and stops the workers itself) and asks the kernel to kill the worker when its parent
  dies (Linux ``prctl(PR_SET_PDEATHSIG)``; elsewhere a thread watching the parent's pid), so a
  killed campaign leaves no worker writing into its directory.
* :class:`CampaignInterrupted` is what a Ctrl-C becomes: the message says how many cases are
  done; every finished case is already on disk (each case's metrics.json is written last) and the
  same command continues from there.
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

from geometries.errors import InputError

LOCK_NAME = ".lock"
_PR_SET_PDEATHSIG = 1


class CampaignInterrupted(KeyboardInterrupt):
    """Ctrl-C during a campaign, after its workers were stopped; the message is for the user."""


@contextlib.contextmanager
def campaign_lock(out: Path) -> Iterator[None]:
    """Hold the campaign lock of ``out`` (created if needed); InputError if another process has it."""
    out.mkdir(parents=True, exist_ok=True)
    fd = os.open(out / LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 64, 0).decode(errors="replace").strip() or "unknown"
            raise InputError(f"another campaign (pid {holder}) is writing this directory", file=out, key="--out",
                             expected="to wait until it has finished, or another --out") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        yield
    finally:
        os.close(fd)  # releases the lock


def init_worker(parent_pid: int) -> None:
    """ProcessPoolExecutor initializer: ignore SIGINT, die with the parent (module docstring)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})  # blocked while the parent spawned us
    armed = False
    if sys.platform.startswith("linux"):
        try:
            armed = ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0
        except (OSError, AttributeError):
            armed = False
    if os.getppid() != parent_pid:  # the parent died before the signal was armed
        os._exit(1)
    if not armed:
        threading.Thread(target=_watch_parent, args=(parent_pid,), daemon=True).start()


def _watch_parent(parent_pid: int) -> None:
    while os.getppid() == parent_pid:
        time.sleep(1.0)
    os._exit(1)


@contextlib.contextmanager
def sigint_blocked() -> Iterator[None]:
    """Block SIGINT while worker processes are started: they inherit the mask, so a Ctrl-C that
    reaches the whole process group cannot interrupt a worker before :func:`init_worker` runs;
    the parent receives it when the block ends."""
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def stop_children(before: set[int]) -> None:
    """Kill the multiprocessing children started since ``before`` (their pids) and reap them."""
    children = [p for p in multiprocessing.active_children() if p.pid not in before]
    for process in children:
        process.kill()
    for process in children:
        process.join(timeout=5)
