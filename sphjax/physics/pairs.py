"""Pair sums: the one combinator every SPH term goes through, and its adjoint.

Every pairwise term of the formulation is a sum over the neighbours ``b`` of a particle
``a`` of a per-pair function of the pair geometry and the two particles' fields:

    out_a = sum_{b in N(a)} f(pair_ab, a, b)

:func:`pair_sum` evaluates it over a dense neighbour list ``[N_a, K]`` (the spirit of
``jax_md.smap.pair_neighbor_list``): it gathers the neighbours' fields, computes the
:class:`PairGeometry` (``r_ab``, ``|r_ab|``, ``W_ab``, ``grad_a W_ab``), calls ``f`` and sums
over the real neighbours inside the support.  ``f`` is written once, per pair; fields of
``a`` arrive with a neighbour axis of length one (``[B, 1, ...]``), those of ``b`` with
``[B, K, ...]``, so ``f`` reads like the equation.

**Reverse mode.**  Autodiff transposes every gather ``q[j]`` into a scatter-add and keeps a
dozen per-pair intermediates; on the CPU the reverse pass then costs about twice the
forward.  Neighbour lists here are symmetric (``b in N(a)`` iff ``a in N(b)``; for two
systems the list of ``B`` against ``A`` is the transpose of ``A`` against ``B``), so the
cotangent of particle ``k``'s fields is a sum over ``k``'s own row:

    abar_k = sum_{b in N(k)} d f(k, b)/d a_k^T obar_k            (k as the row particle)
           + sum_{b in N^T(k)} d f(b, k)/d b_k^T obar_b          (k as the neighbour)

The per-pair derivatives are ``jax.vjp`` of ``f`` itself (with the chain rule of the pair
geometry, :meth:`Geometry.pullback`, and the vector products of :mod:`sphjax.core.space`,
``dot`` and ``scale``, whose derivatives are written so that their transposes fuse),
evaluated in blocks of particles
whose per-pair arrays stay in cache, gathering only per-particle arrays: the forward is
written once and its adjoint follows from it.  Within one system both roles share one pass
and one geometry.  The adjoint is attached with :func:`sphjax._linear_call.custom_adjoint`,
which keeps forward mode (``jvp``, ``jacfwd``) autodiff's; it gives first derivatives
(``Model.pair_adjoint=False`` for second ones).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable

import jax
import jax.numpy as jnp

from sphjax._linear_call import custom_adjoint
from sphjax.core import kernels
from sphjax.core.pytree import pytree_dataclass
from sphjax.core.space import displacement_fn, dot, scale
from sphjax.neighbors.lists import PairList

tree_map = jax.tree_util.tree_map


@pytree_dataclass
class PairGeometry:
    """Geometry of the pairs of a block of rows ``a`` and their neighbours ``b``.

    Attributes:
      dr: ``[B, K, d]`` ``r_ab = r_a - r_b`` (minimum image; 0 outside the support).
      r: ``[B, K]`` ``|r_ab|`` (0 outside the support).
      w: ``[B, K]`` ``W(r_ab, h)`` (0 outside the support).
      grad_w: ``[B, K, d]`` ``grad_a W(r_ab, h)`` (0 outside the support and at ``r = 0``).
      mask: ``[B, K]`` True for a real neighbour inside the support.
    """

    dr: jax.Array
    r: jax.Array
    w: jax.Array
    grad_w: jax.Array
    mask: jax.Array

    def swapped(self) -> PairGeometry:
        """The same pairs seen from ``b``: ``r_ba = -r_ab``, ``grad_b W = -grad_a W``."""
        return dataclasses.replace(self, dr=-self.dr, grad_w=-self.grad_w)


@dataclasses.dataclass(frozen=True)
class Geometry:
    """What pair geometry needs from the Model (hashable): kernel, ``h``, ``d``, domain."""

    kernel: kernels.Kernel
    smoothing_length: float
    dim: int
    cutoff: float
    domain: object

    @classmethod
    def of(cls, model) -> Geometry:
        return cls(model.kernel, model.smoothing_length, model.dim, model.cutoff, model.domain)

    def pairs(self, x_a, x_b, valid) -> PairGeometry:
        """Pair geometry of positions ``x_a`` and ``x_b`` (broadcast to ``[B, K, d]``)."""
        dr = displacement_fn(self.domain)(x_a, x_b)
        return self.pairs_of(
            jnp.broadcast_to(dr, jnp.broadcast_shapes(x_a.shape, x_b.shape)), valid
        )

    def displacement(self, x_a, x_b):
        """``r_ab`` (minimum image), broadcast to ``[B, K, d]``."""
        dr = displacement_fn(self.domain)(x_a, x_b)
        return jnp.broadcast_to(dr, jnp.broadcast_shapes(x_a.shape, x_b.shape))

    def pairs_of(self, dr, valid) -> PairGeometry:
        """Pair geometry from the pair vectors ``r_ab`` (``[B, K, d]``)."""
        return self._pairs_and_factors(dr, valid, second=False)[0]

    def _pairs_and_factors(self, dr, valid, second: bool):
        """:meth:`pairs_of`, and with ``second`` the radial factors ``F = W'(r) / r`` and
        ``G = F'(r) / r`` that :meth:`pullback` needs (0 outside the support, at r = 0)."""
        r2 = sum(dr[..., i] * dr[..., i] for i in range(dr.shape[-1]))
        mask = valid & (r2 < self.cutoff**2)
        inside = mask & (r2 > 0)  # coincident particles: W(0), no gradient
        r = jnp.where(inside, jnp.sqrt(jnp.where(inside, r2, 1.0)), 0.0)
        dr = jnp.where(mask[..., None], dr, 0.0)
        h, dim = self.smoothing_length, self.dim
        w = jnp.where(mask, kernels.W(self.kernel, r, h, dim), 0.0)
        r_safe = jnp.where(inside, r, 1.0)
        if not second:
            # (measured: dividing here is faster in the forward than multiplying by 1 / r)
            factor = jnp.where(inside, kernels.dW_dr(self.kernel, r_safe, h, dim) / r_safe, 0.0)
            return PairGeometry(dr=dr, r=r, w=w, grad_w=factor[..., None] * dr, mask=mask), None
        # the adjoint: one division per pair; the factors below multiply by its result
        inverse_r = jnp.where(inside, 1.0 / r_safe, 0.0)
        first, curvature = jax.jvp(
            lambda r: kernels.dW_dr(self.kernel, r, h, dim), (r_safe,), (jnp.ones_like(r),)
        )
        factor = first * inverse_r
        grad_w = factor[..., None] * dr
        pair = PairGeometry(dr=dr, r=r, w=w, grad_w=grad_w, mask=mask)
        g = (curvature - factor) * inverse_r * inverse_r
        return pair, (factor, g, inverse_r)

    @staticmethod
    def pullback(pair: PairGeometry, factors, bar: PairGeometry):
        """Cotangent of ``r_ab`` from the cotangents ``bar`` of the pair geometry's fields.

        With ``F = W'(r)/r`` and ``G = F'(r)/r``: ``d r / d r_ab = r_ab / r``,
        ``d W / d r_ab = F r_ab`` and ``d (F r_ab) / d r_ab = F I + G r_ab r_ab^T`` (the
        chain rule of eq. 2, written once for every pair term).
        """
        factor, g, inverse_r = factors
        dr = pair.dr
        # a hand-written pull-back (define_pullback) gives a literal 0.0 for the fields
        # it does not read: those terms are left out, and so is the kernel's curvature G
        # when grad W has no cotangent
        radial = [
            term
            for term, field in (
                (lambda: bar.r * inverse_r, bar.r),
                (lambda: bar.w * factor, bar.w),
                (lambda: g * dot(dr, bar.grad_w), bar.grad_w),
            )
            if not _is_zero(field)
            for term in (term(),)
        ]
        out = []
        if not _is_zero(bar.dr):
            out.append(jnp.where(pair.mask[..., None], bar.dr, 0.0))
        if not _is_zero(bar.grad_w):
            out.append(factor[..., None] * bar.grad_w)
        if radial:
            out.append(sum(radial)[..., None] * dr)
        return sum(out) if out else jnp.zeros_like(dr)


