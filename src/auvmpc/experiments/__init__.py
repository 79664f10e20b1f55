"""What a user runs: a run folder (:mod:`.run`), the paper's reproduction, the benchmark,
campaigns (pool or Dask), comparisons, and the rules for where results are written."""
