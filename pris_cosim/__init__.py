"""PRIS co-simulation: circuits, analytic responses, signals, FMUs and spectral estimation."""

__version__ = "0.1.0"
