"""Solver in the loop (sphjax.surrogate.solver_in_the_loop) at CI size: a coarse 8x8
Taylor-Green run corrected towards a 16x16 one.  Cost: 58 s of CPU time, nearly all
compilation (the fine reference, two rollouts, one training step); 3.5 min wall clock
measured on the shared, loaded 2-core machine; the test of the loss relative to the coarse
solver adds 17 s wall (alone on the machine); the start-up term, truncation and refusals
tests 55 s wall; the schedule and split-training test 16 s wall (three trainings of at
most six iterations, its programs compiled once and then read from the compilation cache).
"""

from __future__ import annotations

from pathlib import Path

import jax
import numpy as np
import pytest

import sphjax
from sphjax.surrogate import solver_in_the_loop as sil


@pytest.fixture(scope="module")
def problem():
    # the lattice start with lattice masses (relax_iterations=0): its start-up transient
    # gives the correction something to learn within a few iterations
    coarse = sphjax.cases.taylor_green(n=8, relax_iterations=0)
    fine = sphjax.cases.taylor_green(n=16, relax_iterations=0)
    return sil.make_problem(coarse, fine, horizon=4, ratio=2, viscosities=[0.01], probes_per_side=8)


def test_probe_velocity_interpolates_a_uniform_field_exactly(problem):
    # Shepard normalisation: a constant field is reproduced at every probe
    state = problem.coarse.state.replace(velocity=0 * problem.coarse.state.velocity + 0.3)
    u = np.asarray(sil.probe_velocity(state, problem.coarse, problem.probes))
    np.testing.assert_allclose(u, 0.3, rtol=1e-5)
    assert problem.reference.shape == (1, 5, 64, 2)


def test_zero_initialised_correction_is_the_coarse_solver_and_training_lowers_the_loss(problem):
    net = sil.Corrector(problem, jax.random.PRNGKey(0))
    coarse = sil.errors(problem, None)
    np.testing.assert_allclose(sil.errors(problem, net), coarse, rtol=1e-6)
    assert coarse.shape == (1, 5) and np.all(coarse[0, 1:] > 0)
    # one condition and one start (unroll = horizon): every iteration sees the same
    # problem, so the loss must fall; the gradient flows through four solver steps
    result = sil.train(problem, net, unroll=4, iterations=12, lr=1e-2, log=lambda s: None)
    losses = np.asarray(result.losses)
    assert np.isfinite(losses).all() and result.iterations == 12
    assert 0 < result.cpu_seconds and 0 < result.seconds
    assert losses[-3:].mean() < 0.9 * losses[0]
    trained = sil.errors(problem, result.net)
    assert trained[0, -1] < coarse[0, -1]


def test_a_schedule_reaches_the_optimiser_and_a_split_training_equals_a_whole_one(problem):
    """``lr`` may be an optax schedule: one that drops to zero after four iterations
    leaves the network unchanged from then on (the loss, computed before each update on
    the one condition and start, repeats exactly), while the first four updates lower it.
    Three iterations, then three more given the first piece's network and
    ``opt_state`` (Adam's moments and its step count, the schedule's step), give the
    parameters and losses of the six in one go: a resumed piece that started a new Adam
    state would take three steps at the schedule's first rate from new moments instead.
    """
    import equinox as eqx
    import optax

    net = sil.Corrector(problem, jax.random.PRNGKey(0))
    schedule = optax.piecewise_constant_schedule(1e-2, {4: 0.0})
    result = sil.train(problem, net, unroll=4, iterations=6, lr=schedule, log=lambda s: None)
    losses = np.asarray(result.losses)
    assert losses[4] < losses[0]
    assert len(set(losses[:5].tolist())) == 5  # the first four updates moved the network
    np.testing.assert_array_equal(losses[4:], losses[4])  # the later ones did not

    first = sil.train(problem, net, unroll=4, iterations=3, lr=schedule, log=lambda s: None)
    assert sil.completed_iterations(first.opt_state) == 3
    second = sil.train(
        problem,
        first.net,
        unroll=4,
        iterations=3,
        lr=schedule,
        opt_state=first.opt_state,
        log=lambda s: None,
    )
    assert sil.completed_iterations(second.opt_state) == 6
    np.testing.assert_allclose(first.losses + second.losses, losses, rtol=1e-12)
    split, whole = (
        jax.tree_util.tree_leaves(eqx.filter(r.net, eqx.is_array)) for r in (second, result)
    )
    for a, b in zip(split, whole, strict=True):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-12, atol=1e-15)
    # the state of a constant learning rate does not fit a schedule's optimiser
    constant = sil.optimizer(1e-2).init(eqx.filter(net, eqx.is_array))
    with pytest.raises(ValueError, match="opt_state does not fit this network and lr"):
        sil.train(problem, net, unroll=4, iterations=1, lr=schedule, opt_state=constant)
    # nor does the state of another network (another latent width)
    other = sil.Corrector(problem, jax.random.PRNGKey(0), latent=8)
    with pytest.raises(ValueError, match="opt_state does not fit this network and lr"):
        sil.train(problem, other, unroll=4, iterations=1, lr=schedule, opt_state=first.opt_state)


