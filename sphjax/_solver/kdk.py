"""Kick-drift-kick (velocity Verlet) as a ``diffrax.AbstractSolver``.

Properties: second order, fixed step (no error estimate, so no adaptive step-size
control), symplectic for position-only forces, first-same-as-last: the rates of the last
right-hand-side evaluation are carried in the solver state, so a step costs one
evaluation.  Dense output is linear between steps.

It integrates :class:`sphjax.diffrax_solver.SPHTerm` (y is a
:class:`sphjax.diffrax_solver.Phase`) and performs exactly the operations of
:func:`sphjax.kick_drift_kick`, sharing its two halves (:func:`sphjax.integrate.kick_drift`
and :func:`sphjax.integrate.closing_kick`), so for the same step it reproduces the
``lax.scan`` integrator of :func:`sphjax.simulate` to round-off.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

import diffrax
import jax.numpy as jnp

from sphjax._solver.term import Phase, SPHTerm
from sphjax.integrate import closing_kick, kick_drift


def _term_of(terms) -> SPHTerm:
    """Our term inside diffrax's wrappers (e.g. ``WrapTerm``)."""
    while not isinstance(terms, SPHTerm):
        terms = terms.term
    return terms


def _model_of(terms):
    """The static Model of our term."""
    return _term_of(terms).model


class KickDriftKick(diffrax.AbstractSolver):
    """Kick-drift-kick for an :class:`~sphjax.diffrax_solver.SPHTerm`.

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
        dt = t1 - t0
        state = args.state.replace(
            position=y0.position,
            velocity=y0.velocity,
            density=y0.density,
            acceleration=acceleration,
            density_rate=density_rate,
            shift_acceleration=shift_acceleration,
            time=jnp.asarray(t0, y0.position.dtype),
        )
        state = kick_drift(state, dt, _model_of(terms))
        half_step = Phase(state.position, state.velocity, state.density)
        rates = _term_of(terms).rates(
            t1, half_step, args, density_step=dt, shift_acceleration=shift_acceleration
        )
        state = closing_kick(
            state.replace(
                density=rates.density,
                acceleration=rates.acceleration,
                density_rate=rates.density_rate,
            ),
            dt,
        )
        y1 = Phase(state.position, state.velocity, state.density)
        dense_info = dict(y0=y0, y1=y1)
        return (
            y1,
            None,
            dense_info,
            (rates.acceleration, rates.density_rate, rates.shift_acceleration),
            (diffrax.RESULTS.successful),
        )

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)


KickDriftKick.__init__.__doc__ = """**Arguments:** None"""
