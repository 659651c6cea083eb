"""Diagnosis from PRIS waveform records: the source on a load, the winding's H1 path, signals, synthetic records, report."""
