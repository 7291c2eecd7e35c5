"""Per-trajectory initial conditions of an ensemble: seeded perturbations and Params.

Trajectory ``i`` of split ``S`` draws everything random from one generator seeded with
``(seed, S, i)`` (:func:`trajectory_rng`), in this order: the case's own ``seed`` argument
(if its factory has one and :attr:`Perturbation.case_seed` is set; for Taylor-Green it
is the seed of the disordered start), the scale of the case's velocity field, the random
Fourier field, the particle jitter, then the varied Params.  A trajectory therefore does
not depend on batching, devices or resuming, and ``--seed`` changes all of it.
"""

from __future__ import annotations

import dataclasses
import inspect
import itertools
from collections.abc import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from sphjax import cases as cases_module
from sphjax.core.case import Case
from sphjax.core.params import Params, check_value
from sphjax.core.state import Kind, State

SPLITS = ("train", "valid", "test")


@dataclasses.dataclass(frozen=True)
class Perturbation:
    """Seeded random change of a case's initial state (fluid particles only).

    ``v = s v_case + v_random`` with ``s`` uniform in ``amplitude`` and ``v_random`` a
    divergence-free field (2D: from a random stream function ``psi``; 3D: the curl of a
    random vector potential) built of Fourier modes with wavenumbers up to ``modes``
    (periodic axes: ``cos(2 pi k x / L + phase)``; closed axes: ``sin(pi k x / L)``, so
    no flow crosses the walls), scaled so its largest speed is ``fourier`` times the
    largest speed of the case (or 1 if at rest).

    Attributes:
      amplitude: ``(lo, hi)`` range of the scale ``s`` of the case velocity field.
      fourier: relative size of the random field (0 switches it off).
      modes: largest wavenumber of the random field.
      case_seed: rebuild the case per trajectory with its own ``seed`` argument drawn
        from the trajectory's generator (cases whose factory takes ``seed``, e.g. the
        Taylor-Green disordered start); otherwise every trajectory starts from the
        positions of the given case.
      jitter: largest random displacement of fluid particles, per axis, in units of the
        case's ``dx`` (uniform in ``[-jitter, jitter]``; wrapped on periodic axes).
    """

    amplitude: tuple[float, float] = (1.0, 1.0)
    fourier: float = 0.0
    modes: int = 2
    case_seed: bool = True
    jitter: float = 0.0

    def __post_init__(self):
        lo, hi = self.amplitude
        if not 0 <= lo <= hi:
            raise ValueError(f"Perturbation.amplitude must satisfy 0 <= lo <= hi, got {lo, hi}")
        if self.fourier < 0:
            raise ValueError(f"Perturbation.fourier must be >= 0, got {self.fourier}")
        if self.modes < 1:
            raise ValueError(f"Perturbation.modes must be >= 1, got {self.modes}")
        if not 0 <= self.jitter < 0.5:
            raise ValueError(
                f"Perturbation.jitter must lie in [0, 0.5) (units of dx), got {self.jitter}"
            )


def trajectory_rng(seed: int, split: str, index: int) -> np.random.Generator:
    """Per-trajectory generator: a trajectory does not depend on its batch."""
    return np.random.default_rng([int(seed), SPLITS.index(split), int(index)])


def _axis_factor(s, axis, k, size, periodic, rng):
    """One axis's factor of a Fourier mode and its derivative: ``cos(2 pi k s + phase)``
    on a periodic axis (a random phase drawn from ``rng``), ``sin(pi k s)`` on a closed
    one (zero on both walls)."""
    if periodic:
        phase = rng.uniform(0, 2 * np.pi)
        arg = 2 * np.pi * k * s[:, axis] + phase
        return np.cos(arg), -2 * np.pi * k / size[axis] * np.sin(arg)
    arg = np.pi * k * s[:, axis]
    return np.sin(arg), np.pi * k / size[axis] * np.cos(arg)


def _random_velocity_field_3d(x, domain, rng, modes):
    """``u = curl A``: each component ``A_c`` of the vector potential is a sum of Fourier
    modes (:func:`_axis_factor` on every axis) with amplitudes ``N(0, 1) / |k|^2``.  A
    curl is divergence-free, and ``A_c`` vanishes on the walls of every closed axis, so
    its tangential derivatives do too: no flow through a wall."""
    lower, size = np.asarray(domain.lower), np.asarray(domain.size)
    s = (x - lower) / size  # in [0, 1) per axis
    u = np.zeros_like(x)
    axes_k = [range(0, modes + 1) if p else range(1, modes + 1) for p in domain.periodic]
    for c in range(3):
        for k in itertools.product(*axes_k):
            if not any(k):
                continue
            amp = rng.normal() / sum(ki * ki for ki in k)
            f, df = zip(
                *(_axis_factor(s, a, k[a], size, domain.periodic[a], rng) for a in range(3)),
                strict=True,
            )
            # d A_c / d x_a for the two axes a != c; u_i = eps_ijc d A_c / d x_j
            i, j = (c + 1) % 3, (c + 2) % 3
            grad_j = amp * df[j] * f[i] * f[c]
            grad_i = amp * df[i] * f[j] * f[c]
            u[:, i] += grad_j
            u[:, j] -= grad_i
    return u


