"""Static configuration: the simulation box (:class:`Domain`) and the :class:`Model`.

A Model is hashable and passed to ``jit`` as a static argument: choosing another model
recompiles, changing a :class:`~sphjax.Params` value does not.  It holds

* the geometry of the discretisation: dimension, kernel, smoothing length, domain;
* the *systems*, in the order of their particle blocks in the State: a weakly
  compressible fluid, walls, an elastic solid (``sphjax.FluidSystem``,
  ``sphjax.WallSystem``, ``sphjax.SolidSystem``), each with its own physics choices as
  small objects (equation of state, density formulation, viscosities, ...);
* numerics: neighbour-list capacity and skin, how pair sums are differentiated and blocked.
"""

from __future__ import annotations

import dataclasses
import math
import numbers

from sphjax.core.kernels import KERNELS, Kernel, QuinticSpline
from sphjax.core.params import CONTACT_FIELDS, GROUPS, fields, refusal
from sphjax.neighbors.capacity import NEIGHBOR_MARGIN

#: the values of ``Model.pair_loop``
PAIR_LOOPS = ("xla", "native")


@dataclasses.dataclass(frozen=True)
class Domain:
    """Axis-aligned simulation box ``[lower, upper)`` with per-axis periodicity.

    Non-periodic axes still need bounds: a particle that leaves them stops the run.
    """

    lower: tuple[float, ...]
    upper: tuple[float, ...]
    periodic: tuple[bool, ...]

    def __post_init__(self):
        if not len(self.lower) == len(self.upper) == len(self.periodic):
            raise ValueError("Domain.lower, upper and periodic must have one entry per axis")
        for lo, hi in zip(self.lower, self.upper, strict=True):
            if not hi > lo:
                raise ValueError(f"Domain upper bound {hi} must exceed lower bound {lo}")

    @property
    def dim(self) -> int:
        return len(self.lower)

    @property
    def size(self) -> tuple[float, ...]:
        return tuple(hi - lo for lo, hi in zip(self.lower, self.upper, strict=True))


