"""Weakly compressible fluid SPH (formulation eqs. 5-12)."""
