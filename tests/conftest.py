"""Shared fixtures: paths to the shipped reference data, ngspice availability."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from pris_cosim.circuits import ngspice
from estimation.search._threads import single_threaded_blas
from pris_cosim.datafiles import NETLISTS, REAL  # noqa: F401  (REAL: for the tests that import it)

# Under pytest-xdist (``-n 2``) the worker processes share the cores: one BLAS thread each (numpy is loaded by now,
# so threadpoolctl limits it; the variables set are inherited by the commands the tests start). Multi-threaded
# OpenBLAS on the small matrices of these problems spins idle threads for the cores the other worker uses.
if os.environ.get("PYTEST_XDIST_WORKER"):
    single_threaded_blas()

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def netlist_dir() -> Path:
    """The thesis's circuits as ngspice netlists, shipped in ``pris_cosim/data/netlists``."""
    return NETLISTS


needs_ngspice = pytest.mark.skipif(not ngspice.available(), reason="ngspice is not installed (apt-get install ngspice)")
