"""Foundations every stage uses: diagnostics, resource limits and paths, a run's settings, the
solver catalogue and tableaux, the compile cache and toolchain."""
