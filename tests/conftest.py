"""Shared fixtures: paths to the shipped reference data, ngspice availability."""

from __future__ import annotations

from pathlib import Path

import pytest

from pris_cosim import ngspice
from pris_cosim.datafiles import NETLISTS, REAL  # noqa: F401  (REAL: for the tests that import it)

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def netlist_dir() -> Path:
    """The thesis's circuits as ngspice netlists, shipped in ``pris_cosim/data/netlists``."""
    return NETLISTS


needs_ngspice = pytest.mark.skipif(not ngspice.available(), reason="ngspice is not installed (apt-get install ngspice)")
