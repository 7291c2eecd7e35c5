"""LagrangeBench's rollout metrics against hand-computed values, and the checks that keep
a mismatched dataset or a rollout that does not fit from being scored (sphjax.surrogate).

Cost: the metric tests are pure array arithmetic (< 1 s each with ott-jax's Sinkhorn on
20 points); the rollout checks raise before anything compiles.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from _tiny_dataset import KWARGS, shared

from sphjax.surrogate import LearnedSimulator, SimulatorConfig, data, rollout_metrics
from sphjax.surrogate.metrics import (
    lb_ekin_mse,
    lb_kinetic_energy,
    lb_mse,
    lb_mse_curve,
    mse_sumdim_curve,
    sinkhorn_distance,
)

OPEN = [[0.0, 10.0], [0.0, 10.0]]
NOT_PERIODIC = (False, False)


def test_lb_mse_is_the_mean_over_particles_dimensions_and_first_steps():
    rng = np.random.default_rng(0)
    truth = rng.uniform(2.0, 8.0, (3, 4, 2))
    c = np.array([0.1, 0.2, 0.3])
    pred = truth + np.stack([c, 0 * c], -1)[:, None, :]  # step k shifted by c_k along x
    curve = np.asarray(lb_mse_curve(pred, truth, OPEN, NOT_PERIODIC))
    # by hand: (c_k^2 + 0) / 2 dimensions, the same for every particle
    np.testing.assert_allclose(curve, [0.005, 0.02, 0.045], rtol=1e-12)
    assert lb_mse(curve, 2) == pytest.approx((0.005 + 0.02) / 2, rel=1e-12)
    assert lb_mse(curve, 3) == pytest.approx(0.07 / 3, rel=1e-12)
    with pytest.raises(ValueError, match="MSE5 needs a rollout of at least 5 steps"):
        lb_mse(curve, 5)
    # the original sphjax definition sums over dimensions
    ours = np.asarray(mse_sumdim_curve(pred, truth, OPEN, NOT_PERIODIC, np.ones(4, bool)))
    np.testing.assert_allclose(ours, c**2, rtol=1e-12)
    # a padding mask leaves the padded particles out of the mean
    pred[:, 3] += 100.0
    masked = lb_mse_curve(pred, truth, OPEN, NOT_PERIODIC, np.array([1, 1, 1, 0], bool))
    np.testing.assert_allclose(np.asarray(masked), [0.005, 0.02, 0.045], rtol=1e-12)


def test_lb_mse_uses_the_minimum_image():
    truth = np.array([[[0.01, 0.5]]])
    pred = np.array([[[0.99, 0.5]]])  # 0.02 apart across the periodic edge, not 0.98
    curve = lb_mse_curve(pred, truth, [[0.0, 1.0], [0.0, 1.0]], (True, True))
    assert float(curve[0]) == pytest.approx(0.02**2 / 2, rel=1e-9)


def test_lb_kinetic_energy_and_its_error_by_hand():
    step = np.array([0.01, 0.02])  # displacement per frame
    frames = np.array([[[1.0, 1.0], [2.0, 3.0], [4.0, 4.0]]]) + np.arange(5)[:, None, None] * step
    frame_dt, dx = 0.5, 0.1
    e = np.asarray(lb_kinetic_energy(frames, OPEN, NOT_PERIODIC, frame_dt, dx, stride=2))
    # v = step / frame_dt = (0.02, 0.04); |v|^2 = 0.002; E = dx^2 * 3 particles * 0.002,
    # at rollout frames 0 and 2 (stride 2 over 5 frames)
    np.testing.assert_allclose(e, [6e-5, 6e-5], rtol=1e-9)
    faster = np.array([[[1.0, 1.0], [2.0, 3.0], [4.0, 4.0]]]) + np.arange(5)[:, None, None] * (
        2 * step
    )
    # twice the speed: E = 2.4e-4, error (1.8e-4)^2
    err = lb_ekin_mse(faster, frames, OPEN, NOT_PERIODIC, frame_dt, dx, stride=2)
    assert err == pytest.approx(1.8e-4**2, rel=1e-9)


def test_sinkhorn_distance_of_a_translated_cloud_is_the_squared_shift():
    # entropic OT with squared-distance cost: a translation adds |delta|^2 - 2 delta.(E x - E y)
    # (separable terms), and the self terms cancel, so S(x, x + delta) = |delta|^2 exactly
    rng = np.random.default_rng(1)
    x = rng.uniform(3.0, 7.0, (20, 2))
    delta = np.array([0.05, -0.02])
    assert sinkhorn_distance(x, x + delta, OPEN, NOT_PERIODIC) == pytest.approx(
        float(delta @ delta), rel=2e-3
    )
    assert abs(sinkhorn_distance(x, x, OPEN, NOT_PERIODIC)) < 1e-6


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    return shared(tmp_path_factory)


def test_rollout_metrics_refuse_what_does_not_fit(dataset):
    test_set = data.load(dataset, "test")
    sim = LearnedSimulator(test_set.metadata, SimulatorConfig(history=3))
    frames = KWARGS["steps"] // KWARGS["write_every"] + 1  # 9
    with pytest.raises(ValueError, match=r"n_steps=6 after history=3 needs 10 frames.*have 9"):
        rollout_metrics(sim, None, test_set, n_steps=6)
    with pytest.raises(ValueError, match="start frame 3.*use n_steps <= 2"):
        rollout_metrics(sim, None, test_set, n_steps=4, starts=(0, 3))
    with pytest.raises(ValueError, match="starts is empty"):
        rollout_metrics(sim, None, test_set, n_steps=4, starts=())
    assert frames == 9
    for key, value, message in [
        ("dt", 2 * test_set.metadata["dt"], "frame time"),
        ("bounds", [[0.0, 2.0], [0.0, 1.0]], "bounds"),
        ("periodic_boundary_conditions", [True, False], "periodic axes"),
    ]:
        other = dataclasses.replace(test_set, metadata={**test_set.metadata, key: value})
        with pytest.raises(ValueError, match=message):
            rollout_metrics(sim, None, other, n_steps=4)


def _write(folder, meta, position, types):
    import h5py

    folder.mkdir(exist_ok=True)
    (folder / "metadata.json").write_text(json.dumps(meta))
    with h5py.File(folder / "train.h5", "w") as f:
        g = f.create_group("00000")
        g["position"] = position
        g["particle_type"] = types


GOOD = dict(
    dim=2,
    dt=0.001,
    write_every=10,
    bounds=[[0.0, 1.0], [0.0, 1.0]],
    periodic_boundary_conditions=[True, True],
    default_connectivity_radius=0.1,
    vel_mean=[0, 0],
    vel_std=[1e-3, 1e-3],
    acc_mean=[0, 0],
    acc_std=[1e-4, 1e-4],
)


@pytest.mark.parametrize(
    "change, message",
    [
        ({"bounds": [[0.0, 1.0]]}, "bounds must be"),
        ({"bounds": [[0.0, 1.0], [1.0, 0.0]]}, "lo < hi"),
        ({"dim": 4}, "dim must be 2 or 3"),
        ({"periodic_boundary_conditions": [True]}, "periodic_boundary_conditions"),
        ({"dt": -1.0}, "dt must be"),
        ({"write_every": 0.5}, "write_every"),
        ({"vel_std": [1.0]}, "vel_std"),
        ({"dt": None}, "dt must be"),
    ],
)
def test_loader_checks_the_metadata(tmp_path, change, message):
    x = np.full((4, 3, 2), 0.5, np.float32)
    _write(tmp_path / "d", {**GOOD, **change}, x, np.zeros(3, np.int32))
    with pytest.raises(ValueError, match=message):
        data.load(tmp_path / "d", "train")


def test_loader_checks_the_data_against_the_metadata(tmp_path):
    _write(tmp_path / "a", GOOD, np.full((4, 3, 3), 0.5, np.float32), np.zeros(3, np.int32))
    with pytest.raises(ValueError, match=r"expected \(frames, particles, 2\) for dim=2"):
        data.load(tmp_path / "a", "train")
    outside = np.full((4, 3, 2), 0.5, np.float32)
    outside[2, 1, 0] = 1.7  # beyond the periodic box: the bounds do not fit the data
    _write(tmp_path / "b", GOOD, outside, np.zeros(3, np.int32))
    with pytest.raises(ValueError, match="outside the bounds"):
        data.load(tmp_path / "b", "train")
    _write(tmp_path / "c", GOOD, np.full((4, 3, 2), 0.5, np.float32), np.zeros(2, np.int32))
    with pytest.raises(ValueError, match="particle_type has shape"):
        data.load(tmp_path / "c", "train")
