"""Run many independent study runs in-process, on local processes or on a Dask cluster, resumably.

A study is a list of :class:`Task` objects (an id, an importable top-level
function and its keyword arguments). :func:`run_tasks` sends them to one of
three backends:

- ``"processes"`` (default): :class:`concurrent.futures.ProcessPoolExecutor`
  with ``os.cpu_count()`` workers;
- ``"serial"``: one after the other in this process (for debugging: plain
  tracebacks, breakpoints work);
- a Dask scheduler address such as ``"tcp://10.0.0.5:8786"``: a
  :class:`distributed.Client` connected to that cluster.

Every finished run is written at once by a :class:`ResultsStore`: one JSON
file per run under ``runs/<id>.json`` plus ``results.csv`` regenerated from
them, both replaced atomically (write to a temporary file in the same
directory, flush, ``fsync``, ``os.replace``), so an interruption at any moment
leaves only complete files. Running the same study again skips the ids
already stored: nothing finished is repeated or lost.

Results are returned as stored, i.e. after a JSON round trip (numpy arrays
become lists, objects with ``to_dict()`` become dicts), so a fresh run and a
resumed one give identical values.

Each stored run carries a SHA-256 checksum of its content; a run file whose
content no longer matches (edited, or damaged on disk) is refused with one
line naming it. Runs started together on the same directory share the work:
a task is claimed with an exclusive lock (``claims/<id>.lock``, released by
the kernel when its holder dies) before it starts, so a second run takes only
the unclaimed tasks and waits for the others to be stored.

Ctrl-C (or SIGTERM turned into :class:`KeyboardInterrupt` by the caller)
stops the pool at once and raises :class:`Interrupted`, whose message says
how many runs are stored and that the same command resumes. Pool workers
ignore SIGINT, run with their standard streams on ``/dev/null`` and exit
within a second when the main process dies, even by SIGKILL.
"""

from __future__ import annotations

import concurrent.futures as cf
import csv
import dataclasses
import hashlib
import importlib
import io
import json
import math
import multiprocessing
import os
import re
import socket
import sys
import tempfile
import time
import traceback
import uuid
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import suppress
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["Task", "TaskError", "Interrupted", "ResultsStore", "run_tasks", "to_jsonable", "atomic_write_text"]

_ID_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9._=+-]{0,199}")


# --------------------------------------------------------------------------- #
# JSON conversion
# --------------------------------------------------------------------------- #


def to_jsonable(value: Any) -> Any:
    """Convert ``value`` to JSON types (dict, list, str, int, float, bool, None).

    Handles numpy scalars and arrays, tuples, :class:`pathlib.Path`, objects
    with a ``to_dict()`` method (such as
    :class:`estimation.search.optimisers.OptimResult`) and dataclasses.

    Raises
    ------
    TypeError
        For anything else (complex numbers included), naming the type.
    """
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, np.generic):
        return to_jsonable(value.item())
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, Mapping):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    if callable(getattr(value, "to_dict", None)):
        return to_jsonable(value.to_dict())
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return to_jsonable({f.name: getattr(value, f.name) for f in dataclasses.fields(value)})
    raise TypeError(f"cannot store a {type(value).__name__} as JSON")


def _roundtrip(value: Any) -> Any:
    return json.loads(json.dumps(value))


# --------------------------------------------------------------------------- #
# Tasks
# --------------------------------------------------------------------------- #


def _function_path(fn: Callable[..., Any]) -> str:
    """``module:qualname`` of a top-level function, or ValueError."""
    module = getattr(fn, "__module__", None)
    qualname = getattr(fn, "__qualname__", None)
    if not callable(fn) or module is None or qualname is None or "<" in qualname or "." in qualname:
        raise ValueError(f"task fn must be a top-level function importable by name, got {fn!r}")
    found = getattr(sys.modules.get(module) or importlib.import_module(module), qualname, None)
    if found is not fn:
        raise ValueError(f"task fn {module}:{qualname} cannot be found again by that name (not picklable)")
    return f"{module}:{qualname}"


