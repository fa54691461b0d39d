"""The front door: the README stays short and keeps its two commands, every public
name has an entry in the API reference, the README's layout lists the package's
folders, and the executed notebooks of the documentation hold the code of the
notebooks in examples/."""

import re
from pathlib import Path

import nbformat
import pytest

import jaxchain as jc

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def test_readme_is_short_and_keeps_its_two_commands():
    assert len(README.splitlines()) <= 150
    assert "pip install -e . && jaxchain localized" in README
    assert 'pip install -e ".[test]" && python -m pytest' in README


def test_readme_names_no_issue_and_no_measured_time():
    assert not re.search(r"\bissues? \d+", README, re.IGNORECASE)
    # A measured time: a number followed by a unit of time (s, min, ms, us).
    assert not re.search(r"\b\d+(\.\d+)? ?(s|ms|us|µs|min|minutes|seconds)\b", README)


def test_every_public_name_has_an_api_entry():
    entries = set()
    for page in (ROOT / "docs" / "api").glob("*.md"):
        entries |= set(re.findall(r"^::: jaxchain\.(\w+)$", page.read_text(), re.MULTILINE))
    assert sorted(set(jc.__all__) - entries) == []
    assert sorted(entries - set(jc.__all__)) == []


def test_readme_layout_lists_the_package_folders():
    listing = README.split("## Layout", 1)[1].split("```")[1]
    listed = set(re.findall(r"\b(_\w+)/", listing))
    folders = {p.name for p in (ROOT / "jaxchain").iterdir()
               if p.is_dir() and (p / "__init__.py").exists()}
    assert listed == folders
    modules = {p.name for p in (ROOT / "jaxchain").glob("*.py")}
    assert set(re.findall(r"\b(_?\w+\.py)\b", listing)) == modules


@pytest.mark.parametrize("name", sorted(p.name for p in (ROOT / "examples").glob("*.ipynb")))
def test_executed_notebook_holds_the_code_of_its_notebook(name):
    executed = ROOT / "docs" / "notebooks" / name
    assert executed.exists(), f"run python docs/execute_notebooks.py {name}"

    def code(path):
        nb = nbformat.read(path, as_version=4)
        return [c.source for c in nb.cells if c.cell_type == "code"]

    assert code(executed) == code(ROOT / "examples" / name), (
        f"docs/notebooks/{name} is stale: run python docs/execute_notebooks.py {name}")
    outputs = nbformat.read(executed, as_version=4)
    assert any("image/png" in o.get("data", {}) for c in outputs.cells
               if c.cell_type == "code" for o in c.get("outputs", [])), "no figure shown"


def test_citation_file_is_valid():
    """`cffconvert --validate` on CITATION.cff (the schema of CFF 1.2.0)."""
    import shutil
    import subprocess
    import sys

    cffconvert = shutil.which("cffconvert", path=str(Path(sys.executable).parent))
    assert cffconvert is not None, "pip install -e '.[test]' installs cffconvert"
    run = subprocess.run([cffconvert, "--validate", "-i", str(ROOT / "CITATION.cff")],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stdout + run.stderr


def test_version_is_the_installed_one_and_the_command_prints_it(capsys):
    from importlib.metadata import version

    assert jc.__version__ == version("jaxchain")
    with pytest.raises(SystemExit) as exc:
        jc.main(["--version"])
    assert exc.value.code == 0 and capsys.readouterr().out.strip() == f"jaxchain {jc.__version__}"
