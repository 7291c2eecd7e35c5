"""The version comes from one place, ``sphjax.__version__``: pyproject.toml reads it at build
time, and the installed package's metadata says the same."""

from __future__ import annotations

import ast
import importlib.metadata
import json
import tomllib
import warnings
from pathlib import Path

import pytest

import sphjax

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = ROOT / "pyproject.toml"


def test_pyproject_reads_the_version_from_the_package():
    project = tomllib.loads(PYPROJECT.read_text())
    assert "version" not in project["project"], "pyproject.toml must not repeat the version"
    assert "version" in project["project"]["dynamic"]
    assert project["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "sphjax.__version__"}
    # setuptools reads the attribute without importing sphjax when it is a literal
    tree = ast.parse((ROOT / "sphjax" / "__init__.py").read_text())
    literals = [
        node.value.value
        for node in tree.body
        if isinstance(node, ast.Assign)
        and [getattr(t, "id", None) for t in node.targets] == ["__version__"]
        and isinstance(node.value, ast.Constant)
    ]
    assert literals == [sphjax.__version__]


def test_a_build_declares_the_package_version():
    """What setuptools declares for a build of this checkout (setuptools is in a Python
    3.11 venv; from 3.12 on a venv may lack it)."""
    pyprojecttoml = pytest.importorskip("setuptools.config.pyprojecttoml")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # older setuptools call [tool.setuptools] "beta"
        built = pyprojecttoml.read_configuration(PYPROJECT)
    assert built["project"]["version"] == sphjax.__version__


def _metadata_of_this_checkout(dist) -> bool:
    """Whether the installed metadata was made from this checkout's current pyproject.toml:
    a regular install of the imported package, or an editable install of this folder made
    after pyproject.toml last changed (pip refreshes an editable install's metadata only
    when it is reinstalled)."""
    imported = Path(sphjax.__file__).resolve()
    if Path(dist.locate_file("sphjax/__init__.py")).resolve() == imported:
        return True
    direct_url = json.loads(dist.read_text("direct_url.json") or "{}")
    if not direct_url.get("dir_info", {}).get("editable"):
        return False
    if direct_url.get("url", "").removeprefix("file://") != str(ROOT):
        return False
    folder = getattr(dist, "_path", None)  # the .dist-info folder of a PathDistribution
    if folder is None or not (Path(folder) / "METADATA").is_file():
        return False
    return (Path(folder) / "METADATA").stat().st_mtime >= PYPROJECT.stat().st_mtime


def test_installed_metadata_has_the_package_version():
    """CI installs afresh, so this compares; a stale editable install (made before
    pyproject.toml changed, or from another checkout) is skipped with the fix."""
    try:
        dist = importlib.metadata.distribution("sphjax")
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("sphjax is not installed (pip install -e .)")
    if not _metadata_of_this_checkout(dist):
        pytest.skip(
            f"the installed metadata ({dist.version}) is from another checkout or older than "
            "pyproject.toml; reinstall with `pip install -e .` to compare"
        )
    assert importlib.metadata.version("sphjax") == sphjax.__version__
