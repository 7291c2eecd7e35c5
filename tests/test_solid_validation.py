"""Validation of the elastic solid against the literature (slow).

Reference numbers copied from VALIDATION.md ("Solid cases"):

* Oscillating plate (Gray, Monaghan & Swift 2001), V_f = 0.001: linear-theory period
  0.2541 s, tip amplitude V_f c0 / omega = 2.31e-3 m.  Tolerances (issue 3): period 5 %,
  amplitude 10 % (the reference is linear Euler-Bernoulli theory, which ignores shear and
  rotary inertia of the H / L = 0.1 plate; SPH converges towards it from a softer plate).
* Turek-Hron CSM3: tip u_y = -63.607 +- 65.160 mm at 1.0995 Hz.  Tolerances (issue 3):
  mean and amplitude 10 %, frequency 5 %.

Resolutions are the coarsest that meet the tolerances (docs/validation_solid.md has the
convergence tables); the runs are float32, as a user runs them.  The plate period error is
4.1 % at H/dx = 12.  CSM3 is tested with the default set-up (particles on the faces,
embedded root), which meets the targets of issue 14 (2 / 3 / 1.5 %) at 17 across; the
cell-centred set-up of earlier versions (``placement="cell"``) does not at <= 17 across
(+5.3 % / +2.8 % at 16, docs/validation_solid.md) and is no longer run here.
"""

from __future__ import annotations

import numpy as np
import pytest

import sphjax
from sphjax.cases import oscillation_stats, tip_displacement

PLATE_PERIOD = 0.2541  # s, VALIDATION.md
PLATE_TIP_AMPLITUDE = 2.31e-3  # m, V_f c0 / omega for V_f = 0.001, VALIDATION.md
CSM3_UY_MEAN, CSM3_UY_AMPLITUDE, CSM3_FREQUENCY = -63.607e-3, 65.160e-3, 1.0995

PLATE_N = 12


@pytest.mark.slow
def test_oscillating_plate_period_and_amplitude():
    case = sphjax.cases.oscillating_plate(n=PLATE_N, amplitude=0.001, h_factor=1.2, cfl=0.5)
    save_every = 20
    n_steps = save_every * int(np.ceil(0.42 / case.dt / save_every))  # > 1.5 periods
    traj = sphjax.simulate(case, n_steps=n_steps, save_every=save_every)
    uy = np.asarray(tip_displacement(traj, case))[:, 1]
    stats = oscillation_stats(np.asarray(traj.times), uy)
    assert abs(stats["period"] / PLATE_PERIOD - 1) < 0.05, stats
    assert abs(stats["amplitude"] / PLATE_TIP_AMPLITUDE - 1) < 0.10, stats
    assert abs(stats["mean"]) < 0.05 * PLATE_TIP_AMPLITUDE, stats  # oscillates about 0


@pytest.mark.slow
def test_turek_hron_csm3_tip_reference_setup():
    """CSM3 with the default set-up, the reference SPH codes' one (particles on the faces,
    h = sqrt(2) dp, root embedded in the cylinder), 9 particles across.  Measured
    (float32): mean / amplitude / frequency -0.89 % / -3.25 % / +0.79 % at 9 across,
    -0.86 / -3.22 / +0.86 % at 13,
    +1.46 / -0.96 / -0.30 % at 17, where the targets of issue 14 (2 / 3 / 1.5 %) are met
    (docs/validation_solid.md; 17 across is too expensive for CI).  Bounds here: the
    targets, with 4 % for the amplitude at this resolution."""
    case = sphjax.cases.turek_hron_csm(n=9, cfl=0.5)
    save_every = 50
    n_steps = save_every * int(np.ceil(2.1 / case.dt / save_every))
    traj = sphjax.simulate(case, n_steps=n_steps, save_every=save_every)
    uy = np.asarray(tip_displacement(traj, case))[:, 1]
    stats = oscillation_stats(np.asarray(traj.times), uy)
    assert abs(stats["mean"] / CSM3_UY_MEAN - 1) < 0.02, stats
    assert abs(stats["amplitude"] / CSM3_UY_AMPLITUDE - 1) < 0.04, stats
    assert abs(stats["frequency"] / CSM3_FREQUENCY - 1) < 0.015, stats


