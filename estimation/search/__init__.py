"""Search: optimisers (local, pattern, population, hybrids), local search, the estimation recipe and the process/Dask executor."""
