"""One way to make a pytree: :func:`pytree_dataclass`.

Every container sphjax passes through ``jit``, ``grad`` and ``vmap`` (State, Params, the
neighbour lists, Trajectory, the diffrax phase) is a frozen dataclass registered with
``jax.tree_util.register_dataclass``.  Fields are pytree children (arrays) unless listed in
``static``: static fields are hashable Python values (sizes, flags) that become part of the
tree structure, so changing them retraces.
"""

from __future__ import annotations

import dataclasses

import jax

__all__ = ["pytree_dataclass"]


def pytree_dataclass(cls=None, *, static: tuple[str, ...] = ()):
    """Freeze ``cls`` as a dataclass, register it as a pytree and give it ``replace``.

    Args:
      static: names of fields that are metadata (hashable, not traced).
    """

    def wrap(cls):
        cls = dataclasses.dataclass(frozen=True)(cls)
        names = [f.name for f in dataclasses.fields(cls)]
        unknown = set(static) - set(names)
        if unknown:
            raise TypeError(f"{cls.__name__}: static fields {sorted(unknown)} are not fields")
        jax.tree_util.register_dataclass(
            cls,
            data_fields=[n for n in names if n not in static],
            meta_fields=[n for n in names if n in static],
        )
        if "replace" not in cls.__dict__:
            cls.replace = lambda self, **changes: dataclasses.replace(self, **changes)
        return cls

    return wrap if cls is None else wrap(cls)
