"""Running compiled programs: runner (a run of the C, Python or interpreter backend), outfile
(output files), warm (runs without a compile), prebuild, sweeps."""