def _is_zero(cotangent) -> bool:
    """A cotangent known to be zero when the program is traced (a Python ``0.0``)."""
    return isinstance(cotangent, int | float) and cotangent == 0


def stored_geometry(x, pairs: PairList, geometry: Geometry) -> PairGeometry:
    """The :class:`PairGeometry` of the list ``pairs`` within one system at positions
    ``x`` (``[n, d]``), per neighbour slot (``[n, K, ...]``): what
    :attr:`PairList.geometry` holds.  Differentiable in ``x``."""
    valid = pairs.idx < x.shape[0]
    x_b = x[jnp.where(valid, pairs.idx, 0)]
    return geometry.pairs(x[:, None], x_b, valid)


def define_pullback(summand: Callable, pullback: Callable) -> None:
    """Attach a hand-written reverse mode to the per-pair ``summand`` of a pair sum.

    ``pullback(pair, a, b, shared, bar, **keywords)`` (``keywords``: those of a
    ``functools.partial`` of ``summand``) returns, for the cotangent ``bar`` of
    ``summand(pair, a, b, shared, **keywords)`` (its output pytree, per pair), the tuple
    ``(pair_bar, a_bar, b_bar, shared_bar)``: the cotangents of the pair geometry's
    ``(dr, r, w, grad_w)`` (``0.0`` for none), dicts of per-pair cotangents of the fields of
    ``a`` and of ``b`` it reads (missing keys are zero), and one per-pair cotangent per leaf
    of ``shared``.  Build it with :class:`Cotangents`.  The adjoint of :func:`pair_sum`
    then uses it instead of ``jax.vjp`` of the summand, whose generated code keeps more
    per-pair arrays; a test must check it against ``jax.vjp``
    (``tests/test_pullbacks.py``).
    """
    summand.pullback = pullback


def transpose_by_autodiff(summand: Callable) -> Callable:
    """Mark the per-pair ``summand`` as one whose pair sum is cheaper in reverse mode with
    autodiff's transpose of the forward (which keeps the forward's per-pair residuals)
    than with the custom adjoint (which recomputes the pair geometry in blocks):
    :func:`pair_sum` then attaches no custom adjoint to it.  The choice is a measurement
    (``benchmarks/pair_costs.py``, docs/performance_gradients.md), made per summand."""
    summand.transpose_by_autodiff = True
    return summand


def _autodiff_transposes(f) -> bool:
    func = f.func if isinstance(f, functools.partial) else f
    return getattr(func, "transpose_by_autodiff", False)


def _pullback_of(f):
    """The hand-written pull-back of the summand ``f`` (a function or a
    ``functools.partial`` of one), or ``None``."""
    func = f.func if isinstance(f, functools.partial) else f
    hand = getattr(func, "pullback", None)
    if hand is None:
        return None
    return functools.partial(hand, **f.keywords) if isinstance(f, functools.partial) else hand


