"""Independent local fits of one diagnosis shared between this process and a helper process on another core.

A diagnosis spends most of its time in batches of local fits that do not
depend on each other: the random starts of the baseline
(:func:`.baseline.fit_multistart`), the forms of each cause (:mod:`.single`), the candidate
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
variable ``PRIS_DIAGNOSE_JOBS`` is ``1`` (any other value but a whole
number is refused); it is given up for the rest of the
process if it cannot be started or dies (the work is then done here). It
is started without the caller's main script (:func:`_main_hidden`), so a
script without an ``if __name__ == "__main__"`` guard is not run twice.
"""

from __future__ import annotations

import contextlib
import importlib
import multiprocessing
import os
import pickle
import queue
import signal
import sys
import threading
import types
from collections.abc import Callable, Iterator, Sequence
from typing import Any, TypeVar

T = TypeVar("T")
R = TypeVar("R")

#: Environment variable: ``1`` runs every fit of a diagnosis in this process (unset, or 2 and more: a helper when
#: there is a second core).
JOBS_VARIABLE = "PRIS_DIAGNOSE_JOBS"
#: Seconds between checks that the helper is still alive while its results are awaited.
POLL_S = 0.5


class _Helper:
    """The helper process, its pipe, and the claim bounds ``[low, high)`` of the batch in hand (shared, locked)."""

    def __init__(self) -> None:
        from estimation.search.executor import _start_forkserver_detached

        ctx = multiprocessing.get_context("forkserver")
        self.lock = ctx.Lock()
        self.bounds = ctx.Array("q", 2, lock=False)
        self.conn, child = ctx.Pipe()
        self.batch = 0
        self.busy = False  # the helper has a batch whose end message this process has not read
        self.active = False  # a batch's result is being collected: a batch begun meanwhile runs here
        with _main_hidden():  # the helper starts now, without running the caller's script again
            _start_forkserver_detached()
            self.proc = ctx.Process(target=_helper_loop, args=(child, self.lock, self.bounds, os.getpid()),
                                    name="pris-diagnose-helper", daemon=True)
            self.proc.start()
        child.close()
        self.pid = os.getpid()
        # the helper's messages read as they come: a result larger than the pipe's buffer would otherwise hold the
        # helper until this process finished its own items
        self.inbox: queue.Queue = queue.Queue()
        self.reader = threading.Thread(target=self._read, name="pris-diagnose-helper-reader", daemon=True)
        self.reader.start()

    def _read(self) -> None:
        while True:
            try:
                self.inbox.put(self.conn.recv())
            except Exception:  # noqa: BLE001  (closed, died, or a message that does not unpickle: given up)
                self.inbox.put(None)
                return

    def claim_low(self) -> int:
        """The next item from the start, or -1 when the two ends have met."""
        with self.lock:
            if self.bounds[0] < self.bounds[1]:
                self.bounds[0] += 1
                return int(self.bounds[0] - 1)
        return -1

    def receive(self) -> tuple:
        """The helper's next message; raises ``EOFError`` once it has died."""
        while True:
            try:
                msg = self.inbox.get(timeout=POLL_S)
            except queue.Empty:
                if not self.proc.is_alive() and self.inbox.empty():
                    raise EOFError("the helper process died") from None
                continue
            if msg is None:
                raise EOFError("the helper process died")
            return msg

    def settle(self) -> None:
        """Wait until the helper has finished the batch in hand (its end message read); raises ``EOFError`` if it
        died."""
        while self.busy:
            batch, i, _, _ = self.receive()
            if batch == self.batch and i < 0:
                self.busy = False

    def stop(self) -> None:
        """No more claims in the batch in hand (the helper finishes the item it runs)."""
        with self.lock:
            self.bounds[1] = self.bounds[0]

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.conn.close()
        with contextlib.suppress(Exception):
            self.proc.kill()


_helper: _Helper | None = None
_broken = False


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def jobs_setting() -> int | None:
    """``PRIS_DIAGNOSE_JOBS`` as a whole number >= 1 (None when unset); raises :class:`.fit.DiagnosisError` naming
    the variable for any other value."""
    text = os.environ.get(JOBS_VARIABLE, "").strip()
    if not text:
        return None
    if not text.isdigit() or int(text) < 1:
        from estimation.diagnosis.fit import DiagnosisError

        raise DiagnosisError(f"{JOBS_VARIABLE}={text!r}: expected a whole number of processes >= 1 (1: one core)")
    return int(text)


def helper_wanted() -> bool:
    """A helper process may be used: two or more cores, not a daemonic process, not switched off."""
    if jobs_setting() == 1 or _broken:
        return False
    if multiprocessing.current_process().daemon or _cores() < 2:
        return False
    return "forkserver" in multiprocessing.get_all_start_methods()


def _get_helper() -> _Helper | None:
    global _helper
    if not helper_wanted():
        return None
    if _helper is not None and _helper.pid == os.getpid() and _helper.proc.is_alive():
        return _helper
    try:
        _helper = _Helper()
    except (OSError, ValueError, RuntimeError):
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


