"""Perturbation signals (PRBS, H-bridge, PRIS) and their spectral estimation (Welch, H1, coherence, uncertainty)."""
