"""Kick-drift-kick (velocity Verlet) as a ``diffrax.AbstractSolver``.

Properties: second order, fixed step (no error estimate, so no adaptive step-size
control), symplectic for position-only forces, first-same-as-last: the rates of the last
right-hand-side evaluation are carried in the solver state, so a step costs one
evaluation.  Dense output is linear between steps.

It runs the one step of :func:`sphjax.integration.step.kick_drift_kick`, the one
:func:`sphjax.simulate` runs, with the right-hand side evaluated through the term's vector
field (``terms.vf``), so for the same step it reproduces the ``lax.scan`` integrator to
round-off.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

import diffrax
import jax.numpy as jnp

from sphjax.integration._term import Phase, SPHTerm, with_step
from sphjax.integration.step import kick_drift_kick


def _model_of(terms):
    """The static Model of our term, inside diffrax's wrappers (e.g. ``WrapTerm``)."""
    while not isinstance(terms, SPHTerm):
        terms = terms.term
    return terms.model


class KickDriftKick(diffrax.AbstractSolver):
    """Kick-drift-kick for an :class:`~sphjax.integration.diffrax.SPHTerm`.

    Solver state: ``(acceleration [N, d], density_rate [N], shift_acceleration [N, d])`` of
    the last evaluation.
    """

    term_structure: ClassVar = SPHTerm
    interpolation_cls: ClassVar[Callable[..., diffrax.LocalLinearInterpolation]] = (
        diffrax.LocalLinearInterpolation
    )

    def order(self, terms):
        return 2

    def init(self, terms, t0, t1, y0, args):
        rates = terms.vf(t0, y0, args)
        return rates.acceleration, rates.density_rate, rates.shift_acceleration

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        del made_jump  # the right-hand side has no jumps
        acceleration, density_rate, shift_acceleration = solver_state
        state = args.state.replace(
            position=y0.position,
            velocity=y0.velocity,
            density=y0.density,
            acceleration=acceleration,
            density_rate=density_rate,
            shift_acceleration=shift_acceleration,
            time=jnp.asarray(t0, y0.position.dtype),
        )

        def rates(drifted, density_step):
            y = Phase(drifted.position, drifted.velocity, drifted.density)
            out = terms.vf(t1, y, with_step(args, density_step, shift_acceleration))
            return drifted.replace(
                density=out.density,
                acceleration=out.acceleration,
                density_rate=out.density_rate,
                pressure=out.pressure,
                shift_acceleration=out.shift_acceleration,
            )

        state = kick_drift_kick(state, t1 - t0, _model_of(terms), rates)
        y1 = Phase(state.position, state.velocity, state.density)
        dense_info = dict(y0=y0, y1=y1)
        new_state = (state.acceleration, state.density_rate, state.shift_acceleration)
        return y1, None, dense_info, new_state, diffrax.RESULTS.successful

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)


KickDriftKick.__init__.__doc__ = """**Arguments:** None"""
