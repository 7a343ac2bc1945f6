"""bgc: a compiler for bond-graph models.

    import bgc
    t, Y, names = bgc.simulate("models/pendulum.bg", scene="swing")

The API (bgc.api) is imported on first use of one of its names, so that `bgc --help` and a
warm `bgc simulate` (bgc.warm) start without importing SymPy.
"""
__version__ = "0.1.0"
__all__ = ["BgcArgumentError", "BgcModelError", "Compiled", "SimulationFailed", "build", "check",
           "compile", "equations", "load", "simulate", "sweep"]


def __getattr__(name):
    if name in __all__:
        from . import api
        value = getattr(api, name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'bgc' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
