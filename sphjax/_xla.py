"""XLA compiler flags sphjax sets by default, before JAX creates its CPU backend.

``--xla_cpu_experimental_ynn_fusion_type=`` (empty: no YNNPACK fusions) makes XLA:CPU
compile the per-pair element-wise work of the right-hand side into its own fused loops
instead of splitting it into many YNNPACK calls, each writing an ``[N, K]`` array to
memory.  On the 2D Taylor-Green benchmark it halves the CPU time of a step (see
``docs/performance.md``); results are the same to round-off.

The flags are added to ``XLA_FLAGS`` only if the user has not set the same flag and only
for the jaxlib versions that know them (an unknown flag aborts XLA).  XLA reads the
variable when JAX creates its CPU backend, so importing sphjax after a JAX computation has
already run leaves that process's backend as it was.  ``SPHJAX_XLA_DEFAULTS=0`` turns this
off.
"""

from __future__ import annotations

import os

# (flag, first jaxlib version known to accept it)
DEFAULT_FLAGS = (("--xla_cpu_experimental_ynn_fusion_type=", (0, 10)),)


def _version(text: str) -> tuple[int, ...]:
    parts = []
    for piece in text.split(".")[:2]:
        digits = "".join(ch for ch in piece if ch.isdigit())
        parts.append(int(digits or 0))
    return tuple(parts)


def apply_default_flags() -> list[str]:
    """Add :data:`DEFAULT_FLAGS` to ``XLA_FLAGS``; returns the flags added."""
    if os.environ.get("SPHJAX_XLA_DEFAULTS", "1").strip() == "0":
        return []
    try:
        from importlib.metadata import version

        jaxlib_version = _version(version("jaxlib"))
    except Exception:
        return []
    current = os.environ.get("XLA_FLAGS", "")
    added = [
        flag
        for flag, since in DEFAULT_FLAGS
        if jaxlib_version >= since and flag.split("=")[0] not in current
    ]
    if added:
        os.environ["XLA_FLAGS"] = " ".join([current, *added]).strip()
    return added