@dataclass(frozen=True)
class Task:
    """One independent run.

    Parameters
    ----------
    id : str
        Unique id; also the file name ``runs/<id>.json`` (letters, digits and
        ``. _ = + -``, starting with a letter or digit).
    fn : callable
        Importable top-level function (picklable by reference) called as
        ``fn(**kwargs)``; its return value must be convertible by
        :func:`to_jsonable`.
    kwargs : dict
        Keyword arguments; stored with the result and compared on resume.
    label : str, optional
        Text for progress lines (default: the id), e.g. ``"case 2 pso rmse"``.
    """

    id: str
    fn: Callable[..., Any]
    kwargs: Mapping[str, Any] = field(default_factory=dict)
    label: str | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.id, str) or not _ID_PATTERN.fullmatch(self.id):
            raise ValueError(f"task id {self.id!r} must match {_ID_PATTERN.pattern} (it names a file)")
        _function_path(self.fn)
        if not isinstance(self.kwargs, Mapping) or not all(isinstance(k, str) for k in self.kwargs):
            raise ValueError(f"task {self.id!r}: kwargs must be a mapping with string keys")
        try:
            to_jsonable(self.kwargs)
        except TypeError as exc:
            raise ValueError(f"task {self.id!r}: kwargs cannot be stored ({exc})") from None

    @property
    def fn_path(self) -> str:
        """``module:qualname`` of :attr:`fn`."""
        return _function_path(self.fn)

    @property
    def name(self) -> str:
        """The label, or the id when no label was given."""
        return self.label if self.label is not None else self.id


class TaskError(RuntimeError):
    """Tasks raised; every run that finished is stored.

    Attributes
    ----------
    failures : dict
        Task id -> formatted traceback.
    results : list
        Results in task order, ``None`` where a task failed or did not run.
    """

    def __init__(self, failures: dict[str, str], results: list[Any]) -> None:
        first = next(iter(failures.values())).strip().splitlines()[-1]
        super().__init__(f"{len(failures)} task(s) failed: {', '.join(failures)}; first: {first}")
        self.failures = failures
        self.results = results


class Interrupted(KeyboardInterrupt):
    """The run was interrupted (Ctrl-C, SIGTERM); finished runs are stored.

    The message is one line, e.g. ``interrupted: 3 of 5 runs stored in DIR;
    run the same command again to resume``.
    """


def _execute(fn: Callable[..., Any], kwargs: dict[str, Any]) -> dict[str, Any]:
    """Worker side: run one task, time it, catch its exception, make the result JSON-safe."""
    started = datetime.now(timezone.utc).isoformat(timespec="seconds")
    t0 = time.perf_counter()
    outcome: dict[str, Any] = {"started": started, "host": socket.gethostname(), "pid": os.getpid()}
    try:
        outcome["result"] = to_jsonable(fn(**kwargs))
        outcome["ok"] = True
    except Exception:
        outcome["ok"] = False
        outcome["traceback"] = traceback.format_exc()
    outcome["wall_s"] = time.perf_counter() - t0
    outcome["finished"] = datetime.now(timezone.utc).isoformat(timespec="seconds")
    return outcome


# --------------------------------------------------------------------------- #
# Results store
# --------------------------------------------------------------------------- #


def _fsync_directory(directory: Path) -> None:
    if os.name != "posix":
        return
    fd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def atomic_write_text(path: Path, text: str) -> None:
    """Replace ``path`` with ``text`` so that readers see the old or the new file, never a part."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        with suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
    _fsync_directory(path.parent)


CHECKSUM_KEY = "sha256"


def record_checksum(record: Mapping[str, Any]) -> str:
    """SHA-256 (hex) of a stored record's canonical JSON text, the checksum key left out."""
    body = {k: v for k, v in record.items() if k != CHECKSUM_KEY}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=True)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _flatten(prefix: str, value: Any, out: dict[str, Any]) -> None:
    """Scalars (and short lists of scalars as JSON text) of a record, dotted keys."""
    if isinstance(value, dict):
        for key, item in value.items():
            _flatten(f"{prefix}.{key}", item, out)
    elif isinstance(value, list):
        if len(value) <= 64 and all(v is None or isinstance(v, (bool, int, float, str)) for v in value):
            out[prefix] = json.dumps(value)
    else:
        out[prefix] = value