def random_velocity_field(position, domain, rng, modes: int = 2) -> np.ndarray:
    """Divergence-free velocity at ``position``, largest speed 1.

    In 2D ``(d psi/dy, -d psi/dx)`` of a random stream function ``psi``; in 3D the curl of
    a random vector potential (:func:`_random_velocity_field_3d`).  On periodic axes the
    modes are ``cos(2 pi k x / L + phase)``, on closed axes ``sin(pi k x / L)``, so no
    flow crosses a wall.
    """
    x = np.asarray(position, np.float64)
    if x.shape[1] == 3:
        u = _random_velocity_field_3d(x, domain, rng, modes)
        peak = np.linalg.norm(u, axis=1).max()
        return u / peak if peak > 0 else u
    lower, size = np.asarray(domain.lower), np.asarray(domain.size)
    s = (x - lower) / size  # in [0, 1) per axis
    u = np.zeros_like(x)
    axes_k = [range(0, modes + 1) if p else range(1, modes + 1) for p in domain.periodic]
    for kx in axes_k[0]:
        for ky in axes_k[1]:
            if kx == 0 and ky == 0:
                continue
            amp = rng.normal() / (kx * kx + ky * ky)
            f, df = [], []
            for axis, k in enumerate((kx, ky)):
                if domain.periodic[axis]:
                    phase = rng.uniform(0, 2 * np.pi)
                    arg = 2 * np.pi * k * s[:, axis] + phase
                    f.append(np.cos(arg))
                    df.append(-2 * np.pi * k / size[axis] * np.sin(arg))
                else:
                    arg = np.pi * k * s[:, axis]
                    f.append(np.sin(arg))
                    df.append(np.pi * k / size[axis] * np.cos(arg))
            u[:, 0] += amp * f[0] * df[1]
            u[:, 1] -= amp * df[0] * f[1]
    peak = np.linalg.norm(u, axis=1).max()
    return u / peak if peak > 0 else u


def _factory_takes_seed(case: Case, case_kwargs: Mapping) -> bool:
    factory = cases_module.CASES.get(case.name)
    if factory is None or "seed" in case_kwargs:
        return False
    return "seed" in inspect.signature(factory).parameters


def redraws_case_seed(case: Case, perturbation: Perturbation, case_kwargs: Mapping) -> bool:
    """Whether every trajectory rebuilds ``case`` with its own ``seed``
    (:attr:`Perturbation.case_seed`, a factory that takes ``seed`` and ``case_kwargs``
    that do not fix it)."""
    return perturbation.case_seed and _factory_takes_seed(case, case_kwargs)


def _same_params(a: Params, b: Params) -> bool:
    la, lb = jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)
    return len(la) == len(lb) and all(
        np.shape(x) == np.shape(y) and np.allclose(np.asarray(x), np.asarray(y))
        for x, y in zip(la, lb, strict=True)
    )


def reseeded_case(case: Case, case_kwargs: Mapping, seed: int) -> Case:
    """``case`` rebuilt by its factory from ``case_kwargs`` with ``seed=seed``.

    The rebuilt case must have the same Model, Params and particle count: otherwise
    ``case_kwargs`` do not describe how ``case`` was built (clear error).
    """
    new = cases_module.get(case.name, **dict(case_kwargs), seed=int(seed))
    if (
        new.model != case.model
        or new.n_particles != case.n_particles
        or not _same_params(new.params, case.params)
    ):
        raise ValueError(
            f"case_kwargs={dict(case_kwargs)} do not rebuild the given {case.name} case; pass "
            "the keyword arguments it was built with (--case-arg), or "
            "Perturbation(case_seed=False) to start every trajectory from its positions"
        )
    return new


