"""Set-up of local pool workers: quiet on Ctrl-C, gone when the main process dies, one BLAS thread.

Kept free of numpy imports (like :mod:`estimation.search._threads`): a worker
unpickles :func:`init_worker` before any task, so the BLAS variables are in
place when the task's modules import numpy.
"""

from __future__ import annotations

import os
import select
import signal
import threading
import time


def init_worker(parent_pid: int, single_blas: bool) -> None:
    """Initializer of a pool worker.

    Parameters
    ----------
    parent_pid : int
        Process id of the main process that owns the pool; the worker exits
        (status 1, without cleanup) within a second of that process's death,
        however it died.
    single_blas : bool
        Limit BLAS/LAPACK to one thread (several workers share the cores).
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the main process's to handle
    watch_parent(parent_pid)
    if single_blas:
        from estimation.search._threads import single_threaded_blas

        single_threaded_blas()


def watch_parent(pid: int, poll_s: float = 0.5) -> threading.Thread:
    """Start a daemon thread that ends this process as soon as process ``pid`` has exited."""

    def wait_for_exit() -> None:
        try:
            fd = os.pidfd_open(pid)  # Linux >= 5.3: readable once the process has exited
        except ProcessLookupError:
            os._exit(1)
        except (AttributeError, OSError):
            fd = None
        if fd is not None:
            select.select([fd], [], [])
            os._exit(1)
        while True:
            try:
                os.kill(pid, 0)
            except ProcessLookupError:
                os._exit(1)
            except PermissionError:
                pass
            time.sleep(poll_s)

    thread = threading.Thread(target=wait_for_exit, name="watch-parent", daemon=True)
    thread.start()
    return thread
