"""Parameter estimation on top of :mod:`pris_cosim`: costs, optimisers, studies, diagnosis."""
