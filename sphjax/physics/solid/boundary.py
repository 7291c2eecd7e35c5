"""How a fluid sees an elastic solid: its particles as moving boundary particles."""

from __future__ import annotations

import dataclasses


@dataclasses.dataclass(frozen=True)
class SolidBoundary:
    """The solid's particles as moving boundary particles for a fluid (Adami, Hu & Adams
    2012), each acting with the fluid's rest density times its reference volume as mass
    (its "hydrodynamic mass") and the pressure extrapolated from the fluid.

    Attributes:
      no_slip: the fluid's viscous terms see the solid's velocity (no-slip); ``False``
        leaves the solid out of them (free slip).
      acceleration: ``True``: the pressure extrapolation uses the solid particle's own
        acceleration (from the last evaluation) in ``(g - a_s)``; ``False`` (default)
        uses ``a_s = 0``.  The particle accelerations of an elastic solid carry its
        stress waves, thousands of m/s^2 where the load is applied suddenly, and fed
        back through ``p_s`` they can grow from step to step (docs/validation_fsi.md):
        use ``True`` for slow, smooth motions of a soft or heavy solid.
    """

    no_slip: bool = True
    acceleration: bool = False

    def __post_init__(self):
        for name in ("no_slip", "acceleration"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(
                    f"SolidBoundary.{name} must be True or False, got {getattr(self, name)!r}"
                )
