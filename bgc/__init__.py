"""bgc: a compiler for bond-graph models.

    import bgc
    t, Y, names = bgc.simulate("models/pendulum.bg", scene="swing")
"""
from .api import (BgcArgumentError, BgcModelError, Compiled, SimulationFailed, build, check,
                  compile, equations, load, simulate, sweep)

__version__ = "0.1.0"
__all__ = ["BgcArgumentError", "BgcModelError", "Compiled", "SimulationFailed", "build", "check",
           "compile", "equations", "load", "simulate", "sweep"]