class Cotangents:
    """Accumulates the cotangents of a hand-written pull-back by name (see
    :func:`define_pullback`)."""

    def __init__(self):
        self._pair, self._a, self._b, self._shared = {}, {}, {}, {}

    @staticmethod
    def _add(store, items):
        for key, value in items.items():
            store[key] = value if key not in store else store[key] + value

    def pair(self, **cotangents):
        """Add cotangents of the pair geometry's ``dr``, ``r``, ``w``, ``grad_w``."""
        self._add(self._pair, cotangents)

    def a(self, **cotangents):
        """Add cotangents of the row particle's fields."""
        self._add(self._a, cotangents)

    def b(self, **cotangents):
        """Add cotangents of the neighbour's fields."""
        self._add(self._b, cotangents)

    def shared(self, key: int | str, cotangent):
        """Add the cotangent of the shared parameter ``key``: its field name where the
        shared parameters are a NamedTuple (``"sound_speed"``), else its leaf index."""
        self._add(self._shared, {key: cotangent})

    def result(self, shared):
        """``(pair, a, b, shared)`` cotangents; ``shared``: the summand's shared
        parameters (or their number), whose cotangents come out as a list of leaves."""
        pair = tuple(self._pair.get(k, 0.0) for k in ("dr", "r", "w", "grad_w"))
        names = getattr(shared, "_fields", None) or ()
        n_shared = shared if isinstance(shared, int) else len(shared)
        keys = [names[i] if i < len(names) else i for i in range(n_shared)]
        return pair, dict(self._a), dict(self._b), [self._shared.get(k, 0.0) for k in keys]


def _contract(out, bar):
    """``sum over components of out * bar`` per pair (the cotangent of a weight that
    multiplies ``out``)."""
    leaves = jax.tree_util.tree_leaves
    total = 0.0
    for o, b in zip(leaves(out), leaves(bar), strict=True):
        product = o * b
        total = total + jnp.sum(product, axis=tuple(range(2, product.ndim)))
    return total


def _field_sums(bar: dict, fields: dict, shape):
    """Per-pair cotangents ``bar`` (a subset of ``fields``' keys) summed over the
    neighbours, zeros for the fields they do not mention: a dict like ``fields``'s rows."""
    out = {}
    for key, value in fields.items():
        if key in bar:
            full = jnp.broadcast_to(bar[key], shape + value.shape[1:]).astype(value.dtype)
            out[key] = jnp.sum(full, axis=1)
        else:
            out[key] = jnp.zeros_like(value)
    return out


def _reduce_pairs(per_pair, shape):
    """Each per-pair array of ``per_pair`` (broadcast to ``[B, K, ...]``) summed over the
    neighbour axis, in one reduction over their stack: XLA then computes every per-pair
    cotangent in one loop instead of one loop (and one stored array) per output."""
    if not per_pair:  # no cotangent wanted from this sum's pairs
        return []
    full = [
        jnp.broadcast_to(q, shape + jnp.shape(q)[2:])
        if jnp.ndim(q) >= 2
        else jnp.broadcast_to(q, shape)
        for q in per_pair
    ]
    tails = [q.shape[2:] for q in full]
    flat = [q.reshape(shape + (-1,)) for q in full]
    widths = [f.shape[-1] for f in flat]
    dtype = jnp.result_type(*full)
    total = jnp.sum(jnp.concatenate([f.astype(dtype) for f in flat], axis=-1), axis=1)
    out, start = [], 0
    for width, tail in zip(widths, tails, strict=True):
        out.append(total[:, start : start + width].reshape(shape[:1] + tail))
        start += width
    return out


def _row_and_shared_sums(a_bar, dr_bar, s_bar, fields, shared, shape):
    """The per-pair cotangents of a block of rows summed in one reduction: those of the
    rows' ``fields`` (``a_bar``, plus ``dr_bar`` for ``x`` unless it is ``None``) over the
    neighbours, those of the ``shared`` leaves over the block's pairs."""
    keys = [k for k in fields if k in a_bar]
    s_leaves, s_def = jax.tree_util.tree_flatten(shared)
    s_items = [(i, b) for i, b in enumerate(s_bar) if not _is_zero(b)]
    with_dr = [] if dr_bar is None else [dr_bar]
    sums = _reduce_pairs([a_bar[k] for k in keys] + with_dr + [b for _, b in s_items], shape)
    out = {k: jnp.zeros_like(v) for k, v in fields.items()}
    for k, total in zip(keys, sums, strict=False):
        out[k] = total.astype(fields[k].dtype).reshape(fields[k].shape)
    if dr_bar is not None:
        out["x"] = out["x"] + sums[len(keys)]
    shared_sums = [jnp.zeros(jnp.shape(s), jnp.result_type(s)) for s in s_leaves]
    for (i, _), total in zip(s_items, sums[len(keys) + len(with_dr) :], strict=True):
        shared_sums[i] = jnp.sum(total, axis=0).astype(jnp.result_type(s_leaves[i]))
    return out, jax.tree_util.tree_unflatten(s_def, shared_sums)


def _shared_sums(bar, shared, shape):
    """Per-pair cotangents of the shared leaves summed over the block's pairs."""
    leaves, treedef = jax.tree_util.tree_flatten(shared)
    sums = [
        jnp.sum(jnp.broadcast_to(b, shape + jnp.shape(s)), axis=(0, 1)).astype(jnp.result_type(s))
        for b, s in zip(bar, leaves, strict=True)
    ]
    return jax.tree_util.tree_unflatten(treedef, sums)


def _split_blocks(a, n_blocks, block, pad, pad_index):
    """``[N, ...] -> [n_blocks, block, ...]``; integer (neighbour index) rows are padded
    with ``pad_index`` (no neighbours), float rows with copies of the last row, so that
    per-particle expressions (``p / rho^2``) stay finite on padding."""
    widths = [(0, pad)] + [(0, 0)] * (a.ndim - 1)
    if jnp.issubdtype(a.dtype, jnp.integer):
        a = jnp.pad(a, widths, constant_values=pad_index)
    else:
        a = jnp.pad(a, widths, mode="edge")
    return a.reshape((n_blocks, block) + a.shape[1:])


