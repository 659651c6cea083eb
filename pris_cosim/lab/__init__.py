"""Waveforms: the exact time-domain engine, the virtual laboratory of chapter 5 and the thesis figure reproductions."""
