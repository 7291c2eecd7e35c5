"""Resolution by particle spacing: ``dx -> n`` for any registered case.

Every case factory takes ``n``, the number of particles across its characteristic
length ``L`` (``dx = L / n``), and reports ``dx`` and ``n`` in ``case.info``.  The length
is found by building the case once at its smallest resolution (``MIN_N``, or the
factory's ``min_n`` attribute where a case needs more), so a new case needs no entry here
as long as it follows that convention.  A case whose ``n`` counts lattice *sites* with
one on each end (``dx = L / (n - 1)``, the Turek-Hron beam with particles on its faces)
reports the number of spacings in ``case.info["spacings"]``.
"""

from __future__ import annotations

import inspect
import math

from sphjax.cases._geometry import check_positive

MIN_N = 4


def _smallest(factory) -> int:
    return getattr(factory, "min_n", MIN_N)


def _length_and_offset(factory, **kwargs) -> tuple[float, int]:
    if "n" not in inspect.signature(factory).parameters:
        raise ValueError(f"case {factory.__name__!r} has no resolution argument n")
    case = factory(n=_smallest(factory), **kwargs)
    try:
        n = int(case.info["n"])
        spacings = int(case.info.get("spacings", n))
        return float(case.info["dx"]) * spacings, n - spacings
    except KeyError:
        raise ValueError(
            f"case {factory.__name__!r} does not report dx and n in case.info, so a spacing "
            "cannot be converted to a resolution; pass n instead"
        ) from None


def resolution_length(factory, **kwargs) -> float:
    """The length ``L`` a case's ``n`` divides (``dx = L / n``), for these case arguments."""
    return _length_and_offset(factory, **kwargs)[0]


def n_for_spacing(factory, dx, **kwargs) -> int:
    """The resolution ``n = round(L / dx)`` closest to the particle spacing ``dx``."""
    dx = check_positive("dx", dx)
    length, offset = _length_and_offset(factory, **kwargs)
    n = max(1, round(length / dx)) + offset
    if n < _smallest(factory):
        raise ValueError(
            f"dx={dx:g} is too coarse for {factory.__name__}: its length {length:g} would hold "
            f"only {length / dx:.3g} particles; use dx <= {length / _smallest(factory):g}"
        )
    if not math.isfinite(length / dx) or n > 10**7:
        raise ValueError(f"dx={dx:g} is too fine for {factory.__name__} (n={n}); use a larger dx")
    return n