def test_the_loss_relative_to_the_coarse_solver_by_hand_and_training_lowers_it(problem):
    """``loss="relative_to_coarse"`` is ``mean_k e_k^2 / (e^c_k)^2`` over the window: 1 for
    the untrained (zero) correction, which is the coarse solver; after twelve updates the
    recorded loss (the schedule then stops the updates, so the last losses are those of
    the returned network) equals the value computed by hand from :func:`errors`, and is
    lower than the coarse solver's."""
    import optax

    net = sil.Corrector(problem, jax.random.PRNGKey(0))
    coarse = sil.errors(problem, None)[0, 1:]
    np.testing.assert_allclose(sil.coarse_weights(problem)[0, 1:], 1 / coarse**2)
    schedule = optax.piecewise_constant_schedule(1e-2, {12: 0.0})
    result = sil.train(
        problem,
        net,
        unroll=4,
        iterations=14,
        lr=schedule,
        loss="relative_to_coarse",
        log=lambda s: None,
    )
    losses = np.asarray(result.losses)
    assert losses[0] == pytest.approx(1.0, rel=1e-9)
    trained = sil.errors(problem, result.net)[0, 1:]
    by_hand = np.mean(trained**2 / coarse**2)
    assert losses[13] == pytest.approx(by_hand, rel=1e-9)
    assert by_hand < 0.9


def test_the_density_input_reaches_the_network(problem):
    """``Corrector(density=True)``: one more node input, ``(rho / rho0 - 1) (c0 / U)^2``;
    with a non-zero decoder, a change of the density alone changes the correction, which
    it does not without the input (eager calls on the 64 coarse particles)."""
    import equinox as eqx

    state = problem.coarse.state
    graph = sil._graph(problem)
    nbrs = sil.allocate(problem)
    denser = state.replace(density=state.density * 1.002)
    for density in (True, False):
        net = sil.Corrector(problem, jax.random.PRNGKey(0), density=density)
        last = net.gns.decoder.weights[-1]
        net = eqx.tree_at(lambda n: n.gns.decoder.weights[-1], net, last + 0.1)
        # node inputs: the velocity (2), the density (1 or none), the type embedding (8)
        assert net.gns.node_encoder.weights[0].shape[0] == 2 + density + 8
        a, _ = net(state, graph, nbrs, problem.speed)
        b, _ = net(denser, graph, nbrs, problem.speed)
        change = float(np.abs(np.asarray(a) - np.asarray(b)).max())
        if density:
            params = problem.coarse.params
            c0, rho0 = float(params.sound_speed), float(params.reference_density)
            assert net.density == pytest.approx((rho0, (c0 / problem.speed) ** 2))
            assert change > 1e-6 * float(np.abs(np.asarray(a)).max())
        else:
            assert net.density is None and change == 0.0


