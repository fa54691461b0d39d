"""The front door: the README stays short and keeps its two commands, every public
name has an entry in the API reference, the README's layout lists the package's
folders, every file of the repository that the documentation names is there, the
executed notebooks of the documentation hold the code of the notebooks in examples/
and show no path of the machine that ran them and no progress bar, the home page
reads without a math renderer, the site loads nothing from the network (formulas are
MathML made at build time, docs/hooks.py), and the task index ("How do I ...")
is linked from the home page and names only public names and existing commands."""

import ast
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


def test_readme_says_what_the_warm_process_is_and_how_to_see_stop_and_turn_it_off(capsys):
    """The README's two lines on the warm process: what it holds, the commands that
    show and stop it, and the switch, each of which must exist (`jaxchain server
    ACTION --help` exits 0 for each action; for one that does not exist, 2)."""
    readme = (ROOT / "README.md").read_text()
    lines = [line for line in readme.splitlines() if "warm process" in line]
    assert lines, "the README does not mention the warm process"
    text = readme[readme.index(lines[0]):][:600]
    for needed in ("jaxchain server status", "jaxchain server stop", "JAXCHAIN_SERVER=0",
                   "GiB"):
        assert needed in text, needed
    for action, status in (("status", 0), ("stop", 0), ("no-such-action", 2)):
        with pytest.raises(SystemExit) as exc:
            jc.main(["server", action, "--help"])
        assert exc.value.code == status, action
    capsys.readouterr()


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


#: The pages of the documentation site.
PAGES = sorted((ROOT / "docs").rglob("*.md"))
#: Code in Markdown: a fenced block or an inline span.
CODE = re.compile(r"```.*?```|`[^`\n]+`", re.DOTALL)
#: A relative path to a file (`tests/helpers.py`) or a folder (`examples/chains/`), as
#: the repository's paths are written: lower case, and not inside a URL, an absolute
#: path, `~/...` or a placeholder such as `DIR/sweep.zarr`.
RELATIVE_PATH = re.compile(r"(?<![\w.:/~$-])([a-z_][\w.-]*(?:/[\w.-]+)*(?:/[\w-]+\.\w+|/))"
                           r"(?![\w/])")


def test_every_file_the_docs_name_is_in_the_repository():
    """Each relative path to a file in the code of a page, and each path to a folder
    that starts at a folder of the repository, exists in the repository (a folder in a
    listing, such as `_physics/` under `jaxchain/`, is not one)."""
    folders = {p.name for p in ROOT.iterdir() if p.is_dir()}
    named, missing = 0, []
    for page in PAGES:
        for code in CODE.findall(page.read_text()):
            for path in RELATIVE_PATH.findall(code):
                if path.endswith("/") and path.split("/")[0] not in folders:
                    continue
                named += 1
                if not (ROOT / path).exists():
                    missing.append(f"{page.relative_to(ROOT)}: {path}")
    assert named > 0
    assert missing == []


def test_the_file_the_docs_say_holds_the_public_names_holds_them():
    said = {}
    for page in PAGES:
        text = " ".join(page.read_text().split())
        for path in re.findall(r"public names\b[^.`]*`([\w/.]+\.pyi?)`", text):
            said.setdefault(path, []).append(page.name)
    assert said, "the developers' page says where the public names are"
    for path, pages in said.items():
        tree = ast.parse((ROOT / path).read_text())
        bound = {alias.asname or alias.name for node in ast.walk(tree)
                 if isinstance(node, ast.ImportFrom) for alias in node.names}
        assert sorted(set(jc.__all__) - bound) == [], f"{pages} say {path} holds them"


#: What arithmatex (the extension of mkdocs.yml that marks formulas for docs/hooks.py) takes
#: for a formula: a dollar sign ($...$, $$...$$), \(...\), \[...\] or a TeX command
#: such as \frac or \begin.
TEX = re.compile(r"\$|\\[A-Za-z(\[]")


