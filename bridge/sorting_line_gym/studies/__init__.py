"""Studies: the runs that produce the results ``reports`` reads. `sorting-line-eval` (``evaluate``:
an agent on a line, the paper's protocol), the Table 1 benchmark (``benchmark``:
`sorting-line-benchmark`) and the evolving line's transfer study (``transfer``:
`sorting-line-transfer`, its cells ``transfer_cells``), with what both studies share: a cell store
that saves each finished cell so that a stopped study resumes (``cell_store``), a pool of
worker processes that runs cells side by side (``cell_pool``), and the same cells as tasks of a
Ray cluster (``ray_cells``: ``--ray ADDRESS``).

They train (the training layer), run envs over ROS 2 or the native backend, and hand their saved
records to ``reports`` for tables, statistics and figures.
"""
