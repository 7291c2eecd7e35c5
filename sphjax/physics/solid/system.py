"""The elastic solid system: total-Lagrangian SPH (formulation eqs. 13-19; O'Connor &
Rogers 2021), and its update stage.

Every quantity is evaluated against the reference configuration ``X`` with the reference
neighbours found once:

    L0_a = ( -sum_b V0_b grad0_a W(X_ab) X_ab^T )^-1                         (eq. 15)
    F_a  = -sum_b V0_b x_ab (L0_a grad0_a W(X_ab))^T                         (eq. 16)
    E_a  = 1/2 (F_a^T F_a - I),  S_a = lambda tr(E_a) I + 2 mu E_a           (eqs. 17-18)
    mu = E / (2 (1 + nu)),  lambda = E nu / ((1 + nu)(1 - 2 nu))             (eq. 19)
    P_a  = F_a S_a
    Dv_a/Dt = sum_b m0_b (P_a L0_a / rho0_a^2 + P_b L0_b / rho0_b^2) grad0_a W(X_ab)
              + f_a^PF / m0_a + g                                            (eq. 14)

with ``X_ab = X_a - X_b`` and ``x_ab = x_a - x_b``.  The minus signs in eqs. 15-16 make
``L0 ~ I`` and ``F = I`` on the undeformed configuration.  In 2D the Lamé constants of
eq. 19 give plane strain.  The momentum equation is the solid-solid interaction
(:mod:`sphjax.physics.interactions`); it is the variational discretisation of the St
Venant-Kirchhoff energy: pair forces are antisymmetric (linear momentum is conserved
exactly) and the energy is frame-indifferent.

The system holds solid particles and clamped ones (kind ``CLAMPED``), whose motion is
prescribed; clamped particles take part as neighbours with their own ``F``.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import Any

import jax.numpy as jnp

from sphjax import native
from sphjax.core.params import CONTACT_FIELDS, SOLID_DEFAULTS, fields_read, refusal
from sphjax.core.space import displacement_fn
from sphjax.core.state import Kind
from sphjax.physics import fsi
from sphjax.physics import pairs as pair_sums
from sphjax.physics.fluid.system import FluidSystem
from sphjax.physics.solid.boundary import SolidBoundary
from sphjax.physics.solid.correction import (
    corrected_kernel_gradient,
    correction_matrix,
    correction_moment,
    second_order_kernel_gradient,
    second_order_matrices,
    second_order_moment,
)
from sphjax.physics.solid.deformation import deformation_term
from sphjax.physics.solid.material import StVenantKirchhoff
from sphjax.physics.solid.penalty import PenaltyForce
from sphjax.physics.system import block_fields

#: the choices of ``SolidSystem.gradient_correction``
GRADIENT_CORRECTIONS = ("first_order", "second_order")

#: the stable step with the second-order gradient, over the first-order one's: its
#: one-sided weights at a free face are several times the bulk's, and so is the face
#: particles' stiffness (the dry hydrostatic plate at 3 particles through goes unstable
#: in its first step at solid Courant number 0.5 and runs at 0.25;
#: docs/validation_fsi.md)
SECOND_ORDER_STEP_FACTOR = 0.5


@dataclasses.dataclass(frozen=True)
class SolidSystem:
    """A total-Lagrangian elastic solid (kinds ``SOLID`` and ``CLAMPED``); its parameters
    are ``Params.solid``.

    Attributes:
      material: :class:`~sphjax.StVenantKirchhoff`.
      penalty: ``None`` or :class:`~sphjax.PenaltyForce` (hourglass control, eq. 14).
      clamped_motion: ``None`` (clamped particles stay put) or a hashable function
        ``(t, X) -> x`` giving the prescribed positions of clamped particles.
      boundary: :class:`~sphjax.SolidBoundary`, how a fluid in the same model sees the
        solid (fluid-structure interaction, :mod:`sphjax.physics.fsi`).
      substeps: split integration (:mod:`sphjax.integration.split`): with ``k > 1`` the
        solid advances in ``k`` steps of ``dt / k`` of its own inside every step of
        :func:`sphjax.simulate`, its elastic forces re-evaluated in each and the fluid's
        forces on it applied as half kicks at the ends of the step; the time step is then
        limited by the fluid and ``k`` times the solid's stable step.  ``1``: one step
        for all.
      gradient_correction: the reference kernel gradient of eqs. 14 and 16.
        ``"first_order"`` (default): ``L0_a grad0_a W`` (eq. 15, Bonet & Lok 1999),
        exact for linear displacement fields.  ``"second_order"``: ``psi_ab`` of
        :mod:`sphjax.physics.solid.correction`, exact for quadratic ones also at free
        surfaces (a bent plate's faces); it needs at least three particles through the
        solid in every direction (else its moment matrix is singular) and equals the
        first-order gradient wherever the neighbourhood is symmetric
        (docs/validation_fsi.md, the hydrostatic plate).
    """

    material: object = StVenantKirchhoff()
    penalty: object = None
    clamped_motion: Callable[[Any, Any], Any] | None = None
    boundary: SolidBoundary = SolidBoundary()
    substeps: int = 1
    gradient_correction: str = "first_order"

    kinds = (Kind.SOLID, Kind.CLAMPED)
    current_configuration = False
    #: its place in the update stage: after the fluid, whose pressure it takes as a boundary
    stage = 2
    #: the Params group it reads
    params_group = "solid"

    @property
    def native_pair_sums(self) -> bool:
        """Whether ``Model.pair_loop="native"`` has loops for its own sums: eqs. 16 and 14
        with the first-order correction (the second-order one's stay XLA's)."""
        return self.gradient_correction == "first_order"

    def __post_init__(self):
        if not hasattr(self.material, "pk1"):
            raise ValueError(
                f"SolidSystem.material must be StVenantKirchhoff(), got {self.material!r}"
            )
        if self.penalty is not None and not isinstance(self.penalty, PenaltyForce):
            raise ValueError(
                f"SolidSystem.penalty must be None or PenaltyForce(), got {self.penalty!r}"
            )

        if not isinstance(self.boundary, SolidBoundary):
            raise ValueError(
                f"SolidSystem.boundary must be SolidBoundary(...), got {self.boundary!r}"
            )

        if self.gradient_correction not in GRADIENT_CORRECTIONS:
            raise ValueError(
                f"SolidSystem.gradient_correction must be one of {GRADIENT_CORRECTIONS}, "
                f"got {self.gradient_correction!r}"
            )

        if not (isinstance(self.substeps, int) and self.substeps >= 1):
            raise ValueError(
                f"SolidSystem.substeps must be a positive integer (1: no split integration), "
                f"got {self.substeps!r}"
            )

    def parameters(self) -> frozenset[str]:
        """The Params fields this solid reads: ``gravity`` and ``solid_density`` (eq. 14)
        and those of its material and penalty force."""
        return fields_read(
            (self.material, self.penalty), own=("gravity", "solid_density"), group="solid"
        )

    def unused_parameters(self) -> dict[str, str]:
        """``{field: refusal}`` for the solid fields this solid does not read."""
        hints = {"penalty_alpha": ("no penalty force", "give the solid penalty=PenaltyForce()")}
        contact = (
            "an elastic solid has no wall contact",
            "give a rigid body RigidSystem(wall_contact=WallContact())",
        )
        hints.update(dict.fromkeys(CONTACT_FIELDS, contact))
        generic = ("its choices do not read it", "choose one that does")
        read = self.parameters()
        return {
            name: refusal(name, "solid", *hints.get(name, generic))
            for name in SOLID_DEFAULTS
            if name not in read
        }

    def replace(self, **changes) -> SolidSystem:
        return dataclasses.replace(self, **changes)

    # the system protocol (sphjax.physics.system)

    #: the kinds whose velocity the integrators' kicks change (clamped particles' is set
    #: by their prescribed motion, if any)
    free_kinds = (Kind.SOLID,)

    def held_kinds(self) -> tuple:
        """Clamped particles stay put unless ``clamped_motion`` moves them."""
        return (Kind.CLAMPED,) if self.clamped_motion is None else ()

    def prescribed_motion(self, time, state):
        """``([N, 1] mask, [N, d] positions)``: clamped particles at
        ``clamped_motion(t, X)``, or ``None`` if they stay put."""
        if self.clamped_motion is None:
            return None
        target = self.clamped_motion(time, state.reference_position)
        return (state.kind == Kind.CLAMPED)[:, None], target

    def time_step_limits(self, v_max: float, params, model, cfl: float) -> list[float]:
        """``substeps CFL h / (c_s + |v|max)`` with the bulk sound speed
        :func:`solid_sound_speed` (split integration: the solid takes ``substeps`` steps
        of its own per step), times :data:`SECOND_ORDER_STEP_FACTOR` with the
        second-order gradient."""
        c_s = float(solid_sound_speed(params, model.dim))
        factor = SECOND_ORDER_STEP_FACTOR if self.gradient_correction == "second_order" else 1.0
        return [factor * self.substeps * cfl * model.smoothing_length / (c_s + v_max)]

    def view(self, state, block: slice, density_step=None) -> dict:
        """The solid's fields ``x, v, m, rho``, its reference positions ``X`` and volumes
        ``V``, ``free`` (True for kind ``SOLID``, False for ``CLAMPED``) and ``a``, the
        acceleration of the last evaluation (the fluid's boundary pressure reads it)."""
        view = block_fields(state, block)
        view.update(X=state.reference_position[block], V=state.volume[block])
        view["free"] = state.kind[block] == Kind.SOLID
        view["a"] = state.acceleration[block]
        return view

    def boundary_view(self, view: dict, params) -> dict:
        """A fluid sees the solid as a moving boundary of hydrodynamic mass
        (:func:`sphjax.physics.fsi.fluid_view_of_solid`)."""
        return fsi.fluid_view_of_solid(view, params.fluid)

    def update(self, i: int, views: list, systems: tuple, pairs: dict, ctx, density_step=None):
        """Update stage: ``L0``, ``F`` and the stress (:func:`update_solid`, with the
        reference quantities computed once per run where ``ctx.reference`` has them), then
        its boundary pressure from each fluid it has a list against
        (:func:`sphjax.physics.fsi.update_solid_boundary`)."""
        reference = (ctx.reference or {}).get(i)
        view = update_solid(self, views[i], pairs[(i, i)], ctx, reference)
        for j, fluid in enumerate(systems):
            if (i, j) in pairs and isinstance(fluid, FluidSystem):
                view = fsi.update_solid_boundary(self, view, fluid, views[j], pairs[(i, j)], ctx)
        return view

    def reference_quantities(self, view: dict, pairs, ctx) -> dict:
        """What depends on the reference configuration only, computed once per run: the
        pair geometry of its list (``X_ab``, ``|X_ab|``, ``W0``, ``grad0 W``) and ``L0``
        (eq. 15, :func:`solid_reference`)."""
        geometry = pair_sums.stored_geometry(view["X"], pairs, ctx.geometry)
        own = solid_reference(view, pairs.replace(geometry=geometry), ctx, self.gradient_correction)
        return {**own, "geometry": geometry}

    def body_acceleration(self, view: dict, acceleration, params):
        """The interactions' acceleration plus gravity (eq. 14); none on clamped
        particles, whose motion is prescribed."""
        return jnp.where(view["free"][:, None], acceleration + params.gravity, 0.0)


def solid_sound_speed(params, dim: int):
    """``c_s = sqrt(K / rho0)`` with the bulk modulus ``K = E / (d (1 - 2 nu))``."""
    bulk = params.young_modulus / (dim * (1.0 - 2.0 * params.poisson_ratio))
    return (bulk / params.solid_density) ** 0.5


def _moment_summand(pair, a, b, shared):
    """Eq. 15's pair term per unit neighbour volume (symmetric under ``a <-> b``)."""
    return correction_moment(pair, jnp.ones_like(pair.r))


def _deformation_summand(pair, a, b, shared, *, domain):
    """Eq. 16's pair term ``-V0_b x_ab (L0_a grad0_a W)^T`` (the pair sum is ``F_a``)."""
    dx = displacement_fn(domain)(a["xc"], b["xc"])
    dx = dx * pair.mask[..., None]
    return deformation_term(dx, corrected_kernel_gradient(a["L0"], pair.grad_w), b["V"])


def _deformation_pullback(pair, a, b, shared, bar, *, domain):
    """Reverse mode of :func:`_deformation_summand` for the per-pair cotangent ``bar`` of
    ``T_ij = -V_b dx_i g_j``, ``g = L0_a grad0_a W``, ``dx = x_a - x_b`` (minimum image):

        bar(dx)_i = -V_b bar_ij g_j,   bar(g)_j = -V_b bar_ij dx_i,
        bar(V_b) = -bar_ij dx_i g_j,   bar(L0_a)_jk = bar(g)_j grad0_k W,
        bar(grad0 W)_k = L0_a,jk bar(g)_j,   bar(x_a) = bar(dx) = -bar(x_b).
    """
    mask = pair.mask[..., None]
    dx = displacement_fn(domain)(a["xc"], b["xc"]) * mask
    g = corrected_kernel_gradient(a["L0"], pair.grad_w)
    volume = b["V"][..., None]
    dx_bar = -volume * jnp.einsum("...ij,...j->...i", bar, g)
    g_bar = -volume * jnp.einsum("...ij,...i->...j", bar, dx)
    cot = pair_sums.Cotangents()
    cot.pair(grad_w=jnp.einsum("...jk,...j->...k", a["L0"], g_bar))
    cot.a(xc=dx_bar * mask, L0=g_bar[..., :, None] * pair.grad_w[..., None, :])
    cot.b(xc=-dx_bar * mask, V=-jnp.einsum("...ij,...i,...j->...", bar, dx, g))
    return cot.result(len(shared))


pair_sums.define_pullback(_deformation_summand, _deformation_pullback)
# measured on the CPU: autodiff's transpose (0.87 ms) beats the custom adjoint (2.86 ms) on
# the oscillating plate n = 16 (docs/performance_gradients.md); the pull-back stays, tested,
# for `benchmarks/pair_costs.py` to re-measure on other hardware
pair_sums.transpose_by_autodiff(_deformation_summand)


def _deformation_loop(keywords, geometry, weight, parity, cross, stored):
    """The compiled loop of :func:`_deformation_summand` (eq. 16): row by row over the
    reference kernel gradients stored once per run (:func:`sphjax.native.deformation_by_rows`);
    ``None`` where the list has none (a loop over each pair once with the geometry
    recomputed was slower than XLA's sum; docs/performance.md)."""
    if cross or not stored or weight is not None or keywords["domain"] != geometry.domain:
        return None

    def loop(rows, cols, idx, shared, stored):
        return native.deformation_by_rows(
            rows["xc"], rows["V"], rows["L0"], stored.grad_w, idx, geometry.domain
        )

    return loop


pair_sums.define_native(_deformation_summand, _deformation_loop)


def _second_order_moment_summand(pair, a, b, shared, *, h):
    """The second-order moment's pair term per unit neighbour volume
    (:func:`~sphjax.physics.solid.correction.second_order_moment`)."""
    return second_order_moment(pair, jnp.ones_like(pair.r), h)


def _deformation_summand_second_order(pair, a, b, shared, *, domain, h):
    """Eq. 16's pair term with the second-order gradient: ``-V0_b x_ab psi_ab^T``."""
    dx = displacement_fn(domain)(a["xc"], b["xc"])
    dx = dx * pair.mask[..., None]
    psi = second_order_kernel_gradient(a["L0"], a["L0q"], pair, h)
    return deformation_term(dx, psi, b["V"])


# autodiff's transpose, as for the first-order summand (no hand pull-back)
pair_sums.transpose_by_autodiff(_deformation_summand_second_order)


def solid_reference(solid: dict, pairs, ctx, gradient_correction="first_order") -> dict:
    """The reference-configuration quantities of a solid: ``{"L0": L0}`` (eq. 15), or
    with ``gradient_correction="second_order"`` ``{"L0": G_lin, "L0q": G_quad}``, the
    linear and quadratic blocks of the second-order gradient's ``G_a``
    (:mod:`sphjax.physics.solid.correction`).

    They depend on the reference positions ``X`` and volumes ``V`` only, never on the
    current configuration or the material parameters.
    """
    rows = {"x": solid["X"], "V": solid["V"]}
    if gradient_correction == "second_order":
        summand = functools.partial(_second_order_moment_summand, h=ctx.geometry.smoothing_length)
        moment = ctx.pair_sum(summand, rows, None, pairs, weight="V")
        G_lin, G_quad = second_order_matrices(moment)
        return {"L0": G_lin, "L0q": G_quad}
    moment = ctx.pair_sum(_moment_summand, rows, None, pairs, weight="V", parity=1)
    return {"L0": correction_matrix(moment)}


def update_solid(system: SolidSystem, solid: dict, pairs, ctx, reference=None):
    """Update stage of a solid: ``L0`` (eq. 15), ``F`` (eq. 16) and the stress ``P L0``.

    Args:
      solid: fields ``X`` (reference positions), ``x`` (current), ``V`` (reference
        volumes).
      pairs: the reference-configuration list within the solid.
      reference: :func:`solid_reference` of this solid, computed once per run, or
        ``None`` (computed here).
    Returns:
      ``solid`` with ``L0``, ``F``, ``P`` and ``P L0`` (``[n, d, d]``); with the
      second-order gradient also ``L0q`` and ``P L0q`` (``[n, d, d (d + 1) / 2]``).
    """
    if reference is None:
        reference = solid_reference(solid, pairs, ctx, system.gradient_correction)
    L0 = reference["L0"]
    rows = {"x": solid["X"], "xc": solid["x"], "V": solid["V"], "L0": L0}
    if system.gradient_correction == "second_order":
        summand = functools.partial(
            _deformation_summand_second_order,
            domain=ctx.geometry.domain,
            h=ctx.geometry.smoothing_length,
        )
        F = ctx.pair_sum(summand, {**rows, "L0q": reference["L0q"]}, None, pairs)
        P = system.material.pk1(F, ctx.params.solid)
        L0q = reference["L0q"]
        return {**solid, "L0": L0, "L0q": L0q, "F": F, "P": P, "PL0": P @ L0, "PL0q": P @ L0q}
    summand = functools.partial(_deformation_summand, domain=ctx.geometry.domain)
    F = ctx.pair_sum(summand, rows, None, pairs)
    P = system.material.pk1(F, ctx.params.solid)
    return {**solid, "L0": L0, "F": F, "P": P, "PL0": P @ L0}
