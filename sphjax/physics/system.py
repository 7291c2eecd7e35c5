"""What a system is: the protocol the right-hand side runs every system through.

A simulation holds a tuple of systems (``Model.systems``), each owning one contiguous block
of the State's particles.  :func:`sphjax.physics.rhs.evaluate` knows no system type: it
asks each system, through the members below, for its fields, its update stage and what
it adds to the accelerations of the interactions; the interactions themselves are pure
functions keyed by the pair of system types
(:data:`sphjax.physics.interactions.INTERACTIONS`).  A new kind of system is a class with
these members, its interaction functions registered there, and a case that builds it.

Class attributes:
  kinds: the :class:`~sphjax.Kind` values of its particles.
  current_configuration: whether its neighbour lists follow the particles (``False``: a
    reference-configuration list, found once, as for a total-Lagrangian solid).
  stage: its place in the update stage (lower first; a system's update may read the
    updated fields of the systems of lower stages: walls read the fluid's pressure).
  params_group: the :class:`~sphjax.Params` group it reads (``"fluid"``, ``"solid"``).

  free_kinds: the kinds whose velocity the integrators' kicks change.

Methods:
  ``view(state, block, density_step) -> dict``: its fields, the arrays of its block of
    ``state`` (``x, v, m, rho`` and what its physics needs), at the start of an evaluation.
  ``boundary_view(view, params) -> dict | None``: how a fluid's density sums see its
    particles (``x``, ``m``, ``v``), or ``None`` if it is no boundary to a fluid.
  ``update(i, views, systems, pairs, ctx, density_step) -> dict``: its update stage, the
    view of system ``i`` (itself) with what it computes (density, pressure, stress, ...);
    ``views`` holds every system's view, updated for the systems of lower stages;
    ``pairs[(i, j)]`` the neighbour list of system ``i`` against ``j``.
  ``body_acceleration(view, acceleration, params)``: the sum of its interactions'
    accelerations completed by what acts on it alone (gravity; zero where it is held).
  ``reference_quantities(view, pairs, ctx) -> dict`` (systems with
    ``current_configuration = False``): what depends on the reference configuration
    only, computed once per run and handed to ``update`` as ``ctx.reference[i]``.
  ``held_kinds()``: the kinds whose positions no integrator changes (walls; clamped
    particles without a prescribed motion).
  ``prescribed_motion(time, state)``: ``None``, or ``([N, 1] mask, [N, d] positions)``
    for particles whose motion is prescribed (placed there by each drift, their velocity
    the displacement over the step).
  ``time_step_limits(v_max, params, model, cfl) -> list[float]``: its stable-step
    limits (``v_max``: the largest speed of its free particles; ``cfl``: the Courant
    number of its Params group).
  ``transfer(state) -> state`` (optional; systems whose particles enter and leave):
    after each drift, the State with the particles that crossed its zones' planes
    traded between blocks at fixed capacity (each block keeps its size;
    :class:`sphjax.physics.open_boundary.OpenBoundarySystem`).
  ``parameters()``, ``unused_parameters()``: the Params fields it reads and a one-line
    refusal for each of its group's fields it does not read (the honest-API rule).
  ``check_params(params)`` (optional): refuse, in one line, concrete Params that
    contradict one of its choices (``simulate`` and ``diffeqsolve_case`` call it before a
    concrete run; :meth:`sphjax.RigidSystem.check_params`).
"""

from __future__ import annotations


def block_fields(state, block: slice) -> dict:
    """``x, v, m, rho``: the positions, velocities, masses and densities of the particles
    ``block`` of ``state``, what every system's view starts from."""
    return {
        "x": state.position[block],
        "v": state.velocity[block],
        "m": state.mass[block],
        "rho": state.density[block],
    }
