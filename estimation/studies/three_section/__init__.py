"""The three-section study (thesis 4.2): its cases, the time-domain and frequency stages, the unguided search."""
