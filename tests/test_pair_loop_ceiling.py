"""The pair loops that benchmarks/pair_loop_ceiling.py and benchmarks/pair_loop_ffi.py time
against the XLA step do the step's work: from the same lattice start, after 40 steps, the
C loop's kinetic energy (each pair once or from both sides, or cell-blocked: one and two
threads, cells of the support and of half of it, four particles at once) and the FFI
handler's positions and velocities are sphjax's to float32 round-off (otherwise their
timings would not be of the same computation)."""

from __future__ import annotations

import importlib.util
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import sphjax

BENCHMARK = Path(__file__).resolve().parent.parent / "benchmarks" / "pair_loop_ceiling.py"


def built(compile):
    """What ``compile()`` builds; the test is skipped, with the compiler's message, where
    this machine's compiler cannot build it (no OpenMP, no C++17)."""
    try:
        return compile()
    except subprocess.CalledProcessError as error:
        pytest.skip(f"the compiler could not build the loop: {error.stderr.strip()[:200]}")


def lattice_taylor_green(n):
    """The benchmarks' Taylor-Green (benchmarks/throughput.py) from the lattice, the C
    loops' start."""
    return sphjax.cases.taylor_green(
        n=n,
        kernel="quintic_spline",
        h_factor=1.0,
        density="summation",
        transport_velocity=False,
        disorder=0.0,
        relax_iterations=0,
    )


@pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")
def test_the_c_pair_loop_computes_the_sphjax_step(tmp_path):
    spec = importlib.util.spec_from_file_location("pair_loop_ceiling", BENCHMARK)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    binary = built(lambda: bench.compile_loop("gcc", str(tmp_path)))
    n, steps = 40, 40
    both = bench.run_loop(binary, n, steps, threads=1, mode="both")
    once = bench.run_loop(binary, n, steps, threads=1, mode="once")
    cells = [
        bench.run_loop(binary, n, steps, threads, mode="cells", split=split)
        for threads in (1, 2)
        for split in (1, 2)
    ]
    cells.append(bench.run_loop(binary, n, steps, threads=1, mode="cells_by_4"))
    case = lattice_taylor_green(n)
    traj = sphjax.simulate(case, n_steps=steps, save_every=steps, dt=0.25 / n / 11.0)
    velocity = np.asarray(traj.states.velocity[-1], dtype=np.float64)
    mass = np.asarray(traj.states.mass[-1], dtype=np.float64)
    kinetic = 0.5 * np.sum(mass[:, None] * velocity**2)
    assert 0.23 < kinetic < 0.25  # it decayed from 1/4, as the vortex does
    for row in (both, once, *cells):
        assert abs(row["kinetic_energy"] / kinetic - 1) < 1e-5
    # quintic spline, support 3 h = 3 dx: about pi 3^2 = 28 neighbours on the lattice
    assert 26 <= both["neighbours_inside"] <= 30
    # each pair once (the cell-blocked loop too): the same pairs, less the particle itself
    for row in (once, *cells):
        assert row["neighbours_inside"] == pytest.approx(both["neighbours_inside"] - 1)


@pytest.mark.skipif(shutil.which("g++") is None, reason="needs a C++ compiler")
def test_the_ffi_pair_loop_in_a_jitted_scan_is_the_sphjax_step(tmp_path):
    """benchmarks/pair_loop_ffi.py: the same right-hand side as an XLA FFI handler inside a
    jitted lax.scan; after 40 steps from the lattice its positions and velocities are
    sphjax's to float32 round-off."""
    spec = importlib.util.spec_from_file_location(
        "pair_loop_ffi", BENCHMARK.parent / "pair_loop_ffi.py"
    )
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    bench.register(built(lambda: bench.build("g++", str(tmp_path))))
    n, steps = 40, 40
    case = lattice_taylor_green(n)
    dt = 0.25 / n / 11.0
    run, x0, v0 = bench.simulate_ffi(case, steps, dt)
    position, velocity = (np.asarray(a) for a in run(x0, v0))
    traj = sphjax.simulate(case, n_steps=steps, save_every=steps, dt=dt)
    np.testing.assert_allclose(position, np.asarray(traj.states.position[-1]), atol=1e-6)
    # velocities of order 1: float32 round-off over 40 steps of two pair sums
    np.testing.assert_allclose(velocity, np.asarray(traj.states.velocity[-1]), atol=1e-4)
    assert np.abs(velocity - np.asarray(v0)).max() > 1e-3  # it moved
