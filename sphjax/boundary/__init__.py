"""Boundary treatments: dummy wall particles (Adami, Hu & Adams 2012)."""
