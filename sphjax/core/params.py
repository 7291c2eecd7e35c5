"""Differentiable parameters: every float ``jax.grad`` should see, grouped by system.

* :class:`FluidParams` — the weakly compressible fluid (eqs. 10-12, viscosities, delta-SPH).
* :class:`SolidParams` — the bodies: the elastic solid (eqs. 14, 18-19, penalty force) and a
  rigid body's wall contact (:class:`~sphjax.WallContact`).
* :class:`Params` — the body acceleration ``gravity`` and one group per kind of system the
  model has (``None`` for a kind it lacks).

Fields are read and replaced by their names, whatever group they sit in:
``params.kinematic_viscosity``, ``params.replace(young_modulus=2e6)``.  Concrete values are
checked where they are set (positive densities and sound speed, non-negative viscosities,
a Poisson's ratio in (-1, 0.5), finite numbers), so that bad input fails with the field
named rather than as an unstable run.

Parameters act or are refused.  A system and its choice objects say which fields they
read (``parameters``); the Params of a :class:`~sphjax.Case` carry the fields its model
does not read as static metadata (:attr:`Params.unused`), and ``replace`` refuses to set
one, concrete value or tracer alike, with one line that names the field, the system and
the choice that would read it (:class:`UnusedParameterError`).  So a run never silently
ignores a value, and differentiating with respect to one field the model does not read
(through ``replace``) fails with that line.

Differentiating with respect to the whole Params pytree (``jax.grad(loss)(params)``) gives a
Params of gradients in which the fields the model does not read are exactly 0: their
leaves are in the pytree (so that one tree structure serves every model) but no equation
reads them.  The gradient carries the same :attr:`Params.unused` as the Params it was
taken at, so :attr:`Params.used` names the fields that mean something and
``grads.items(used_only=True)`` gives only their gradients.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from sphjax._host import device_array
from sphjax._text import show
from sphjax.core.pytree import pytree_dataclass

Array = jax.Array


class UnusedParameterError(ValueError):
    """A Params field was set that the model does not read (its message says which
    choice would read it)."""


@pytree_dataclass
class FluidParams:
    """Parameters of a weakly compressible fluid.

    Attributes:
      reference_density: rest density ``rho0`` (eq. 12).
      sound_speed: artificial sound speed ``c0`` (eq. 12).
      artificial_alpha: Monaghan artificial viscosity ``alpha`` (``Pi_ab`` in eq. 10).
      artificial_beta: Monaghan ``beta`` (quadratic term).
      kinematic_viscosity: physical kinematic viscosity ``nu`` (Morris et al. 1997).
      background_pressure: ``p_background`` subtracted in eq. 12.
      transport_pressure: added to the transport-velocity background pressure
        ``p_b = TransportVelocity.pressure_factor * rho0 c0^2 + transport_pressure``
        (Adami, Hu & Adams 2013); 0 by default, so ``p_b = rho0 c0^2``.
      reference_pressure: ``p0`` added in eq. 12.
      density_diffusion: delta-SPH coefficient ``delta``.
    """

    reference_density: Array
    sound_speed: Array
    artificial_alpha: Array
    artificial_beta: Array
    kinematic_viscosity: Array
    background_pressure: Array
    transport_pressure: Array
    reference_pressure: Array
    density_diffusion: Array


@pytree_dataclass
class SolidParams:
    """Parameters of the bodies: a total-Lagrangian elastic solid, a rigid body and its
    contact with the walls.

    Attributes:
      young_modulus: Young's modulus ``E`` (eq. 19).
      poisson_ratio: Poisson's ratio ``nu`` (eq. 19).
      solid_density: reference density ``rho0`` (eq. 14); a rigid body's density.
      penalty_alpha: hourglass penalty coefficient (eq. 14, Ganzenmüller 2015).
      contact_frequency: a rigid body's wall contact (:class:`~sphjax.WallContact`):
        ``omega`` in rad/s, the stiffness per unit mass of a body particle's spring,
        ``k = m omega^2`` (> 0).
      contact_damping_ratio: the contact dashpots' fraction ``zeta`` of critical damping
        (>= 0; 1: a particle on its spring comes to rest without bouncing).
      contact_friction: the Coulomb coefficient ``mu`` that caps the contact's tangential
        dashpot (>= 0; 0: the body slides freely).
    """

    young_modulus: Array
    poisson_ratio: Array
    solid_density: Array
    penalty_alpha: Array
    contact_frequency: Array
    contact_damping_ratio: Array
    contact_friction: Array


FLUID_DEFAULTS = dict(
    reference_density=1000.0,
    sound_speed=10.0,
    artificial_alpha=0.0,
    artificial_beta=0.0,
    kinematic_viscosity=0.0,
    background_pressure=0.0,
    transport_pressure=0.0,
    reference_pressure=0.0,
    density_diffusion=0.1,
)
SOLID_DEFAULTS = dict(
    young_modulus=1.0e6,
    poisson_ratio=0.3,
    solid_density=1000.0,
    penalty_alpha=0.0,
    # a rigid body's wall contact (sphjax.cases.sinking_body sets a frequency for its body)
    contact_frequency=800.0,
    contact_damping_ratio=1.0,
    contact_friction=0.5,
)
#: the fields of a rigid body's wall contact (read only by a RigidSystem with wall_contact)
CONTACT_FIELDS = ("contact_frequency", "contact_damping_ratio", "contact_friction")
GROUPS = {"fluid": FLUID_DEFAULTS, "solid": SOLID_DEFAULTS}

# field -> (test, what the value must be)
_POSITIVE = (lambda v: v > 0, "a positive number")
_NON_NEGATIVE = (lambda v: v >= 0, "a non-negative number")
_FINITE = (lambda v: True, "a finite number")
RULES = dict(
    reference_density=_POSITIVE,
    sound_speed=_POSITIVE,
    artificial_alpha=_NON_NEGATIVE,
    artificial_beta=_NON_NEGATIVE,
    kinematic_viscosity=_NON_NEGATIVE,
    background_pressure=_FINITE,
    transport_pressure=_NON_NEGATIVE,
    reference_pressure=_FINITE,
    density_diffusion=_NON_NEGATIVE,
    young_modulus=_POSITIVE,
    poisson_ratio=(lambda v: -1.0 < v < 0.5, "a number in (-1, 0.5)"),
    solid_density=_POSITIVE,
    penalty_alpha=_NON_NEGATIVE,
    contact_frequency=_POSITIVE,
    contact_damping_ratio=_NON_NEGATIVE,
    contact_friction=_NON_NEGATIVE,
)


def check_value(name: str, value):
    """Raise a ValueError naming ``name`` if a concrete ``value`` is not valid for it."""
    if isinstance(value, jax.core.Tracer):
        return
    test, what = RULES.get(name, _FINITE) if name != "gravity" else _FINITE
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"Params.{name} must be {what}, got {show(value)}") from None
    if not np.all(np.isfinite(array)):
        raise ValueError(f"Params.{name} must be {what}, got {show(value)}")
    if array.ndim == 0 and not test(float(array)):
        raise ValueError(f"Params.{name} must be {what}, got {show(value)}")


def _group_of(name: str) -> str | None:
    for group, fields in GROUPS.items():
        if name in fields:
            return group
    return None


@pytree_dataclass(static=("unused",))
class Params:
    """Differentiable parameters of a simulation (a pytree).

    Attributes:
      gravity: ``[d]`` body acceleration ``g`` (eqs. 10, 14), or a driving body force per
        unit mass.
      fluid: :class:`FluidParams`, or ``None`` when the model has no fluid.
      solid: :class:`SolidParams`, or ``None`` when the model has no solid.
      unused: static metadata, not a leaf: ``(field, reason)`` for every field the model
        does not read (set by :meth:`for_model`; a :class:`~sphjax.Case` sets it for its
        model), ``reason`` the one-line refusal :meth:`replace` raises.  ``()`` (as
        :func:`make_params` builds them): every field may be set.
    """

    gravity: Array
    fluid: FluidParams | None = None
    solid: SolidParams | None = None
    unused: tuple[tuple[str, str], ...] = ()

    def __getattr__(self, name):
        group = _group_of(name)
        if group is None or name.startswith("_"):
            raise AttributeError(f"Params has no field {name!r}; fields: {', '.join(fields())}")
        values = object.__getattribute__(self, group)
        if values is None:
            raise AttributeError(
                f"Params.{name} belongs to the {group} parameters, which this model lacks"
            )
        return getattr(values, name)

    def for_model(self, model) -> Params:
        """These Params as ``model`` reads them: the fields none of its systems read become
        :attr:`unused`, which :meth:`replace` refuses (see ``Model.unused_parameters``)."""
        present = {name for name, _ in self.items()}
        unused = tuple(item for item in model.unused_parameters() if item[0] in present)
        return self if unused == self.unused else dataclasses.replace(self, unused=unused)

    def check_used(self, name: str) -> None:
        """Raise :class:`UnusedParameterError` (one line: the field, the system, the choice
        that would read it) if the model these Params were built for does not read ``name``."""
        reason = dict(self.unused).get(name)
        if reason is not None:
            raise UnusedParameterError(reason)

    def replace(self, **changes) -> Params:
        """A new Params with the named fields replaced (in whichever group they live).

        Raises :class:`UnusedParameterError` for a field the model does not read
        (:attr:`unused`), whether the value is concrete or a tracer.
        """
        dtype = self.gravity.dtype
        grouped: dict[str, dict] = {}
        top = {}
        for name in changes:
            self.check_used(name)
        for name, value in changes.items():
            check_value(name, value)
            if name == "gravity":
                value = jnp.asarray(value, dtype)
                if value.shape != self.gravity.shape:
                    raise ValueError(
                        f"Params.gravity must have shape {self.gravity.shape}, got {value.shape}"
                    )
                top[name] = value
                continue
            if name in ("fluid", "solid", "unused"):
                top[name] = value
                continue
            group = _group_of(name)
            if group is None:
                raise ValueError(
                    f"Params has no field {name!r}; valid fields: {', '.join(fields())}"
                )
            if object.__getattribute__(self, group) is None:
                raise ValueError(
                    f"Params.{name} belongs to the {group} parameters, which this model lacks"
                )
            grouped.setdefault(group, {})[name] = _as_float(value, dtype)
        for group, values in grouped.items():
            top[group] = dataclasses.replace(object.__getattribute__(self, group), **values)
        return dataclasses.replace(self, **top)

    @property
    def used(self) -> tuple[str, ...]:
        """The names of the fields the model reads, in field order: those not in
        :attr:`unused` (every field present for Params built without a model, by
        :func:`make_params`).  A gradient taken with respect to the whole Params is
        meaningful for these fields only; the others' gradients are exactly 0."""
        return tuple(name for name, _ in self.items(used_only=True))

    def items(self, used_only: bool = False):
        """``(name, value)`` of every field, flat (gravity first); with ``used_only``, of
        the fields the model reads (those not in :attr:`unused`)."""
        skip = {name for name, _ in self.unused} if used_only else set()
        out = [("gravity", self.gravity)]
        for group in GROUPS:
            values = object.__getattribute__(self, group)
            if values is not None:
                out += [(f.name, getattr(values, f.name)) for f in dataclasses.fields(values)]
        return [(name, value) for name, value in out if name not in skip]


