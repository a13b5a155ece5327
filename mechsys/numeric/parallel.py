"""Forked worker processes for independent pieces of one analysis, with the serial loop as fallback and reference.

A sweep's multistart at each sample value and its continuation branches are independent computations on the same
compiled equations. Forked workers inherit those (ctypes libraries, closures) without pickling; only indices go
out and plain results (arrays, dataclasses) come back, so the results are those of the serial loop, bit for bit.

``MECHSYS_WORKERS`` caps the processes one analysis forks (1: serial). A process started by ``multiprocessing``
(a worker of ``mechsys sweep`` or ``check``, or of this module) never forks further: the batch commands already
use every core. Without ``fork`` (Windows, macOS' default) the loop runs serially.
"""
from __future__ import annotations

import multiprocessing
import os
import sys
from concurrent.futures import Future, ProcessPoolExecutor
from typing import Any, Callable

ENV = "MECHSYS_WORKERS"

#: (take, give): what a worker hands back after each task, and what this process does with it.
Share = tuple[Callable[[], Any], Callable[[Any], None]]

#: The tasks of the open pools by token, set before their workers are forked (inherited, never pickled).
_TASKS: dict[int, tuple[Callable[[int], Any], Callable[[], Any] | None]] = {}


def available() -> int:
    """How many processes one analysis may use: MECHSYS_WORKERS, else the CPUs this process may run on; 1 inside
    a worker process or where fork is not the platform's safe default."""
    if multiprocessing.parent_process() is not None or sys.platform != "linux":
        return 1
    text = os.environ.get(ENV, "").strip()
    if text:
        try:
            return max(1, int(text))
        except ValueError:
            from mechsys.errors import InputError

            raise InputError(f"{ENV}={text!r}: expected a whole number of worker processes") from None
    return cores()


def cores() -> int:
    """The CPUs this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def _run(token: int, k: int) -> Any:
    task, take = _TASKS[token]
    value = task(k)
    return value, (take() if take is not None else None)


class Workers:
    """``submit(k)`` runs ``task(k)`` in a forked worker (or here, at ``result``, when serial); use as a context
    manager. ``task`` must be a pure function of its index and the state at construction: the workers see the
    process as it was then, and what they change stays in them, except what ``share = (take, give)`` carries
    back: a worker calls ``take()`` after each task (e.g. the new entries of a memo) and this process
    ``give(taken)`` with it when it reads the result."""

    def __init__(self, task: Callable[[int], Any], count: int, share: Share | None = None) -> None:
        self.task = task
        self.share = share
        self.processes = min(available(), max(count, 1))
        self._pool: ProcessPoolExecutor | None = None
        self._token = id(self)
        if self.processes > 1:
            _TASKS[self._token] = (task, share[0] if share else None)
            self._pool = ProcessPoolExecutor(self.processes, mp_context=multiprocessing.get_context("fork"))

    def submit(self, k: int) -> Future | int:
        return self._pool.submit(_run, self._token, k) if self._pool is not None else k

    def result(self, handle: Future | int) -> Any:
        """The task's value (its exception re-raised here; a crashed worker raises BrokenProcessPool)."""
        if not isinstance(handle, Future):
            return self.task(handle)
        value, taken = handle.result()
        if self.share is not None:
            self.share[1](taken)
        return value

    def discard(self, *handles: Future | int) -> None:
        """Results not wanted: not run when they have not started."""
        for handle in handles:
            if isinstance(handle, Future):
                handle.cancel()

    def __enter__(self) -> "Workers":
        return self

    def __exit__(self, *exc: object) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            _TASKS.pop(self._token, None)


def fork_map(task: Callable[[int], Any], count: int, share: Share | None = None) -> list[Any]:
    """[task(0), ..., task(count - 1)], spread over forked workers when more than one process is available."""
    with Workers(task, count, share) as workers:
        handles = [workers.submit(k) for k in range(count)]
        return [workers.result(h) for h in handles]