# Turek & Hron (2006), CSM1 and CSM2 steady tip displacements (m), E = 1.4e6 / 5.6e6 Pa.
CSM_STEADY = {"CSM1": (1.4e6, -7.187e-3, -66.10e-3), "CSM2": (5.6e6, -0.469e-3, -16.97e-3)}
# end time of the damped run (s): settled to about 0.1 % by then (measured at 9 across)
CSM_STEADY_T_END = {"CSM1": 1.2, "CSM2": 0.9}
CSM_STEADY_N = 9


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CSM_STEADY))
def test_turek_hron_steady_tip(name):
    """CSM1 / CSM2: the static equilibrium under gravity (damped dynamics,
    ``relax_to_rest``) with the reference SPH codes' set-up (particles on the faces,
    h = sqrt(2) dp, root embedded in the cylinder), 9 particles across.  Measured there:
    u_y -3.4 % / -3.3 %, u_x -8.6 % / -8.3 % (u_x is the shortening of the bent beam,
    about quadratic in u_y); at 17 across see docs/validation_solid.md.  Bounds: u_y 4 %,
    u_x 10 %, and the beam must have settled (the last two segments, 0.1 s apart, agree to
    0.2 %).
    About 30 s each on an idle core."""
    E, ux_ref, uy_ref = CSM_STEADY[name]
    case = sphjax.cases.turek_hron_csm(n=CSM_STEADY_N, young_modulus=E, cfl=0.5)
    assert case.info["reference_steady"]["uy"] == uy_ref
    # damping rate 1.4 * 2 pi f sqrt(E / E_CSM1), f = CSM3's frequency: the beam settles
    # in about one period without overshooting much
    rate = 1.4 * 2 * np.pi * 1.0995 * np.sqrt(E / 1.4e6)
    t_end = CSM_STEADY_T_END[name]
    _, states = sphjax.cases.relax_to_rest(
        case, t_end=t_end, damping_rate=rate, segments=int(round(10 * t_end))
    )
    ux, uy = np.asarray(tip_displacement(states, case)).T
    assert abs(uy[-1] - uy[-2]) < 0.002 * abs(uy_ref)
    assert uy[-1] == pytest.approx(uy_ref, rel=0.04)
    assert ux[-1] == pytest.approx(ux_ref, rel=0.10)


@pytest.fixture(scope="module")
def small_beam():
    return sphjax.cases.turek_hron_csm(n=3)


@pytest.mark.parametrize(
    "bad, name",
    [
        (dict(t_end=-1.0, damping_rate=1.0, segments=2), "t_end"),
        (dict(t_end=1.0, damping_rate=-1.0, segments=2), "damping_rate"),
        (dict(t_end=1.0, damping_rate=1.0, segments=0), "segments"),
    ],
)
def test_relax_to_rest_bad_input_is_named(bad, name, small_beam):
    with pytest.raises(ValueError, match=f"^{name} must be"):
        sphjax.cases.relax_to_rest(small_beam, **bad)


def test_turek_hron_bad_placement_is_named():
    with pytest.raises(ValueError, match="^placement must be 'cell' or 'surface'"):
        sphjax.cases.turek_hron_csm(n=3, placement="edges")


def test_turek_hron_default_is_the_reference_setup(small_beam):
    """The default is the set-up that converges (docs/validation_solid.md): rows on the
    faces (spacing H / (n - 1)), h = sqrt(2) dx; the cell-centred one stays reachable."""
    case = small_beam  # n = 3, the defaults
    assert case.info["dx"] == pytest.approx(0.02 / 2)
    old = sphjax.cases.turek_hron_csm(n=3, placement="cell", embedded_root=False)
    assert old.info["dx"] == pytest.approx(0.02 / 3)

    # the embedded root: free beam particles inside the cylinder's right half (x < 0.25)
    def free_in_cylinder(c):
        x, kind = np.asarray(c.state.position), np.asarray(c.state.kind)
        return int(np.sum((kind == sphjax.Kind.SOLID) & (x[:, 0] < 0.245)))

    assert free_in_cylinder(case) > 0
    assert free_in_cylinder(old) == 0
    # a spacing maps onto n rows with H / (n - 1) between them
    by_spacing = sphjax.cases.get("turek_hron_csm", dx=0.02 / 4)
    assert by_spacing.info["n"] == 5 and by_spacing.info["dx"] == pytest.approx(0.005)
