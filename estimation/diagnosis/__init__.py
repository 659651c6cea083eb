"""Diagnosis: where the simulation is wrong, why, what to add, and how much it gains."""

from .diagnose import Diagnosis, diagnose_frequency
from .fit import DiagnosisError, FitResult, FrequencyFit
from .waveform import WaveformDiagnosis, diagnose_waveforms

__all__ = ["Diagnosis", "DiagnosisError", "FitResult", "FrequencyFit", "WaveformDiagnosis", "diagnose_frequency",
           "diagnose_waveforms"]
