"""Where the dry clamped plate's extra compliance comes from (issue 31): the deflection
profile along the span against Euler-Bernoulli, and variants of the clamp.

    python docs/scripts/plate_clamp_probe.py --n 8 --variant base zero_clamp_stress clamp1

Each run: the dry plate of ``validate_fsi.py --dry-only`` (``--gradient-correction``,
second order by default),
``--periods`` dry periods undamped; prints the mid-span w / w_ref (mid-range and mean over
the second half), the column-mean profile (time mean over the second half) over
w_EB(x) = 16 w_ref (x/L)^2 (1 - x/L)^2, and a least-squares fit
w = c (x + e)^2 (L + e - x)^2 (effective span L + 2 e, compliance c over Euler-Bernoulli's).
Variants: ``base``; ``zero_clamp_stress`` (the clamped particles' P = 0, i.e. F = I,
in the force sum); ``clampK`` (only the K clamped columns nearest each end kept);
``inwardK`` (the first K free columns at each end clamped too); ``stiffK`` (the clamped
particles' stress times K, a clamp material K times stiffer, the step divided by
sqrt(K)); ``ghost`` (each clamped particle moved to ``X_b - u_m``, m its mirror image
about the clamp face, its force handed back to m: u = 0 on the face); ``face`` (the
clamped lattice replaced by one clamped column on each clamp face, their stress zero).
Variants that patch
the solid (``zero_clamp_stress``, ``stiffK``, ``ghost``, ``face``) each need a process of their own:
an already compiled run would not see the patch.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import pathlib
import re
import time

import jax
import jax.numpy as jnp
import numpy as np

import sphjax
from sphjax.cases.fsi import hydrostatic_fsi_plate, midspan_deflection
from sphjax.core.state import Kind
from sphjax.physics.solid import system as solid_system

HERE = pathlib.Path(__file__).resolve().parent
_spec = importlib.util.spec_from_file_location("validate_fsi", HERE / "validate_fsi.py")
vf = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(vf)

_update_solid = solid_system.update_solid


def _zero_clamped_stress(system, solid, pairs, ctx, reference=None):
    """update_solid with the clamped particles' stress set to zero (F = I for SVK)."""
    out = _update_solid(system, solid, pairs, ctx, reference)
    free = solid["free"][:, None, None]
    for key in ("P", "PL0", "PL0q"):
        if key in out:
            out[key] = out[key] * free
    return out


_STIFFNESS = {"K": 1.0}


def _stiff_clamp(system, solid, pairs, ctx, reference=None):
    """update_solid with the clamped particles' stress times K: a clamp material K times
    stiffer than the plate's (the force stays the gradient of an energy)."""
    out = _update_solid(system, solid, pairs, ctx, reference)
    scale = jnp.where(solid["free"], 1.0, _STIFFNESS["K"])[:, None, None]
    for key in ("P", "PL0", "PL0q"):
        if key in out:
            out[key] = out[key] * scale
    return out


_GHOST = {}
_body_acceleration = solid_system.SolidSystem.body_acceleration


def _ghost_update(system, solid, pairs, ctx, reference=None):
    """update_solid with each clamped particle b moved to ``X_b - u_m(b)`` (u = x - X),
    m(b) its mirror image about the clamp face: a ghost whose displacement is the odd
    continuation of the plate's, so u = 0 on the face (a Dirichlet clamp)."""
    ghost, mirror = _GHOST["ghost"], _GHOST["mirror"]
    X, x = solid["X"], solid["x"]
    x = x.at[ghost].set(X[ghost] - (x[mirror] - X[mirror]))
    return _update_solid(system, {**solid, "x": x}, pairs, ctx, reference)


def _ghost_acceleration(self, view, acceleration, params):
    """The force on each ghost, negated, added to its mirror image (the energy's gradient
    through ``u_b = -u_m(b)``); equal masses."""
    ghost, mirror = _GHOST["ghost"], _GHOST["mirror"]
    acceleration = acceleration.at[mirror].add(-acceleration[ghost])
    return _body_acceleration(self, view, acceleration, params)


