"""Execute the notebooks of examples/ at their full size and write them, with their
outputs, to docs/notebooks/, where the documentation shows them. The notebooks in
examples/ stay stored without outputs; tests/test_docs.py checks that the code of
each executed copy is the code of its notebook.

    python docs/execute_notebooks.py [NAME ...]
"""

import sys
import time
from pathlib import Path

import nbformat
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parents[1]
SOURCE, TARGET = ROOT / "examples", ROOT / "docs" / "notebooks"


def execute(name: str) -> float:
    """Run examples/NAME in a fresh kernel, from a scratch folder, and write
    docs/notebooks/NAME (through a temporary name). Returns the wall time in s."""
    import tempfile

    nb = nbformat.read(SOURCE / name, as_version=4)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as scratch:
        NotebookClient(nb, timeout=3600, kernel_name="python3",
                       resources={"metadata": {"path": scratch}}).execute()
    TARGET.mkdir(exist_ok=True)
    partial = TARGET / (name + ".partial")
    nbformat.write(nb, partial)
    partial.replace(TARGET / name)
    return time.perf_counter() - start


if __name__ == "__main__":
    names = sys.argv[1:] or sorted(p.name for p in SOURCE.glob("*.ipynb"))
    for name in names:
        print(f"{name}: {execute(name):.0f} s", flush=True)
