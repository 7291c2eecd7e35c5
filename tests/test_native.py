"""``Model.pair_loop="native"``: the fluid's own density and momentum sums as compiled
loops (:mod:`sphjax.native`, each pair once) give XLA's sums to round-off, for every
kernel, in 2D and 3D, with summation and continuity density, delta-SPH and both
viscosities; runs
follow XLA's; derivatives are XLA's exactly; what it cannot do is refused in one line."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import sphjax
from sphjax import native
from sphjax.core.kernels import CubicSpline, QuinticSpline
from sphjax.physics import rhs

pytestmark = pytest.mark.skipif(
    native.compiler() is None, reason="no C++ compiler to build sphjax.native"
)


def with_kernel(case, kernel):
    return case.replace(model=dataclasses.replace(case.model, kernel=kernel))


def natively(case):
    return case.replace(model=dataclasses.replace(case.model, pair_loop="native"))


def relative(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


CASES = {
    # summation density, Morris viscosity, quintic spline (the throughput benchmark's)
    "taylor_green": lambda: sphjax.cases.taylor_green(
        n=12, h_factor=1.0, transport_velocity=False, relax_iterations=20
    ),
    # continuity density, Monaghan and Morris viscosity, Wendland C2
    "taylor_green_continuity": lambda: sphjax.cases.taylor_green(
        n=12,
        kernel="wendland_c2",
        density="continuity",
        artificial_alpha=0.1,
        transport_velocity=False,
        relax_iterations=20,
    ),
    # cubic spline, continuity density, walls (their sums in XLA beside the loops)
    "dam_break": lambda: with_kernel(
        sphjax.cases.dam_break(n=10, density_diffusion=None), CubicSpline()
    ),
    # delta-SPH of Molteni & Colagrossi (both roles of each pair in the loop), quintic
    "dam_break_molteni": lambda: sphjax.cases.dam_break(n=10),
    # summation density against no-slip walls, one of them sliding (the lid), Morris
    "cavity": lambda: sphjax.cases.lid_driven_cavity(n=12, transport_velocity=False),
    # the fluid against an elastic plate's particles (fluid-solid momentum in the loop)
    "fsi_plate": lambda: sphjax.cases.hydrostatic_fsi_plate(n=4),
    # a rigid body's particles as the fluid's moving boundary
    "settling_disk": lambda: sphjax.cases.settling_disk(n=6),
    # inflow and outflow buffers (fluid-open boundary momentum in the loop)
    "channel_flow": lambda: sphjax.cases.channel_flow(n=8),
    # 3D, Wendland C4
    "abc_flow_3d": lambda: sphjax.cases.abc_flow_3d(
        n=6, kernel="wendland_c4", transport_velocity=False, relax_iterations=10
    ),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_native_sums_equal_xla_to_round_off(name):
    """One evaluation (float64) from the case's start, with uneven masses and a
    perturbed velocity: acceleration, density, its rate and pressure within 1e-12 of
    XLA's (relative to their largest entries)."""
    case = CASES[name]()
    s = case.state
    state = s.replace(
        mass=s.mass * (1.0 + 0.05 * jnp.sin(7.0 * s.position[:, 0])),
        velocity=s.velocity + 0.01 * jnp.cos(5.0 * s.position),
    )
    neighbors = rhs.build_neighbors(state, case.model)
    xla = rhs.evaluate(state, neighbors, case.model, case.params)
    loops = rhs.evaluate(state, neighbors, natively(case).model, case.params)
    for field in ("acceleration", "density", "density_rate", "pressure"):
        expected = getattr(xla, field)
        if np.abs(np.asarray(expected)).max() > 0:
            assert relative(getattr(loops, field), expected) < 1e-12, field


def _native_calls(case) -> dict[str, int]:
    """How many times one evaluation of ``case`` calls each native handler."""
    neighbors = rhs.build_neighbors(case.state, case.model)
    text = str(
        jax.make_jaxpr(lambda s: rhs.evaluate(s, neighbors, case.model, case.params))(case.state)
    )
    names = [part.split()[0].rstrip(",]") for part in text.split("target_name=")[1:]]
    return {name: names.count(name) for name in names}


def test_the_walls_sums_run_in_the_loops():
    """A dam break's sums between the fluid and its walls (the walls' extrapolation, the
    fluid's density rate and momentum against them) are native calls beside the fluid's
    own; so are the summation density against a cavity's walls and the momentum against
    a plate's particles."""
    dam = _native_calls(natively(CASES["dam_break"]()))
    assert dam == {
        "sphjax_extrapolation": 1,
        "sphjax_velocity_divergence": 2,
        "sphjax_momentum": 2,
    }, dam
    cavity = _native_calls(natively(CASES["cavity"]()))
    assert cavity["sphjax_kernel_sum"] == 2 and cavity["sphjax_momentum"] == 2, cavity
    fsi = _native_calls(natively(CASES["fsi_plate"]()))
    assert fsi["sphjax_momentum"] == 3, fsi  # fluid-fluid, fluid-wall, fluid-plate