class ResultsStore:
    """Finished runs on disk: ``runs/<id>.json`` and ``results.csv``, written atomically.

    Parameters
    ----------
    directory : str or pathlib.Path
        Created if missing. Files named ``.*.tmp`` are transient (an
        interrupted write) and ignored.

    Raises
    ------
    ValueError
        If a stored run file is not valid JSON (the message names the file).
    """

    BASE_COLUMNS = ("id", "label", "fn", "wall_s", "finished")

    def __init__(self, directory: str | os.PathLike[str]) -> None:
        self.directory = Path(directory)
        self.runs_dir = self.directory / "runs"
        self.errors_dir = self.directory / "errors"
        self.csv_path = self.directory / "results.csv"
        self.claims_dir = self.directory / "claims"
        self.runs_dir.mkdir(parents=True, exist_ok=True)
        self._records: dict[str, dict[str, Any]] = {}
        self._claims: dict[str, int] = {}
        for path in sorted(self.runs_dir.glob("*.json")):
            if not path.name.startswith("."):
                self._records[path.stem] = self._read(path)

    @staticmethod
    def _read(path: Path) -> dict[str, Any]:
        try:
            record = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise ValueError(f"stored run {path} is unreadable ({' '.join(str(exc).split())}); "
                             f"delete it to run it again") from None
        if not isinstance(record, dict) or record.get("id") != path.stem:
            raise ValueError(f"stored run {path} does not hold a run with id {path.stem!r}")
        stored = record.pop(CHECKSUM_KEY, None)
        if stored is None:
            raise ValueError(f"stored run {path} has no checksum (written by an older version or edited); "
                             f"delete it to run it again")
        if stored != record_checksum(record):
            raise ValueError(f"stored run {path} fails its checksum (changed or damaged since it was written); "
                             f"delete it to run it again")
        return record

    def __contains__(self, run_id: object) -> bool:
        return run_id in self._records

    def __len__(self) -> int:
        return len(self._records)

    def ids(self) -> list[str]:
        """Ids of the stored runs, sorted."""
        return sorted(self._records)

    def load(self, run_id: str) -> dict[str, Any]:
        """The stored record of ``run_id`` (KeyError if absent)."""
        return self._records[run_id]

    def records(self) -> list[dict[str, Any]]:
        """All stored records, sorted by id."""
        return [self._records[k] for k in self.ids()]

    def save(self, record: Mapping[str, Any]) -> dict[str, Any]:
        """Write one finished run and regenerate ``results.csv``; return the record as stored."""
        run_id = record.get("id")
        if not isinstance(run_id, str) or not _ID_PATTERN.fullmatch(run_id):
            raise ValueError(f"record id {run_id!r} must match {_ID_PATTERN.pattern}")
        stored = json.loads(json.dumps(to_jsonable(record)))
        text = json.dumps({**stored, CHECKSUM_KEY: record_checksum(stored)}, indent=1)
        atomic_write_text(self.runs_dir / f"{run_id}.json", text + "\n")
        self._records[run_id] = stored
        with suppress(FileNotFoundError):
            os.unlink(self.errors_dir / f"{run_id}.txt")
        self.write_csv()
        return stored

    # ------------------------------------------------------------------ claims
    def claim(self, run_id: str) -> str | dict[str, Any]:
        """Try to claim a task before running it.

        Returns
        -------
        str or dict
            ``"claimed"`` (this process holds the lock until :meth:`release`),
            ``"busy"`` (another process holds it), or the stored record when
            another process has stored the run meanwhile.
        """
        if run_id in self._records:
            return self._records[run_id]
        import fcntl

        self.claims_dir.mkdir(exist_ok=True)
        path = self.claims_dir / f"{run_id}.lock"
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            return "busy"
        record = self.refresh(run_id)
        if record is not None:
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)
            return record
        os.ftruncate(fd, 0)
        os.write(fd, f"{socket.gethostname()} {os.getpid()}\n".encode())
        self._claims[run_id] = fd
        return "claimed"

    def release(self, run_id: str) -> None:
        """Give up the claim on ``run_id`` (after storing it, or when stopping)."""
        fd = self._claims.pop(run_id, None)
        if fd is None:
            return
        with suppress(OSError):
            if run_id in self._records:
                os.unlink(self.claims_dir / f"{run_id}.lock")  # harmless race: holders re-check the store
        os.close(fd)  # closing releases the lock

    def release_all(self) -> None:
        """Give up every claim this store holds."""
        for run_id in list(self._claims):
            self.release(run_id)

    def refresh(self, run_id: str) -> dict[str, Any] | None:
        """Load ``run_id`` if another process stored it since this store was opened."""
        if run_id not in self._records:
            path = self.runs_dir / f"{run_id}.json"
            if path.exists():
                self._records[run_id] = self._read(path)
        return self._records.get(run_id)

    def save_error(self, run_id: str, text: str) -> Path:
        """Keep the traceback of a failed run in ``errors/<id>.txt`` (not a finished run)."""
        self.errors_dir.mkdir(exist_ok=True)
        path = self.errors_dir / f"{run_id}.txt"
        atomic_write_text(path, text)
        return path

    def write_csv(self) -> Path:
        """Regenerate ``results.csv`` (one row per run, flattened scalars) atomically."""
        for path in self.runs_dir.glob("*.json"):  # runs stored by another process on the same directory
            if not path.name.startswith(".") and path.stem not in self._records:
                with suppress(ValueError):
                    self._records[path.stem] = self._read(path)
        rows = []
        columns = list(self.BASE_COLUMNS)
        for record in self.records():
            row = {key: record.get(key) for key in self.BASE_COLUMNS}
            _flatten("kwargs", record.get("kwargs", {}), row)
            _flatten("result", record.get("result"), row)
            columns.extend(key for key in row if key not in columns)
            rows.append(row)
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=columns, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
        atomic_write_text(self.csv_path, buffer.getvalue())
        return self.csv_path