def _prose(markdown: str) -> str:
    """`markdown` without its code: fenced blocks and inline code spans, which
    arithmatex leaves alone."""
    fenceless = re.sub(r"^(```|~~~).*?^\1", "", markdown, flags=re.DOTALL | re.MULTILINE)
    return re.sub(r"(`+).+?\1", "", fenceless, flags=re.DOTALL)


def test_the_home_page_reads_without_mathjax():
    """The home page's formulas are text and HTML, so that arithmatex finds none: no
    dollar sign and no TeX command outside code, and the page reads the same wherever
    its Markdown is shown (the repository's own view of docs/index.md renders no TeX).
    Read from the page's source, so that the README's test command, which installs
    no documentation tools, runs it."""
    prose = _prose((ROOT / "docs" / "index.md").read_text())
    assert TEX.findall(prose) == []
    # the check sees a formula where one is, and none in code
    assert TEX.findall(_prose("a $x_1$ and \\(y\\) and $$z$$ or \\frac{1}{2}")) == [
        "$", "$", "\\(", "$", "$", "$", "$", "\\f"]
    assert TEX.findall(_prose("`$HOME` and ``\\n``\n```sh\necho $PATH\n```\n")) == []


#: The notebooks of examples/ and their executed copies that the site shows.
NOTEBOOKS = sorted([*(ROOT / "examples").glob("*.ipynb"),
                    *(ROOT / "docs" / "notebooks").glob("*.ipynb")])
#: An absolute path (of a checkout, a Python installation, a temporary or a home
#: folder), not a URL's path.
ABSOLUTE_PATH = re.compile(r"(?<![\w.:/<~-])/[A-Za-z_][\w.-]*/[\w.-]")


def _output_texts(nb):
    """(cell index, text) of every text that the outputs of `nb` show."""
    for i, cell in enumerate(nb.cells):
        for output in cell.get("outputs", []):
            texts = [output.get("text", ""), *output.get("traceback", [])]
            texts += [v for k, v in output.get("data", {}).items()
                      if isinstance(v, str) and not k.startswith("image/")]
            yield from ((i, text) for text in texts if text)


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_stored_outputs_show_no_path_of_the_machine_that_ran_them(path):
    """Neither an absolute path, nor the site-packages of an installation, nor tqdm's
    warning that its widget bar is missing (which names the path of its file)."""
    for i, text in _output_texts(nbformat.read(path, as_version=4)):
        for bad in (ABSOLUTE_PATH.search(text), "site-packages" in text,
                    "TqdmWarning" in text):
            assert not bad, f"{path.name}, cell {i}: {text[:300]}"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_stored_outputs_show_a_progress_bar_once(path):
    """Each redraw of a progress bar arrives as an output of its own; the stored copy
    keeps what a terminal shows at the end (docs/execute_notebooks.py:
    compact_streams), not every state of the bar one under the other."""
    for i, text in _output_texts(nbformat.read(path, as_version=4)):
        assert "\r" not in text, f"{path.name}, cell {i}: {text[:300]!r}"


#: What a text progress bar (tqdm's) leaves in an output: "100%|" before its bar, a
#: rate such as "4.04trajectory/s]" or "2.96s/it]" at its end.
PROGRESS_TEXT = re.compile(r"\d%\||\d(?:[A-Za-z]+/s|s/[A-Za-z]+)\]")


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_stored_outputs_show_no_progress_bar(path):
    """A page shows a stored progress bar as raw text (its bar, counts and rate):
    docs/execute_notebooks.py drops the bars' lines when it stores a run."""
    for i, text in _output_texts(nbformat.read(path, as_version=4)):
        for line in text.splitlines():
            assert not PROGRESS_TEXT.search(line), f"{path.name}, cell {i}: {line!r}"
    # the check sees the bars of the two notebooks that showed them, and no table
    assert PROGRESS_TEXT.search("sweep: 100%|##########| 420/420 [01:44<00:00,  4.04trajectory/s]")
    assert PROGRESS_TEXT.search("simulation check: 5/5 [00:14<00:00,  2.96s/it]")
    assert not PROGRESS_TEXT.search("v_d = 1.300:  2 distinct states, n_HALC in [1, 20]")
    assert not PROGRESS_TEXT.search("belt speed 0.1 [m/s], 50% | 50%")