def perturb_state(
    case: Case, perturbation: Perturbation, rng: np.random.Generator, state: State | None = None
) -> State:
    """``state`` (default: the case's initial state) changed by ``perturbation``."""
    state = case.state if state is None else state
    velocity = np.asarray(state.velocity, np.float64)
    fluid = np.asarray(state.kind) == Kind.FLUID
    scale = rng.uniform(*perturbation.amplitude)
    new = velocity.copy()
    new[fluid] = scale * velocity[fluid]
    if perturbation.fourier > 0:
        speed = np.linalg.norm(velocity[fluid], axis=1).max(initial=0.0)
        speed = speed if speed > 0 else 1.0
        field = random_velocity_field(
            np.asarray(state.position), case.model.domain, rng, perturbation.modes
        )
        new[fluid] += perturbation.fourier * speed * field[fluid]
    state = state.replace(velocity=jnp.asarray(new, state.velocity.dtype))
    if perturbation.jitter > 0:
        domain = case.model.domain
        dx = float(case.info.get("dx", case.model.smoothing_length))
        x = np.asarray(state.position, np.float64)
        shift = perturbation.jitter * dx * rng.uniform(-1.0, 1.0, x.shape)
        x = x + shift * fluid[:, None]
        lower, size = np.asarray(domain.lower), np.asarray(domain.size)
        x = np.where(np.asarray(domain.periodic), lower + np.mod(x - lower, size), x)
        state = state.replace(position=jnp.asarray(x, state.position.dtype))
    return state


def speed_bound(case: Case, perturbation: Perturbation) -> float:
    """The largest fluid speed :func:`perturb_state` can give the case's initial state.

    ``|s v + f U w| <= a_hi U + f U'`` for every draw: ``s <= a_hi`` (the top of
    ``perturbation.amplitude``), ``|v| <= U`` (``U`` the case's peak fluid speed), and the
    random field ``w`` has peak norm 1 and is scaled by ``f U'`` (``f`` =
    ``perturbation.fourier``, ``U' = U``, or 1 m/s for a case at rest).  Jitter moves
    particles and leaves velocities alone.
    """
    state = case.state
    fluid = np.asarray(state.kind) == Kind.FLUID
    peak = float(np.linalg.norm(np.asarray(state.velocity)[fluid], axis=1).max(initial=0.0))
    return perturbation.amplitude[1] * peak + perturbation.fourier * (peak if peak > 0 else 1.0)


def sample_params(
    params: Params, vary: Mapping[str, tuple[float, float]], rng: np.random.Generator
) -> Params:
    """``params`` with each field named in ``vary`` drawn uniformly from ``(lo, hi)``."""
    changes = {}
    for name in sorted(vary):
        lo, hi = vary[name]
        changes[name] = jnp.asarray(rng.uniform(lo, hi), getattr(params, name).dtype)
    return params.replace(**changes)


def check_vary(params: Params, vary: Mapping[str, tuple[float, float]]) -> dict:
    """Validate ``vary``: scalar Params fields the model reads, with ``lo <= hi`` and both
    ends valid values of the field (:func:`~sphjax.core.params.check_value`: the ends are
    what :func:`~sphjax.dataset.generate.ensemble_time_step` evaluates, and every draw lies
    between them)."""
    scalar = [name for name, value in params.items() if np.ndim(value) == 0]
    used = [name for name, value in params.items(used_only=True) if np.ndim(value) == 0]
    out = {}
    for name, rng in vary.items():
        if name not in scalar:
            raise ValueError(
                f"vary: {name!r} is not a scalar Params field; choose from {', '.join(used)}"
            )
        params.check_used(name)
        lo, hi = (float(v) for v in rng)
        if not lo <= hi:
            raise ValueError(f"vary: {name}={lo:g}:{hi:g} needs lo <= hi")
        for end in (lo, hi):
            try:
                check_value(name, end)
            except ValueError as error:
                raise ValueError(
                    f"vary: {name}={lo:g}:{hi:g}: {error}; give a range of valid values"
                ) from None
        out[name] = (lo, hi)
    return out


def initial_conditions(
    case: Case,
    counts,
    perturbation: Perturbation,
    vary: Mapping[str, tuple[float, float]],
    seed: int,
    case_kwargs: Mapping,
) -> list[tuple[str, int, State, Params]]:
    """``(split, index, state, params)`` of every trajectory of the ensemble."""
    reseed = redraws_case_seed(case, perturbation, case_kwargs)
    jobs = []
    for split, n in zip(SPLITS, counts, strict=True):
        for i in range(n):
            rng = trajectory_rng(seed, split, i)
            base = case
            if reseed:
                base = reseeded_case(case, case_kwargs, int(rng.integers(0, 2**31 - 1)))
            state = perturb_state(case, perturbation, rng, state=base.state)
            params = sample_params(case.params, vary, rng)
            jobs.append((split, i, state, params))
    return jobs
