"""docs/surrogates.md: its reproduce command is the one the figures script runs, and that
command, at a small size, writes the metadata the page documents, and the shipped model
was trained on its data; the LagrangeBench recipe writes their set-up (~25 s, the recipe
11 s)."""

from __future__ import annotations

import importlib.util
import json
import re
import shlex
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "surrogates.md"


def _script():
    path = ROOT / "docs" / "scripts" / "surrogate_figures.py"
    spec = importlib.util.spec_from_file_location("surrogate_figures", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _documented_command() -> list[str]:
    text = DOC.read_text().replace("\\\n", " ")
    lines = [
        line.strip() for line in text.splitlines() if line.strip().startswith("sphjax dataset")
    ]
    assert lines, "docs/surrogates.md prints no `sphjax dataset` command"
    return shlex.split(lines[0])


def _documented_metadata() -> dict:
    text = DOC.read_text()
    match = re.search(r"Metadata of the reproduce command.*?```json\n(.*?)```", text, re.S)
    assert match, "docs/surrogates.md has no metadata block for the reproduce command"
    return json.loads(match.group(1))


def test_the_documented_command_is_the_one_the_figures_script_runs():
    script = _script()
    documented = _documented_command()
    expected = shlex.split(script.DATASET_COMMAND)
    expected[expected.index("DIR")] = documented[documented.index("--out") + 1]
    assert documented == expected
    # the command parses as printed (no missing case arguments or --dt)
    from sphjax.cli import _parser

    args = _parser().parse_args(documented[1:])
    assert args.command == "dataset"


def test_the_documented_command_writes_the_documented_metadata(tmp_path):
    script = _script()
    from sphjax.cli import main

    folder = tmp_path / "tg"
    assert main(script.dataset_argv(folder, small=True)) == 0
    meta = json.loads((folder / "metadata.json").read_text())
    doc = _documented_metadata()
    small = script.SMALL_OVERRIDES
    n = int(small["--case-arg"].split("=")[1])
    steps = int(small["--steps"])
    scaled = {
        "steps": steps,
        "sequence_length_train": steps // doc["write_every"] + 1,
        "num_trajs_train": int(small["--n-train"]),
        "num_trajs_valid": int(small["--n-valid"]),
        "num_trajs_test": int(small["--n-test"]),
        "num_particles_max": n * n,
        "dx": 1.0 / n,
        "case_kwargs": {"n": n},
    }
    # at full size the scaled values are what the page says
    assert doc["sequence_length_train"] == doc["steps"] // doc["write_every"] + 1
    assert doc["num_particles_max"] == doc["case_kwargs"]["n"] ** 2
    assert doc["dx"] == pytest.approx(1.0 / doc["case_kwargs"]["n"])
    for key, value in doc.items():
        want = scaled.get(key, value)
        if isinstance(want, float):
            assert meta[key] == pytest.approx(want), key
        else:
            assert meta[key] == want, key


def test_the_documented_command_writes_one_dt_for_every_seed(tmp_path):
    """Issue 32: the documented command with its ``--seed`` and with another writes the
    same ``dt``, and that ``dt`` is the stable step at the worst end of the documented
    ranges (``--amplitude`` top, ``--fourier``, the redrawn case seed's 1.1, the
    ``--vary`` viscosity's top), from the formula here (at ``n = 8``, one trajectory of
    two frames' worth of steps: ~5 s)."""
    import numpy as np

    import sphjax
    from sphjax.cli import main

    documented = _script().dataset_argv("DIR")
    assert _option(documented, "--seed") == "1"
    dts = {}
    for seed in ("1", "7"):
        argv = list(documented)
        every = int(_option(argv, "--write-every"))
        for name, value in (
            ("--out", str(tmp_path / f"seed{seed}")),
            ("--case-arg", "n=8"),
            ("--n-train", "1"),
            ("--n-valid", "0"),
            ("--n-test", "0"),
            ("--steps", str(2 * every)),
            ("--seed", seed),
        ):
            argv[argv.index(name) + 1] = value
        assert main([*argv, "--no-progress"]) == 0
        meta = json.loads((tmp_path / f"seed{seed}" / "metadata.json").read_text())
        assert meta["seed"] == int(seed)
        dts[seed] = meta["dt"]
    assert dts["1"] == dts["7"]
    # the formula at the worst end of the documented ranges
    a_hi = float(_option(documented, "--amplitude").split(":")[1])
    fourier = float(_option(documented, "--fourier"))
    name, span = _option(documented, "--vary").split("=")
    assert name == "kinematic_viscosity"
    nu_hi = float(span.split(":")[1])
    case = sphjax.cases.taylor_green(n=8)
    h, c0 = case.model.smoothing_length, float(case.params.sound_speed)
    peak = float(np.linalg.norm(np.asarray(case.state.velocity, np.float64), axis=1).max())
    fastest = 1.1 * (a_hi + fourier) * peak  # the case seed is redrawn: 1.1
    expected = min(0.25 * h / (c0 + fastest), 0.125 * h**2 / nu_hi)
    assert dts["1"] == pytest.approx(expected, rel=1e-12)


def test_the_shipped_model_was_trained_on_the_documented_dataset():
    # docs/models/tg32_gns.eqx must come from the reproduce command (today's defaults)
    from sphjax.surrogate import LearnedSimulator

    doc = _documented_metadata()
    sim, model = LearnedSimulator.load(ROOT / "docs" / "models" / "tg32_gns.eqx")
    meta = json.loads((ROOT / "docs" / "models" / "tg32_gns.eqx.json").read_text())["metadata"]
    for key in ("case", "case_kwargs", "steps", "write_every", "sequence_length_train", "seed"):
        assert meta[key] == doc[key], key
    assert meta["perturbation"] == doc["perturbation"]
    assert sim.metadata["dx"] == pytest.approx(doc["dx"])
    assert model is not None
    # and its step is today's rule's: the documented command, with any --seed, writes data
    # of the model's frame time
    import sphjax
    from sphjax.dataset import Perturbation, ensemble_time_step

    perturbation = dict(doc["perturbation"], amplitude=tuple(doc["perturbation"]["amplitude"]))
    vary = {name: tuple(r) for name, r in doc["varied_params"].items()}
    case = sphjax.cases.get(doc["case"], **doc["case_kwargs"])
    dt = ensemble_time_step(case, Perturbation(**perturbation), vary, doc["case_kwargs"])
    # (the command runs in float32, the tests in float64: the case's speeds differ by
    # rounding)
    assert sim.metadata["dt"] == pytest.approx(dt, rel=1e-6)


# LagrangeBench's 2D Taylor-Green (`2D_TGV_2500_10kevery100`), from their generation
# scripts (docs/surrogates.md, "Against LagrangeBench's 2D Taylor-Green", gives each source):
LAGRANGEBENCH_TGV2D = {
    # tumaer/lagrangebench data_gen/lagrangebench_data/dataset_tgv.sh: case.dx=0.02;
    # notebooks/datasets.ipynb prints traj_shape= (126, 2500, 2)
    "num_particles_max": 2500,
    "dx": 0.02,
    "frames": 126,
    # dataset_tgv.sh: solver.dt=0.0004 solver.t_end=5
    "dt": 0.0004,
    "t_end": 5.0,
    # tumaer/jax-sph cases/tgv.yaml: io.write_every 100
    "write_every": 100,
    # dataset_tgv.sh: seeds 0..199, --split=2_1_1 (gen_dataset.py: 100 / 50 / 50)
    "num_trajs": (100, 50, 50),
    # tumaer/jax-sph jax_sph/defaults.py (tag v0.0.2): viscosity 0.01, rho_ref 1, u_ref 1,
    # c_ref_factor 10, QSK kernel with h_factor 1
    "kinematic_viscosity": 0.01,
    "sound_speed": 10.0,
    "smoothing_length": 0.02,
}


def _lagrangebench_command() -> list[str]:
    text = DOC.read_text()
    start = text.index("## Against LagrangeBench's 2D Taylor–Green")
    section = text[start:].replace("\\\n", " ")
    lines = [line.strip() for line in section.splitlines() if line.strip().startswith("sphjax")]
    assert lines, "the LagrangeBench section prints no `sphjax dataset` command"
    return shlex.split(lines[0])


def _option(argv: list[str], name: str) -> str:
    return argv[argv.index(name) + 1]


def test_the_lagrangebench_recipe_writes_their_set_up(tmp_path):
    lb = LAGRANGEBENCH_TGV2D
    argv = _lagrangebench_command()
    assert argv[:3] == ["sphjax", "dataset", "taylor_green"]
    # at full size: their length, frame time and number of trajectories
    steps, every = int(_option(argv, "--steps")), int(_option(argv, "--write-every"))
    dt = float(_option(argv, "--dt"))
    assert every == lb["write_every"] and dt == lb["dt"]
    assert steps // every + 1 == lb["frames"] and steps % every == 0
    assert steps * dt == pytest.approx(lb["t_end"])
    splits = tuple(int(_option(argv, f"--n-{s}")) for s in ("train", "valid", "test"))
    assert splits == lb["num_trajs"]
    # run it at one trajectory and two frames' worth of steps
    from sphjax.cli import main

    small = list(argv[1:])
    for name, value in (
        ("--out", str(tmp_path / "lb")),
        ("--n-train", "1"),
        ("--n-valid", "0"),
        ("--n-test", "0"),
        ("--steps", str(2 * every)),
    ):
        small[small.index(name) + 1] = value
    assert main([*small, "--no-progress"]) == 0
    meta = json.loads((tmp_path / "lb" / "metadata.json").read_text())
    assert meta["num_particles_max"] == lb["num_particles_max"]
    assert meta["dx"] == pytest.approx(lb["dx"])
    assert meta["dt"] * meta["write_every"] == pytest.approx(lb["dt"] * lb["write_every"])
    assert meta["viscosity"] == pytest.approx(lb["kinematic_viscosity"], rel=1e-6)
    assert meta["sound_speed"] == pytest.approx(lb["sound_speed"])
    assert meta["smoothing_length"] == pytest.approx(lb["smoothing_length"])
    assert meta["default_connectivity_radius"] == pytest.approx(1.45 * lb["dx"])
    assert meta["bounds"] == [[0.0, 1.0], [0.0, 1.0]]
    assert meta["periodic_boundary_conditions"] == [True, True]
    assert meta["density_evolution"] is False and meta["p_bg_factor"] == 0.0
    assert meta["gamma"] == 1.0 and meta["kernel"] == "QuinticSpline"
    assert meta["varied_params"] == {}
    assert meta["perturbation"]["amplitude"] == [1.0, 1.0]
    assert meta["perturbation"]["fourier"] == 0.0
