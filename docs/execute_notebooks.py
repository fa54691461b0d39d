"""Execute the notebooks of examples/ at their full size and write them, with their
outputs, to docs/notebooks/, where the documentation shows them. The notebooks in
examples/ stay stored without outputs; tests/test_docs.py checks that the code of
each executed copy is the code of its notebook, and that no output names a path of
the machine that ran it.

    python docs/execute_notebooks.py [NAME ...]
    python docs/execute_notebooks.py --compact   (the stored copies' figures and
                                                  printed outputs only, no run)
"""

import base64
import io
import re
import sys
import tempfile
import time
from pathlib import Path

import nbformat
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parents[1]
SOURCE, TARGET = ROOT / "examples", ROOT / "docs" / "notebooks"


def compact_figures(nb) -> None:
    """Store each PNG figure of `nb` with a palette of 256 colours (Pillow), a few
    times smaller than matplotlib's RGBA and alike to the eye for line and dot
    plots: the executed notebooks stay small in the repository."""
    from PIL import Image

    for cell in nb.cells:
        for output in cell.get("outputs", []):
            data = output.get("data", {})
            if "image/png" not in data:
                continue
            image = Image.open(io.BytesIO(base64.b64decode(data["image/png"])))
            buffer = io.BytesIO()
            image.convert("RGB").quantize(colors=256).save(buffer, format="PNG",
                                                           optimize=True)
            data["image/png"] = base64.b64encode(buffer.getvalue()).decode("ascii")


def _redraw(line: str) -> str:
    """What a terminal shows of `line`: each carriage return starts the next piece
    over the previous ones (a progress bar's successive states)."""
    shown = ""
    for piece in line.split("\r"):
        shown = piece + shown[len(piece):]
    return shown.rstrip()


#: A line of a text progress bar (tqdm's: "sweep: 100%|####| 420/420 [01:44<00:00,
#: 4.04trajectory/s]", or "12it [00:01, 8.00it/s]" without a total): a terminal's
#: display, which a page shows as raw text.
PROGRESS = re.compile(r"\d+%\|[^\n]*\|[^\n]*\[[\d:]+"
                      r"|\[\d+:\d\d(?::\d\d)?(?:<[\d:?]+)?, *[\d.?]+ ?[^\]\n/]*/[^\]\n]*\]")


def compact_streams(nb) -> None:
    """Join each run of printed outputs of a cell (stdout or stderr) into one, keep of
    each line what a terminal would show at the end (the last state of a line redrawn
    by carriage returns), and drop the lines of progress bars (`PROGRESS`): the run's
    display, not its result. Without this, each redraw of a bar is an output of its
    own, and the documentation shows them all as raw text."""
    for cell in nb.cells:
        joined = []
        for output in cell.get("outputs", []):
            if (output.get("output_type") == "stream" and joined
                    and joined[-1].get("output_type") == "stream"
                    and joined[-1]["name"] == output["name"]):
                joined[-1]["text"] += output["text"]
            else:
                joined.append(output)
        for output in joined:
            if output.get("output_type") == "stream":
                lines = output["text"].split("\n")
                shown = (_redraw(line) for line in lines if "\r" not in line or _redraw(line))
                output["text"] = "\n".join(line for line in shown if not PROGRESS.search(line))
        if "outputs" in cell:
            cell["outputs"] = [o for o in joined if o.get("output_type") != "stream"
                               or o["text"].strip()]


#: What no published output may hold: an absolute path of the machine that ran the
#: notebook (of this checkout, of the Python installation, of a temporary or home
#: folder; not a URL's path), or a warning of tqdm's (which names its own file).
MACHINE = re.compile(r"(?<![\w.:/<~-])/[A-Za-z_][\w.-]*/[\w.-]|site-packages|TqdmWarning")


def machine_outputs(nb) -> list[str]:
    """The outputs of `nb` (as 'cell I: text') that hold a match of `MACHINE`."""
    found = []
    for i, cell in enumerate(nb.cells):
        for output in cell.get("outputs", []):
            texts = [output.get("text", ""), *output.get("traceback", [])]
            texts += [v for k, v in output.get("data", {}).items()
                      if isinstance(v, str) and not k.startswith("image/")]
            found += [f"cell {i}: {t.strip()[:300]}" for t in texts if MACHINE.search(t)]
    return found


def execute(name: str) -> float:
    """Run examples/NAME in a fresh kernel, from a scratch folder, and write
    docs/notebooks/NAME (through a temporary name). Returns the wall time in s.
    Raises `RuntimeError`, leaving the run in docs/notebooks/NAME.partial, where an
    output names a path of this machine (`machine_outputs`)."""
    nb = nbformat.read(SOURCE / name, as_version=4)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as scratch:
        NotebookClient(nb, timeout=3600, kernel_name="python3",
                       resources={"metadata": {"path": scratch}}).execute()
    compact_figures(nb)
    compact_streams(nb)
    TARGET.mkdir(exist_ok=True)
    partial = TARGET / (name + ".partial")
    nbformat.write(nb, partial)
    if found := machine_outputs(nb):
        raise RuntimeError(f"{name}: outputs name a path of this machine (remove their "
                           f"cause, then run it again; the run is in {partial}):\n"
                           + "\n".join(found))
    partial.replace(TARGET / name)
    return time.perf_counter() - start


if __name__ == "__main__":
    if sys.argv[1:] == ["--compact"]:  # the stored copies' outputs only, no run
        for path in sorted(TARGET.glob("*.ipynb")):
            nb = nbformat.read(path, as_version=4)
            compact_figures(nb)
            compact_streams(nb)
            nbformat.write(nb, path)
        sys.exit(0)
    names = sys.argv[1:] or sorted(p.name for p in SOURCE.glob("*.ipynb"))
    for name in names:
        print(f"{name}: {execute(name):.0f} s", flush=True)
