"""Elastic solids: total-Lagrangian SPH (formulation eqs. 13-19)."""
