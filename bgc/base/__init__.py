"""Foundations every stage uses: diagnostics, resource limits and paths, a run's settings, the
solver catalogue and tableaux, the C toolchain, the compile cache and the processes that run
what it holds."""
