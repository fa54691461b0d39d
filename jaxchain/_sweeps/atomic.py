"""Files written whole or not at all, and the test hook that holds a writer.

Every file that jaxchain writes (netCDF, JSON, CSV, Markdown, figures) is written
to a temporary file beside it, in the same folder, and renamed into place with
`os.replace`, which is atomic on POSIX and Windows: a process killed at any point
leaves the previous file whole (or no file), never a truncated one. Nothing here
calls fsync: a kill is covered, a power loss is not.
"""

import contextlib
import os
import shutil
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

#: The environment variable of the test hook (`hold`): a folder.
HOLD = "JAXCHAIN_TEST_HOLD"


def hold(what: str) -> None:
    """Test hook: hold a writer where a test wants to kill it. A no-op (one look
    at the environment) unless the variable `JAXCHAIN_TEST_HOLD` names a folder.

    There, a writer about to commit a write (`replacing` before its rename, a
    sweep store before it writes a batch, an overwritten sweep store before its
    swap) takes the next free number n, shared by every process holding in that
    folder, writes the file `reached-<n>` (the line `what`, then its process id),
    and waits until a file `release-<n>` or `release` exists there. A test kills
    it while it waits, so that the kill lands exactly at that write, or releases
    it (`tests/helpers.py`: `held`, `release`).
    """
    folder = os.environ.get(HOLD)
    if not folder:
        return
    folder, n = Path(folder), 1
    while True:  # claim n: O_EXCL makes two processes never take the same one
        try:
            os.close(os.open(folder / f"{n}.claimed", os.O_CREAT | os.O_EXCL))
            break
        except FileExistsError:
            n += 1
    note = folder / f"{n}.note"
    note.write_text(f"{what}\n{os.getpid()}\n")
    os.replace(note, folder / f"reached-{n}")  # seen whole or not at all
    while not ((folder / f"release-{n}").exists() or (folder / "release").exists()):
        time.sleep(0.01)


def partial_path(path: Path) -> Path:
    """A fresh temporary name beside `path`: `<name>.<random>.partial`."""
    return path.with_name(f"{path.name}.{uuid.uuid4().hex[:12]}.partial")


@contextlib.contextmanager
def replacing(path: str | Path) -> Iterator[Path]:
    """A temporary path beside `path` (`partial_path`), creating the parent
    folder: write the file there inside the block. On leaving it, the file is
    renamed to `path` (`os.replace`); if the block raises, the temporary file is
    removed and `path` is left as it was.

    **Example:**

    ```python
    with replacing(out / "summary.json") as tmp:
        tmp.write_text(text)
    ```
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = partial_path(path)
    try:
        yield partial
        hold(f"write {path.name}")
        os.replace(partial, path)
    except BaseException:
        if partial.is_dir():
            shutil.rmtree(partial, ignore_errors=True)
        else:
            partial.unlink(missing_ok=True)
        raise


def write_text(path: str | Path, text: str) -> Path:
    """Write `text` (UTF-8) to `path` whole or not at all (`replacing`).

    **Returns:**

    The path written.
    """
    with replacing(path) as partial:
        partial.write_text(text, encoding="utf-8")
    return Path(path)


def save_figure(fig, path: str | Path, dpi: int = 150, close: bool = True) -> Path:
    """Write a matplotlib figure to `path` whole or not at all (`replacing`), in
    the format of its suffix (.png, .pdf, .svg), and close it unless `close` is
    False (a command makes several, and may save one in several formats).

    **Returns:**

    The path written.
    """
    import matplotlib.pyplot as plt  # imported by the figure's maker already

    path = Path(path)
    try:
        with replacing(path) as partial:
            fig.savefig(partial, dpi=dpi,
                        format=path.suffix.lstrip(".") or plt.rcParams["savefig.format"])
    finally:
        if close:
            plt.close(fig)
    return path
