"""docs/surrogates.md: its reproduce command is the one the figures script runs, and that
command, at a small size, writes the metadata the page documents, and the shipped model
was trained on its data (~25 s)."""

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
