"""Every Python name that README.md and docs/*.md give exists: each ``sphjax.x.y`` name is
imported, and each call in a code span (``read_trajectory(``, ``optax.adam(``,
``case.state_for(``, ``Mesh.from_stl(``) is looked up, so a renamed or removed function
cannot stay in the documentation.  A few seconds (every sphjax module is imported)."""

from __future__ import annotations

import builtins
import functools
import importlib
import inspect
import pkgutil
import re
import types
from pathlib import Path

import pytest

import sphjax

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

# sphjax 0.1's modules, named as history in the notes for users coming from it
FORMER = {"sphjax.state", "sphjax.integrate", "sphjax.rhs", "sphjax.fluid", "sphjax.fluid.adjoint"}

# the first word of a dotted call in a code span -> the module it names
MODULES = {
    "sphjax": "sphjax",
    "jax": "jax",
    "jnp": "jax.numpy",
    "lax": "jax.lax",
    "np": "numpy",
    "numpy": "numpy",
    "optax": "optax",
    "diffrax": "diffrax",
    "eqx": "equinox",
    "equinox": "equinox",
    "h5py": "h5py",
    "meshio": "meshio",
}
# variables the docs use for the package's types -> their type
RECEIVERS = {
    "case": "sphjax.Case",
    "params": "sphjax.Params",
    "state": "sphjax.State",
    "model": "sphjax.Model",
    "trajectory": "sphjax.Trajectory",
}
# names written as calls in formulas, not Python: exp(-16 pi^2 nu t), W(r, h), ...
NOTATION = {
    "C_theta", "GNS", "GNS_theta", "KE", "P", "Psi", "R", "S_coarse", "W", "ceil", "cos",
    "diag", "e", "exp", "f", "floor", "log", "logit", "logsumexp", "prod", "psi", "sin",
    "sqrt", "std", "u",
}  # fmt: skip
# third-party modules whose names the docs give bare (SaveAt, RecursiveCheckpointAdjoint)
THIRD_PARTY = ("diffrax", "optax", "jax", "jax.sharding", "equinox")


def _attribute(obj, name: str):
    """``obj.name``; a dataclass field without a default counts as present."""
    if not hasattr(obj, name) and name in getattr(obj, "__dataclass_fields__", {}):
        return None  # a dataclass field without a default (an instance attribute)
    return getattr(obj, name)


def _resolve(dotted: str) -> bool:
    """Whether ``dotted`` exists: from its first module, attribute by attribute, importing
    a submodule where an attribute is missing (as ``import sphjax.physics.rhs`` would)."""
    first, *rest = dotted.split(".")
    try:
        obj = importlib.import_module(first)
    except ImportError:
        return False
    for i, name in enumerate(rest):
        try:
            obj = _attribute(obj, name)
            continue
        except AttributeError:
            pass
        if not isinstance(obj, types.ModuleType):
            return False
        try:
            importlib.import_module(".".join([first, *rest[: i + 1]]))
            obj = _attribute(obj, name)
        except (ImportError, AttributeError):
            return False
    return True


@functools.cache
def _index() -> dict[str, list]:
    """Every name a bare call in the docs may mean: the public names of every sphjax module,
    the methods of its classes, the case names and the names of a few libraries."""
    names: dict[str, list] = {}

    def add(name, obj):
        names.setdefault(name, []).append(obj)

    for name in dir(sphjax):
        add(name, getattr(sphjax, name))
    for info in pkgutil.walk_packages(sphjax.__path__, "sphjax."):
        module = importlib.import_module(info.name)
        add(info.name.rsplit(".", 1)[1], module)
        for name, obj in vars(module).items():
            if name.startswith("__"):
                continue
            add(name, obj)
            if isinstance(obj, type) and obj.__module__.startswith("sphjax"):
                for member in vars(obj):
                    add(member, getattr(obj, member, None))
    for name, factory in sphjax.cases.CASES.items():
        add(name, factory)
    for module_name in THIRD_PARTY:
        module = importlib.import_module(module_name)
        for name in dir(module):
            if not name.startswith("_"):
                add(name, getattr(module, name))
    return names


