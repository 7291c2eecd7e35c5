"""Every ``sphjax`` command in the README's bash blocks runs and exits 0, in the order shown
(later commands read the files of earlier ones).  About 60 s on two cores, mostly the
compilation of the four runs."""

from __future__ import annotations

import re
import shlex
import shutil
from pathlib import Path

import pytest

from sphjax.cli import main

README = Path(__file__).resolve().parents[1] / "README.md"


def readme_commands(text: str) -> list[list[str]]:
    """The argument lists of the ``sphjax`` commands in the bash blocks of ``text``."""
    commands = []
    for block in re.findall(r"```bash\n(.*?)```", text, flags=re.S):
        block = block.replace("\\\n", " ")  # continued lines
        for line in block.splitlines():
            for part in re.split(r"&&|;", line):
                words = shlex.split(part, comments=True)
                if words and (words[0] == "sphjax" or words[0].endswith("/sphjax")):
                    commands.append(words[1:])
    return commands


def test_the_readme_shows_the_commands_it_should():
    commands = readme_commands(README.read_text())
    shown = {c[0] for c in commands}
    assert {"run", "plot", "animate", "export", "cases"} <= shown
    assert ["run", "dam_break", "--dx", "0.02", "--t-end", "0.3", "--save-every", "20",
            "--out", "dam.h5"] in commands  # fmt: skip
    files = [c[1] for c in commands if c[0] == "run" and c[1].endswith(".toml")]
    assert files and all((README.parent / f).is_file() for f in files)  # a set-up file


@pytest.mark.slow
def test_every_readme_command_runs(tmp_path, monkeypatch):
    shutil.copytree(README.parent / "examples", tmp_path / "examples")  # the set-up files
    monkeypatch.chdir(tmp_path)
    for argv in readme_commands(README.read_text()):
        quiet = ["--quiet"] if argv[0] in ("run", "animate") else []
        assert main([*argv, *quiet]) == 0, argv
    assert (tmp_path / "dam.xdmf").is_file() and (tmp_path / "dam_vtk" / "dam.pvd").is_file()


OUTSIDE = ("VALIDATION.md", "DESIGN.md", "../shared", "shared/reference")


def test_user_docs_cite_no_file_outside_the_repository(capsys):
    root = README.parent
    pages = [README, *sorted((root / "docs").rglob("*.md"))]
    for page in pages:
        text = page.read_text()
        assert not [name for name in OUTSIDE if name in text], page
    assert main(["cases"]) == 0
    listing = capsys.readouterr().out
    assert not [name for name in OUTSIDE if name in listing]


@pytest.mark.slow
def test_every_readme_python_block_runs(tmp_path, monkeypatch):
    """The README's Python examples run as shown, in order (the quick start writes tg.h5)."""
    monkeypatch.chdir(tmp_path)
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    assert len(blocks) >= 3
    for block in blocks:
        exec(compile(block, "README.md", "exec"), {"__name__": "readme"})
    assert (tmp_path / "tg.h5").is_file()
