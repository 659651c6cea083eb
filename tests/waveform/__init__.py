"""Diagnosis from PRIS waveform records."""
