"""Running compiled programs: runner (a run of the C, Python or interpreter backend), outfile
(output files), warm (runs without a compile), prebuild, sweeps.  Entry: runner.run, the one
place bgc runs a simulation (a program runner.prepare made, or a compiled model); a sweep's
many runs go through sweeps.run_batches."""