# --------------------------------------------------------------------------- #
# Backends
# --------------------------------------------------------------------------- #


def _failure(exc: BaseException) -> dict[str, Any]:
    text = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
    return {"ok": False, "traceback": text, "wall_s": math.nan}


class _SerialBackend:
    """Runs tasks one by one in this process, lazily, so results are stored as they finish."""

    name = "serial"

    def __init__(self) -> None:
        self._cancelled = False

    def run(self, jobs: list[tuple[int, Task]], claim: Any = None) -> Iterator[tuple[int, dict[str, Any]]]:
        queue = deque(jobs)
        busy = 0
        while queue and not self._cancelled:
            index, task = queue.popleft()
            status = claim(task) if claim is not None else "claimed"
            if status == "busy":  # another run on the same directory has it: come back to it later
                queue.append((index, task))
                busy += 1
                if busy >= len(queue):
                    time.sleep(_POLL_S)
                    busy = 0
                continue
            busy = 0
            if isinstance(status, dict):
                yield index, {"ok": True, "stored": status}
                continue
            yield index, _execute(task.fn, dict(task.kwargs))

    def cancel(self) -> None:
        self._cancelled = True

    def abort(self) -> None:
        self._cancelled = True

    def close(self, wait: bool) -> None:
        pass


class _WindowBackend:
    """Keeps at most ``capacity()`` tasks in flight, submitting more as others finish.

    Holding back the queue (rather than submitting everything at once) makes
    :meth:`cancel` exact on every backend: nothing new starts, and the runs
    already in flight finish and are stored.
    """

    name = ""

    def __init__(self) -> None:
        self._stopped = False

    def submit(self, task: Task) -> Any:
        raise NotImplementedError

    def wait_first(self, futures: list[Any], timeout: float | None = None) -> list[Any]:
        """Futures among ``futures`` that are done (at least one unless ``timeout`` s passed), in the given order."""
        raise NotImplementedError

    def capacity(self) -> int:
        raise NotImplementedError

    def run(self, jobs: list[tuple[int, Task]], claim: Any = None) -> Iterator[tuple[int, dict[str, Any]]]:
        queue = deque(jobs)
        in_flight: dict[Any, int] = {}
        while queue or in_flight:
            busy = 0
            while queue and not self._stopped and len(in_flight) < max(1, self.capacity()) and busy < len(queue):
                index, task = queue.popleft()
                status = claim(task) if claim is not None else "claimed"
                if status == "busy":  # another run on the same directory has it: come back to it later
                    queue.append((index, task))
                    busy += 1
                    continue
                busy = 0
                if isinstance(status, dict):
                    yield index, {"ok": True, "stored": status}
                    continue
                in_flight[self.submit(task)] = index
            if not in_flight:
                if not queue or self._stopped:
                    return
                time.sleep(_POLL_S)
                continue
            for future in self.wait_first(list(in_flight), _POLL_S if busy else None):
                index = in_flight.pop(future)
                try:
                    outcome = future.result()
                except Exception as exc:  # the worker died (BrokenProcessPool, KilledWorker) or unpickling failed
                    outcome = _failure(exc)
                yield index, outcome

    def cancel(self) -> None:
        self._stopped = True


