"""sphjax imports jax-md's cell lists without jax-md's package initialiser
(:mod:`sphjax._jax_md`), and leaves ``import jax_md`` working in full afterwards."""

from __future__ import annotations

import subprocess
import sys

PROBE = """
import sys
import sphjax.cases
from sphjax.neighbors import search as neighbors
heavy = [m for m in ("jax_md.energy", "jax_md.rigid_body", "jax_md.nn", "e3nn_jax", "flax")
         if m in sys.modules]
assert not heavy, heavy
# the stand-in package is gone: a later `import jax_md` runs the real initialiser, which
# binds the submodules already loaded
assert "jax_md" not in sys.modules
assert neighbors.partition is sys.modules["jax_md.partition"]
assert neighbors.jmd_space is sys.modules["jax_md.space"]
print("ok")
"""


def test_sphjax_imports_only_the_jax_md_modules_it_uses():
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-2000:]
