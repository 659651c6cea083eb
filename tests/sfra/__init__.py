"""SFRA comparison against a healthy reference, on real sweeps."""
