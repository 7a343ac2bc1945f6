"""bgc: a compiler for bond-graph models.

    import bgc
    t, Y, names = bgc.simulate("models/pendulum.bg", scene="swing")

The API (bgc.api; bgc.model for `load`) is imported on first use of one of its names, so that
`bgc --help` and a warm `bgc simulate` (bgc.execute.warm) start without importing SymPy.  The names
are served here and never written over a submodule: no module of bgc has an API function's name
(the equations stage is bgc.middle.system, so `bgc.equations` is always the function).
"""
__version__ = "0.1.0"
__all__ = ["BgcArgumentError", "BgcModelError", "Compiled", "SimulationFailed", "build", "check",
           "compile", "equations", "fit", "linearize", "load", "periodic", "sensitivities", "simulate",
           "steady", "sweep", "units"]


def __getattr__(name):
    if name == "load":
        from .model import load as value
    elif name == "linearize":
        from .analysis.linear import linearize as value
    elif name == "periodic":
        from .analysis.periodic import periodic as value
    elif name == "steady":
        from .analysis.equilibrium import steady as value
    elif name in ("fit", "sensitivities"):
        from .analysis import estimate
        value = getattr(estimate, name)
    elif name in __all__:
        from . import api
        value = getattr(api, name)
    else:
        raise AttributeError(f"module 'bgc' has no attribute {name!r}")
    return value  # (not stored: the package's attributes are its modules' and these)


def __dir__():
    return sorted(set(globals()) | set(__all__))
