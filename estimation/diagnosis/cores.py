"""Independent local fits of one diagnosis shared between this process and a helper process on another core.

A diagnosis spends most of its time in batches of local fits that do not
depend on each other: the random starts of the baseline
(:func:`.baseline.fit_multistart`), the forms of each cause, the candidate
sections and seeds of a missing section, the baseline refitted from each
candidate's values, and the check of each drifted value
(:func:`.drift.relaxed_drift`). On a machine with a second core, one helper
process (started once per Python process from multiprocessing's fork
server, one BLAS thread) takes the items of each batch from its end while
this process takes them from its start (:class:`SharedBatch`). The items
are pickled when they are handed over, so the helper sees the objects as
they were then, and every fit is the same deterministic computation in
either process: which process runs an item depends on timing, its result
does not. A diagnosis gives the same answer with or without the helper.

The helper is not used inside a daemonic process (a Dask worker cannot
have children), on a machine with one core, or when the environment
variable ``PRIS_DIAGNOSE_JOBS`` is ``1``; it is given up for the rest of the
process if it cannot be started or dies (the work is then done here). It
is started without the caller's main script (:func:`_main_hidden`), so a
script without an ``if __name__ == "__main__"`` guard is not run twice.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import importlib
import multiprocessing
import os
import pickle
import sys
import types
from collections.abc import Callable, Iterator, Sequence
from typing import Any, TypeVar

import numpy as np

T = TypeVar("T")
R = TypeVar("R")

#: Environment variable: ``1`` (or ``0``) runs every fit of a diagnosis in this process.
JOBS_VARIABLE = "PRIS_DIAGNOSE_JOBS"

_helper: cf.ProcessPoolExecutor | None = None
_broken = False
_helper_pid = 0


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def helper_wanted() -> bool:
    """A helper process may be used: two or more cores, not a daemonic process, not switched off."""
    if os.environ.get(JOBS_VARIABLE, "").strip() in ("0", "1") or _broken:
        return False
    if multiprocessing.current_process().daemon or _cores() < 2:
        return False
    return "forkserver" in multiprocessing.get_all_start_methods()


def _get_helper() -> cf.ProcessPoolExecutor | None:
    global _helper, _helper_pid
    if not helper_wanted():
        return None
    if _helper is not None and _helper_pid == os.getpid():
        return _helper
    try:
        from .._workers import init_worker
        from ..executor import _start_forkserver_detached

        with _main_hidden():  # the helper process starts now, without running the caller's script again
            _start_forkserver_detached()
            _helper = cf.ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("forkserver"),
                                             initializer=init_worker, initargs=(os.getpid(), True))
            _helper.submit(_import_fits)
        _helper_pid = os.getpid()
    except (OSError, ValueError, RuntimeError, cf.process.BrokenProcessPool):
        _give_up()
        return None
    return _helper


@contextlib.contextmanager
def _main_hidden() -> Iterator[None]:
    """An empty ``__main__`` while a process is started.

    A process started by the fork server or by spawning imports the parent's
    main script again (as ``__mp_main__``) unless its top level is guarded
    by ``if __name__ == "__main__"``. The helper only runs functions of this
    package, so it is given no main script: a user's unguarded script is not
    run twice.
    """
    saved = sys.modules.get("__main__")
    sys.modules["__main__"] = types.ModuleType("__main__")
    try:
        yield
    finally:
        if saved is not None:
            sys.modules["__main__"] = saved


def _import_fits() -> bool:
    """Import the modules whose functions the batches of a diagnosis run (done once, while this process fits)."""
    importlib.import_module(f"{__package__}.diagnose")
    return True


def helper_available() -> bool:
    """A helper process runs (started now if wanted and not yet running)."""
    return _get_helper() is not None


def warm_up() -> None:
    """Start the helper (if wanted; it imports the fitting modules in the background)."""
    _get_helper()


def _give_up() -> None:
    global _helper, _broken
    _broken = True  # for the rest of this process: the work is done here
    if _helper is not None:
        _helper.shutdown(wait=False, cancel_futures=True)
    _helper = None


def _run_pickled(payload: bytes) -> Any:
    """``fn(item)`` of a pickled ``(fn, item)`` (the helper's side of :class:`SharedBatch`)."""
    fn, item = pickle.loads(payload)
    return fn(item)


class SharedBatch:
    """``[fn(item) for item in items]`` shared with the helper process: it takes items from the end of the list,
    this process from the start, until they meet.

    Every item but the first is handed to the helper at once, pickled then
    (a snapshot: this process may go on changing the objects, a fit's
    smoothing during a continuation, before :meth:`result`). :meth:`result`
    runs the items from the start here, taking back each one the helper has
    not begun, and collects the helper's results from where they met. Which
    process runs an item depends on timing; its result does not (the same
    deterministic computation on the same values). ``fn`` must be a
    module-level function and ``items`` picklable. Without a helper (or when
    it fails), every item is run here.
    """

    def __init__(self, fn: Callable[[T], R], items: Sequence[T]) -> None:
        self.fn, self.items = fn, list(items)
        self.futures: dict[int, cf.Future] = {}
        helper = _get_helper() if len(self.items) > 1 else None
        if helper is None:
            return
        try:
            for i in range(len(self.items) - 1, 0, -1):  # the helper begins at the end
                payload = pickle.dumps((fn, self.items[i]), protocol=pickle.HIGHEST_PROTOCOL)
                self.futures[i] = helper.submit(_run_pickled, payload)
        except (RuntimeError, cf.process.BrokenProcessPool, pickle.PicklingError):
            self._cancel_all()
            _give_up()

    def _cancel_all(self) -> None:
        for future in self.futures.values():
            future.cancel()
        self.futures = {}

    def result(self) -> list[R]:
        """Every item's result, in the order of the items."""
        out: list[Any] = [None] * len(self.items)
        i = 0
        while i < len(self.items) and (i not in self.futures or self.futures[i].cancel()):
            out[i] = self.fn(self.items[i])  # not begun by the helper: run here
            i += 1
        for j in range(i, len(self.items)):
            try:
                out[j] = self.futures[j].result()
            except cf.process.BrokenProcessPool:
                self._cancel_all()
                _give_up()
                out[j:] = [self.fn(item) for item in self.items[j:]]
                break
        return out


def shared_map(fn: Callable[[T], R], items: Sequence[T]) -> list[R]:
    """``[fn(item) for item in items]``, shared with the helper process.

    ``fn`` must be a module-level function and ``items`` picklable; results
    come back in the order of ``items``; the helper runs items from the end
    while this process runs them from the start (:class:`SharedBatch`).
    """
    return SharedBatch(fn, items).result()


def starts_fitted(args: tuple[Any, Any, dict[str, Any]]) -> tuple[Any, float, int]:
    """One local fit from one start row: ``(fit, x0, options)`` to ``(x, cost, nfev)`` (for :func:`shared_map`)."""
    fit, x0, options = args
    r = fit.fit(x0s=x0[None], grid=False, keep_starts=1, **options)
    return r.x, float(np.sum(fit.residuals(r.x) ** 2)), int(r.nfev)
