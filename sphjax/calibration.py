"""Calibrate Params against observations by gradient descent through a simulation.

The loop accepts any optax optimiser (``optax.adam(0.05)``, ``optax.lbfgs()``, a
``optax.chain`` of your own); it does not wrap one.  What it adds:

* a loss: the mean squared misfit between simulated observables and observed data,
  normalised by the mean square of the data (so 1e-4 means a 1 % RMS misfit);
* a parameterisation: each fitted Params field is optimised as ``log(value)``
  (``"log"``, the default: keeps E, nu, viscosities positive and makes steps relative),
  as itself (``"identity"``), or for a bounded field as ``logit`` of its position in an
  interval ``(lo, hi)`` (e.g. ``(0.0, 0.5)`` for Poisson's ratio);
* a progress line per iteration and a history of loss, gradient norm and parameters.

    result = calibrate(
        lambda p: observe(simulate(case, p, ...)),      # Params -> observables
        observed, case.params, {"kinematic_viscosity": 0.03},
        optax.adam(0.1), n_iterations=60,
    )
    result.values["kinematic_viscosity"], result.history["loss"]

The loss and its gradient are compiled once, and so is the optimiser's update; the
observations are an argument of both programs, not a constant in them, so a second fit to
other data (another noise draw) finds them in the persistent compilation cache.
``mode="reverse"`` takes the gradient with ``jax.value_and_grad`` (one forward and one
reverse pass, whatever the number of fitted fields); ``mode="forward"`` with one
forward-mode tangent per fitted field (``jax.jvp``, vmapped): nothing is stored along the
simulation and, for one or two fields, it is the cheaper of the two
(``docs/performance_gradients.md``).  ``"auto"`` (the default) picks forward mode for at
most two fields.  The mode holds for every gradient of the fit: an optimiser with a line
search (``optax.lbfgs()``) differentiates the loss it is given, whose reverse-mode
derivative is then the forward-mode one (:func:`with_forward_mode_gradient`), and the
loss and gradient the line search leaves in its state are used for the next iteration
instead of being computed again.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping

import jax
import jax.numpy as jnp
import optax
from jax.flatten_util import ravel_pytree

from sphjax.core.params import Params
from sphjax.integration.simulate import failures_as_nan

TRANSFORMS = {
    "log": (jnp.log, jnp.exp),
    "identity": (lambda x: x, lambda x: x),
}


def _interval(lo, hi):
    """``x in (lo, hi)`` optimised as ``logit((x - lo) / (hi - lo))``."""

    def forward(x):
        s = (x - lo) / (hi - lo)
        return jnp.log(s) - jnp.log1p(-s)

    def backward(theta):
        return lo + (hi - lo) * jax.nn.sigmoid(theta)

    return forward, backward


@dataclasses.dataclass
class CalibrationResult:
    """Outcome of :func:`calibrate`.

    Attributes:
      params: the calibrated Params (``base_params`` with the fitted fields replaced).
      values: the fitted values by field name (Python floats).
      history: ``"loss"``, ``"grad_norm"`` and one list per fitted field, one entry per
        iteration, evaluated *before* that iteration's update; the final values are
        appended at the end of each parameter list (so those lists are one longer).
      iterations: number of updates performed.
    """

    params: Params
    values: dict[str, float]
    history: dict[str, list[float]]
    iterations: int


def relative_misfit(simulated, observed, weights=None):
    """``mean(w (s - o)^2) / mean(w o^2)`` over all entries (pytrees allowed)."""
    sim, obs = jax.tree_util.tree_leaves(simulated), jax.tree_util.tree_leaves(observed)
    ws = [None] * len(sim) if weights is None else jax.tree_util.tree_leaves(weights)
    num = den = 0.0
    for s, o, w in zip(sim, obs, ws, strict=True):
        w = 1.0 if w is None else w
        num = num + jnp.mean(w * (s - o) ** 2)
        den = den + jnp.mean(w * o**2)
    return num / den


MODES = ("auto", "forward", "reverse")
FORWARD_MODE_MAX_FIELDS = 2


def forward_value_and_grad(fn):
    """``fn(theta) -> (value, gradient)`` by forward mode: one ``jax.jvp`` tangent per
    entry of ``theta`` (a pytree of arrays), vmapped, so the primal runs once and nothing
    is stored for a reverse pass.  Same result as ``jax.value_and_grad(fn)``."""

    def value_and_grad(theta):
        flat, unravel = ravel_pytree(theta)

        def along(tangent):
            return jax.jvp(lambda x: fn(unravel(x)), (flat,), (tangent,))

        value, slopes = jax.vmap(along, out_axes=(None, 0))(jnp.eye(flat.size, dtype=flat.dtype))
        return value, unravel(slopes)

    return value_and_grad


def with_forward_mode_gradient(fn):
    """``fn(theta, data) -> scalar`` whose reverse-mode derivative in ``theta`` is taken
    by forward mode (:func:`forward_value_and_grad`, one tangent per entry) and kept as
    the residual: ``jax.grad`` of the result, wherever it is called (an optimiser's line
    search included), runs no reverse pass through the simulation.  First derivatives
    only; ``data`` (the observations) gets no gradient."""

    @jax.custom_vjp
    def wrapped(theta, data):
        return fn(theta, data)

    def value_and_residual(theta, data):
        value, grad = forward_value_and_grad(lambda t: fn(t, data))(theta)
        return value, (grad, data)

    def pullback(residual, cotangent):
        grad, data = residual
        return jax.tree.map(lambda g: cotangent * g, grad), jax.tree.map(jnp.zeros_like, data)

    wrapped.defvjp(value_and_residual, pullback)
    return wrapped


def _strongly_typed(tree):
    """The same pytree with no weakly typed leaves.  Optimiser states start with weakly
    typed scalars (``optax.lbfgs``' line-search counters) that come back strongly typed
    from the first update: without this the jitted update is compiled a second time."""
    return jax.tree.map(lambda x: jnp.asarray(x, dtype=jnp.result_type(x)), tree)


def _stored_value_and_grad(state):
    """``(value, grad)`` that a line search (``optax.lbfgs``) left in the optimiser state
    for the parameters it moved to, or ``None`` before its first update / without one."""
    value = optax.tree_utils.tree_get(state, "value", default=None)
    grad = optax.tree_utils.tree_get(state, "grad", default=None)
    if value is None or grad is None or not math.isfinite(float(value)):
        return None
    return value, grad


def calibrate(
    observables: Callable[[Params], jax.Array],
    observed,
    base_params: Params,
    initial: Mapping[str, float],
    optimizer: optax.GradientTransformation,
    n_iterations: int = 100,
    *,
    transform: str | tuple | Mapping[str, str | tuple] = "log",
    weights=None,
    loss_tolerance: float | None = None,
    step_tolerance: float | None = None,
    mode: str = "auto",
    verbose: bool = True,
    print_fn: Callable[[str], None] = print,
) -> CalibrationResult:
    """Fit the Params fields named in ``initial`` so that ``observables(params)`` matches
    ``observed``.

    Args:
      observables: ``Params -> observables`` (an array or pytree), typically a
        :func:`sphjax.simulate` run reduced to probes (kinetic energy series, tip
        displacement series, ...).  Must be differentiable (traced Params).
      observed: data of the same structure.
      base_params: Params for every field that is not fitted.
      initial: ``{field: starting value}``; the fields to fit.
      optimizer: any optax ``GradientTransformation``.  Optimisers that take extra
        arguments (``optax.lbfgs`` line search) receive ``value``, ``grad`` and
        ``value_fn``.
      n_iterations: maximum number of updates.
      transform: ``"log"`` (default), ``"identity"`` or an interval ``(lo, hi)``, or a
        mapping per field.
      weights: optional per-entry weights for :func:`relative_misfit`.
      loss_tolerance: stop once the loss is below this.
      step_tolerance: stop once every fitted value changes by less than this
        relative amount in one update.
      mode: how every gradient of the fit is taken (the optimiser's line search
        included): ``"reverse"`` (``jax.value_and_grad``), ``"forward"`` (one
        ``jax.jvp`` tangent per field) or ``"auto"``: forward for at most two fields,
        reverse otherwise.
      verbose: print one line per iteration.
    Returns:
      :class:`CalibrationResult`.
    """
    names = tuple(initial)
    if not names:
        raise ValueError("initial: give at least one Params field to fit")
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    if mode == "auto":
        mode = "forward" if len(names) <= FORWARD_MODE_MAX_FIELDS else "reverse"
    fields = {name for name, _ in base_params.items()}
    for name in names:
        if name not in fields:
            used = sorted(name for name, _ in base_params.items(used_only=True))
            raise ValueError(f"initial: {name!r} is not a Params field; choose from {used}")
        base_params.check_used(name)  # a field the model does not read cannot be fitted
    if isinstance(transform, str):
        transform = dict.fromkeys(names, transform)
    pairs = {}
    for name in names:
        kind = transform.get(name, "log")
        if isinstance(kind, tuple):
            lo, hi = (float(b) for b in kind)
            if not lo < float(initial[name]) < hi:
                raise ValueError(
                    f"initial[{name!r}] = {initial[name]} must lie inside its interval {kind}"
                )
            pairs[name] = _interval(lo, hi)
            continue
        if kind not in TRANSFORMS:
            raise ValueError(
                f"transform[{name!r}] must be one of {sorted(TRANSFORMS)} or an interval (lo, hi)"
            )
        pairs[name] = TRANSFORMS[kind]
        if kind == "log" and not float(initial[name]) > 0:
            raise ValueError(
                f"initial[{name!r}] = {initial[name]} must be positive for the log "
                "parameterisation; pass transform={name!r: 'identity'} for signed values"
            )
    forward = {n: pairs[n][0] for n in names}
    backward = {n: pairs[n][1] for n in names}
    dtype = jnp.result_type(float)

    def to_params(theta):
        return base_params.replace(**{n: backward[n](theta[n]) for n in names})

    # The observations are an argument of the compiled programs, not a constant in them:
    # the same fit to other data (another noise draw) reuses the compiled programs.
    def loss_fn(theta, data):
        return relative_misfit(observables(to_params(theta)), data, weights)

    if mode == "forward":
        loss_fn = with_forward_mode_gradient(loss_fn)
    value_and_grad = jax.jit(jax.value_and_grad(loss_fn))
    if isinstance(optimizer, optax.GradientTransformationExtraArgs):

        @jax.jit
        def update(grad, state, theta, value, data):
            return optimizer.update(
                grad, state, theta, value=value, grad=grad, value_fn=lambda t: loss_fn(t, data)
            )

    else:

        @jax.jit
        def update(grad, state, theta, value, data):
            del value, data
            return optimizer.update(grad, state, theta)

    observed = jax.tree.map(lambda o: jnp.asarray(o, dtype), observed)
    theta = {n: forward[n](jnp.asarray(initial[n], dtype)) for n in names}
    state = _strongly_typed(optimizer.init(theta))
    history: dict[str, list[float]] = {"loss": [], "grad_norm": []}
    history.update({n: [] for n in names})

    def current(theta):
        return {n: float(backward[n](theta[n])) for n in names}

    iterations = 0
    for iteration in range(n_iterations):
        # a line search has already evaluated the loss and its gradient where it moved to;
        # the programs are traced with the runs' failures as NaN (no host callbacks), so
        # that the persistent compilation cache keeps them
        with failures_as_nan():
            value, grad = _stored_value_and_grad(state) or value_and_grad(theta, observed)
        values = current(theta)
        grad_norm = float(optax.global_norm(grad))
        if not math.isfinite(float(value)) or not math.isfinite(grad_norm):
            # run the model concretely: a failed simulation raises its SimulationError or
            # NeighborOverflowError, which says where and when
            observables(to_params(theta))
            raise FloatingPointError(
                f"calibration iteration {iteration}: loss {float(value)} / gradient norm "
                f"{grad_norm} is not finite at {values}; lower the learning rate or start "
                "closer to the data"
            )
        history["loss"].append(float(value))
        history["grad_norm"].append(grad_norm)
        for n in names:
            history[n].append(values[n])
        if verbose:
            shown = "  ".join(f"{n}={v:.6g}" for n, v in values.items())
            print_fn(
                f"iter {iteration:4d}  loss {float(value):.4e}  |grad| {grad_norm:.3e}  {shown}"
            )
        if loss_tolerance is not None and float(value) < loss_tolerance:
            break
        with failures_as_nan():
            updates, state = update(grad, state, theta, value, observed)
        theta = optax.apply_updates(theta, updates)
        iterations += 1
        if step_tolerance is not None:
            new = current(theta)
            if all(abs(new[n] - values[n]) <= step_tolerance * abs(values[n]) for n in names):
                break
    values = current(theta)
    for n in names:
        history[n].append(values[n])
    if verbose:
        shown = "  ".join(f"{n}={v:.6g}" for n, v in values.items())
        print_fn(f"final after {iterations} updates: {shown}")
    return CalibrationResult(
        params=to_params(theta), values=values, history=history, iterations=iterations
    )


__all__ = [
    "CalibrationResult",
    "calibrate",
    "forward_value_and_grad",
    "relative_misfit",
    "with_forward_mode_gradient",
]
