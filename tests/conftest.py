"""Shared fixtures: paths to the reference material beside the checkout, ngspice availability."""

from __future__ import annotations

from pathlib import Path

import pytest

from pris_cosim import ngspice

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
NETLISTS = SHARED / "netlists"


@pytest.fixture(scope="session")
def netlist_dir() -> Path:
    if not NETLISTS.is_dir():
        pytest.skip(f"reference netlists not found at {NETLISTS}")
    return NETLISTS


needs_ngspice = pytest.mark.skipif(not ngspice.available(), reason="ngspice is not installed (apt-get install ngspice)")