def test_the_time_since_the_start_reaches_the_network(problem):
    """``Corrector(time_scales=(2, 8))``: two more node inputs, ``exp(-k / tau)`` with ``k``
    the coarse steps since the initial state; with a non-zero decoder, the same state at
    another step gets another correction, which it does not without them (eager calls)."""
    import equinox as eqx

    state, graph, nbrs = problem.coarse.state, sil._graph(problem), sil.allocate(problem)
    for time_scales in ((2, 8), None):
        net = sil.Corrector(problem, jax.random.PRNGKey(0), time_scales=time_scales)
        last = net.gns.decoder.weights[-1]
        net = eqx.tree_at(lambda n: n.gns.decoder.weights[-1], net, last + 0.1)
        # node inputs: the velocity (2), the clocks (2 or none), the type embedding (8)
        width = 2 + (2 if time_scales else 0) + 8
        assert net.gns.node_encoder.weights[0].shape[0] == width
        a, _ = net(state, graph, nbrs, problem.speed, 1)
        b, _ = net(state, graph, nbrs, problem.speed, 5)
        change = float(np.abs(np.asarray(a) - np.asarray(b)).max())
        if time_scales:
            assert change > 1e-6 * float(np.abs(np.asarray(a)).max())
        else:
            assert change == 0.0
    with pytest.raises(ValueError, match="time_scales must be positive numbers"):
        sil.Corrector(problem, jax.random.PRNGKey(0), time_scales=(0.0,))
    # a clock the caller did not give is refused, not read as step 0
    timed = sil.Corrector(problem, jax.random.PRNGKey(0), time_scales=(2,))
    with pytest.raises(ValueError, match="needs step, the coarse steps since the initial"):
        timed(state, graph, nbrs, problem.speed)
    for mode in ("correction", "gns"):
        with pytest.raises(ValueError, match="needs step"):
            sil.step(problem, timed, mode, state, problem.coarse.params, graph, nbrs)


def test_bad_arguments_are_named(problem):
    with pytest.raises(ValueError, match="loss must be one of relative, relative_to_coarse"):
        sil.train(
            problem,
            sil.Corrector(problem, jax.random.PRNGKey(0)),
            unroll=4,
            iterations=1,
            loss="mse",
        )
    with pytest.raises(ValueError, match="unroll must lie in 1..4"):
        sil.train(problem, sil.Corrector(problem, jax.random.PRNGKey(0)), unroll=5, iterations=1)
    with pytest.raises(ValueError, match="lr must be a positive number or an optax schedule"):
        sil.train(
            problem, sil.Corrector(problem, jax.random.PRNGKey(0)), lr=0.0, unroll=4, iterations=1
        )
    with pytest.raises(ValueError, match="mode must be one of"):
        sil.Corrector(problem, jax.random.PRNGKey(0), mode="hybrid")
    with pytest.raises(ValueError, match="scale must be a positive velocity"):
        sil.Corrector(problem, jax.random.PRNGKey(0), scale=0.0)
    with pytest.raises(ValueError, match="ratio must be a positive integer"):
        sil.make_problem(problem.coarse, problem.fine, horizon=2, ratio=0, viscosities=[0.01])
    with pytest.raises(ValueError, match="viscosities or conditions, not both"):
        sil.make_problem(
            problem.coarse, problem.fine, horizon=2, ratio=2, viscosities=[0.01], conditions=[{}]
        )
    # a closed tank may differ in its wall layers, a periodic box may not differ at all
    other = sphjax.cases.dam_break(n=4)
    with pytest.raises(ValueError, match="share the periodic axes"):
        sil.make_problem(problem.coarse, other, horizon=2, ratio=2)
    with pytest.raises(ValueError, match="probe_box must be"):
        sil.make_problem(problem.coarse, problem.fine, horizon=2, ratio=2, probe_box=((0, 1),))


def test_a_non_finite_gradient_stops_training_with_its_iteration(problem):
    """A NaN in the gradient (here from a NaN reference) stops ``train`` before Adam
    writes NaN into every weight, naming the iteration, instead of failing later as an
    unstable rollout."""
    import dataclasses

    poisoned = dataclasses.replace(problem, reference=problem.reference * np.nan)
    net = sil.Corrector(problem, jax.random.PRNGKey(0))
    with pytest.raises(FloatingPointError, match="not finite at iteration 1"):
        sil.train(poisoned, net, unroll=1, iterations=3, log=lambda s: None)


def test_the_startup_term_and_the_power_by_hand(problem):
    """``startup_steps=m, startup_weight=w, power=p``: the loss is ``(mean_k r_k^p + (w /
    m) sum_{k <= m} r_k^p)^(2/p)``, ``r_k = e_k / e^c_k`` (at ``p = 2`` the window's mean
    square plus the start-up term): ``(1 + w)^(2/p)`` for the untrained (zero) correction,
    the coarse solver; after eight updates (the schedule then stops them) the recorded
    loss equals the value computed by hand from :func:`errors` for the returned network,
    is lower than the untrained one, and lies above the window's mean square (p = 8 is
    nearer the largest step)."""
    import optax

    net = sil.Corrector(problem, jax.random.PRNGKey(0))
    coarse = sil.errors(problem, None)[0, 1:]
    schedule = optax.piecewise_constant_schedule(1e-2, {8: 0.0})
    result = sil.train(
        problem,
        net,
        unroll=4,
        iterations=10,
        lr=schedule,
        loss="relative_to_coarse",
        startup_steps=2,
        startup_weight=0.5,
        power=8,
        log=lambda s: None,
    )
    losses = np.asarray(result.losses)
    assert losses[0] == pytest.approx(1.5**0.25, rel=1e-6)
    r = sil.errors(problem, result.net)[0, 1:] / coarse
    by_hand = (np.mean(r**8) + 0.5 * np.mean(r[:2] ** 8)) ** 0.25
    assert losses[9] == pytest.approx(by_hand, rel=1e-6)
    assert np.mean(r**2) < by_hand < 0.9 * 1.5**0.25


