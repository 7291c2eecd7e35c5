"""The suite compiles with XLA:CPU's loop emitters (tests/conftest.py, ``TEST_XLA_FLAGS``),
users with its default fusion emitters: the same simulation gives the same result both
ways, to round-off, so what the suite checks holds for what users run."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
from conftest import TEST_XLA_FLAGS

# A dam break with walls (continuity density, Molteni & Colagrossi's diffusion, Adami's
# walls) and 20 steps: every kind of pair sum of the fluid, float64.
RUN = """
import json, os
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import sphjax
case = sphjax.cases.dam_break(n=12)
final = sphjax.simulate(case, n_steps=20, save_every=20).final
print(json.dumps({"flags": os.environ.get("XLA_FLAGS", ""),
                  "position": np.asarray(final.position).tolist(),
                  "velocity": np.asarray(final.velocity).tolist()}))
"""


def _run(flags: str) -> dict:
    environ = {**os.environ, "XLA_FLAGS": flags}
    out = subprocess.run(
        [sys.executable, "-c", RUN], env=environ, capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_the_suites_compiler_gives_the_users_results():
    assert all(flag in os.environ["XLA_FLAGS"] for flag in TEST_XLA_FLAGS)
    suites = _run(os.environ["XLA_FLAGS"])
    users = _run("")  # sphjax adds only its own defaults
    assert "fusion_emitters" in suites["flags"] and "fusion_emitters" not in users["flags"]
    for field in ("position", "velocity"):
        a, b = np.asarray(suites[field]), np.asarray(users[field])
        scale = np.abs(b).max()
        assert np.abs(a - b).max() <= 1e-11 * scale, (field, np.abs(a - b).max(), scale)