class _FuturesBackend(_WindowBackend):
    """A :mod:`concurrent.futures` executor (owned: shut down at the end)."""

    def __init__(self, executor: cf.Executor, owned: bool, name: str, workers: int) -> None:
        super().__init__()
        self.executor = executor
        self.owned = owned
        self.name = name
        self.workers = workers

    def submit(self, task: Task) -> cf.Future[Any]:
        return self.executor.submit(_execute, task.fn, dict(task.kwargs))

    def wait_first(self, futures: list[Any], timeout: float | None = None) -> list[Any]:
        done, _ = cf.wait(futures, timeout=timeout, return_when=cf.FIRST_COMPLETED)
        return [f for f in futures if f in done]

    def capacity(self) -> int:
        return self.workers

    def close(self, wait: bool) -> None:
        if self.owned:
            self.executor.shutdown(wait=wait, cancel_futures=True)

    def abort(self) -> None:
        """Stop now: cancel what has not started and end the owned pool's workers (their runs are lost)."""
        self._stopped = True
        if not self.owned:
            return
        processes = list((getattr(self.executor, "_processes", None) or {}).values())
        self.executor.shutdown(wait=False, cancel_futures=True)
        for process in processes:
            with suppress(Exception):
                process.terminate()
        for process in processes:
            with suppress(Exception):
                process.join(2.0)
        # The pool's management thread closes its wake-up pipe once it sees the workers gone. Left running, it
        # races the interpreter's exit hook, which writes to that pipe: "OSError: [Errno 9] Bad file descriptor"
        # after the one-line message (Python 3.11). Waiting for it here leaves the pipe closed before exit.
        manager = getattr(self.executor, "_executor_manager_thread", None)
        if manager is not None:
            with suppress(Exception):
                manager.join(5.0)


class _DaskBackend(_WindowBackend):
    """A :class:`distributed.Client` (owned when made here from an address: closed at the end).

    The window follows the cluster's current thread count, so workers that
    join later are used.
    """

    def __init__(self, client: Any, owned: bool) -> None:
        super().__init__()
        self.client = client
        self.owned = owned
        self.name = f"dask {client.scheduler.address}"
        self._batch = uuid.uuid4().hex[:8]
        from distributed import as_completed

        self._completed = as_completed(loop=client.loop)

    def submit(self, task: Task) -> Any:
        key = f"{task.id}-{self._batch}"
        future = self.client.submit(_execute, task.fn, dict(task.kwargs), key=key, pure=False)
        self._completed.add(future)
        return future

    def wait_first(self, futures: list[Any], timeout: float | None = None) -> list[Any]:
        return [next(self._completed)]

    def capacity(self) -> int:
        return sum(self.client.nthreads().values())

    def close(self, wait: bool) -> None:
        if self.owned:
            self.client.close()

    def abort(self) -> None:
        self._stopped = True
        if self.owned:
            with suppress(Exception):
                self.client.close(timeout=5)


def _is_dask_client(obj: Any) -> bool:
    return type(obj).__module__.split(".")[0] == "distributed" and hasattr(obj, "submit")


def _start_forkserver_detached() -> None:
    """Start multiprocessing's fork server (and resource tracker) with ``/dev/null`` as standard streams.

    Pool workers are forked from the fork server and inherit its streams: so
    neither they nor the server hold the caller's pipes open, and nothing a
    worker prints reaches the terminal (task errors travel back as results).
    """
    from multiprocessing import forkserver

    server = getattr(forkserver, "_forkserver", None)
    if server is not None and getattr(server, "_forkserver_pid", None) is not None:
        return
    with suppress(ValueError, OSError):
        sys.stdout.flush()
        sys.stderr.flush()
    try:
        saved = [os.dup(fd) for fd in (0, 1, 2)]
    except OSError:
        forkserver.ensure_running()
        return
    null = os.open(os.devnull, os.O_RDWR)
    try:
        for fd in (0, 1, 2):
            os.dup2(null, fd)
        forkserver.ensure_running()
    finally:
        for fd, copy in zip((0, 1, 2), saved):
            os.dup2(copy, fd)
            os.close(copy)
        os.close(null)


