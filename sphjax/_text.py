"""Values in user messages written as a user types them (standard library only).

``show(jnp.asarray(0.7))`` is ``0.7``, not ``Array(0.7, dtype=float32)``;
``show(np.float64(0.0))`` is ``0.0``, not ``np.float64(0.0)``; strings keep their quotes.
"""

from __future__ import annotations


def _number(value) -> str:
    if isinstance(value, bool):
        return repr(value)
    if isinstance(value, int):
        return str(value)
    return repr(float(value))


def show(value) -> str:
    """``value`` as plain text for an error message: numbers as numbers, arrays as lists."""
    if value is None or isinstance(value, bool | str):
        return repr(value)
    if isinstance(value, int | float):
        return _number(value)
    if isinstance(value, list | tuple):
        inner = ", ".join(show(v) for v in value)
        return f"[{inner}]" if isinstance(value, list) else f"({inner})"
    if hasattr(value, "dtype") and hasattr(value, "shape"):  # NumPy and JAX, not imported
        try:
            import numpy as np

            array = np.asarray(value)
        except Exception:  # a tracer, or something else that will not become an array
            return repr(value)
        if array.dtype.kind in "biuf":
            if array.dtype.kind == "f" and array.dtype.itemsize < 8:
                items = [float(f"{v:.7g}") for v in array.ravel().tolist()]
            else:
                items = array.ravel().tolist()
            if array.ndim == 0:
                return _number(items[0])
            return "[" + ", ".join(_number(v) for v in items) + "]"
    return repr(value)
