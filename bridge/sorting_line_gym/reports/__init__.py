"""Reports of the benchmark: statistics and (after the package's reorganisation) evaluation,
the benchmark driver and its figures."""
