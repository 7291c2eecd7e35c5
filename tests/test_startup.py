"""Start-up (issue 30): set-up data stays out of XLA, and the radius search that replaced
scipy's k-d tree in the packing finds what it found.

The quick start (``sphjax run taylor_green``) compiled 75 programs before its first step,
65 of them one jax.numpy operation each on set-up data; these tests keep that from
creeping back.  Timings are ``benchmarks/startup.py``'s business, not a test's.
"""

from __future__ import annotations

import contextlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sphjax
from sphjax.cases._packing import periodic_neighbours
from sphjax.neighbors.search import DENSE_SEARCH_PAIRS, points_within

# lowered once per program this process compiles (or loads from the persistent cache)
COMPILE_EVENT = "/jax/core/compile/jaxpr_to_mlir_module_duration"


@contextlib.contextmanager
def compiled_programs():
    """A list that collects one entry per program compiled inside the ``with`` block."""
    compiled = []

    def listen(event, duration, **_):
        if event == COMPILE_EVENT:
            compiled.append(duration)

    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        yield compiled
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)


def _brute_force(x, radius, box, closed):
    """Rows of the points within ``radius`` (minimum image in ``box`` where given)."""
    n = len(x)
    rows = []
    for a in range(n):
        dr = x - x[a]
        if box is not None:
            dr = dr - box * np.round(dr / box)
        r2 = np.sum(dr * dr, axis=1)
        near = (r2 <= radius**2) if closed else (r2 < radius**2)
        rows.append([b for b in np.flatnonzero(near) if b != a])
    width = max(1, max(len(r) for r in rows))
    idx = np.full((n, width), n, np.int32)
    for a, r in enumerate(rows):
        idx[a, : len(r)] = r
    return idx


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("periodic", [True, False])
def test_points_within_both_paths_match_brute_force(dim, periodic, monkeypatch):
    """The all-pairs path (small sets) and the cell-list path give the same rows, each in
    increasing index order, as a brute-force search."""
    rng = np.random.default_rng(dim + 2 * periodic)
    box = 1.0
    x = rng.uniform(0.0, box, (300, dim))
    radius = 0.2
    expected = _brute_force(x, radius, box if periodic else None, closed=False)
    args = (x, radius, (0.0,) * dim, (box,) * dim, (periodic,) * dim)
    assert 300**2 <= DENSE_SEARCH_PAIRS
    np.testing.assert_array_equal(points_within(*args), expected)
    monkeypatch.setattr("sphjax.neighbors.search.DENSE_SEARCH_PAIRS", 0)  # the cell list
    np.testing.assert_array_equal(points_within(*args), expected)


def test_periodic_neighbours_count_the_radius_itself():
    """The packing's search includes pairs at exactly ``radius`` (as scipy's
    ``cKDTree.query_ball_point`` did), the radius search of the reference lists does not:
    on a square lattice of spacing 1/8 (exact in binary), radius 2 dx."""
    g = np.arange(8) / 8
    x = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    idx = periodic_neighbours(x, 1.0, 0.25)
    # lattice vectors with |(i, j)| <= 2, the origin left out: 12; strictly inside: 8
    assert np.all(np.sum(idx < len(x), axis=1) == 12)
    np.testing.assert_array_equal(idx, _brute_force(x, 0.25, 1.0, closed=True))
    open_ball = points_within(x, 0.25, (0.0, 0.0), (1.0, 1.0), (True, True))
    assert np.all(np.sum(open_ball < len(x), axis=1) == 8)


def test_quick_start_compiles_no_set_up_operations():
    """Building the quick start's Taylor-Green case and running two steps compiles at
    most eleven programs: the packing block, the initial state, the constants jax-md
    computes when it builds its neighbour-list functions (five operations in float32
    sessions, seven in float64 ones like this), the allocation's rebuild and the chunk of
    steps (fewer if this process compiled one of them before).  Before issue 30: 75."""
    with compiled_programs() as compiled:
        case = sphjax.cases.taylor_green(n=20)
        traj = sphjax.simulate(case, n_steps=2, save_every=1)
        np.asarray(traj.states.position)
    assert len(traj) == 3
    assert 0 < len(compiled) <= 11, len(compiled)


def test_make_state_concrete_equals_traced():
    """make_state builds concrete States in numpy and traced ones in jax.numpy: the same
    fields, shapes, dtypes and values either way."""
    from sphjax.core.state import Kind, make_state

    rng = np.random.default_rng(0)
    x = rng.uniform(0.0, 1.0, (12, 2))
    kind = np.array([Kind.FLUID] * 8 + [Kind.WALL] * 4)
    density = rng.uniform(990.0, 1010.0, 12)

    def build(density, mass):
        return make_state(x, (0.5, -1.0), density, mass, kind)

    concrete = build(density, 0.25)
    traced = jax.jit(build)(density, 0.25)
    for name in concrete.__dataclass_fields__:
        a, b = getattr(concrete, name), getattr(traced, name)
        assert isinstance(a, jax.Array), name
        assert (a.shape, a.dtype) == (b.shape, b.dtype), name
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b), err_msg=name)


