"""Interactions: the pairwise terms between two systems, keyed by their types.

The second stage of the right-hand side is a sum over interactions: for each ordered pair
of systems ``(A, B)`` whose types appear in :data:`INTERACTIONS`, a pure function over the
neighbour pairs of those two systems returns the accelerations of ``A``'s particles due to
``B``'s.  Pairs of systems that do not interact (wall-wall) have no entry: their pairs are
never formed.  A coupling is a pair of such functions; each is a sum of per-pair terms of
the formulation through :func:`sphjax.physics.pairs.pair_sum`.

* fluid-fluid: pressure and artificial viscosity (eq. 10), Morris viscosity, the
  transport-velocity stress and background-pressure shift (Adami, Hu & Adams 2013);
* fluid-wall: the same pressure and viscous terms against the boundary particles' pressure,
  density and (no-slip) velocity from the wall's update stage (Adami et al. 2012);
* solid-solid: the TLSPH momentum equation (eq. 14) with the optional penalty force;
* fluid-solid and solid-fluid: the solid's particles as moving boundary particles for the
  fluid (the fluid-wall terms against the pressure, density and velocity of
  :func:`sphjax.physics.fsi.update_solid_boundary`), and every such pair force equal and
  opposite on the solid (:mod:`sphjax.physics.fsi`); the same for a rigid body;
* fluid-open boundary: eq. 10 and the viscous terms against the buffer particles of an
  inflow or outflow (:mod:`sphjax.physics.open_boundary`), which move as prescribed;
* rigid-wall: the contact force that keeps a rigid body off the walls
  (:mod:`sphjax.physics.rigid.contact`); the walls do not move, so it has no reaction.

Each function returns a dict with ``"a"`` (``[n_A, d]``) and, for fluids, ``"shift"``.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp

from sphjax import native
from sphjax.core.space import displacement_fn
from sphjax.physics import fsi
from sphjax.physics import pairs as pair_sums
from sphjax.physics.boundary.system import WallSystem
from sphjax.physics.fluid.momentum import (
    pressure_acceleration,
    pressure_acceleration_pullback,
    transport_stress_acceleration,
    transport_stress_acceleration_pullback,
)
from sphjax.physics.fluid.system import FluidSystem
from sphjax.physics.fluid.viscosity import (
    monaghan_pi,
    monaghan_pi_pullback,
    morris_acceleration,
    morris_acceleration_pullback,
)
from sphjax.physics.open_boundary import OpenBoundarySystem
from sphjax.physics.rigid.system import RigidSystem
from sphjax.physics.solid.correction import quadratic_weights
from sphjax.physics.solid.penalty import penalty_force
from sphjax.physics.solid.system import SolidSystem


def _hydrodynamic_summand(pair, a, b, shared, *, h, artificial, morris, stress, shift, viscous):
    """Eq. 10 per pair (pressure, ``Pi_ab``, Morris) plus the transport-velocity terms,
    per unit neighbour mass (``pair_sum`` multiplies by the weight ``m_b``).  Every term
    is antisymmetric under ``a <-> b``.

    The particles' fields include the per-particle ``P = p / rho^2`` and ``i = 1 / rho``
    (:func:`momentum_fields`), so that the pair arithmetic has no divisions by density.
    ``viscous``: whether the pair takes part in the viscous terms (no-slip walls and
    fluid neighbours do, free-slip walls do not); ``b["vv"]`` is the velocity they see.
    """
    c0, alpha, beta = shared.sound_speed, shared.artificial_alpha, shared.artificial_beta
    nu, p_transport = shared.kinematic_viscosity, shared.transport_pressure
    unit = jnp.ones_like(pair.r)
    out = {}
    pi_ab = 0.0
    v_ab = a["v"] - b["vv"]
    if artificial and viscous:
        pi_ab = monaghan_pi(pair, v_ab, a["rho"], b["rho"], c0, h, alpha, beta)
    acceleration = pressure_acceleration(pair, unit, a["P"], b["P"], pi_ab)
    if morris and viscous:
        acceleration = acceleration + morris_acceleration(pair, v_ab, unit, a["i"], b["i"], nu, h)
    if stress:
        acceleration = acceleration + transport_stress_acceleration(
            pair, unit, a["i"], b["i"], a["v"], b["v"], a["dv"], b["dv"]
        )
    out["a"] = acceleration
    if shift:
        out["shift"] = pressure_acceleration(
            pair, unit, p_transport * a["i"] ** 2, p_transport * b["i"] ** 2
        )
    return out


def _hydrodynamic_pullback(
    pair, a, b, shared, bar, *, h, artificial, morris, stress, shift, viscous
):
    """Reverse mode of :func:`_hydrodynamic_summand`, written out per pair from the
    terms' own pull-backs (:func:`pressure_acceleration_pullback`, ...): the cotangents of
    the pair geometry ``(r_ab, |r_ab|, W, grad_a W)``, of ``a``'s and ``b``'s fields and of
    the parameters, for the cotangent ``bar`` of the summand's output (see
    :func:`sphjax.physics.pairs.define_pullback`)."""
    c0, alpha, beta = shared.sound_speed, shared.artificial_alpha, shared.artificial_beta
    nu, p_transport = shared.kinematic_viscosity, shared.transport_pressure
    unit = jnp.ones_like(pair.r)
    cot = pair_sums.Cotangents()
    v_ab = a["v"] - b["vv"]
    pi_ab = 0.0
    if artificial and viscous:
        pi_ab = monaghan_pi(pair, v_ab, a["rho"], b["rho"], c0, h, alpha, beta)
    pressure = pressure_acceleration_pullback(pair, unit, a["P"], b["P"], pi_ab, bar["a"])
    cot.pair(grad_w=pressure["grad_w"])
    cot.a(P=pressure["coefficient"])
    cot.b(P=pressure["coefficient"])
    v_ab_bar = 0.0
    if artificial and viscous:
        pi = monaghan_pi_pullback(
            pair, v_ab, a["rho"], b["rho"], c0, h, alpha, beta, pressure["coefficient"]
        )
        cot.pair(dr=pi["dr"], r=pi["r"])
        cot.a(rho=pi["density_a"])
        cot.b(rho=pi["density_b"])
        cot.shared("sound_speed", pi["sound_speed"])
        cot.shared("artificial_alpha", pi["alpha"])
        cot.shared("artificial_beta", pi["beta"])
        v_ab_bar = v_ab_bar + pi["v_ab"]
    if morris and viscous:
        viscous_bar = morris_acceleration_pullback(
            pair, v_ab, unit, a["i"], b["i"], nu, h, bar["a"]
        )
        cot.pair(dr=viscous_bar["dr"], r=viscous_bar["r"], grad_w=viscous_bar["grad_w"])
        cot.a(i=viscous_bar["inverse_density"])
        cot.b(i=viscous_bar["inverse_density"])
        cot.shared("kinematic_viscosity", viscous_bar["nu"])
        v_ab_bar = v_ab_bar + viscous_bar["v_ab"]
    if stress:
        flux = transport_stress_acceleration_pullback(
            pair, unit, a["i"], b["i"], a["v"], b["v"], a["dv"], b["dv"], bar["a"]
        )
        cot.pair(grad_w=flux["grad_w"])
        cot.a(i=flux["inverse_density_a"], v=flux["v_a"], dv=flux["dv_a"])
        cot.b(i=flux["inverse_density_b"], v=flux["v_b"], dv=flux["dv_b"])
    if (artificial or morris) and viscous:
        cot.a(v=v_ab_bar)
        cot.b(vv=-v_ab_bar)
    if shift:
        background = pressure_acceleration_pullback(
            pair, unit, p_transport * a["i"] ** 2, p_transport * b["i"] ** 2, 0.0, bar["shift"]
        )
        coefficient_bar = background["coefficient"]
        cot.pair(grad_w=background["grad_w"])
        cot.a(i=2.0 * p_transport * a["i"] * coefficient_bar)
        cot.b(i=2.0 * p_transport * b["i"] * coefficient_bar)
        cot.shared("transport_pressure", (a["i"] ** 2 + b["i"] ** 2) * coefficient_bar)
    return cot.result(shared)


pair_sums.define_pullback(_hydrodynamic_summand, _hydrodynamic_pullback)


def _hydrodynamic_loop(keywords, geometry, weight, parity, cross, stored):
    """The compiled loop of :func:`_hydrodynamic_summand` (eq. 10 with Monaghan's and
    Morris' viscosity), within one fluid or against a boundary's columns (their ``vv``:
    the velocity the viscous terms see); ``None`` with the transport-velocity terms,
    which it lacks."""
    if weight != "m" or keywords["stress"] or keywords["shift"]:
        return None
    viscous = keywords["viscous"]

    def loop(rows, cols, idx, shared, stored):
        parameters = (
            shared.sound_speed,
            shared.artificial_alpha,
            shared.artificial_beta,
            shared.kinematic_viscosity,
        )
        columns = None if cols is None else {**cols, "v": cols["vv"]}
        a = native.momentum(
            rows,
            idx,
            geometry,
            parameters,
            artificial=keywords["artificial"] and viscous,
            morris=keywords["morris"] and viscous,
            columns=columns,
        )
        return {"a": a}

    return loop


pair_sums.define_native(_hydrodynamic_summand, _hydrodynamic_loop)


class FluidPairParameters(NamedTuple):
    """The parameters every fluid pair sees (``pair_sum``'s ``shared``), by name."""

    sound_speed: object
    artificial_alpha: object
    artificial_beta: object
    kinematic_viscosity: object
    #: the transport-velocity background pressure ``p_b`` (0 without it)
    transport_pressure: object


def _fluid_shared(system: FluidSystem, ctx) -> FluidPairParameters:
    """The parameters every fluid pair sees; the transport-velocity background pressure
    ``p_b`` is derived from them here (it follows ``sound_speed``)."""
    fluid = ctx.params.fluid
    tvf = system.transport_velocity
    return FluidPairParameters(
        sound_speed=fluid.sound_speed,
        artificial_alpha=fluid.artificial_alpha,
        artificial_beta=fluid.artificial_beta,
        kinematic_viscosity=fluid.kinematic_viscosity,
        transport_pressure=0.0 if tvf is None else tvf.background_pressure(fluid),
    )


def momentum_fields(fields: dict) -> dict:
    """``fields`` (with ``p`` and ``rho``) and the per-particle quantities the momentum
    summand reads instead of dividing per pair: ``P = p / rho^2`` and ``i = 1 / rho``."""
    inverse_density = 1.0 / fields["rho"]
    return {**fields, "P": fields["p"] * inverse_density**2, "i": inverse_density}


def _fluid_rows(fluid, stress):
    rows = {k: fluid[k] for k in ("x", "v", "m", "rho", "p")}
    rows["vv"] = fluid["v"]
    if stress:
        rows["dv"] = fluid["dv"]
    return momentum_fields(rows)


def fluid_fluid(system: FluidSystem, fluid, _other, _fluid, pairs, ctx):
    """Fluid-fluid momentum (eq. 10, viscosities, transport velocity)."""
    stress = system.transport_velocity is not None and "dv" in fluid
    summand = _fluid_momentum(system, ctx.geometry.smoothing_length, stress, viscous=True)
    rows = _fluid_rows(fluid, stress)
    return ctx.pair_sum(
        summand, rows, None, pairs, _fluid_shared(system, ctx), weight="m", parity=-1
    )


def fluid_wall(system: FluidSystem, fluid, wall_system: WallSystem, wall, pairs, ctx):
    """Fluid-wall momentum: eq. 10 against the walls' extrapolated pressure and density;
    viscous terms with the extrapolated velocity for no-slip walls only."""
    summand = _fluid_on_boundary(
        system, ctx.geometry.smoothing_length, wall_system.boundary.no_slip
    )
    cols = {"x": wall["x"], "m": wall["m"], "rho": wall["rho"], "p": wall["p"]}
    cols = momentum_fields({**cols, "vv": wall["v_viscous"]})
    rows = _fluid_rows(fluid, False)
    return ctx.pair_sum(summand, rows, cols, pairs, _fluid_shared(system, ctx), weight="m")


class SolidPairParameters(NamedTuple):
    """The parameters every solid pair sees (``pair_sum``'s ``shared``), by name."""

    solid_density: object
    young_modulus: object
    penalty_alpha: object


def _solid_summand(pair, a, b, shared, *, domain, penalty):
    """Eq. 14 per pair per unit neighbour volume (``pair_sum`` multiplies by ``V0_b``):
    ``(P_a L0_a + P_b L0_b) / rho0 grad0_a W`` plus the penalty force ``f^PF / (m0_a V0_b)``;
    antisymmetric under ``a <-> b``."""
    rho0, young_modulus, alpha = shared.solid_density, shared.young_modulus, shared.penalty_alpha
    acceleration = _matvec((a["PL0"] + b["PL0"]) / rho0, pair.grad_w)
    if penalty:
        dx = displacement_fn(domain)(a["xc"], b["xc"]) * pair.mask[..., None]
        unit = jnp.ones_like(pair.r)
        force = penalty_force(pair, dx, a["F"], b["F"], unit, unit, young_modulus, alpha)
        acceleration = acceleration + force / rho0
    return {"a": acceleration}


def _solid_pullback(pair, a, b, shared, bar, *, domain, penalty):
    """Reverse mode of :func:`_solid_summand` for the cotangent ``bar["a"]`` of
    ``S grad0_a W / rho0`` (``S = P_a L0_a + P_b L0_b``), by hand:

        bar(grad0 W) = S^T bar / rho0,   bar(P_a L0_a) = bar(P_b L0_b) = bar grad0 W^T / rho0,
        bar(rho0) = -bar . (S grad0 W) / rho0^2;

    the penalty force's, when present, is autodiff's (``jax.vjp`` of
    :func:`~sphjax.physics.solid.penalty.penalty_force`)."""
    rho0, young_modulus, alpha = shared.solid_density, shared.young_modulus, shared.penalty_alpha
    acceleration_bar = bar["a"]
    stress = a["PL0"] + b["PL0"]
    elastic = _matvec(stress, pair.grad_w)
    stress_bar = acceleration_bar[..., :, None] * pair.grad_w[..., None, :] / rho0
    cot = pair_sums.Cotangents()
    cot.pair(grad_w=_matvec(jnp.swapaxes(stress, -1, -2), acceleration_bar) / rho0)
    cot.a(PL0=stress_bar)
    cot.b(PL0=stress_bar)
    cot.shared("solid_density", -jnp.sum(acceleration_bar * elastic, axis=-1) / rho0**2)
    if penalty:

        def force(geometry, xc_a, xc_b, F_a, F_b, young_modulus, alpha, rho0):
            reference = pair_sums.PairGeometry(*geometry, pair.mask)
            dx = displacement_fn(domain)(xc_a, xc_b) * pair.mask[..., None]
            unit = jnp.ones_like(pair.r)
            force = penalty_force(reference, dx, F_a, F_b, unit, unit, young_modulus, alpha)
            return force / rho0[..., None]

        geometry = (pair.dr, pair.r, pair.w, pair.grad_w)
        # per-pair copies of the parameters: their cotangents are per pair, summed later
        per_pair = [jnp.broadcast_to(s, pair.r.shape) for s in (young_modulus, alpha, rho0)]
        _, pull = jax.vjp(force, geometry, a["xc"], b["xc"], a["F"], b["F"], *per_pair)
        (dr, r, w, grad_w), xc_a, xc_b, F_a, F_b, e_bar, alpha_bar, rho0_bar = pull(
            acceleration_bar
        )
        cot.pair(dr=dr, r=r, w=w, grad_w=grad_w)
        cot.a(xc=xc_a, F=F_a)
        cot.b(xc=xc_b, F=F_b)
        cot.shared("solid_density", rho0_bar)
        cot.shared("young_modulus", e_bar)
        cot.shared("penalty_alpha", alpha_bar)
    return cot.result(shared)


pair_sums.define_pullback(_solid_summand, _solid_pullback)


def _solid_loop(keywords, geometry, weight, parity, cross, stored):
    """The compiled loop of :func:`_solid_summand` (eq. 14): without the penalty force,
    row by row over the reference kernel gradients stored once per run
    (:func:`sphjax.native.elastic_by_rows`; ``None`` where the list has none); with
    Ganzenmüller's penalty force, each pair once over the reference geometry
    (:func:`sphjax.native.solid_momentum`)."""
    if cross or weight != "V" or parity != -1:
        return None
    if keywords["domain"] != geometry.domain:
        return None
    if not keywords["penalty"]:
        if not stored:
            return None

        def elastic(rows, cols, idx, shared, stored):
            a = native.elastic_by_rows(
                rows["V"], rows["PL0"], stored.grad_w, idx, shared.solid_density
            )
            return {"a": a}

        return elastic

    def loop(rows, cols, idx, shared, stored):
        parameters = (shared.solid_density, shared.young_modulus, shared.penalty_alpha)
        a = native.solid_momentum(
            rows["x"],
            rows["xc"],
            rows["V"],
            rows["PL0"],
            rows["F"],
            idx,
            geometry,
            parameters,
            penalty=keywords["penalty"],
        )
        return {"a": a}

    return loop


pair_sums.define_native(_solid_summand, _solid_loop)


def _solid_summand_second_order(pair, a, b, shared, *, domain, penalty, h):
    """Eq. 14 with the second-order gradient ``psi_ab = G_a omega_ab p(X_ba)``
    (:mod:`sphjax.physics.solid.correction`), per unit neighbour volume: the variational
    counterpart of its ``F``, ``(P_a psi_ab - P_b psi_ba) / rho0``,

        = ((P G_lin)_a + (P G_lin)_b) grad0_a W / rho0
          + ((P G_quad)_a - (P G_quad)_b) q_ab / rho0,

    ``q_ab = omega_ab X_i X_j / h`` (even in ``X_ab``), plus the penalty force;
    antisymmetric under ``a <-> b``.  Reverse mode: autodiff's (``jax.vjp``)."""
    out = _solid_summand(pair, a, b, shared, domain=domain, penalty=penalty)
    quadratic = _matvec((a["PL0q"] - b["PL0q"]) / shared.solid_density, quadratic_weights(pair, h))
    return {"a": out["a"] + quadratic}


def _matvec(matrix, vector):
    return sum(matrix[..., :, i] * vector[..., i, None] for i in range(vector.shape[-1]))


def solid_solid(system: SolidSystem, solid, _other, _solid, pairs, ctx):
    """Solid momentum (eq. 14) over the reference-configuration neighbours."""
    params = ctx.params.solid
    penalty = system.penalty is not None
    rows = {
        "x": solid["X"],
        "xc": solid["x"],
        "V": solid["V"],
        "PL0": solid["PL0"],
        "F": solid["F"],
    }
    if system.gradient_correction == "second_order":
        summand = functools.partial(
            _solid_summand_second_order,
            domain=ctx.geometry.domain,
            penalty=penalty,
            h=ctx.geometry.smoothing_length,
        )
        rows["PL0q"] = solid["PL0q"]
    else:
        summand = functools.partial(_solid_summand, domain=ctx.geometry.domain, penalty=penalty)
    shared = SolidPairParameters(params.solid_density, params.young_modulus, params.penalty_alpha)
    return ctx.pair_sum(summand, rows, None, pairs, shared, weight="V", parity=-1)


def _fluid_momentum(system: FluidSystem, h, stress: bool, viscous: bool):
    """The fluid's momentum summand (eq. 10 with ``system``'s viscosities and transport
    velocity); ``stress``: with the transport-velocity stress (fluid-fluid pairs only);
    ``viscous``: with the viscous terms (not against free-slip boundaries)."""
    return functools.partial(
        _hydrodynamic_summand,
        h=h,
        artificial=system.artificial_viscosity,
        morris=system.physical_viscosity,
        stress=stress,
        shift=system.transport_velocity is not None,
        viscous=viscous,
    )


def _fluid_on_boundary(system: FluidSystem, h, no_slip):
    """The fluid's momentum summand against boundary particles (walls, solids)."""
    return _fluid_momentum(system, h, stress=False, viscous=no_slip)


def fluid_solid(system: FluidSystem, fluid, solid_system: SolidSystem, solid, pairs, ctx):
    """Fluid-solid momentum: the solid's particles as moving boundary particles (eq. 10
    against their extrapolated pressure and density, viscous terms with their velocity
    for a no-slip :class:`~sphjax.SolidBoundary`)."""
    h = ctx.geometry.smoothing_length
    summand = _fluid_on_boundary(system, h, solid_system.boundary.no_slip)
    cols = momentum_fields(fsi.solid_as_boundary_columns(solid))
    rows = _fluid_rows(fluid, False)
    return ctx.pair_sum(summand, rows, cols, pairs, _fluid_shared(system, ctx), weight="m")


def solid_fluid(solid_system: SolidSystem, solid, system: FluidSystem, fluid, pairs, ctx):
    """Solid-fluid: each fluid-solid pair force of :func:`fluid_solid`, equal and opposite
    on the solid particle (:func:`sphjax.physics.fsi.reaction_summand`)."""
    h = ctx.geometry.smoothing_length
    fluid_term = _fluid_on_boundary(system, h, solid_system.boundary.no_slip)
    fluid_term = functools.partial(fluid_term, shift=False)
    summand = functools.partial(fsi.reaction_summand, fluid_term=fluid_term)
    rows = momentum_fields({**fsi.solid_as_boundary_columns(solid), "m_solid": solid["m"]})
    cols = _fluid_rows(fluid, False)
    return ctx.pair_sum(summand, rows, cols, pairs, _fluid_shared(system, ctx), weight="m")


def rigid_wall(system: RigidSystem, body, wall_system: WallSystem, wall, pairs, ctx):
    """Rigid-wall contact: the spring-dashpot force of ``system.wall_contact`` per unit
    mass of the body's particles (:class:`~sphjax.WallContact`); active (its neighbour
    lists formed) only for a body with one."""
    return {"a": system.wall_contact.acceleration(body, wall, pairs, ctx)}


rigid_wall.active = lambda system, wall_system: system.wall_contact is not None


def fluid_open(system: FluidSystem, fluid, open_system: OpenBoundarySystem, buffer, pairs, ctx):
    """Fluid-open boundary momentum: eq. 10 and the viscous terms against the buffer
    particles' pressure, density and velocity (:mod:`sphjax.physics.open_boundary`): a
    fluid particle sees them as fluid.  The buffers move as prescribed, so no reaction."""
    summand = _fluid_on_boundary(system, ctx.geometry.smoothing_length, True)
    cols = {"x": buffer["x"], "m": buffer["m"], "rho": buffer["rho"], "p": buffer["p"]}
    cols = momentum_fields({**cols, "vv": buffer["v"]})
    rows = _fluid_rows(fluid, False)
    return ctx.pair_sum(summand, rows, cols, pairs, _fluid_shared(system, ctx), weight="m")


#: (row system type, neighbour system type) -> interaction function
INTERACTIONS = {
    (FluidSystem, FluidSystem): fluid_fluid,
    (FluidSystem, WallSystem): fluid_wall,
    (SolidSystem, SolidSystem): solid_solid,
    (FluidSystem, SolidSystem): fluid_solid,
    (SolidSystem, FluidSystem): solid_fluid,
    # a rigid body is a moving boundary for the fluid as an elastic solid is
    (FluidSystem, RigidSystem): fluid_solid,
    (RigidSystem, FluidSystem): solid_fluid,
    (RigidSystem, WallSystem): rigid_wall,
    (FluidSystem, OpenBoundarySystem): fluid_open,
}

#: pairs of system types whose neighbour lists the update stage needs besides those of
#: INTERACTIONS (the walls' extrapolation from the fluid)
UPDATE_PAIRS = {(WallSystem, FluidSystem)}
