"""Analytic frequency responses of a circuit: pole/residue and dense nodal paths, batched kernels, sparse AC."""
