"""Compilation for the command line: a persistent cache, and the time spent compiling.

Every ``sphjax run`` would otherwise compile its chunk program again (seconds to tens of
seconds).  :func:`enable_compilation_cache` points JAX's persistent compilation cache at a
user folder, so a second run of the same shape loads the compiled program instead:

- ``$SPHJAX_CACHE_DIR`` if set; ``SPHJAX_CACHE_DIR=off`` (or ``0``, ``none``, empty)
  turns the cache off;
- else JAX's own ``JAX_COMPILATION_CACHE_DIR`` if set (left as it is, thresholds included);
- else ``$XDG_CACHE_HOME/sphjax/jax``, by default ``~/.cache/sphjax/jax``.

The folder grows by about 1 MB per new shape of run and may be deleted at any time.

:class:`CompileTimer` adds up the wall time JAX spends tracing, lowering and compiling (or
loading a compiled program from the cache) while it is open, from JAX's monitoring events,
so that a reported speed can leave compilation out.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

ENV = "SPHJAX_CACHE_DIR"
OFF = ("", "0", "off", "none", "false", "no")

#: every program is cached: besides its chunk a run compiles its set-up's programs (a
#: case's packing and initial state, the neighbour allocation) and a few of jax-md's small
#: ones, most under 0.3 s, together about half the compile time of a small run
MIN_COMPILE_SECONDS = 0.0


def default_cache_dir(environ=os.environ) -> Path:
    """``$XDG_CACHE_HOME/sphjax/jax``, or ``~/.cache/sphjax/jax``."""
    base = environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "sphjax" / "jax"


def cache_dir_setting(environ=os.environ) -> tuple[Path | None, str]:
    """The folder the CLI would use and where the choice came from (for messages)."""
    import jax

    if ENV in environ:
        value = environ[ENV].strip()
        if value.lower() in OFF:
            return None, f"{ENV}={environ[ENV]}"
        return Path(value).expanduser(), ENV
    if jax.config.jax_compilation_cache_dir:
        return Path(jax.config.jax_compilation_cache_dir), "JAX_COMPILATION_CACHE_DIR"
    return default_cache_dir(environ), "default"


def enable_compilation_cache(environ=os.environ) -> tuple[Path | None, str | None]:
    """Turn JAX's persistent compilation cache on for this process.

    Call before anything is compiled.  Returns ``(folder, note)``: the folder in use (or
    ``None`` when off) and a one-line note when the folder could not be used.
    """
    import jax

    folder, source = cache_dir_setting(environ)
    if folder is None:
        return None, None
    if source == "JAX_COMPILATION_CACHE_DIR":
        return folder, None  # the user's own JAX set-up: left alone
    try:
        folder.mkdir(parents=True, exist_ok=True)
        writable = os.access(folder, os.W_OK | os.X_OK)
    except OSError:
        writable = False
    if not writable:
        return None, (
            f"note: the compilation cache folder '{folder}' cannot be written; compiling "
            f"without it (set {ENV} to another folder, or {ENV}=off)"
        )
    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_SECONDS)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return folder, None


#: JAX's events for tracing, lowering and compiling (or loading from the cache)
COMPILE_EVENTS = (
    "/jax/core/compile/jaxpr_trace_duration",
    "/jax/core/compile/jaxpr_to_mlir_module_duration",
    "/jax/core/compile/backend_compile_duration",
)


class CompileTimer:
    """Wall seconds spent compiling while open (nested events counted once).

    Use as ``with CompileTimer() as timer: ...; timer.seconds``.
    """

    def __init__(self):
        self._spans: list[tuple[float, float]] = []

    def _listen(self, event, duration, **_):
        if event in COMPILE_EVENTS:
            end = time.perf_counter()
            self._spans.append((end - duration, end))

    def __enter__(self):
        import jax.monitoring

        jax.monitoring.register_event_duration_secs_listener(self._listen)
        return self

    def __exit__(self, *exc):
        import jax.monitoring

        jax.monitoring.unregister_event_duration_listener(self._listen)
        return False

    def seconds(self, since: float = -float("inf"), until: float = float("inf")) -> float:
        """Seconds of compilation between ``since`` and ``until`` (``time.perf_counter``)."""
        total, reach = 0.0, since
        for start, end in sorted(self._spans):
            start, end = max(start, reach), min(end, until)
            if end > start:
                total += end - start
                reach = end
        return total


# ---------------------------------------------------------------------------- speeds


def rates_file(environ=os.environ) -> Path | None:
    """Where runs remember their speed (``rates.json`` in the sphjax cache folder), or
    ``None`` when the cache is off or is JAX's own folder."""
    folder, source = cache_dir_setting(environ)
    if folder is None or source == "JAX_COMPILATION_CACHE_DIR":
        return None
    return folder / "rates.json"


def remembered_rate(key: str, environ=os.environ) -> float | None:
    """The particle-steps per second (after compilation) a previous run of ``key``
    measured on this machine, or ``None``."""
    import json

    path = rates_file(environ)
    try:
        rate = json.loads(path.read_text()).get(key) if path is not None else None
    except (OSError, ValueError, AttributeError):
        return None
    return float(rate) if isinstance(rate, int | float) and rate > 0 else None


def remember_rate(key: str, rate: float, environ=os.environ) -> None:
    """Keep ``rate`` for ``key`` (best effort: a folder that cannot be written is skipped)."""
    import json

    path = rates_file(environ)
    if path is None or not rate > 0:
        return
    try:
        rates = json.loads(path.read_text()) if path.exists() else {}
        if not isinstance(rates, dict):
            rates = {}
        rates[key] = float(f"{rate:.3g}")
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(rates, indent=1, sort_keys=True))
    except (OSError, ValueError):
        pass
