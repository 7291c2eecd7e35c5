"""jax-md's cell lists without its package initialiser.

``import jax_md`` runs ``jax_md/__init__.py``, which imports every jax-md module: its
neural networks (flax, e3nn-jax, which imports scipy.signal and sympy) and its rigid
bodies (which compile about 140 small XLA programs at import).  On a 2-core CPU that costs
about 12 CPU-seconds in every process that imports sphjax: each ``sphjax`` command, each
notebook kernel, each worker of a dataset run.  sphjax needs two of its modules,
``jax_md.partition`` (cell and neighbour lists) and ``jax_md.space``; together they import
in about 0.1 s.

:func:`modules` imports them under a bare package object standing in for ``jax_md``
(it has the real package's search path, so the submodules load from the installed
jax-md, unchanged) and removes that stand-in again.  A later ``import jax_md``, by the
user or another library, then runs the real initialiser, which finds the submodules
already loaded and uses them: the package behaves exactly as if imported in full.
Nothing of jax-md or JAX is modified.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
import types


def modules(*names: str) -> tuple[types.ModuleType, ...]:
    """The submodules ``jax_md.<name>`` for ``names``, without running jax-md's
    ``__init__`` unless it has already run."""
    if "jax_md" in sys.modules:  # imported in full already: nothing to save
        return tuple(importlib.import_module(f"jax_md.{name}") for name in names)
    spec = importlib.util.find_spec("jax_md")
    if spec is None or not spec.submodule_search_locations:
        raise ImportError("sphjax needs jax-md: pip install 'jax-md==0.2.29'")
    stand_in = types.ModuleType("jax_md")
    stand_in.__path__ = list(spec.submodule_search_locations)
    sys.modules["jax_md"] = stand_in
    try:
        return tuple(importlib.import_module(f"jax_md.{name}") for name in names)
    finally:
        if sys.modules.get("jax_md") is stand_in:
            del sys.modules["jax_md"]
