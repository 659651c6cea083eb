"""One BLAS thread per pool worker, set before numpy is imported there.

Kept free of numpy imports: a pool worker unpickles this initializer before
any task, so the environment variables below are in place when the task's
modules import numpy and OpenBLAS starts. When numpy is already loaded (a
forkserver that preloaded the main module), threadpoolctl limits it instead.
With two workers on two cores, multi-threaded OpenBLAS on the small
matrices of the estimation problems (eigen-decompositions of 20-50 states)
made every task 3-7 times slower (idle BLAS threads spin for the cores).
"""

from __future__ import annotations

import os
import sys

_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def single_threaded_blas() -> None:
    """Limit BLAS/LAPACK to one thread in this process (user settings of the variables are kept)."""
    for var in _VARIABLES:
        os.environ.setdefault(var, "1")
    if "numpy" in sys.modules:
        from threadpoolctl import threadpool_limits

        threadpool_limits(limits=1)
