"""Foundations every stage uses: diagnostics (spans, ModelError, format_diagnostic), resources
(limits and paths), si (the dimensions of units), run_settings (RunSettings, the choices and
checks of a run's options), solvers and tableaux (the solver catalogue, solvers.get),
toolchain (the C compiler, BackendError), cache (the compile cache: compile_c,
compile_c_linked, cache_python) and processes (generated programs run: run_captured,
run_streaming, load_python_module).  A library, not a stage: no one entry, each module is
read by name."""