def _process_pool(workers: int) -> cf.ProcessPoolExecutor:
    # forkserver (Python 3.14's default) avoids forking a process that may run threads.
    methods = multiprocessing.get_all_start_methods()
    method = "forkserver" if "forkserver" in methods else "spawn"
    if method == "forkserver":
        _start_forkserver_detached()
    context = multiprocessing.get_context(method)
    from estimation.search._workers import init_worker

    return cf.ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=init_worker,
                                  initargs=(os.getpid(), workers > 1))


def _make_backend(executor: Any, workers: int | None, jobs: int) -> Any:
    """Backend for ``executor`` (None/"processes", "serial", address, Executor or Client)."""
    if workers is not None and (not isinstance(workers, int) or isinstance(workers, bool) or workers < 1):
        raise ValueError(f"workers must be an integer >= 1, got {workers!r}")
    if executor is None or executor == "processes":
        count = min(workers or os.cpu_count() or 1, max(1, jobs))
        return _FuturesBackend(_process_pool(count), owned=True, name=f"processes ({count} workers)", workers=count)
    if executor == "serial":
        return _SerialBackend()
    if isinstance(executor, str) and ":" in executor:
        from distributed import Client

        return _DaskBackend(Client(executor, set_as_default=False), owned=True)
    if isinstance(executor, cf.Executor):
        count = workers or getattr(executor, "_max_workers", None) or os.cpu_count() or 1
        return _FuturesBackend(executor, owned=False, name=type(executor).__name__, workers=count)
    if _is_dask_client(executor):
        return _DaskBackend(executor, owned=False)
    raise ValueError(
        f"executor must be None, 'processes', 'serial', a Dask scheduler address such as "
        f"'tcp://host:8786', a concurrent.futures.Executor or a distributed.Client; got {executor!r}"
    )


# --------------------------------------------------------------------------- #
# run_tasks
# --------------------------------------------------------------------------- #


_POLL_S = 0.25  # how often a run waiting for tasks claimed by another run looks again, s


def _check_tasks(tasks: Iterable[Task]) -> list[Task]:
    tasks = list(tasks)
    seen: set[str] = set()
    for task in tasks:
        if not isinstance(task, Task):
            raise ValueError(f"tasks must be Task objects, got {task!r}")
        if task.id in seen:
            raise ValueError(f"duplicate task id {task.id!r}")
        seen.add(task.id)
    return tasks


def _check_stored(record: Mapping[str, Any], task: Task, store: ResultsStore) -> None:
    """A stored run may only stand in for a task with the same function and arguments."""
    if record.get("fn") != task.fn_path or record.get("kwargs") != _roundtrip(to_jsonable(task.kwargs)):
        raise ValueError(
            f"stored run {task.id!r} in {store.runs_dir} was made with a different fn or kwargs; "
            f"delete {task.id}.json or give the task a new id"
        )


def _record(task: Task, outcome: Mapping[str, Any], backend: str) -> dict[str, Any]:
    return {
        "id": task.id,
        "label": task.name,
        "fn": task.fn_path,
        "kwargs": to_jsonable(task.kwargs),
        "result": outcome["result"],
        "wall_s": outcome["wall_s"],
        "started": outcome["started"],
        "finished": outcome["finished"],
        "host": outcome["host"],
        "pid": outcome["pid"],
        "backend": backend,
    }


def _say(enabled: bool, text: str) -> None:
    if enabled:
        print(text, file=sys.stderr, flush=True)