def test_a_run_compiles_one_chunk_program():
    """A run's chunks share one compiled program: the last, shorter chunk and the steps
    after the last whole frame (a remainder frame) run in the same program as the others
    (their frame buffer is the longest chunk's, the frame spacing and the stop are
    arguments).  Before: one program per chunk length and per frame spacing, three here.
    The frames are those of one chunk per frame (the same run in chunks of 7 steps)."""
    case = sphjax.cases.taylor_green(n=10)
    sphjax.simulate(case, n_steps=3, save_every=3, steps_per_chunk=3)  # warm: set-up
    with compiled_programs() as compiled:
        # 50 steps, a frame every 7: chunks of 4, 3 frames (28 + 21 steps), then 1 step
        traj = sphjax.simulate(case, n_steps=50, save_every=7, steps_per_chunk=28)
    assert len(compiled) <= 1, len(compiled)
    np.testing.assert_allclose(np.asarray(traj.times) / case.dt, [0, *range(7, 50, 7), 50])
    reference = sphjax.simulate(case, n_steps=50, save_every=7, steps_per_chunk=7)
    np.testing.assert_array_equal(
        np.asarray(traj.states.position), np.asarray(reference.states.position)
    )


def test_a_concrete_evaluate_is_one_program():
    """``sphjax.evaluate`` called with concrete arrays runs as one compiled program (it
    compiled some 450 one-operation programs, 7.7 s for this dam break, before), equal to
    the right-hand side traced into a caller's program, whose derivative it keeps."""
    case = sphjax.cases.dam_break(n=6)
    neighbors = sphjax.build_neighbors(case.state, case.model)
    with compiled_programs() as compiled:
        rates = sphjax.evaluate(case.state, neighbors, case.model, case.params)
        np.asarray(rates.acceleration)
    assert len(compiled) <= 1, len(compiled)

    def traced(params):
        return sphjax.evaluate(case.state, neighbors, case.model, params).acceleration

    expected = np.asarray(jax.jit(traced)(case.params))
    # to round-off of the largest acceleration (gravity cancels in the column: 1e-4 of it)
    scale = np.max(np.abs(expected))
    np.testing.assert_allclose(np.asarray(rates.acceleration), expected, atol=1e-12 * scale)
    # jitted: one program, not one per operation
    alpha = jax.jit(
        jax.grad(lambda a: jnp.sum(traced(case.params.replace(artificial_alpha=a)) ** 2))
    )
    assert np.isfinite(float(alpha(case.params.fluid.artificial_alpha)))


def _constants(lowered) -> list[tuple[int, ...]]:
    """The shapes of the constants of a lowered program (its StableHLO text)."""
    import re

    shapes = []
    for match in re.finditer(r"stablehlo\.constant .*?: tensor<([^>]*)>", lowered.as_text()):
        dims = match.group(1).split("x")[:-1]  # the last entry is the element type
        shapes.append(tuple(int(d) for d in dims))
    return shapes


def test_a_loss_closing_over_the_case_captures_no_neighbour_list():
    """A jitted loss that closes over the case (its state is then a constant of the
    loss's program) keeps the neighbour lists out of the program: the allocation's
    ``[N, K]`` lists are rebuilt by the run, not embedded, and nothing is evaluated by
    constant folding at compile time.  Before: the allocated list (``[N, 45]``) and the
    candidates of its rebuild (``[N, 180]``) were constants of the program, 36 MB at
    40,000 particles and 2.9 GB at one million, and XLA sorted the particles by cell
    while compiling.  Constants of at most ``N x d`` elements (the state) remain."""
    case = sphjax.cases.taylor_green(n=12, relax_iterations=0)
    n, dim = case.state.position.shape

    def loss(nu):
        params = case.params.replace(kinematic_viscosity=nu)
        traj = sphjax.simulate(case, params, n_steps=4, checkpoint_every=2)
        return jnp.sum(traj.states.velocity[-1] ** 2)

    nu = case.params.fluid.kinematic_viscosity
    lowered = jax.jit(jax.grad(loss)).lower(nu)
    largest = max(int(np.prod(s)) for s in _constants(lowered))
    assert largest <= n * dim, (largest, n, dim)
    # the same derivative as with the state an argument of the program (no constants)
    by_argument = jax.jit(
        jax.grad(
            lambda nu, state: jnp.sum(
                sphjax.simulate(
                    case,
                    case.params.replace(kinematic_viscosity=nu),
                    state=state,
                    n_steps=4,
                    checkpoint_every=2,
                ).states.velocity[-1]
                ** 2
            )
        )
    )(nu, case.state)
    np.testing.assert_allclose(float(lowered.compile()(nu)), float(by_argument), rtol=1e-6)
