"""Output paths checked before any work (standard library only, so the CLI answers fast)."""

from __future__ import annotations

import os
from pathlib import Path


def check_writable(path, argument: str = "path") -> Path:
    """Raise a ValueError naming ``argument`` if a file cannot be written at ``path``.

    Call this before a run starts, so a long simulation never ends in an unwritable path.
    Returns ``path`` as a :class:`~pathlib.Path`.
    """
    if path is None or str(path) == "":
        raise ValueError(f"{argument}: an output file name is required, e.g. run.h5")
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise ValueError(
            f"{argument}: '{path}' is a directory; give a file name inside it, "
            f"e.g. '{path / 'run.h5'}'"
        )
    if not parent.exists():
        raise ValueError(
            f"{argument}: cannot write '{path}': directory '{parent}' does not exist; "
            f"create it first (mkdir -p '{parent}') or choose another path"
        )
    if not parent.is_dir():
        raise ValueError(f"{argument}: cannot write '{path}': '{parent}' is not a directory")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(
            f"{argument}: cannot write '{path}': directory '{parent}' is not writable; "
            "choose a path in a directory you can write to"
        )
    if path.exists() and not os.access(path, os.W_OK):
        raise ValueError(
            f"{argument}: cannot overwrite '{path}': the file is read-only; "
            "remove it, change its permissions or choose another path"
        )
    if not path.exists():  # permissions can say yes where the file system says no (/proc)
        try:
            os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644))
        except OSError as err:
            raise ValueError(
                f"{argument}: cannot write '{path}': files cannot be created in the folder "
                f"'{parent}' ({err.strerror}); choose a path in a folder you can write to"
            ) from None
        os.unlink(path)
    return path


def overwrite_flag(argument: str) -> str:
    """How to allow replacing an output: ``--overwrite`` on the command line (an argument
    named like ``--out``), ``overwrite=True`` in Python."""
    return "--overwrite" if argument.startswith("-") else "overwrite=True"


def exists_message(path, argument: str) -> str:
    """The one line that refuses to replace an existing output (every command and writer)."""
    return f"'{path}' exists; pass {overwrite_flag(argument)} to replace it, or choose another path"


def check_new(paths, argument: str = "path", overwrite: bool = False) -> None:
    """Raise FileExistsError (``argument: 'x' exists; pass --overwrite ...``) if one of
    ``paths`` exists and ``overwrite`` is false: no output is replaced silently."""
    if overwrite:
        return
    for path in paths:
        if Path(path).exists():
            raise FileExistsError(f"{argument}: {exists_message(path, argument)}")