def fields() -> list[str]:
    """Every Params field name."""
    return ["gravity", *FLUID_DEFAULTS, *SOLID_DEFAULTS]


def fields_read(choices, own=(), group: str = "fluid") -> frozenset[str]:
    """The Params fields a system reads: its ``own`` and each choice object's
    ``parameters``; a choice that does not say (a user's own) counts as reading every field
    of the system's ``group``, so that nothing it might read is refused."""
    read = set(own)
    for choice in choices:
        if choice is None:
            continue
        names = getattr(choice, "parameters", None)
        read |= set(GROUPS[group]) if names is None else set(names)
    return frozenset(read)


def refusal(name: str, system: str, why: str, fix: str) -> str:
    """The one-line refusal of setting ``name``: ``"kinematic_viscosity is not used by this
    fluid (artificial viscosity only): add MorrisViscosity() to its viscosity to use it"``."""
    return f"{name} is not used by this {system} ({why}): {fix} to use it"


def _as_float(value, dtype):
    if isinstance(value, jax.core.Tracer):
        return value
    return device_array(value, dtype)


def make_params(dim: int, *, gravity=None, fluid=None, solid=None, **values) -> Params:
    """Params with defaults for the groups a model needs.

    Args:
      dim: spatial dimension (the length of ``gravity``).
      gravity: ``[dim]`` body acceleration (default zero).
      fluid, solid: include that group (``True``/``False``); by default a group is
        included when one of its fields is given, and both when none is.
      **values: field values by name (see :class:`FluidParams`, :class:`SolidParams`).
    """
    dtype = jnp.result_type(float)
    unknown = sorted(set(values) - set(fields()))
    if unknown:
        raise ValueError(
            f"make_params: unknown field(s) {', '.join(unknown)}; valid fields: "
            f"{', '.join(fields())}"
        )
    for name, value in values.items():
        check_value(name, value)
    wanted = {"fluid": fluid, "solid": solid}
    given = {group: any(k in d for k in values) for group, d in GROUPS.items()}
    if not any(given.values()):
        given = {group: True for group in GROUPS}
    groups = {}
    for group, defaults in GROUPS.items():
        include = given[group] if wanted[group] is None else wanted[group]
        if not include:
            if any(k in defaults for k in values):
                raise ValueError(f"make_params: {group} fields given with {group}=False")
            groups[group] = None
            continue
        merged = {k: _as_float(values.get(k, v), dtype) for k, v in defaults.items()}
        groups[group] = (FluidParams if group == "fluid" else SolidParams)(**merged)
    gravity = device_array(np.zeros(dim) if gravity is None else gravity, dtype)
    check_value("gravity", gravity)
    if gravity.shape != (dim,):
        raise ValueError(f"Params.gravity must have shape ({dim},), got {gravity.shape}")
    return Params(gravity=gravity, **groups)