def _helper_loop(conn: Any, lock: Any, bounds: Any, parent: int) -> None:
    """The helper's life: for each batch received, claim items from the end, run them, send each result back.

    Every batch ends with a ``(batch, -1, True, None)`` message, sent once
    the two ends have met. An item that raises (or whose result does not
    pickle) is sent back as not done: this process then runs it itself.
    """
    from estimation.search._threads import single_threaded_blas
    from estimation.search._workers import watch_parent

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the main process's to handle
    watch_parent(parent)
    single_threaded_blas()
    importlib.import_module(f"{__package__}.diagnose")  # what the batches' functions need, before the first
    while True:
        try:
            batch, payload = conn.recv()
        except (EOFError, OSError):
            return
        try:
            fn, items = pickle.loads(payload)
        except Exception:  # noqa: BLE001  (nothing claimed: this process runs every item)
            fn, items = None, []
        while fn is not None:
            with lock:
                if bounds[1] <= bounds[0]:
                    break
                bounds[1] -= 1
                i = int(bounds[1])
            try:
                conn.send((batch, i, True, fn(items[i])))
            except Exception:  # noqa: BLE001  (run again where the batch came from, which raises it there)
                conn.send((batch, i, False, None))
        conn.send((batch, -1, True, None))


def helper_available() -> bool:
    """A helper process runs (started now if wanted and not yet running; it imports the fitting modules in the
    background)."""
    return _get_helper() is not None


def _give_up() -> None:
    global _helper, _broken
    _broken = True  # for the rest of this process: the work is done here
    if _helper is not None:
        _helper.close()
    _helper = None


class SharedBatch:
    """``[fn(item) for item in items]`` shared with the helper process: it takes items from the end of the list,
    this process from the start, one at a time, until they meet.

    The batch is handed to the helper at once, pickled then (a snapshot:
    this process may go on changing the objects, a fit's smoothing during a
    continuation, before :meth:`result`). :meth:`result` runs items from the
    start here and then collects the helper's. Which process runs an item
    depends on timing; its result does not (the same deterministic
    computation on the same values). ``fn`` must be a module-level function
    and ``items`` picklable. Without a helper (none wanted, or a failure),
    every item is run here. One batch at a time: a batch begun while
    another is handed over (within one of its items, say) runs here; a
    batch whose results are not wanted is given up with :meth:`cancel`.
    """

    def __init__(self, fn: Callable[[T], R], items: Sequence[T]) -> None:
        self.fn, self.items = fn, list(items)
        self.helper: _Helper | None = None
        helper = _get_helper() if len(self.items) > 1 else None
        if helper is None or helper.active:  # a batch within an item of another (run here): this one runs here
            return
        try:
            helper.settle()  # a batch left unfinished by an error here: its end message first
            payload = pickle.dumps((fn, self.items), protocol=pickle.HIGHEST_PROTOCOL)
            helper.batch += 1
            with helper.lock:
                helper.bounds[0], helper.bounds[1] = 0, len(self.items)
            helper.conn.send((helper.batch, payload))
        except (pickle.PicklingError, AttributeError, TypeError):  # not picklable: run here
            return
        except (OSError, EOFError):
            _give_up()
            return
        helper.busy, helper.active, self.helper = True, True, helper

    def cancel(self) -> None:
        """Give the batch up without its results: the helper stops claiming (it finishes the item it runs, whose
        result is read and dropped before the next batch) and is free for the next batch."""
        if self.helper is not None:
            self.helper.stop()
            self.helper.active = False
            self.helper = None

    @property
    def shared(self) -> bool:
        """The helper has this batch."""
        return self.helper is not None

    def result(self) -> list[R]:
        """Every item's result, in the order of the items."""
        n = len(self.items)
        out: list[Any] = [None] * n
        done = [False] * n
        helper, self.helper = self.helper, None
        if helper is None:
            return [self.fn(item) for item in self.items]
        try:
            while (i := helper.claim_low()) >= 0:
                out[i], done[i] = self.fn(self.items[i]), True
            while True:
                batch, i, ok, value = helper.receive()
                if batch != helper.batch:
                    continue
                if i < 0:
                    break
                if ok:
                    out[i], done[i] = value, True
            helper.busy = False
        except (EOFError, OSError):
            _give_up()
        except BaseException:  # an error (or Ctrl-C) here: the helper stops claiming, its end message read later
            helper.stop()
            raise
        finally:
            helper.active = False
        # items the helper could not finish (it died, or the item raised there): run here
        for i in range(n):
            if not done[i]:
                out[i] = self.fn(self.items[i])
        return out


def shared_map(fn: Callable[[T], R], items: Sequence[T]) -> list[R]:
    """``[fn(item) for item in items]``, shared with the helper process.

    ``fn`` must be a module-level function and ``items`` picklable; results
    come back in the order of ``items``; the helper runs items from the end
    while this process runs them from the start (:class:`SharedBatch`).
    """
    return SharedBatch(fn, items).result()
