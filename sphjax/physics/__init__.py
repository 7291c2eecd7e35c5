"""Physics: systems, per-pair terms of the formulation, interactions, the right-hand side."""
