"""Diagnosis: where the simulation is wrong, why, what to add, and how much it gains.

The public names are imported on first use, so that registering the
``diagnose`` command (``pris-cosim --help``) does not load SciPy.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

_WHERE = {"Diagnosis": "result", "diagnose_frequency": "diagnose", "DiagnosisError": "fit", "FitResult": "fit",
          "FrequencyFit": "fit", "WaveformDiagnosis": "waveform.source", "diagnose_waveforms": "waveform.source"}

__all__ = sorted(_WHERE)


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        return getattr(import_module(f".{_WHERE[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