def ghosts(case):
    X = np.asarray(case.state.reference_position)
    kind = np.asarray(case.state.kind)
    dx, L = case.info["dx"], case.info["length"]
    col = np.round(X[:, 0] / dx - 0.5).astype(int)
    row = np.floor(X[:, 1] / dx).astype(int)
    index = {(c, r): i for i, (c, r) in enumerate(zip(col, row, strict=True))}
    ncol = int(round(L / dx))
    g, m = [], []
    for i in np.flatnonzero(kind == Kind.CLAMPED):
        c, r = col[i], row[i]
        mc = -c - 1 if c < 0 else 2 * ncol - 1 - c
        if 0 <= mc < ncol and (mc, r) in index:
            g.append(i)
            m.append(index[(mc, r)])
    _GHOST.update(ghost=jnp.asarray(g), mirror=jnp.asarray(m))


def face_clamped(case):
    """``case`` with its clamped lattice replaced by one column of clamped particles on each
    clamp face (x = 0 and x = L, the rows of the plate): Dirichlet data u = 0 where the
    clamp begins, no elastic clamp region beyond it (their stress is zeroed by
    :func:`_zero_clamped_stress`, so the energy is the free plate's alone)."""
    X = np.asarray(case.state.reference_position)
    kind = np.asarray(case.state.kind)
    dx, L = case.info["dx"], case.info["length"]
    keep = np.flatnonzero(kind != Kind.CLAMPED)
    first = np.flatnonzero((kind == Kind.SOLID) & (X[:, 0] < dx))
    n_all = len(kind)
    take = np.concatenate([keep, first, first])
    face = np.concatenate([np.zeros(len(first)), np.full(len(first), L)])

    def pick(a):
        return a[take] if getattr(a, "ndim", 0) >= 1 and a.shape[0] == n_all else a

    state = jax.tree_util.tree_map(pick, case.state)
    new = slice(len(keep), None)
    Xn = np.asarray(state.reference_position).copy()
    Xn[new, 0] = face
    kn = np.asarray(state.kind).copy()
    kn[new] = Kind.CLAMPED
    state = state.replace(
        reference_position=jnp.asarray(Xn), position=jnp.asarray(Xn), kind=jnp.asarray(kn)
    )
    midspan = tuple(int(np.searchsorted(keep, i)) for i in case.info["midspan_indices"])
    return case.replace(state=state, info=dict(case.info, midspan_indices=midspan))


def trimmed(case, keep_columns):
    """``case`` with only the ``keep_columns`` clamped columns nearest each end."""
    X = np.asarray(case.state.reference_position)
    kind = np.asarray(case.state.kind)
    dx, L = case.info["dx"], case.info["length"]
    dist = np.where(X[:, 0] < 0.5 * L, -X[:, 0], X[:, 0] - L)
    keep = (kind != Kind.CLAMPED) | (dist < keep_columns * dx)
    n_all = len(kind)

    def take(a):
        return a[keep] if getattr(a, "ndim", 0) >= 1 and a.shape[0] == n_all else a

    state = jax.tree_util.tree_map(take, case.state)
    old = np.flatnonzero(keep)
    midspan = tuple(int(np.searchsorted(old, i)) for i in case.info["midspan_indices"])
    return case.replace(state=state, info=dict(case.info, midspan_indices=midspan))


def inward(case, columns):
    """``case`` with its first ``columns`` free columns at each end clamped too."""
    X = np.asarray(case.state.reference_position)
    kind = np.asarray(case.state.kind)
    dx, L = case.info["dx"], case.info["length"]
    near = (X[:, 0] < columns * dx) | (X[:, 0] > L - columns * dx)
    kind = np.where((kind == Kind.SOLID) & near, Kind.CLAMPED, kind).astype(kind.dtype)
    return case.replace(state=case.state.replace(kind=kind))


