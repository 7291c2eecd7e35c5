"""Boundaries: wall particles (Adami, Hu & Adams 2012)."""
