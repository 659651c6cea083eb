"""Measured data in and out: the interface CSV, instrument formats, Touchstone, MATLAB, waveform records."""
