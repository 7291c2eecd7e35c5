"""Graph network simulator (Sanchez-Gonzalez et al. 2020): encode, process, decode.

Nodes are particles, edges join particles closer than the connectivity radius (minimum
image on periodic axes, :mod:`sphjax.surrogate.graph`).

* node features: the last ``H`` per-frame velocities, normalised with the dataset
  statistics; clipped distances to the walls of non-periodic axes (``/ radius``); a
  learned embedding of the particle type.
* edge features: ``(x_i - x_j) / radius`` and ``|x_i - x_j| / radius``.
* encoder: MLPs to a latent size ``L`` (LayerNorm); processor: ``M`` interaction-network
  steps with residuals, ``e_ij += f_e(e_ij, v_i, v_j)``, ``v_i += f_v(v_i, sum_j e_ij)``;
  decoder: MLP to the normalised acceleration ``[N, d]``.

Edges are kept dense, ``[N, K]`` (receiver ``i``, sender ``idx[i, k]``), so aggregation is
a masked sum over ``K``.  The model is an ``equinox.Module``: a pytree of arrays that
``jax.grad`` and optax act on directly.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

N_TYPES = 9  # LagrangeBench types -1 .. 7, shifted by one


class MLP(eqx.Module):
    """Dense layers with ReLU between them, optionally a LayerNorm on the output."""

    weights: list
    biases: list
    norm_scale: jax.Array | None
    norm_offset: jax.Array | None

    def __init__(self, sizes, key, layer_norm: bool = True):
        keys = jax.random.split(key, len(sizes) - 1)
        self.weights = [
            jax.random.normal(k, (a, b)) * np.sqrt(2.0 / a)
            for k, a, b in zip(keys, sizes[:-1], sizes[1:], strict=True)
        ]
        self.biases = [jnp.zeros(b) for b in sizes[1:]]
        self.norm_scale = jnp.ones(sizes[-1]) if layer_norm else None
        self.norm_offset = jnp.zeros(sizes[-1]) if layer_norm else None

    def __call__(self, x):
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            x = x @ w + b
            if i < len(self.weights) - 1:
                x = jax.nn.relu(x)
        if self.norm_scale is not None:
            mean = x.mean(-1, keepdims=True)
            var = ((x - mean) ** 2).mean(-1, keepdims=True)
            x = (x - mean) * jax.lax.rsqrt(var + 1e-5) * self.norm_scale + self.norm_offset
        return x


class GNS(eqx.Module):
    """Encode-process-decode graph network; call with features, returns ``[N, d]``."""

    type_embedding: jax.Array
    node_encoder: MLP
    edge_encoder: MLP
    edge_mlps: list
    node_mlps: list
    decoder: MLP

    def __init__(
        self,
        node_in: int,
        edge_in: int,
        dim: int,
        key,
        latent: int = 64,
        hidden: int = 64,
        steps: int = 5,
        embedding: int = 8,
    ):
        keys = jax.random.split(key, 4 + 2 * steps)
        self.type_embedding = 0.1 * jax.random.normal(keys[0], (N_TYPES, embedding))
        self.node_encoder = MLP([node_in + embedding, hidden, latent], keys[1])
        self.edge_encoder = MLP([edge_in, hidden, latent], keys[2])
        self.edge_mlps = [MLP([3 * latent, hidden, latent], keys[4 + i]) for i in range(steps)]
        self.node_mlps = [
            MLP([2 * latent, hidden, latent], keys[4 + steps + i]) for i in range(steps)
        ]
        self.decoder = MLP([latent, hidden, dim], keys[3], layer_norm=False)

    def __call__(self, node_features, types, edge_features, senders, edge_mask):
        """
        Args:
          node_features: ``[N, F]``; types: ``[N]`` int (LagrangeBench types).
          edge_features: ``[N, K, G]``; senders: ``[N, K]`` int in ``[0, N)``;
          edge_mask: ``[N, K]`` bool, True for a real edge.
        Returns:
          ``[N, d]`` normalised accelerations.
        """
        emb = self.type_embedding[types + 1]
        v = self.node_encoder(jnp.concatenate([node_features, emb], -1))
        e = self.edge_encoder(edge_features)
        mask = edge_mask[..., None].astype(v.dtype)
        for f_e, f_v in zip(self.edge_mlps, self.node_mlps, strict=True):
            vi = jnp.broadcast_to(v[:, None, :], e.shape)
            e = e + f_e(jnp.concatenate([e, vi, v[senders]], -1))
            v = v + f_v(jnp.concatenate([v, jnp.sum(e * mask, axis=1)], -1))
        return self.decoder(v)