def run_tasks(
    tasks: Iterable[Task],
    executor: Any = None,
    store: ResultsStore | str | os.PathLike[str] | None = None,
    progress: bool = True,
    workers: int | None = None,
    on_error: str = "raise",
) -> list[Any]:
    """Run independent tasks, storing each as it finishes and skipping those already stored.

    Parameters
    ----------
    tasks : iterable of Task
        Unique ids.
    executor : None, str, concurrent.futures.Executor or distributed.Client
        ``None`` or ``"processes"``: a local process pool (``os.cpu_count()``
        workers, or ``workers``); ``"serial"``: in this process; a scheduler
        address (``"tcp://host:8786"``): a Dask cluster. Executors and clients
        passed in are used and left open; those made here are closed.
    store : ResultsStore or path, optional
        Where finished runs go; ids found there are not run again (their
        stored function and kwargs must match the task).
    progress : bool
        Print one line per finished run to stderr
        (``[3/12] case 2 pso rmse done in 4.1 s``).
    workers : int, optional
        Process-pool size (default ``os.cpu_count()``, at most the number of
        tasks to run); for an executor passed in, how many tasks to keep in
        flight (default: its worker count). A Dask cluster keeps one task per
        worker thread in flight.
    on_error : {"raise", "continue"}
        On a failing task, ``"raise"`` starts no further task, lets those
        already running finish (and stores them), then raises; ``"continue"``
        runs everything first. Either way :class:`TaskError` is raised at the
        end and failed tasks are not marked done (a rerun retries them).

    Returns
    -------
    list
        The tasks' results in task order, as stored (after a JSON round trip).

    Raises
    ------
    TaskError
        If any task raised.
    ValueError
        For bad arguments, duplicate ids, or a stored run whose function or
        kwargs differ from its task.
    """
    if on_error not in ("raise", "continue"):
        raise ValueError(f"on_error must be 'raise' or 'continue', got {on_error!r}")
    tasks = _check_tasks(tasks)
    if store is not None and not isinstance(store, ResultsStore):
        store = ResultsStore(store)
    results: list[Any] = [None] * len(tasks)
    todo = []
    for i, task in enumerate(tasks):
        if store is not None and task.id in store:
            record = store.load(task.id)
            _check_stored(record, task, store)
            results[i] = record["result"]
        else:
            todo.append((i, task))
    if not todo:
        _say(progress, f"{len(tasks)} task(s), all already stored in {store.directory if store else '-'}")
        return results
    backend = _make_backend(executor, workers, len(todo))
    where = f" (results in {store.directory})" if store is not None else ""
    stored = len(tasks) - len(todo)
    _say(progress, f"{len(tasks)} task(s): {stored} already stored, {len(todo)} to run on {backend.name}{where}")
    failures = _run_backend(backend, tasks, todo, results, store, progress, on_error)
    if failures:
        raise TaskError(failures, results)
    return results


def _run_backend(
    backend: Any,
    tasks: list[Task],
    todo: list[tuple[int, Task]],
    results: list[Any],
    store: ResultsStore | None,
    progress: bool,
    on_error: str,
) -> dict[str, str]:
    """Drive ``backend`` over ``todo``; store and report each outcome; return failures.

    With a store, each task is claimed before it starts (runs on the same
    directory share the work); Ctrl-C ends the pool and raises
    :class:`Interrupted`.
    """
    finished = len(tasks) - len(todo)
    failures: dict[str, str] = {}
    completed = False

    def claim(task: Task) -> str | dict[str, Any]:
        assert store is not None
        status = store.claim(task.id)
        if isinstance(status, dict):
            _check_stored(status, task, store)
        return status

    try:
        for index, outcome in backend.run(todo, claim if store is not None else None):
            finished += 1
            task = tasks[index]
            if "stored" in outcome:
                results[index] = outcome["stored"]["result"]
                _say(progress, f"[{finished}/{len(tasks)}] {task.name} stored by another run")
                continue
            try:
                if outcome["ok"]:
                    record = _record(task, outcome, backend.name)
                    stored = store.save(record) if store is not None else _roundtrip(record)
                    results[index] = stored["result"]
                    _say(progress, f"[{finished}/{len(tasks)}] {task.name} done in {outcome['wall_s']:.1f} s")
                    continue
                failures[task.id] = outcome["traceback"]
                if store is not None:
                    store.save_error(task.id, outcome["traceback"])
            finally:
                if store is not None:
                    store.release(task.id)
            last = outcome["traceback"].strip().splitlines()[-1]
            _say(progress, f"[{finished}/{len(tasks)}] {task.name} FAILED: {last}")
            if on_error == "raise":
                backend.cancel()
        completed = True
    except KeyboardInterrupt:
        backend.abort()
        if store is not None:
            store.release_all()
            done = sum(1 for t in tasks if t.id in store)
            raise Interrupted(f"interrupted: {done} of {len(tasks)} runs stored in {store.directory}; "
                              f"run the same command again to resume") from None
        done = sum(1 for r in results if r is not None)
        raise Interrupted(f"interrupted: {done} of {len(tasks)} runs finished (no results directory)") from None
    finally:
        if store is not None:
            store.release_all()
        backend.close(wait=completed)
    return failures
