"""Run a reader in a forked child process, so that a crash in it (a C++ reader trusting damaged
input) ends the child, not the caller: the crash becomes an InputError naming the file.

The child inherits the parent's memory (modules already imported, the arguments), runs the
function, and sends back through a pipe its result or its InputError, and the warnings it
emitted, which the parent emits again. Nothing of the child's state comes back otherwise.
"""

from __future__ import annotations

import faulthandler
import gc
import os
import pickle
import signal
import traceback
import warnings
from collections.abc import Callable
from typing import Any

from geometries.errors import InputError

__all__ = ["run_in_child"]


def run_in_child(function: Callable[..., Any], *args: Any, file: str, key: str | None, expected: str) -> Any:
    """``function(*args)`` computed in a forked child process.

    Returns its result (which must pickle), raises its InputError, and emits again the warnings
    it emitted; another exception in the child is a RuntimeError carrying its traceback. When the
    child dies without an answer (a signal such as SIGSEGV or SIGABRT, an exit without a result)
    raises InputError naming ``file`` and ``key``, with ``expected`` as the expectation. Where the platform cannot fork,
    runs ``function`` in this process.
    """
    if not hasattr(os, "fork"):  # pragma: no cover - not on Linux or macOS
        return function(*args)
    read_end, write_end = os.pipe()
    with warnings.catch_warnings():
        # Python 3.12 warns that a fork of a threaded process may deadlock in the child: the
        # child here only reads a file and writes a pipe, and the parent never waits on it
        # without reading (a child that hangs hangs the read, as an in-process reader would).
        warnings.simplefilter("ignore", DeprecationWarning)
        pid = os.fork()
    if pid == 0:  # the child: never returns, never runs the parent's cleanup (os._exit)
        status = 1
        try:
            # The collector would walk every object the parent had, copying each page it
            # touches: a short-lived child does without it.
            gc.disable()
            # A crash ends the child by its signal, not in a handler the parent installed
            # (PETSc's calls MPI_Abort, which under mpirun takes every rank down).
            faulthandler.disable()
            for crash in (signal.SIGSEGV, signal.SIGBUS, signal.SIGFPE, signal.SIGILL, signal.SIGABRT):
                signal.signal(crash, signal.SIG_DFL)
            os.close(read_end)
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                try:
                    answer: tuple = ("result", function(*args))
                except InputError as err:
                    answer = ("input_error", (err.problem, err.file, err.key, err.expected))
                except Exception:  # a bug, not the file: its traceback goes to the parent
                    answer = ("bug", traceback.format_exc())
            emitted = [(w.category, str(w.message)) for w in caught]
            with os.fdopen(write_end, "wb") as stream:
                pickle.dump((answer, emitted), stream, protocol=pickle.HIGHEST_PROTOCOL)
            status = 0
        finally:
            os._exit(status)
    os.close(write_end)
    try:
        with os.fdopen(read_end, "rb") as stream:
            payload = stream.read()  # until the child closes its end: it exited or wrote everything
    except BaseException:  # Ctrl-C: the child goes too
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        raise
    _, wait_status = os.waitpid(pid, 0)
    if os.WIFSIGNALED(wait_status) or os.WEXITSTATUS(wait_status) != 0 or not payload:
        raise InputError(f"the reader crashed on this file ({_death(wait_status)}); nothing of it was used",
                         file=file, key=key, expected=expected)
    (kind, value), emitted = pickle.loads(payload)
    for category, text in emitted:
        warnings.warn(text, category, stacklevel=2)
    if kind == "bug":
        raise RuntimeError(f"{getattr(function, '__name__', function)} failed in the child process:\n{value}")
    if kind == "input_error":
        problem, err_file, err_key, err_expected = value
        raise InputError(problem, file=err_file, key=err_key, expected=err_expected)
    return value


def _death(wait_status: int) -> str:
    if os.WIFSIGNALED(wait_status):
        number = os.WTERMSIG(wait_status)
        try:
            return f"killed by signal {signal.Signals(number).name}"
        except ValueError:
            return f"killed by signal {number}"
    return f"exit status {os.WEXITSTATUS(wait_status)} without an answer"
