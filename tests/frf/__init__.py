"""Analytic frequency responses against ngspice AC and a separate nodal solver."""