def _code_spans(text: str) -> list[str]:
    """The inline code spans of a Markdown page (fenced blocks left out)."""
    text = re.sub(r"^[ \t]*```.*?^[ \t]*```", "", text, flags=re.S | re.M)
    return [span.replace("\n", " ") for span in re.findall(r"`([^`]+)`", text)]


def _calls(span: str) -> list[str]:
    return re.findall(r"(?<![\w.])([A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*)\(", span)


def _missing_call(call: str, index: dict[str, object]) -> bool:
    first, *rest = call.split(".")
    if first in MODULES:
        return not _resolve(".".join([MODULES[first], *rest]))
    if first in RECEIVERS:
        return not _resolve(".".join([RECEIVERS[first], *rest]))
    if rest and not first[0].isupper():
        return False  # an attribute of some variable of the text's
    if hasattr(builtins, first) or first in NOTATION:
        return bool(rest) and not all(hasattr(getattr(builtins, first, None), r) for r in rest)
    for obj in index.get(first, []):  # any of the things of that name
        try:
            for part in rest:
                obj = getattr(obj, part)
            return False
        except AttributeError:
            continue
    return True


def test_every_sphjax_name_in_the_docs_exists():
    missing = []
    for page in PAGES:
        text = page.read_text()
        for name in sorted(set(re.findall(r"(?<![\w./-])sphjax(?:\.[A-Za-z_]\w*)+", text))):
            if name not in FORMER and not _resolve(name):
                missing.append(f"{page.relative_to(ROOT)}: {name}")
    assert not missing, "names in the docs that do not exist:\n" + "\n".join(missing)
    assert not [name for name in FORMER if _resolve(name)], "a former module exists again"


def test_every_call_in_a_code_span_exists():
    index = _index()
    missing = []
    for page in PAGES:
        calls = {call for span in _code_spans(page.read_text()) for call in _calls(span)}
        missing += [
            f"{page.relative_to(ROOT)}: {call}("
            for call in sorted(calls)
            if _missing_call(call, index)
        ]
    assert not missing, "calls in the docs' code spans that do not exist:\n" + "\n".join(missing)


@pytest.mark.parametrize(
    ("call", "exists"),
    [
        ("read_trajectory", True), ("sphjax.io.read_trajectory", True),
        ("case.state_for", True), ("optax.adam", True), ("Mesh.from_stl", True),
        ("sphjax.calibrate.forward_value_and_grad", False),
        ("read_trajectroy", False), ("optax.adamm", False), ("case.nope", False),
        ("sqrt", True), ("some_variable.anything", True),
    ],
)  # fmt: skip
def test_the_checker_finds_what_is_missing(call, exists):
    """The look-up itself: a misspelt name is found missing, notation and unknown
    variables are left alone."""
    assert _missing_call(call, _index()) is not exists


def _signature_spans():
    """Code spans that give a signature: ``sphjax.m.f(a, b, c="x") -> Type``."""
    for page in PAGES:
        for span in _code_spans(page.read_text()):
            match = re.fullmatch(r"\s*(sphjax(?:\.\w+)+)\((.*)\)\s*->\s*.+", span)
            if match:
                yield page, match.group(1), match.group(2)


def test_documented_signatures_match_the_functions():
    spans = list(_signature_spans())
    assert "sphjax.vtk_export.export_vtk" in {name for _, name, _ in spans}
    for page, name, arguments in spans:
        module, function = name.rsplit(".", 1)
        parameters = inspect.signature(getattr(importlib.import_module(module), function))
        documented = [a.split("=")[0].strip() for a in arguments.split(",") if a.strip()]
        assert documented == list(parameters.parameters), (page.name, name, documented)
        for argument in arguments.split(","):
            if "=" in argument:  # a documented default is the default
                key, value = (x.strip() for x in argument.split("=", 1))
                assert repr(parameters.parameters[key].default) == value.replace('"', "'")
