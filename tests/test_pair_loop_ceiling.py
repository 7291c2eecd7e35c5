"""The C pair loop that benchmarks/pair_loop_ceiling.py times against the XLA step does the
step's work: from the same lattice start its kinetic energy after 40 steps is sphjax's to
float32 round-off, visiting each pair once or from both sides (otherwise its timings would
not be of the same computation)."""

from __future__ import annotations

import importlib.util
import shutil
from pathlib import Path

import numpy as np
import pytest

import sphjax

BENCHMARK = Path(__file__).resolve().parent.parent / "benchmarks" / "pair_loop_ceiling.py"


@pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")
def test_the_c_pair_loop_computes_the_sphjax_step(tmp_path):
    spec = importlib.util.spec_from_file_location("pair_loop_ceiling", BENCHMARK)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    binary = bench.compile_loop("gcc", str(tmp_path))
    n, steps = 40, 40
    both = bench.run_loop(binary, n, steps, threads=1, half=False)
    once = bench.run_loop(binary, n, steps, threads=1, half=True)
    # the benchmark's Taylor-Green from the lattice (the C loop's start), its time step
    case = sphjax.cases.taylor_green(
        n=n,
        kernel="quintic_spline",
        h_factor=1.0,
        density="summation",
        transport_velocity=False,
        disorder=0.0,
        relax_iterations=0,
    )
    traj = sphjax.simulate(case, n_steps=steps, save_every=steps, dt=0.25 / n / 11.0)
    velocity = np.asarray(traj.states.velocity[-1], dtype=np.float64)
    mass = np.asarray(traj.states.mass[-1], dtype=np.float64)
    kinetic = 0.5 * np.sum(mass[:, None] * velocity**2)
    assert 0.23 < kinetic < 0.25  # it decayed from 1/4, as the vortex does
    for row in (both, once):
        assert abs(row["kinetic_energy"] / kinetic - 1) < 1e-5
    # quintic spline, support 3 h = 3 dx: about pi 3^2 = 28 neighbours on the lattice
    assert 26 <= both["neighbours_inside"] <= 30
