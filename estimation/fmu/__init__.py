"""Estimation with any FMU in the loop: the FMU as a model, the estimation problem on a record, the FMU recipe."""
