"""Analysis on top of the pipeline: linearize (linear, operating), steady (equilibrium), fit and
sensitivities (estimate), accuracy, stability."""
