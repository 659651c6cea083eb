"""Costs, optimisers, executor, approaches, parameters, verdicts and estimation with netlists and FMUs."""
