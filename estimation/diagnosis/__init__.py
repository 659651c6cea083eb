"""Diagnosis: where the simulation is wrong, why, what to add, and how much it gains."""

from .diagnose import Diagnosis, diagnose_frequency
from .fit import DiagnosisError, FitResult, FrequencyFit

__all__ = ["Diagnosis", "DiagnosisError", "FitResult", "FrequencyFit", "diagnose_frequency"]