def test_truncated_backpropagation_cuts_the_gradient_every_k_steps(problem):
    """``rollout(truncate=2)``: the same values; the gradient of the field at step 4 is
    that of a two-step rollout from the state after step 2 (held fixed), and differs from
    the untruncated one."""
    import equinox as eqx

    net = sil.Corrector(problem, jax.random.PRNGKey(0))
    last = net.gns.decoder.weights[-1]
    net = eqx.tree_at(lambda n: n.gns.decoder.weights[-1], net, last + 0.1)
    pc = problem.conditions[0][0]
    state, nbrs = problem.coarse.state, sil.allocate(problem)
    weight = jax.random.normal(jax.random.PRNGKey(1), problem.probes.shape)

    def field(net, start, n_steps, k, truncate):
        _, fields, _ = sil.rollout(problem, net, "correction", start, pc, n_steps, nbrs, truncate)
        return (fields[k - 1] * weight).sum()

    def grad(*args):
        g = eqx.filter_grad(field)(net, *args)
        return np.concatenate([np.ravel(a) for a in jax.tree_util.tree_leaves(g)])

    full = sil.rollout(problem, net, "correction", state, pc, 4, nbrs)
    cut = sil.rollout(problem, net, "correction", state, pc, 4, nbrs, truncate=2)
    np.testing.assert_array_equal(np.asarray(full[1]), np.asarray(cut[1]))
    after2 = jax.tree_util.tree_map(lambda a: a[1], full[0])
    g_cut, g_full = grad(state, 4, 4, 2), grad(state, 4, 4, None)
    g_restart = grad(after2, 2, 2, None)
    scale = np.abs(g_restart).max()
    np.testing.assert_allclose(g_cut, g_restart, atol=1e-4 * scale)
    assert np.abs(g_full - g_cut).max() > 1e-2 * scale


def test_meaningless_startup_and_truncation_arguments_are_refused(problem):
    net = sil.Corrector(problem, jax.random.PRNGKey(0))
    cases = [
        (dict(startup_weight=1.0), "startup_weight has no effect without startup_steps"),
        (dict(startup_steps=4), r"startup_steps must lie in 1..3"),
        (dict(startup_steps=0), r"startup_steps must lie in 1..3"),
        (dict(startup_steps=1.5), "startup_steps must be an integer"),
        (dict(startup_steps=2, startup_weight=0.0), "startup_weight must be positive"),
        (dict(startup_steps=2, startup_weight=-1.0), "startup_weight must be positive"),
        (dict(truncate=4), r"truncate must be an integer in 1..3"),
        (dict(truncate=0), r"truncate must be an integer in 1..3"),
        (dict(power=1.0), "power must be a finite number >= 2"),
        (dict(power=float("inf")), "power must be a finite number >= 2"),
    ]
    for kwargs, message in cases:
        with pytest.raises(ValueError, match=message) as info:
            sil.train(problem, net, unroll=4, iterations=1, log=lambda s: None, **kwargs)
        assert "\n" not in str(info.value)


