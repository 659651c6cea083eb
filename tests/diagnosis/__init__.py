"""Diagnosis on frequency data: causes, drift, selection, on independently generated cases."""
