"""bgc: a compiler for bond-graph models."""
__version__ = "0.1.0"
