"""The tiny Taylor-Green ensemble shared by the dataset and surrogate tests.

Run as a script (``python tests/_tiny_dataset.py OUT BATCH``) it writes the same dataset in
a fresh process: the sharding test runs it with several host devices.
"""

from __future__ import annotations

import sys

N_SIDE = 8
KWARGS = dict(
    n_train=3,
    n_valid=1,
    n_test=1,
    steps=16,
    write_every=2,
    seed=3,
    vary={"kinematic_viscosity": (0.008, 0.012)},
)


def make(out, batch_size=2, **extra):
    import sphjax
    from sphjax.dataset import Perturbation, generate_dataset

    case = sphjax.cases.taylor_green(n=N_SIDE)
    return generate_dataset(
        case,
        out,
        batch_size=batch_size,
        progress=False,
        perturbation=Perturbation((0.8, 1.2), 0.3, 2),
        case_kwargs={"n": N_SIDE},
        **KWARGS,
        **extra,
    )


_SHARED: dict = {}


def shared(tmp_path_factory):
    """One tiny dataset per test session (used by test_dataset and test_surrogate)."""
    if "path" not in _SHARED:
        _SHARED["path"] = make(tmp_path_factory.mktemp("data") / "tg")
    return _SHARED["path"]


if __name__ == "__main__":
    import jax

    make(sys.argv[1], int(sys.argv[2]))
    print("devices", jax.device_count())