MKDOCS = (ROOT / "mkdocs.yml").read_text()


def test_the_site_loads_nothing_from_the_network():
    """An offline reader sees the whole site: no script or style sheet from a URL
    (formulas are rendered to MathML at build time by docs/hooks.py, not by MathJax
    from a CDN) and no web font (`theme.font: false`)."""
    import yaml

    config = yaml.safe_load(MKDOCS)
    assets = [*config.get("extra_javascript", []), *config.get("extra_css", [])]
    assert [a for a in assets if "://" in str(a) or str(a).startswith("//")] == []
    for asset in assets:
        assert (ROOT / "docs" / asset).is_file(), asset
    assert config["theme"].get("font") is False
    assert "docs/hooks.py" in config["hooks"]
    assert "def on_page_content" in (ROOT / "docs" / "hooks.py").read_text()


TASKS = (ROOT / "docs" / "tasks.md").read_text()


def test_the_task_index_is_linked_from_the_home_page_and_near_the_top_of_the_nav():
    assert "(tasks.md)" in (ROOT / "docs" / "index.md").read_text()
    nav = [line.strip() for line in MKDOCS.split("\nnav:", 1)[1].splitlines() if line.strip()]
    assert any(line.endswith(": tasks.md") for line in nav[:4]), nav[:4]


def test_the_task_index_names_public_names_and_existing_commands(capsys):
    """Each `jc.NAME` of the task index is a public name (its attribute too, as in
    `jc.Graph.lattice`), each `jaxchain COMMAND` a command (`jaxchain COMMAND --help`
    exits 0; for one that does not exist, 2), and it has twenty tasks, each with a
    Python or shell example."""
    names = re.findall(r"\bjc\.(\w+(?:\.\w+)?)", TASKS)
    assert len(set(names)) >= 40
    for name in set(names):
        head, _, attr = name.partition(".")
        assert head in jc.__all__, name
        if attr and head[0].isupper():
            assert hasattr(getattr(jc, head), attr), name
    commands = set(re.findall(r"(?<!import )\bjaxchain ([a-z][\w-]*)", TASKS))
    assert len(commands) >= 10
    for command, status in [*((c, 0) for c in sorted(commands)), ("no-such-command", 2)]:
        with pytest.raises(SystemExit) as exc:
            jc.main([command, "--help"])
        assert exc.value.code == status, command
    capsys.readouterr()
    sections = TASKS.split("\n## ")[1:]
    assert len(sections) == 21
    assert all("```python" in s or "```bash" in s for s in sections)


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


LAYOUT = (ROOT / "docs" / "layout.md").read_text()
#: An entry of the package's listing in docs/layout.md: a file or a folder, indented two
#: spaces a level, then its description after two spaces or more (a description's
#: second line starts deeper than any entry).
LISTED = re.compile(r"^((?:  )*)([\w.]+/|[\w.]+\.pyi?)(?: {2,}|$)")


