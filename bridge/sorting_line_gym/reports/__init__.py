"""Results people read, from results already saved: the benchmark's numbers (``benchmark_summary``)
and its Table 1 as markdown (``benchmark_tables``), its figures (``plots``), the published figures
it compares with (``paper``), the transfer study's report (``transfer_report``), and the
statistics both use (``stats``: IQM, bootstrap intervals over whole runs, probability of improvement);
the benchmark's machine-readable results (``results_csv``) and a user's agent beside them (``comparison``).

Pure analysis: no training and no rclpy here. The runs that produce the results are ``studies``'.
"""