@dataclasses.dataclass(frozen=True)
class Model:
    """Static configuration of a simulation (hashable; passed as a static argument).

    Attributes:
      dim: spatial dimension, 2 or 3.
      smoothing_length: ``h``; the support radius is ``kernel.support * h``.
      domain: the simulation box and its periodic axes.
      systems: the systems, in the order of their particle blocks in the State
        (e.g. ``(FluidSystem(...), WallSystem(...))``).
      kernel: smoothing kernel (see :mod:`sphjax.core.kernels`).
      neighbor_capacity: multiplier on the measured neighbour count that sizes each
        neighbour list; raise it if a run reports a neighbour-list overflow.  Runs under
        ``jit``/``grad``/``vmap`` size their lists by it; a concrete ``sphjax.simulate``
        sizes by it the fluid's rows compacted against a wall or body only.
      neighbor_margin: room above the largest neighbour count at allocation in the
        lists of a concrete ``sphjax.simulate``, which re-allocates a list that
        overflows (a new compilation) and goes on: each list holds ``1 +
        neighbor_margin`` times that count.  Raise it (e.g. ``0.5``) for a flow that
        crowds its particles (a lid-driven corner, an impact) to trade a few padded
        slots for fewer re-allocations; traced runs do not read it.
      neighbor_skin: Verlet skin as a fraction of the support radius; the list is
        rebuilt only when a particle has moved half the skin.
      pair_adjoint: reverse mode through the pair sums uses their custom adjoint (a sum
        over each particle's own neighbours, no scatters; :mod:`sphjax.physics.pairs`):
        gradients ~1.5x faster than autodiff's transpose.  It gives first derivatives only;
        set ``False`` for second derivatives (``jax.hessian``) through a simulation.
      pair_block: most particles per block of the pair sums' adjoint passes (``None``:
        all at once); blocks keep each block's per-pair arrays in cache, and are made
        equal (2,640 particles: two blocks of 1,320).
      pair_loop: ``"xla"`` (default) evaluates every pair sum in XLA, each pair from
        both sides; ``"native"`` evaluates a fluid's density and momentum sums (its
        own each pair once, found through a grid of cells, and against walls, solids,
        bodies and open boundaries, with the walls' pressure extrapolation) and an
        elastic solid's deformation gradient and momentum (eqs. 16 and 14, first-order
        gradient correction, with or without the penalty force) with the compiled loops of
        :mod:`sphjax.native` (threads over rows; the CPU only, built with the machine's
        C++ compiler at first use), and
        rebuilds the neighbour list with its compiled cell list (the same list as
        jax-md's).  Derivatives are the same either way: they always go through XLA.
    """

    dim: int
    smoothing_length: float
    domain: Domain
    systems: tuple
    kernel: Kernel = QuinticSpline()
    neighbor_capacity: float = 1.25
    neighbor_margin: float = NEIGHBOR_MARGIN
    neighbor_skin: float = 0.25
    pair_adjoint: bool = True
    pair_block: int | None = 2048
    pair_loop: str = "xla"

    def __post_init__(self):
        if self.dim not in (2, 3):
            raise ValueError(f"Model.dim must be 2 or 3, got {self.dim}")
        if self.domain.dim != self.dim:
            raise ValueError(f"Model.domain has {self.domain.dim} axes but dim={self.dim}")
        if not self.smoothing_length > 0:
            raise ValueError(
                f"Model.smoothing_length must be positive, got {self.smoothing_length}"
            )
        systems = tuple(self.systems) if isinstance(self.systems, list | tuple) else None
        if not systems or not all(hasattr(s, "kinds") for s in systems):
            raise ValueError(
                "Model.systems must be a non-empty tuple of systems, e.g. "
                "(sphjax.FluidSystem(), sphjax.WallSystem())"
            )
        object.__setattr__(self, "systems", systems)
        kinds = [min(k) for k in (s.kinds for s in systems)]
        if kinds != sorted(kinds) or len(set(kinds)) != len(kinds):
            raise ValueError(
                "Model.systems must be ordered as their particle blocks: fluid, wall, solid, "
                "one system of each kind"
            )
        if not self.neighbor_capacity >= 1.0:
            raise ValueError("Model.neighbor_capacity must be >= 1")
        margin = self.neighbor_margin
        if isinstance(margin, bool) or not (
            isinstance(margin, numbers.Real) and math.isfinite(margin) and margin >= 0
        ):
            raise ValueError(
                "Model.neighbor_margin must be a finite number >= 0 (room above the largest "
                f"neighbour count, e.g. 0.5 for 50 %), got {margin!r}"
            )
        object.__setattr__(self, "neighbor_margin", float(margin))
        if not isinstance(self.pair_adjoint, bool):
            raise ValueError(f"Model.pair_adjoint must be True or False, got {self.pair_adjoint!r}")
        if self.pair_block is not None and not (
            isinstance(self.pair_block, int) and self.pair_block > 0
        ):
            raise ValueError(
                f"Model.pair_block must be None or a positive int, got {self.pair_block!r}"
            )
        if self.pair_loop not in PAIR_LOOPS:
            raise ValueError(f"Model.pair_loop must be 'xla' or 'native', got {self.pair_loop!r}")
        if self.pair_loop == "native":
            self._check_native()

    def _check_native(self):
        """Refuse ``pair_loop="native"`` where no pair sum of the model would use it."""
        if not any(getattr(s, "native_pair_sums", False) for s in self.systems):
            raise ValueError(
                "Model.pair_loop='native' has loops for the own pair sums of a fluid and "
                "of an elastic solid only (the solid's with the first-order correction) "
                "and this model has neither; use pair_loop='xla'"
            )
        if type(self.kernel) not in KERNELS.values():
            raise ValueError(
                f"Model.pair_loop='native' has loops for the kernels {', '.join(KERNELS)}, "
                f"not {type(self.kernel).__name__}; use pair_loop='xla' or one of those"
            )

    @property
    def cutoff(self) -> float:
        """Kernel support radius ``k h``."""
        return self.kernel.support * self.smoothing_length

    @property
    def particle_kinds(self) -> tuple[int, ...]:
        """The :class:`~sphjax.Kind` values the systems own."""
        return tuple(sorted(int(k) for s in self.systems for k in s.kinds))

    def system(self, cls):
        """The system of type ``cls``, or ``None``."""
        return next((s for s in self.systems if isinstance(s, cls)), None)

    def parameters(self) -> frozenset[str] | None:
        """The Params fields the systems read (``None`` if a system does not say)."""
        if not all(hasattr(s, "parameters") for s in self.systems):
            return None
        return frozenset().union(*(s.parameters() for s in self.systems))

    def unused_parameters(self) -> tuple[tuple[str, str], ...]:
        """``(field, refusal)`` for each Params field that no system reads, in field order;
        the refusal is one line naming the system and the choice that would read it.
        Changing a field not listed can change the run.  ``()`` if a system does not say
        what it reads."""
        read = self.parameters()
        if read is None:
            return ()
        unused = {}
        for system in self.systems:
            for name, why in getattr(system, "unused_parameters", dict)().items():
                if name not in read:
                    unused.setdefault(name, why)
        system_of = {"fluid": "FluidSystem()", "solid": "SolidSystem()"}
        for group, defaults in GROUPS.items():  # a group no system of the model reads
            for name in defaults:
                if name not in read and name not in unused:
                    why, fix = f"it has no {group}", f"add a {system_of[group]}"
                    if name in CONTACT_FIELDS:
                        why = "it has no rigid body"
                        fix = "add a RigidSystem(wall_contact=WallContact())"
                    unused[name] = refusal(name, "model", why, fix)
        return tuple(sorted(unused.items(), key=lambda item: fields().index(item[0])))

    def replace(self, **changes) -> Model:
        return dataclasses.replace(self, **changes)