def _layout_listing() -> list[str]:
    """The files and folders that the listing of docs/layout.md names, as paths from
    the repository's root (`jaxchain/_engine/exact/solve.py`, `jaxchain/_engine/`), in
    the listing's order."""
    listing = LAYOUT.split("## Layout", 1)[1].split("```")[1]
    paths, folders = [], []
    for line in listing.splitlines():
        entry = LISTED.match(line)
        if entry is None or len(entry[1]) // 2 > len(folders):
            continue
        del folders[len(entry[1]) // 2:]
        paths.append("".join(folders) + entry[2])
        if entry[2].endswith("/"):
            folders.append(entry[2])
    return paths


def _layer(path: str) -> str:
    """The layer of a file or folder of the package: the package's root (`jaxchain/`,
    for the files that stand there) or the folder under it (`jaxchain/_engine/`)."""
    parts = path.split("/")
    return "jaxchain/" if len(parts) == 2 else f"jaxchain/{parts[1]}/"


def _layer_order(paths) -> list[str]:
    """The layers in the order a listing gives them, from the bottom up."""
    return list(dict.fromkeys(_layer(path) for path in paths if path != "jaxchain/"))


def _module_path(dotted: str) -> str:
    """A dotted module name (the engines' module, say) as the file that holds it."""
    path = ROOT / dotted.replace(".", "/")
    return (path / "__init__.py" if path.is_dir() else path.with_suffix(".py")
            ).relative_to(ROOT).as_posix()


def _package_imports():
    """Every import of a jaxchain module by a jaxchain module, read with `ast` (not the
    modules that `importlib.import_module` is given as a string): (importer, imported,
    whether the import is made inside a function), as paths from the repository's root."""
    for path in sorted((ROOT / "jaxchain").rglob("*.py")):
        importer = path.relative_to(ROOT).as_posix()
        package = importer.split("/")[:-1]
        tree = ast.parse(path.read_text())
        inside = {id(node) for function in ast.walk(tree)
                  if isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef))
                  for node in ast.walk(function)}
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                targets = [node.module]
            elif isinstance(node, ast.ImportFrom):
                base = package[:len(package) - node.level + 1]
                targets = ([".".join(base + [node.module])] if node.module else
                           [".".join(base + [alias.name]) for alias in node.names])
            else:
                continue
            for target in targets:
                if target.split(".")[0] == "jaxchain":
                    yield importer, _module_path(target), id(node) in inside


def test_the_developers_page_lists_every_module():
    """The listing of docs/layout.md names every module of the package and nothing
    else: each file, and each folder (which stands for its `__init__.py`)."""
    listed = _layout_listing()
    package = ROOT / "jaxchain"
    files = {p.relative_to(ROOT).as_posix() for p in package.rglob("*.py*")
             if p.suffix in (".py", ".pyi")}
    there = {f for f in files if not (f.endswith("/__init__.py") and f.count("/") > 1)}
    there |= {p.parent.relative_to(ROOT).as_posix() + "/" for p in package.rglob("__init__.py")}
    assert sorted(there - set(listed)) == [], "not on the developers' page"
    assert sorted(set(listed) - there) == [], "on the developers' page, not in the package"
    assert len(listed) == len(set(listed))


def test_every_import_keeps_the_layer_order_of_the_developers_page():
    """No module imports from a layer that docs/layout.md lists below its own (the
    folders from the bottom up), except the imports that the page names as running
    against the order; each of those is still there and made inside a function."""
    order = _layer_order(_layout_listing())
    assert order[:3] == ["jaxchain/", "jaxchain/_physics/", "jaxchain/_engine/"]
    against = set(re.findall(r"^- `(jaxchain/[\w/]+\.py)` imports `(jaxchain/[\w/]+\.py)`",
                             LAYOUT, re.MULTILINE))
    crossing, named = [], {}
    for importer, imported, lazy in _package_imports():
        if order.index(_layer(imported)) <= order.index(_layer(importer)):
            continue
        if (importer, imported) in against:
            named[importer, imported] = named.get((importer, imported), True) and lazy
        else:
            crossing.append(f"{importer} imports {imported}")
    assert sorted(set(crossing)) == []
    assert sorted(against - set(named)) == [], "named on the page, no longer in the code"
    loaded = [pair for pair, lazy in named.items() if not lazy]
    assert loaded == [], "against the order, and made when the module loads"


def test_the_readme_gives_the_layer_order_of_the_developers_page():
    listing = README.split("## Layout", 1)[1].split("```")[1]
    readme = re.findall(r"^  (_\w+)/", listing, re.MULTILINE)
    page = [layer.split("/")[1] for layer in _layer_order(_layout_listing())[1:]]
    assert readme == page