def run(n, variant, periods, h_factor=None, gradient_correction="second_order"):
    zero = variant in ("zero_clamp_stress", "face")
    stiff = variant.startswith("stiff")
    ghost = variant == "ghost"
    solid_system.SolidSystem.body_acceleration = (
        _ghost_acceleration if ghost else _body_acceleration
    )
    solid_system.update_solid = (
        _zero_clamped_stress
        if zero
        else _stiff_clamp
        if stiff
        else _ghost_update
        if ghost
        else _update_solid
    )
    case = hydrostatic_fsi_plate(
        n=n, depth=0.5, h_factor=h_factor, gradient_correction=gradient_correction
    )
    case = vf.dry_case(case)
    if variant.startswith("clamp"):
        case = trimmed(case, int(variant[5:]))
    if variant == "face":
        case = face_clamped(case)
    if variant.startswith("inward"):
        case = inward(case, int(variant[6:]))
    if ghost:
        ghosts(case)
    if stiff:
        _STIFFNESS["K"] = float(variant[5:])
        case = case.replace(dt=case.dt / _STIFFNESS["K"] ** 0.5)
    kind = np.asarray(case.state.kind)
    n_steps = int(round(periods * case.info["dry_period"] / case.dt))
    start = time.perf_counter()
    traj = sphjax.simulate(
        case, n_steps=n_steps, save_every=max(1, n_steps // 200), cell_order=not ghost
    )
    wall = time.perf_counter() - start
    ref = case.info["reference_deflection"]
    wt = np.asarray(midspan_deflection(traj, case)) / ref
    late = wt[len(wt) // 2 :]
    pos = np.asarray(traj.states.position)
    x = pos[len(pos) // 2 :].mean(axis=0)
    X = np.asarray(case.state.reference_position)
    free = (X[:, 0] > 0) & (X[:, 0] < case.info["length"]) & (kind >= Kind.SOLID)
    L, dx = case.info["length"], case.info["dx"]
    cols = np.round(X[free, 0] / dx - 0.5).astype(int)
    nx = cols.max() + 1
    w = np.bincount(cols, x[free, 1] - X[free, 1], nx) / np.bincount(cols, None, nx)
    xc = (np.arange(nx) + 0.5) * dx
    s = xc / L
    w_eb = 16 * ref * s**2 * (1 - s) ** 2
    best = None
    for e in np.linspace(-3 * dx, 3 * dx, 601):
        g = (xc + e) ** 2 * (L + e - xc) ** 2
        c = float(g @ w / (g @ g))
        r = float(np.sum((w - c * g) ** 2))
        if best is None or r < best[0]:
            best = (r, e, c)
    r, e, c = best
    ratio = w / w_eb
    pick = [0, 1, 2, 3, 5, 8, nx // 8, nx // 4, 3 * nx // 8, nx // 2]
    row = dict(
        n=n,
        variant=variant,
        h_factor=h_factor,
        n_clamped=int((kind == Kind.CLAMPED).sum()),
        dx=dx,
        wall_s=round(wall, 1),
        w_mid_range=float(0.5 * (late.max() + late.min())),
        w_mid_mean=float(late.mean()),
        profile_ratio={f"{xc[i] / dx:.1f}dx": round(float(ratio[i]), 4) for i in pick},
        fit_e_over_dx=round(float(e / dx), 3),
        fit_compliance_ratio=round(float(c / (16 * ref / L**4)), 4),
        fit_rel_resid=float(np.sqrt(r / np.sum(w**2))),
        fit0_compliance_ratio=round(float((w_eb @ w) / (w_eb @ w_eb)), 4),
    )
    print(json.dumps(row), flush=True)
    return row


#: the variants :func:`run` knows (K: a whole number >= 1; stiffK: a positive number)
VARIANT = re.compile(r"base|zero_clamp_stress|ghost|face|(clamp|inward)[1-9][0-9]*|stiff[0-9.]+")


def _number(text):
    """``float(text)`` if it is a positive number, else None."""
    try:
        value = float(text)
    except ValueError:
        return None
    return value if value > 0 else None


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--n", type=int, nargs="+", default=[8])
    p.add_argument("--variant", nargs="+", default=["base"])
    p.add_argument("--periods", type=float, default=8.0)
    p.add_argument("--h-factor", type=float, default=None)
    p.add_argument("--gradient-correction", default="second_order")
    p.add_argument("--out", default=None)
    args = p.parse_args()
    if not args.periods > 0:
        p.error(f"--periods: give a positive number of dry periods, got {args.periods}")
    for v in args.variant:
        stiffness = v.startswith("stiff") and VARIANT.fullmatch(v) and _number(v[5:])
        if not VARIANT.fullmatch(v) or (v.startswith("stiff") and not stiffness):
            p.error(
                f"--variant: unknown variant {v!r}; give base, zero_clamp_stress, ghost, "
                "face, clampK, inwardK (K a whole number >= 1) or stiffK (K > 0)"
            )
    for n in args.n:
        for v in args.variant:
            row = run(n, v, args.periods, args.h_factor, args.gradient_correction)
            if args.out:
                with open(args.out, "a") as f:
                    f.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
