"""Execute the notebooks of examples/ at their full size and write them, with their
outputs, to docs/notebooks/, where the documentation shows them. The notebooks in
examples/ stay stored without outputs; tests/test_docs.py checks that the code of
each executed copy is the code of its notebook.

    python docs/execute_notebooks.py [NAME ...]
    python docs/execute_notebooks.py --compact   (the stored copies' figures only)
"""

import base64
import io
import sys
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


def execute(name: str) -> float:
    """Run examples/NAME in a fresh kernel, from a scratch folder, and write
    docs/notebooks/NAME (through a temporary name). Returns the wall time in s."""
    import tempfile

    nb = nbformat.read(SOURCE / name, as_version=4)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as scratch:
        NotebookClient(nb, timeout=3600, kernel_name="python3",
                       resources={"metadata": {"path": scratch}}).execute()
    compact_figures(nb)
    TARGET.mkdir(exist_ok=True)
    partial = TARGET / (name + ".partial")
    nbformat.write(nb, partial)
    partial.replace(TARGET / name)
    return time.perf_counter() - start


if __name__ == "__main__":
    if sys.argv[1:] == ["--compact"]:  # the stored copies' figures only, no run
        for path in sorted(TARGET.glob("*.ipynb")):
            nb = nbformat.read(path, as_version=4)
            compact_figures(nb)
            nbformat.write(nb, path)
        sys.exit(0)
    names = sys.argv[1:] or sorted(p.name for p in SOURCE.glob("*.ipynb"))
    for name in names:
        print(f"{name}: {execute(name):.0f} s", flush=True)