def _rowwise(fn, rows, block: int | None, pad_index: int, shared_output: bool = False):
    """``fn`` over blocks of ``block`` rows with ``lax.map``; ``rows`` a pytree of
    ``[N, ...]`` arrays, integer leaves padded with ``pad_index``.  Returns ``fn``'s pytree
    of ``[N, ...]`` arrays; with ``shared_output``, ``fn`` returns ``(per-row, shared)``
    and the shared part is summed over the blocks."""
    n = jax.tree_util.tree_leaves(rows)[0].shape[0]
    if block is None or block >= n:
        return fn(rows)
    # blocks of at most ``block`` rows, as equal as can be: 2,640 rows are two blocks of
    # 1,320, not two of 2,048 of which 1,456 are padding
    n_blocks = -(-n // block)
    block = -(-n // n_blocks)
    pad = n_blocks * block - n
    out = jax.lax.map(
        fn, tree_map(lambda a: _split_blocks(a, n_blocks, block, pad, pad_index), rows)
    )
    per_row, shared = out if shared_output else (out, None)
    per_row = tree_map(lambda a: a.reshape((n_blocks * block,) + a.shape[2:])[:n], per_row)
    if not shared_output:
        return per_row
    return per_row, tree_map(lambda a: jnp.sum(a, axis=0), shared)


def _without_mask(pair: PairGeometry):
    """The differentiable fields of ``pair`` (its mask is boolean)."""
    return (pair.dr, pair.r, pair.w, pair.grad_w)


def _with_mask(fields, mask) -> PairGeometry:
    dr, r, w, grad_w = fields
    return PairGeometry(dr=dr, r=r, w=w, grad_w=grad_w, mask=mask)


def _gather(fields, j):
    return tree_map(lambda q: q[j], fields)


def _masked(out, mask):
    return tree_map(
        lambda o: jnp.where(mask.reshape(mask.shape + (1,) * (o.ndim - mask.ndim)), o, 0.0), out
    )


def _row_view(fields):
    return tree_map(lambda q: q[:, None], fields)


def _sum_pairs(out):
    return tree_map(lambda o: jnp.sum(o, axis=1), out)


def _weighted(f, weight):
    """``f`` times the neighbour's ``weight`` field (``None``: ``f`` itself)."""
    if weight is None:
        return f

    def weighted(pair, a, b, shared):
        return _scale(f(pair, a, b, shared), b[weight])

    return weighted


def _scale(out, factor):
    def one(o):
        if o.ndim == factor.ndim + 1:
            return scale(factor, o)
        return o * factor.reshape(factor.shape + (1,) * (o.ndim - factor.ndim))

    return tree_map(one, out)


def _forward(f, geometry, block, rows, cols, shared, idx, stored=None):
    """The pair sum itself; ``stored``: the list's :attr:`PairList.geometry` (else the
    geometry is computed from the positions)."""
    n_cols = jax.tree_util.tree_leaves(cols)[0].shape[0]

    def one_block(args):
        rows_k, idx_k, stored_k = args
        valid = idx_k < n_cols
        b = _gather(cols, jnp.where(valid, idx_k, 0))
        a = _row_view(rows_k)
        pair = geometry.pairs(a["x"], b["x"], valid) if stored_k is None else stored_k
        return _sum_pairs(_masked(f(pair, a, b, shared), pair.mask))

    return _rowwise(one_block, (rows, idx, stored), block, n_cols)


def _per_pair(fields, shape):
    """Row fields ``[B, ...]`` repeated along the neighbour axis: ``[B, K, ...]``."""
    return tree_map(lambda q: jnp.broadcast_to(q[:, None], shape + q.shape[1:]), fields)


def _sum_over_pairs(tree):
    return tree_map(lambda q: jnp.sum(q, axis=1), tree)


def _adjoint_self(
    f,
    weight,
    parity,
    geometry,
    block,
    fields,
    shared,
    idx,
    obar,
    stored=None,
    stored_bar=False,
    active=None,
):
    """Cotangents of ``fields`` and ``shared`` for a sum ``w_b f(a, b)`` within one system:
    both roles of each particle ``k`` in one pass over its own row.

    Without ``parity``, ``k``'s neighbour role is ``f`` evaluated with the roles swapped,
    ``w_k f(b, k)``.  With ``f(b, a) = parity * f(a, b)`` (``-1`` for the antisymmetric
    pair forces of eqs. 10 and 14, ``+1`` for eqs. 5, 11 and 15) it is ``parity w_k
    f(k, b)``: one evaluation of ``f`` serves both roles and its derivative is taken once,
    with the cotangent ``w_b obar_k + parity w_k obar_b``; the parameters then see each
    pair in both roles, and as the list is symmetric the two halves are equal, so their
    cotangent is halved.

    ``f`` is differentiated with respect to per-pair copies of its inputs (the pair
    geometry's fields, the row's fields), so that its derivative is element-wise code
    that XLA fuses into few loops, like the forward; the sums over the neighbours follow.
    The pair geometry's own derivative (``r``, ``W`` and ``grad W`` as functions of
    ``r_kb``) is :meth:`Geometry.pullback`, written once; ``x_k`` enters through ``r_kb``
    only.

    With ``stored`` (the list's :attr:`PairList.geometry`) the pair geometry is read, not
    computed, and ``x`` gets no cotangent from the sum; with ``stored_bar`` the cotangent
    of the stored geometry is returned as well, per slot: a pair appears in two slots
    (``(k, b)`` and ``(b, k)``, the same geometry swapped) and the pass over ``k``'s row
    gives the cotangent of both roles, so each slot gets half of it.  Returns
    ``(fields_bar, shared_bar, stored geometry's (dr, r, w, grad_w) bars or None)``.

    ``active``: ``None``, or ``(fields, shared)`` the keys of ``fields`` and the indices of
    the leaves of ``shared`` whose cotangents are wanted; the hand-written path then
    leaves the others out of its one reduction (zeros are returned for them), where XLA
    would not drop them itself.
    """
    n = jax.tree_util.tree_leaves(fields)[0].shape[0]
    wanted_fields = set(fields) if active is None else set(active[0])
    wanted_shared = None if active is None else set(active[1])
    full = _weighted(f, weight)

    def both_roles(pair, a, b, s):
        if parity is None:
            as_row = _masked(full(pair, a, b, s), pair.mask)
            swapped = full(pair.swapped(), b, a, jax.lax.stop_gradient(s))
            return as_row, _masked(swapped, pair.mask)
        term = _masked(f(pair, a, b, s), pair.mask)
        return _scale(term, b[weight]), _scale(term, parity * a[weight])

    hand = _pullback_of(f)

    def by_hand(pair, a, b, s, obar_a, obar_b):
        """``(pair_bar, a_bar, s_bar)`` of both roles from the hand-written pull-back."""
        if parity is not None:
            bar = _masked(
                tree_map(
                    lambda oa, ob: _scale(oa, b[weight]) + _scale(ob, parity * a[weight]),
                    obar_a,
                    obar_b,
                ),
                pair.mask,
            )
            pair_bar, a_bar, _, s_bar = hand(pair, a, b, s, bar)
            if weight is not None and weight in wanted_fields:
                term = _masked(f(pair, a, b, s), pair.mask)
                a_bar = {**a_bar, weight: a_bar.get(weight, 0.0) + parity * _contract(term, obar_b)}
            return pair_bar, a_bar, [0.5 * q for q in s_bar]
        as_row = obar_a if weight is None else _scale(obar_a, b[weight])
        pair_bar, a_bar, _, s_bar = hand(pair, a, b, s, _masked(as_row, pair.mask))
        swapped = pair.swapped()
        as_neighbour = obar_b if weight is None else _scale(obar_b, a[weight])
        swapped_bar, _, a_as_b, _ = hand(swapped, b, a, s, _masked(as_neighbour, pair.mask))
        dr1, r1, w1, g1 = pair_bar
        dr2, r2, w2, g2 = swapped_bar
        pair_bar = (dr1 - dr2, r1 + r2, w1 + w2, g1 - g2)
        a_bar = dict(a_bar)
        Cotangents._add(a_bar, a_as_b)
        if weight is not None and weight in wanted_fields:
            term = _masked(f(swapped, b, a, s), pair.mask)
            a_bar[weight] = a_bar.get(weight, 0.0) + _contract(term, obar_b)
        return pair_bar, a_bar, s_bar

    def wanted(a_bar, s_bar):
        """Only the cotangents asked for (``active``)."""
        a_bar = {k: v for k, v in a_bar.items() if k in wanted_fields}
        if wanted_shared is not None:
            s_bar = [q if i in wanted_shared else 0.0 for i, q in enumerate(s_bar)]
        return a_bar, s_bar

    def halved(pair_bar, pair):
        """Each slot's half of the cotangent of the stored geometry (see above)."""
        bars = _with_mask(pair_bar, pair.mask)
        return tuple(
            jnp.zeros_like(q) if _is_zero(q_bar) else 0.5 * jnp.broadcast_to(q_bar, q.shape)
            for q, q_bar in zip(_without_mask(pair), _without_mask(bars), strict=True)
        )

    def one_block(args):
        fields_k, idx_k, obar_k, stored_k = args
        valid = idx_k < n
        j = jnp.where(valid, idx_k, 0)
        b = _gather(fields, j)
        a = _per_pair(fields_k, idx_k.shape)
        if stored_k is None:
            dr = geometry.displacement(a["x"], b["x"])
            pair, factors = geometry._pairs_and_factors(dr, valid, second=True)
        else:
            pair, factors = stored_k, None
        if hand is not None:
            pair_bar, a_bar, s_bar = by_hand(
                pair, a, b, shared, _per_pair(obar_k, idx_k.shape), _gather(obar, j)
            )
            a_bar, s_bar = wanted(a_bar, s_bar)
            if stored_k is not None:
                sums, s_sums = _row_and_shared_sums(
                    a_bar, None, s_bar, fields_k, shared, idx_k.shape
                )
                return (sums, halved(pair_bar, pair) if stored_bar else None), s_sums
            dr_bar = None
            if "x" in wanted_fields:
                dr_bar = Geometry.pullback(pair, factors, _with_mask(pair_bar, pair.mask))
            sums, s_sums = _row_and_shared_sums(a_bar, dr_bar, s_bar, fields_k, shared, idx_k.shape)
            return (sums, None), s_sums
        _, pull = jax.vjp(
            lambda p, a, s: both_roles(_with_mask(p, pair.mask), a, b, s),
            _without_mask(pair),
            a,
            shared,
        )
        pair_bar, a_bar, s_bar = pull((_per_pair(obar_k, idx_k.shape), _gather(obar, j)))
        a_bar = _sum_over_pairs(a_bar)
        if parity is not None:
            s_bar = tree_map(lambda q: 0.5 * q, s_bar)
        if stored_k is not None:
            return (a_bar, halved(pair_bar, pair) if stored_bar else None), s_bar
        dr_bar = Geometry.pullback(pair, factors, _with_mask(pair_bar, pair.mask))
        a_bar["x"] = a_bar["x"] + jnp.sum(dr_bar, axis=1)
        return (a_bar, None), s_bar

    (fields_bar, stored_bars), shared_bar = _rowwise_with_shared(
        one_block, (fields, idx, obar, stored), block, n
    )
    return fields_bar, shared_bar, stored_bars


def _rowwise_with_shared(one_block, rows, block, pad_index):
    """:func:`_rowwise` for a ``one_block`` that returns ``(per-row cotangents, shared
    cotangent)``: per-row ones are concatenated, the shared ones summed over blocks."""
    return _rowwise(one_block, rows, block, pad_index, shared_output=True)


def _adjoint_cross(
    f, weight, geometry, block, rows, cols, shared, idx, transpose, obar, members=None
):
    """Cotangents of ``rows``, ``cols`` and ``shared`` for a sum ``w_b f(a, b)`` of one
    system's rows over another system's particles: one pass over the rows, one over the
    columns (over the columns ``members`` only, when given: the rows of ``transpose``)."""
    n_rows = jax.tree_util.tree_leaves(rows)[0].shape[0]
    n_cols = jax.tree_util.tree_leaves(cols)[0].shape[0]
    hand = _pullback_of(f)
    full = _weighted(f, weight)

    def row_by_hand(pair, factors, rows_k, a, b, obar_a):
        as_row = obar_a if weight is None else _scale(obar_a, b[weight])
        pair_bar, a_bar, _, s_bar = hand(pair, a, b, shared, _masked(as_row, pair.mask))
        dr_bar = Geometry.pullback(pair, factors, _with_mask(pair_bar, pair.mask))
        a_bar = _field_sums(a_bar, rows_k, pair.mask.shape)
        a_bar["x"] = a_bar["x"] + jnp.sum(dr_bar, axis=1)
        return a_bar, _shared_sums(s_bar, shared, pair.mask.shape)

    def column_by_hand(pair, factors, cols_k, a, b, obar_a):
        as_row = obar_a if weight is None else _scale(obar_a, b[weight])
        pair_bar, _, b_bar, _ = hand(pair, a, b, shared, _masked(as_row, pair.mask))
        if weight is not None:
            term = _masked(f(pair, a, b, shared), pair.mask)
            b_bar = {**b_bar, weight: b_bar.get(weight, 0.0) + _contract(term, obar_a)}
        dr_bar = Geometry.pullback(pair, factors, _with_mask(pair_bar, pair.mask))
        b_bar = _field_sums(b_bar, cols_k, pair.mask.shape)
        b_bar["x"] = b_bar["x"] - jnp.sum(dr_bar, axis=1)
        return b_bar

    def row_block(args):
        rows_k, idx_k, obar_k = args
        valid = idx_k < n_cols
        b = _gather(cols, jnp.where(valid, idx_k, 0))
        a = _per_pair(rows_k, idx_k.shape)
        dr = geometry.displacement(a["x"], b["x"])
        pair, factors = geometry._pairs_and_factors(dr, valid, second=True)
        if hand is not None:
            return row_by_hand(pair, factors, rows_k, a, b, _per_pair(obar_k, idx_k.shape))

        def as_row(p, a, s):
            return _masked(full(_with_mask(p, pair.mask), a, b, s), pair.mask)

        _, pull = jax.vjp(as_row, _without_mask(pair), a, shared)
        pair_bar, a_bar, s_bar = pull(_per_pair(obar_k, idx_k.shape))
        dr_bar = Geometry.pullback(pair, factors, _with_mask(pair_bar, pair.mask))
        a_bar = _sum_over_pairs(a_bar)
        a_bar["x"] = a_bar["x"] + jnp.sum(dr_bar, axis=1)
        return a_bar, s_bar

    def col_block(args):
        cols_k, idx_k = args
        valid = idx_k < n_rows
        j = jnp.where(valid, idx_k, 0)
        a = _gather(rows, j)
        obar_a = _gather(obar, j)
        b = _per_pair(cols_k, idx_k.shape)
        dr = geometry.displacement(a["x"], b["x"])
        pair, factors = geometry._pairs_and_factors(dr, valid, second=True)
        if hand is not None:
            return column_by_hand(pair, factors, cols_k, a, b, obar_a)

        def as_neighbour(p, b):
            p = _with_mask(p, pair.mask)
            return _masked(full(p, a, b, shared), pair.mask)

        _, pull = jax.vjp(as_neighbour, _without_mask(pair), b)
        pair_bar, b_bar = pull(obar_a)
        dr_bar = Geometry.pullback(pair, factors, _with_mask(pair_bar, pair.mask))
        b_bar = _sum_over_pairs(b_bar)
        b_bar["x"] = b_bar["x"] - jnp.sum(dr_bar, axis=1)
        return b_bar

    rows_bar, shared_bar = _rowwise_with_shared(row_block, (rows, idx, obar), block, n_cols)
    if members is None:
        cols_bar = _rowwise(col_block, (cols, transpose), block, n_rows)
        return rows_bar, cols_bar, shared_bar
    cols_m = tree_map(lambda q: q[jnp.minimum(members, n_cols - 1)], cols)
    bar_m = _rowwise(col_block, (cols_m, transpose), block, n_rows)
    cols_bar = tree_map(lambda q, b: jnp.zeros_like(q).at[members].add(b, mode="drop"), cols, bar_m)
    return rows_bar, cols_bar, shared_bar


def _custom_sum(
    f, geometry, block, structure, same, weight=None, parity=None, compact=False, stores=False
):
    """The pair sum of ``f`` with its adjoint attached; ``stores``: the list carries its
    geometry (:attr:`PairList.geometry`), passed after the shared leaves."""
    rows_def, cols_def, shared_def, n_rows_leaves, n_cols_leaves, n_shared = structure

    def unflatten(flat):
        rows = jax.tree_util.tree_unflatten(rows_def, flat[:n_rows_leaves])
        k = n_rows_leaves
        if same:
            cols = rows
        else:
            cols = jax.tree_util.tree_unflatten(cols_def, flat[k : k + n_cols_leaves])
            k += n_cols_leaves
        shared = jax.tree_util.tree_unflatten(shared_def, flat[k : k + n_shared])
        k += n_shared
        if not stores:
            return rows, cols, shared, None, flat[k:]
        # the stored geometry: its four float fields, then (after the integer arrays) its mask
        rest = flat[k + 4 :]
        stored = _with_mask(flat[k : k + 4], rest[-1])
        return rows, cols, shared, stored, rest[:-1]

    full = _weighted(f, weight)

    def forward(*flat):
        rows, cols, shared, stored, (idx, *_) = unflatten(flat)
        return _forward(full, geometry, None, rows, cols, shared, idx, stored)

    def adjoint(flat, obar, active):
        rows, cols, shared, stored, (idx, *transpose) = unflatten(flat)
        members = transpose[1] if compact else None
        leaves = jax.tree_util.tree_leaves
        if same:
            # the stored geometry's cotangent only where it has a tangent (its positions
            # are differentiated)
            stored_bar = stored is not None and any(active[n_linear - 4 :])
            which = jax.tree_util.tree_unflatten(rows_def, active[:n_rows_leaves])
            wanted = (
                [k for k, on in which.items() if on],
                [i for i, on in enumerate(active[n_rows_leaves : n_rows_leaves + n_shared]) if on],
            )
            fields_bar, shared_bar, stored_bars = _adjoint_self(
                f,
                weight,
                parity,
                geometry,
                block,
                rows,
                shared,
                idx,
                obar,
                stored,
                stored_bar,
                wanted,
            )
            if stored is None:
                return (*leaves(fields_bar), *leaves(shared_bar))
            return (*leaves(fields_bar), *leaves(shared_bar), *(stored_bars or (None,) * 4))
        rows_bar, cols_bar, shared_bar = _adjoint_cross(
            f, weight, geometry, block, rows, cols, shared, idx, transpose[0], obar, members
        )
        return (*leaves(rows_bar), *leaves(cols_bar), *leaves(shared_bar))

    n_linear = n_rows_leaves + (0 if same else n_cols_leaves) + n_shared + (4 if stores else 0)
    return custom_adjoint(forward, adjoint, n_linear=n_linear)


def pair_sum(
    f: Callable,
    rows: dict,
    cols: dict | None,
    pairs: PairList,
    geometry: Geometry,
    shared=(),
    *,
    weight: str | None = None,
    parity: int | None = None,
    adjoint: bool = True,
    block: int | None = None,
    native: bool = False,
):
    """``out_a = sum_{b in N(a)} w_b f(pair_ab, a, b, shared)`` over a neighbour list.

    Args:
      f: ``f(pair: PairGeometry, a, b, shared) -> pytree of [B, K, ...]`` per-pair terms;
        ``a`` and ``b`` are dicts of the rows' and neighbours' fields.  Must be a
        hashable function (a module-level function or a ``functools.partial`` of one)
        that is finite for any pair (padding and ``r = 0`` included).
      rows: dict of ``[N_a, ...]`` float arrays; ``rows["x"]`` are the positions the pair
        geometry is computed from.
      cols: the neighbours' fields (same keys as ``f`` reads), or ``None`` for a sum within
        one system (``cols = rows``, symmetric list).
      pairs: the :class:`PairList` of ``rows`` against ``cols``.
      geometry: kernel, smoothing length and domain (:meth:`Geometry.of`).
      shared: pytree of arrays every pair sees (parameters).
      weight: key of the neighbours' field ``w_b`` that multiplies ``f`` (``None``: 1).
      parity: for a sum within one system, ``-1`` if ``f(b, a) = -f(a, b)`` (pair forces)
        or ``+1`` if ``f(b, a) = f(a, b)``; the adjoint then evaluates ``f`` once per pair
        for both roles.  ``None``: no symmetry assumed (two evaluations).
      adjoint: attach the custom adjoint (else autodiff transposes the forward).
      block: rows per block of the adjoint's passes (``None``: all at once); the forward
        runs over all rows at once (faster on the CPU than blocks).
      native: evaluate the sum with the compiled loop of :mod:`sphjax.native` where
        ``f`` has one (:func:`define_native`): within one system each pair once, between
        two systems from the rows' side (over the compacted rows of ``pairs.members``),
        on the CPU; its derivatives are this function's without ``native``.
    Returns:
      pytree of ``[N_a, ...]`` sums.
    """
    same = cols is None
    if parity is not None and (not same or weight is None):
        raise ValueError("pair_sum: parity needs a sum within one system and a weight")
    stored = pairs.geometry
    if stored is not None and (not same or pairs.members is not None):
        raise ValueError("pair_sum: a stored geometry needs a sum within one system")
    loop = None
    if native and pairs.members is None and (same or stored is None):
        loop = _native_loop(f, geometry, weight, parity, cross=not same, stored=stored is not None)
    if loop is not None:
        xla = functools.partial(
            pair_sum,
            f,
            geometry=geometry,
            weight=weight,
            parity=parity,
            adjoint=adjoint,
            block=block,
        )
        return _native_sum(loop, xla, rows, cols, pairs, shared)
    if pairs.members is not None:
        return _member_sum(f, rows, cols, pairs, geometry, shared, weight, adjoint, block, native)
    if not adjoint or _autodiff_transposes(f):
        full = _weighted(f, weight)
        return _forward(
            full, geometry, None, rows, rows if same else cols, shared, pairs.idx, stored
        )
    rows_leaves, rows_def = jax.tree_util.tree_flatten(rows)
    cols_leaves, cols_def = jax.tree_util.tree_flatten(rows if same else cols)
    shared_leaves, shared_def = jax.tree_util.tree_flatten(shared)
    if not same and pairs.transpose is None:
        raise ValueError("pair_sum between two systems needs the transposed neighbour list")
    structure = (
        rows_def,
        cols_def,
        shared_def,
        len(rows_leaves),
        len(cols_leaves),
        len(shared_leaves),
    )
    compact = pairs.transpose_members is not None
    fn = _custom_sum(
        f, geometry, block, structure, same, weight, parity, compact, stored is not None
    )
    dtype = rows_leaves[0].dtype
    shared_leaves = [jnp.asarray(s, dtype) for s in shared_leaves]
    stored_leaves = [] if stored is None else list(_without_mask(stored))
    args = [*rows_leaves, *([] if same else cols_leaves), *shared_leaves, *stored_leaves]
    args.append(pairs.idx)
    if not same:
        args.append(pairs.transpose)
    if compact:
        args.append(pairs.transpose_members)
    if stored is not None:
        args.append(stored.mask)
    return fn(*args)


# ---------------------------------------------------------------------------- native loops

_NATIVE_LOOPS: dict = {}


def define_native(summand: Callable, loop_for: Callable) -> None:
    """Give ``summand`` a compiled loop of :mod:`sphjax.native`: ``loop_for(keywords,
    geometry, weight, parity, cross, stored)`` returns ``loop(rows, cols, idx, shared,
    stored)`` (the sum as :func:`pair_sum` returns it: within one system over the
    symmetric list ``idx`` with ``cols=None``, or, with ``cross``, the rows against the
    columns ``cols`` of another system) for the summand's keyword arguments (those of a
    ``functools.partial``), or ``None`` where the loop lacks a term they ask for.
    ``stored``: for ``loop_for`` whether the list holds the pair geometry stored once per
    run (:attr:`PairList.geometry`), for ``loop`` that :class:`PairGeometry` (or
    ``None``), which a loop may read instead of recomputing the geometry."""
    _NATIVE_LOOPS[summand] = loop_for


def _native_loop(f, geometry, weight, parity, cross: bool, stored: bool):
    from sphjax import native

    func, keywords = (f.func, f.keywords) if isinstance(f, functools.partial) else (f, {})
    loop_for = _NATIVE_LOOPS.get(func)
    if loop_for is None or not native.supports(geometry):
        return None
    return loop_for(keywords, geometry, weight, parity, cross, stored)


def _native_sum(loop, xla, rows, cols, pairs: PairList, shared):
    """``loop(rows, cols, idx, shared)``, whose derivative rule is ``xla``'s (the pair sum
    without ``native``): forward mode, reverse mode and the custom adjoint never see the
    loop.  A stored pair geometry (:attr:`PairList.geometry`) is an argument of the rule,
    so derivatives flow through it as through the XLA sum.  Inputs without a tangent stay
    constants of ``xla`` (no zero tangents are made up and pushed through it)."""
    stored = pairs.geometry
    stored_leaves = None if stored is None else _without_mask(stored)
    # the lists (integers) and the stored geometry's mask are arguments too: a closure
    # over them would leak their tracers out of the transformations of the rule
    lists = (dataclasses.replace(pairs, geometry=None), None if stored is None else stored.mask)

    @jax.custom_jvp
    def summed(rows, cols, shared, stored_leaves, lists):
        pairs, mask = lists
        geometry = None if mask is None else PairGeometry(*stored_leaves, mask)
        return loop(rows, cols, pairs.idx, shared, geometry)

    @functools.partial(summed.defjvp, symbolic_zeros=True)
    def summed_jvp(primals, tangents):
        *differentiable, (pairs, mask) = primals
        leaves, treedef = jax.tree_util.tree_flatten(tuple(differentiable))
        zero = lambda t: isinstance(t, jax.custom_derivatives.SymbolicZero)  # noqa: E731
        dots = jax.tree_util.tree_leaves(tuple(tangents[:-1]), is_leaf=zero)
        live = [k for k, t in enumerate(dots) if not zero(t)]

        def of_live(*values):
            full = list(leaves)
            for k, value in zip(live, values, strict=True):
                full[k] = value
            rows, cols, shared, stored_leaves = jax.tree_util.tree_unflatten(treedef, full)
            geometry = None if mask is None else PairGeometry(*stored_leaves, mask)
            at = dataclasses.replace(pairs, geometry=geometry)
            return xla(rows, cols, pairs=at, shared=shared)

        return jax.jvp(of_live, [leaves[k] for k in live], [dots[k] for k in live])

    return summed(rows, cols, shared, stored_leaves, lists)


def _member_sum(f, rows, cols, pairs: PairList, geometry, shared, weight, adjoint, block, native):
    """:func:`pair_sum` over the rows ``pairs.members`` only, scattered back to all rows
    (the others have no neighbours: their sums are zero)."""
    members = pairs.members
    n_rows = pairs.n_rows
    take = jnp.minimum(members, n_rows - 1)
    rows_m = tree_map(lambda q: q[take], rows)
    inner = PairList(
        pairs.idx, pairs.transpose, members.shape[0], pairs.n_cols, None, pairs.transpose_members
    )
    out = pair_sum(
        f,
        rows_m,
        cols,
        inner,
        geometry,
        shared,
        weight=weight,
        adjoint=adjoint,
        block=block,
        native=native,
    )
    return tree_map(
        lambda o: jnp.zeros((n_rows,) + o.shape[1:], o.dtype).at[members].add(o, mode="drop"),
        out,
    )
