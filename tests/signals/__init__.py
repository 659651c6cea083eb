"""PRBS, H-bridge and PRIS signals; spectral estimation and its uncertainty."""
