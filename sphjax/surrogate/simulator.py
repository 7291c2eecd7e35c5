"""The learned simulator: features, one step, rollouts, training loss and metrics.

``LearnedSimulator`` holds the static part (box, periodic axes, radius, history length,
normalisation, noise level); the trainable part is a :class:`~sphjax.surrogate.gns.GNS`
pytree.  One step maps the last ``H + 1`` positions to the next:

    v_t = x_t - x_{t-1}  (minimum image),   a_t = GNS(...) * acc_std + acc_mean,
    x_{t+1} = x_t + v_t + a_t               (semi-implicit Euler, per frame)

Training follows GNS: the input positions get random-walk noise (velocity noise summed
over the history, std ``noise_std`` at the last step), and the target acceleration is
corrected so that the predicted velocity removes the noise of the last step.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from sphjax.surrogate.data import (
    FLUID,
    PAD,
    Normalization,
    displacement,
    frame_velocities,
    wrap,
)
from sphjax.surrogate.gns import GNS
from sphjax.surrogate.graph import RadiusGraph, overflowed


@dataclasses.dataclass(frozen=True)
class SimulatorConfig:
    """Hyper-parameters of the learned simulator (saved beside the weights).

    Attributes:
      history: ``H``, number of past velocities in the node features.
      radius: connectivity radius (default: the dataset's ``default_connectivity_radius``).
      noise_std: std of the random-walk position noise at the last input frame.
      latent, hidden, message_steps: network sizes.
      capacity_multiplier: neighbour-list head room.
    """

    history: int = 5
    radius: float | None = None
    noise_std: float | None = None
    latent: int = 64
    hidden: int = 64
    message_steps: int = 5
    capacity_multiplier: float = 1.5


class LearnedSimulator:
    """Static helper around a GNS for one dataset geometry (not a pytree)."""

    def __init__(self, metadata: dict, config: SimulatorConfig | None = None):
        config = SimulatorConfig() if config is None else config
        radius = config.radius or float(metadata["default_connectivity_radius"])
        noise = config.noise_std
        if noise is None:  # a fraction of the per-frame acceleration scale
            noise = 0.5 * float(np.mean(metadata["acc_std"]))
        self.config = dataclasses.replace(config, radius=radius, noise_std=float(noise))
        self.metadata = metadata
        self.dim = int(metadata["dim"])
        self.bounds = tuple((float(lo), float(hi)) for lo, hi in metadata["bounds"])
        self.periodic = tuple(bool(p) for p in metadata["periodic_boundary_conditions"])
        self.norm = Normalization.from_metadata(metadata, self.config.noise_std)
        self.graph = RadiusGraph(self.bounds, self.periodic, radius, config.capacity_multiplier)
        self.frame_dt = float(metadata["dt"]) * float(metadata["write_every"])

    # ------------------------------------------------------------------ model

    @property
    def node_in(self) -> int:
        return self.config.history * self.dim + 2 * sum(not p for p in self.periodic)

    def init_model(self, key) -> GNS:
        c = self.config
        return GNS(
            self.node_in,
            self.dim + 1,
            self.dim,
            key,
            latent=c.latent,
            hidden=c.hidden,
            steps=c.message_steps,
        )

    def allocate(self, position, extra_capacity: int = 0):
        """Neighbour-list template for concrete ``[N, d]`` positions (outside jit)."""
        return self.graph.allocate(np.asarray(position), extra_capacity)

    def _features(self, positions, types, neighbors):
        """Node and edge features of ``[H+1, N, d]`` positions."""
        c = self.config
        x = positions[-1]
        n = x.shape[0]
        vel = frame_velocities(positions, self.bounds, self.periodic)  # [H, N, d]
        vel = (vel - self.norm.vel_mean) / self.norm.vel_std
        node = [jnp.transpose(vel, (1, 0, 2)).reshape(n, -1)]
        for axis, periodic in enumerate(self.periodic):
            if not periodic:
                lo, hi = self.bounds[axis]
                node.append(jnp.clip((x[:, axis : axis + 1] - lo) / c.radius, 0.0, 1.0))
                node.append(jnp.clip((hi - x[:, axis : axis + 1]) / c.radius, 0.0, 1.0))
        node = jnp.concatenate(node, -1)
        neighbors = self.graph.update(x, neighbors)
        idx = neighbors.idx
        senders = jnp.where(idx < n, idx, 0)
        dr = displacement(x[:, None, :], x[senders], self.bounds, self.periodic) / c.radius
        r2 = jnp.sum(dr * dr, -1, keepdims=True)
        r = jnp.sqrt(jnp.where(r2 > 0, r2, 1.0)) * (r2 > 0)
        real = types != PAD
        mask = (idx < n) & (r[..., 0] < 1.0) & real[:, None] & real[senders]
        edge = jnp.where(mask[..., None], jnp.concatenate([dr, r], -1), 0.0)
        return node, edge, senders, mask, neighbors

    def acceleration(self, model: GNS | None, positions, types, neighbors):
        """Per-frame acceleration ``[N, d]`` (``model=None``: zero, the constant-velocity
        baseline); returns ``(acc, neighbors)``."""
        if model is None:
            return jnp.zeros_like(positions[-1]), neighbors
        node, edge, senders, mask, neighbors = self._features(positions, types, neighbors)
        out = model(node, types, edge, senders, mask)
        return out * self.norm.acc_std + self.norm.acc_mean, neighbors

    def step(self, model, positions, types, neighbors):
        """Next positions ``[N, d]`` from ``[H+1, N, d]``; returns ``(x, neighbors)``."""
        acc, neighbors = self.acceleration(model, positions, types, neighbors)
        x, x_prev = positions[-1], positions[-2]
        v = displacement(x, x_prev, self.bounds, self.periodic)
        new = wrap(x + v + acc, self.bounds, self.periodic)
        return new, neighbors

    def rollout(self, model, positions, types, n_steps: int, neighbors, kinematic=None):
        """Autoregressive rollout of ``n_steps`` frames after ``[H+1, N, d]`` positions.

        Non-fluid particles follow ``kinematic`` (``[n_steps, N, d]`` ground truth) if
        given, else stay where they are.  Returns ``(frames [n_steps, N, d], overflow)``.
        """
        moving = (types == FLUID)[:, None]

        def body(carry, k):
            hist, nbrs, over = carry
            new, nbrs = self.step(model, hist, types, nbrs)
            fixed = hist[-1] if kinematic is None else kinematic[k]
            new = jnp.where(moving, new, fixed).astype(hist.dtype)
            hist = jnp.concatenate([hist[1:], new[None]], 0)
            return (hist, nbrs, over | overflowed(nbrs)), new

        carry = (positions, neighbors, jnp.asarray(False))
        (_, _, over), frames = jax.lax.scan(body, carry, jnp.arange(n_steps))
        return frames, over

    def compiled_rollout(self, n_steps: int):
        """Jitted ``(model, x0, types, kinematic, neighbors) -> (frames, overflow)``,
        compiled once per rollout length."""
        cache = self.__dict__.setdefault("_rollouts", {})
        if n_steps not in cache:

            def run(model, x0, types, kinematic, neighbors):
                return self.rollout(model, x0, types, n_steps, neighbors, kinematic=kinematic)

            cache[n_steps] = jax.jit(run)
        return cache[n_steps]

    # ------------------------------------------------------------------ training

    def noisy_inputs(self, positions, target, types, key):
        """GNS random-walk noise on ``[H+1, N, d]`` inputs and the corrected target."""
        h = positions.shape[0] - 1
        std = self.config.noise_std / np.sqrt(h)
        vel_noise = std * jax.random.normal(key, (h,) + positions.shape[1:], positions.dtype)
        pos_noise = jnp.concatenate([jnp.zeros_like(positions[:1]), jnp.cumsum(vel_noise, 0)])
        pos_noise = pos_noise * (types == FLUID)[None, :, None]
        noisy = positions + pos_noise
        return noisy, target + pos_noise[-1]

    def target_acceleration(self, positions, target):
        """Normalised per-frame acceleration that takes ``positions`` to ``target``."""
        v_last = displacement(positions[-1], positions[-2], self.bounds, self.periodic)
        v_next = displacement(target, positions[-1], self.bounds, self.periodic)
        return (v_next - v_last - self.norm.acc_mean) / self.norm.acc_std

    def loss(self, model, positions, target, types, key, neighbors, unroll: int = 0):
        """Mean squared error of normalised accelerations over fluid particles of a batch;
        returns ``(loss, overflow)``.

        ``positions`` is ``[B, H+1+unroll, N, d]``.  With ``unroll = 0`` the input history
        gets GNS random-walk noise and the target its correction (one-step training).
        With ``unroll = u > 0`` (push-forward, Brandstetter et al. 2022, as LagrangeBench):
        the noisy history is advanced ``u`` steps by the model itself under
        ``stop_gradient`` (non-fluid particles follow the ground truth), and the loss is
        the error of the next step from that predicted history against the true
        ``target``, so the model learns to correct its own drift."""
        keys = jax.random.split(key, positions.shape[0])
        h1 = positions.shape[1] - unroll
        fixed_model = jax.lax.stop_gradient(model)

        def one(x, y, t, k):
            hist, y_noisy = self.noisy_inputs(x[:h1], y, t, k)
            hist = wrap(hist, self.bounds, self.periodic)
            nbrs = neighbors
            if unroll == 0:
                y = y_noisy
            moving = (t == FLUID)[:, None]
            over = jnp.asarray(False)
            for j in range(unroll):
                new, nbrs = self.step(fixed_model, hist, t, nbrs)
                new = jax.lax.stop_gradient(jnp.where(moving, new, x[h1 + j]))
                hist = jnp.concatenate([hist[1:], new[None].astype(hist.dtype)], 0)
                over = over | overflowed(nbrs)
            node, edge, senders, mask, nbrs = self._features(hist, t, nbrs)
            pred = model(node, t, edge, senders, mask)
            err = jnp.sum((pred - self.target_acceleration(hist, y)) ** 2, -1)
            fluid = (t == FLUID).astype(err.dtype)
            return jnp.sum(err * fluid), jnp.sum(fluid), over | overflowed(nbrs)

        err, count, over = jax.vmap(one)(positions, target, types, keys)
        return jnp.sum(err) / jnp.maximum(jnp.sum(count), 1.0), jnp.any(over)

    # ------------------------------------------------------------------ saving

    def save(self, model: GNS, path, *, overwrite: bool = False) -> None:
        """Weights to ``path`` (equinox serialisation) and settings to ``path.json``.

        An existing ``path`` or ``path.json`` raises :class:`FileExistsError` (``path: '...'
        exists; pass overwrite=True to replace it, ...``) before anything is written;
        ``overwrite=True`` replaces them."""
        from sphjax._paths import check_new

        path = Path(path)
        check_new([path, path.with_suffix(path.suffix + ".json")], "path", overwrite)
        path.parent.mkdir(parents=True, exist_ok=True)
        eqx.tree_serialise_leaves(path, model)
        floats = [a.dtype for a in jax.tree_util.tree_leaves(model) if _is_float(a)]
        info = dict(
            config=dataclasses.asdict(self.config),
            metadata=self.metadata,
            dtype=str(floats[0]) if floats else "float32",
        )
        path.with_suffix(path.suffix + ".json").write_text(json.dumps(info, indent=1))

    @classmethod
    def load(cls, path) -> tuple[LearnedSimulator, GNS]:
        """Weights saved by :meth:`save`, in the float dtype they were saved with (files
        without a ``dtype`` entry: float32), whether or not x64 is enabled now."""
        path = Path(path)
        info = json.loads(path.with_suffix(path.suffix + ".json").read_text())
        sim = cls(info["metadata"], SimulatorConfig(**info["config"]))
        dtype = jnp.dtype(info.get("dtype", "float32"))
        like = jax.tree_util.tree_map(
            lambda a: a.astype(dtype) if _is_float(a) else a,
            sim.init_model(jax.random.PRNGKey(0)),
        )
        model = eqx.tree_deserialise_leaves(path, like)
        return sim, model


def _is_float(a) -> bool:
    return isinstance(a, jax.Array | np.ndarray) and jnp.issubdtype(a.dtype, jnp.floating)
