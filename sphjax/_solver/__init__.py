"""diffrax solvers for SPH (private; public names are re-exported from ``sphjax``)."""

from sphjax._solver.kdk import KickDriftKick
from sphjax._solver.term import Phase, Rates, SPHArgs, SPHTerm

__all__ = ["KickDriftKick", "Phase", "Rates", "SPHArgs", "SPHTerm"]