def test_derivatives_through_native_walls_are_xlas():
    """Reverse mode through 10 steps of a native dam break (walls, Molteni's diffusion)
    equals that through the XLA run to round-off."""
    case = CASES["dam_break_molteni"]()

    def loss(case, alpha, velocity):
        params = case.params.replace(artificial_alpha=alpha)
        state = case.state.replace(velocity=velocity)
        final = sphjax.simulate(case, params, n_steps=10, state=state).final
        return jnp.sum(final.mass * final.position[:, 1])

    alpha, v = case.params.artificial_alpha, case.state.velocity
    grads = [
        jax.jit(jax.grad(lambda a, v, c=c: loss(c, a, v), argnums=(0, 1)))(alpha, v)
        for c in (case, natively(case))
    ]
    assert relative(grads[1][0], grads[0][0]) < 1e-10
    assert relative(grads[1][1], grads[0][1]) < 1e-10
    assert np.abs(np.asarray(grads[0][1])).max() > 0


def test_a_native_run_follows_the_xla_run():
    """100 steps of the Taylor-Green vortex (float64): positions within 1e-10 of XLA's
    run (the box is 1), the kinetic energy within 1e-10 relative."""
    case = CASES["taylor_green"]()
    xla = sphjax.simulate(case, n_steps=100)
    loops = sphjax.simulate(natively(case), n_steps=100)
    assert float(np.abs(np.asarray(loops.final.position - xla.final.position)).max()) < 1e-10
    energy = [float(jnp.sum(t.final.mass * jnp.sum(t.final.velocity**2, -1))) for t in (xla, loops)]
    assert abs(energy[1] - energy[0]) < 1e-10 * energy[0]


def test_a_native_run_in_float32_agrees_with_xla_to_its_round_off():
    """The same run in float32: positions within 1e-5 of XLA's after 100 steps."""
    previous = jax.config.jax_enable_x64
    jax.config.update("jax_enable_x64", False)
    try:
        case = CASES["taylor_green"]()
        xla = sphjax.simulate(case, n_steps=100)
        loops = sphjax.simulate(natively(case), n_steps=100)
        assert loops.final.position.dtype == jnp.float32
        difference = np.abs(np.asarray(loops.final.position - xla.final.position)).max()
        assert difference < 1e-5
    finally:
        jax.config.update("jax_enable_x64", previous)


def test_derivatives_through_a_native_run_are_xlas():
    """Reverse and forward mode through a native run (10 steps, checkpointed) equal
    those through the XLA run to round-off: derivatives never see the loops."""
    case = CASES["taylor_green_continuity"]()

    def loss(case, nu, velocity):
        params = case.params.replace(kinematic_viscosity=nu)
        state = case.state.replace(velocity=velocity)
        final = sphjax.simulate(case, params, n_steps=10, state=state, checkpoint_every=5).final
        return jnp.sum(final.mass * jnp.sum(final.velocity**2, -1))

    nu, v = case.params.kinematic_viscosity, case.state.velocity
    grads = [jax.grad(loss, argnums=(1, 2))(c, nu, v) for c in (case, natively(case))]
    assert float(grads[0][0]) < 0
    assert relative(grads[1][0], grads[0][0]) < 1e-12
    assert relative(grads[1][1], grads[0][1]) < 1e-12
    direction = jnp.sin(3.0 * case.state.position)
    tangents = [
        jax.jvp(lambda nu, v, c=c: loss(c, nu, v), (nu, v), (0.5 * nu, direction))[1]
        for c in (case, natively(case))
    ]
    assert relative(tangents[1], tangents[0]) < 1e-12


def test_native_sums_batch_under_vmap():
    """``jax.vmap`` over two viscosities: each row equals its own native evaluation."""
    case = natively(CASES["taylor_green"]())
    neighbors = rhs.build_neighbors(case.state, case.model)

    def acceleration(nu):
        params = case.params.replace(kinematic_viscosity=nu)
        return rhs.evaluate(case.state, neighbors, case.model, params).acceleration

    nus = jnp.stack([case.params.kinematic_viscosity, 3.0 * case.params.kinematic_viscosity])
    batched = jax.vmap(acceleration)(nus)
    for k in range(2):
        assert relative(batched[k], acceleration(nus[k])) < 1e-12
    assert relative(batched[0], batched[1]) > 1e-6  # the viscosity reached the loop