def test_the_scripts_meaningless_arguments_are_refused_before_any_work(tmp_path, capsys):
    """docs/scripts/solver_in_the_loop.py refuses, in one line naming the flag and before
    it builds anything: a stage restart with nothing to resume, non-positive time scales,
    and a --resume PREFIX that no earlier --save wrote."""
    import importlib.util

    path = Path(__file__).resolve().parent.parent / "docs" / "scripts" / "solver_in_the_loop.py"
    spec = importlib.util.spec_from_file_location("sil_script", path)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    missing = str(tmp_path / "nothing")
    for argv, message in [
        (["--restart-optimizer"], "--restart-optimizer needs --resume"),
        (["--time-scales", "5", "0"], "--time-scales must be positive numbers"),
        (["--resume", missing], f"{missing}.correction.eqx does not exist"),
        (["--warmup", "10"], "--warmup 10 needs --iterations"),
        (["--early", missing], "--early and --switch go together"),
        (["--early", missing, "--switch", "20"], "--early: a staged correction; give --networks"),
        (
            ["--early", missing, "--switch", "1", "--networks", "correction"],
            "--switch 1: give a coarse step in 2..100",
        ),
        (
            ["--early", missing, "--switch", "20", "--networks", "correction"],
            f"{missing}.correction.eqx does not exist",
        ),
        (["--warmup", "50", "--iterations", "50"], "must lie between 0 and it"),
    ]:
        with pytest.raises(SystemExit):
            script.main(["--out", str(tmp_path / "out.json"), *argv])
        assert message in capsys.readouterr().err


def test_the_scripts_warmup_rises_to_the_rate_then_decays_to_the_final_one():
    """docs/scripts/solver_in_the_loop.py --warmup W: 0 at the first iteration, --lr after
    W, --lr-final at --iterations; without a warm-up the decay starts at --lr."""
    import importlib.util

    path = Path(__file__).resolve().parent.parent / "docs" / "scripts" / "solver_in_the_loop.py"
    spec = importlib.util.spec_from_file_location("sil_script", path)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    schedule = script.learning_rate(3e-4, 250, 1e-5, warmup=50)
    assert float(schedule(0)) == 0.0
    np.testing.assert_allclose(float(schedule(25)), 1.5e-4, rtol=1e-6)
    np.testing.assert_allclose(float(schedule(50)), 3e-4, rtol=1e-6)
    np.testing.assert_allclose(float(schedule(250)), 1e-5, rtol=1e-5)
    assert float(schedule(150)) < 3e-4
    constant = script.learning_rate(1e-3, 100, None, warmup=10)
    np.testing.assert_allclose([float(constant(k)) for k in (5, 10, 99)], [5e-4, 1e-3, 1e-3])
    np.testing.assert_allclose(float(script.learning_rate(3e-4, 250, 1e-5)(0)), 3e-4)
    assert script.learning_rate(1e-3) == 1e-3


def test_a_staged_correction_switches_networks_and_trains_the_late_one_only(problem):
    """``StagedCorrector(early, late, switch)``: the early network's correction before
    step ``switch``, the late one's from it on (eager calls); trained, the early network's
    parameters stay exactly as they were and the late one's change, and the loss falls."""
    import equinox as eqx

    state, graph, nbrs = problem.coarse.state, sil._graph(problem), sil.allocate(problem)
    early = sil.Corrector(problem, jax.random.PRNGKey(0))
    early = eqx.tree_at(
        lambda n: n.gns.decoder.weights[-1], early, early.gns.decoder.weights[-1] + 0.1
    )
    late = sil.Corrector(problem, jax.random.PRNGKey(1))
    staged = sil.StagedCorrector(early, late, 3)
    for k, alone in ((1, early), (2, early), (3, late), (4, late)):
        got, _ = staged(state, graph, nbrs, problem.speed, k)
        want, _ = alone(state, graph, nbrs, problem.speed, k)
        np.testing.assert_allclose(np.asarray(got), np.asarray(want), rtol=1e-12, atol=1e-15)
    assert float(np.abs(np.asarray(staged(state, graph, nbrs, problem.speed, 1)[0])).max()) > 0
    result = sil.train(problem, staged, unroll=4, iterations=8, lr=1e-2, log=lambda s: None)
    before, after = eqx.filter(staged, eqx.is_array), eqx.filter(result.net, eqx.is_array)
    for a, b in zip(jax.tree.leaves(before.early), jax.tree.leaves(after.early), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    changed = [
        not np.array_equal(np.asarray(a), np.asarray(b))
        for a, b in zip(jax.tree.leaves(before.late), jax.tree.leaves(after.late), strict=True)
    ]
    assert any(changed)
    losses = np.asarray(result.losses)
    assert np.isfinite(losses).all() and losses[-2:].mean() < losses[0]
    for switch in (1, True, 2.5):
        with pytest.raises(ValueError, match="switch must be an integer >= 2"):
            sil.StagedCorrector(early, late, switch)
    with pytest.raises(ValueError, match="needs step"):
        staged(state, graph, nbrs, problem.speed)