def test_what_the_native_loops_cannot_do_is_refused_in_one_line(monkeypatch):
    case = CASES["taylor_green"]()
    with pytest.raises(ValueError, match=r"Model.pair_loop must be 'xla' or 'native'"):
        dataclasses.replace(case.model, pair_loop="c++")
    walls = sphjax.Model(
        dim=2,
        smoothing_length=0.1,
        domain=sphjax.Domain((0.0, 0.0), (1.0, 1.0), (False, False)),
        systems=(sphjax.WallSystem(),),
    )
    with pytest.raises(
        ValueError, match=r"a fluid and of an elastic solid only .* use pair_loop='xla'"
    ):
        dataclasses.replace(walls, pair_loop="native")
    # a solid with the second-order correction: no loop (its sums stay XLA's)
    plate = sphjax.cases.oscillating_plate(n=6)
    second_order = plate.model.systems[0].replace(gradient_correction="second_order")
    with pytest.raises(ValueError, match=r"first-order correction\) .* use pair_loop='xla'"):
        dataclasses.replace(plate.model, systems=(second_order,), pair_loop="native")
    for options in ({}, {"penalty_alpha": 0.1}):
        solid = sphjax.cases.oscillating_plate(n=6, **options).model
        assert dataclasses.replace(solid, pair_loop="native").pair_loop == "native"

    @dataclasses.dataclass(frozen=True)
    class Gaussian(QuinticSpline):
        pass

    with pytest.raises(ValueError, match=r"not Gaussian; use pair_loop='xla'"):
        dataclasses.replace(case.model, kernel=Gaussian(), pair_loop="native")

    # no compiler: the first run that needs the loops says so, naming the fix
    monkeypatch.setattr(native, "compiler", lambda: None)
    native.library.cache_clear()
    try:
        with pytest.raises(
            native.NativeUnavailable, match=r"needs a C\+\+ compiler .*pair_loop='xla'"
        ):
            native.library()
    finally:
        monkeypatch.undo()
        native.library.cache_clear()


@pytest.mark.parametrize(
    "case",
    [
        ["taylor_green", "--n", "8", "--t-end", "0.011"],
        # an elastic solid's loops (eq. 16, eq. 14 row by row over the stored weights)
        ["oscillating_plate", "--n", "4", "--t-end", "0.001"],
        # eq. 14 with the penalty force, each pair once
        ["oscillating_plate", "--n", "4", "--t-end", "0.001", "--case-arg", "penalty_alpha=0.1"],
    ],
    ids=["taylor_green", "oscillating_plate", "oscillating_plate_penalty"],
)
def test_sphjax_run_with_native_loops_writes_the_xla_runs_frames(tmp_path, case):
    """``sphjax run ... --pair-loop native`` (float64) writes the frames of the run
    without it to 1e-10."""
    from sphjax.cli import main
    from sphjax.io import read_trajectory

    tiny = [*case, "--quiet", "--float64"]
    paths = {loop: tmp_path / f"{loop}.h5" for loop in ("xla", "native")}
    for loop, path in paths.items():
        assert main(["run", *tiny, "--pair-loop", loop, "--out", str(path)]) == 0
    xla, loops = (read_trajectory(paths[k])[0] for k in ("xla", "native"))
    assert xla.states.position.shape == loops.states.position.shape
    assert len(xla.times) > 1
    assert float(np.abs(np.asarray(loops.states.position - xla.states.position)).max()) < 1e-10


def test_the_pair_loops_are_vectorised():
    """The built library's momentum and kernel sums (float32, 2D, quintic spline) run
    their pair loops on AVX registers: GCC leaves a loop scalar, three times slower, when
    it does not inline the pair geometry into it (it happened once, silently)."""
    import re
    import shutil
    import subprocess
    from pathlib import Path

    objdump = shutil.which("objdump")
    flags = Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").exists() else ""
    if objdump is None or " avx2" not in flags:
        pytest.skip("needs objdump and an AVX2 CPU")
    text = subprocess.run(
        [objdump, "-d", "-C", "--no-show-raw-insn", native.library()],
        capture_output=True,
        text=True,
    ).stdout
    functions = re.split(r"\n(?=[0-9a-f]+ <)", text)
    for term in ("MomentumTerm<float, 2>", "KernelSumTerm<float, 2>"):
        for loop in ("each_pair_once", "rows_against_columns"):
            name = f"{loop}<float, 2, 1, (anonymous namespace)::{term}"
            bodies = [f for f in functions if name in f.split("\n", 1)[0]]
            packed = sum(len(re.findall(r"\tv\w+ps\s[^\n]*%ymm", f)) for f in bodies)
            assert packed >= 10, (loop, term, packed)
