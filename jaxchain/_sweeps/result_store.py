"""Stored results keyed by everything that determines them, so that a resumed study
never reads back a result computed with other settings."""

from __future__ import annotations

from typing import TYPE_CHECKING

import csv
from collections.abc import Callable
from pathlib import Path


from .atomic import replacing
from .._engine.hashes import FORMAT_VERSION, canonical, settings_json, settings_key  # noqa: F401
from .datasets import save_dataset
from .._errors import ValidationError

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr


def read_dataset(path: Path, kind: str, **settings) -> xr.Dataset | None:
    """The Dataset that `write_dataset` stored at `path` for these settings, loaded
    into memory.

    **Returns:**

    The Dataset, or None when there is no file, when it cannot be read, or when it
    was stored under another key (a result of other settings, to be recomputed).
    """
    import xarray as xr

    if not Path(path).exists():
        return None
    try:
        with xr.open_dataset(path, engine="h5netcdf") as stored:
            if stored.attrs.get("settings_key") != settings_key(kind, **settings):
                return None
            return stored.load()
    except (OSError, ValueError):
        return None


def write_dataset(ds: xr.Dataset, path: Path, kind: str, **settings) -> Path:
    """Store `ds` at `path` with the key of its settings (`settings_key`) and the
    JSON that the key hashes, as the attributes `settings_key` and `settings`. The
    file is written whole or not at all (`save_dataset`): an interrupted run
    leaves the previous file, never a truncated one.

    **Returns:**

    The path written.
    """
    path = Path(path)
    ds = ds.assign_attrs(settings_key=settings_key(kind, **settings),
                         settings=settings_json(kind, **settings))
    return save_dataset(ds, path)


class CsvStore:
    """A CSV file of results, one row each, appended as they come and keyed by the
    column `key` (`settings_key` of the row's settings). Use as a context manager.

    A row is read back only for its own key (`row`); rows of other keys stay in
    the file and are never read back. A file of another layout (columns) is
    rewritten in `columns` first, with its rows kept and the missing columns left
    empty, so that its rows, without a key, are never read back either. Rows are
    only ever appended, whole lines flushed one at a time; the rewrite goes to a
    temporary file renamed into place (`replacing`), so that a kill never loses
    the rows already written.

    **Arguments:**

    - `path`: the CSV file, created with its parent folder if missing.
    - `columns`: the columns, `key` among them.

    **Raises:**

    `ValidationError` when `columns` has no `key`.
    """

    def __init__(self, path: Path, columns: tuple[str, ...]):
        if "key" not in columns:
            raise ValidationError(f"CsvStore columns must include 'key', got {columns}")
        self.path, self.columns = Path(path), tuple(columns)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        stored = []
        if self.path.exists():
            with open(self.path, newline="") as f:
                reader = csv.DictReader(f)
                stored = list(reader)
                header = reader.fieldnames or []
            if list(header) != list(self.columns):
                self._rewrite(stored)
        self.stored = {r["key"]: r for r in stored if r.get("key")}
        self.file = open(self.path, "a", newline="")
        self.writer = csv.DictWriter(self.file, fieldnames=self.columns)
        if self.file.tell() == 0:
            self.writer.writeheader()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.file.close()

    def row(self, key: str) -> dict | None:
        """The stored row of `key` (a dict of strings), or None."""
        return self.stored.get(key)

    def append(self, row: dict) -> dict:
        """Write `row` (a missing column left empty) to the file at once.

        **Returns:**

        The row as the file holds it, a dict of strings.
        """
        full = {c: str(row.get(c, "")) for c in self.columns}
        self.writer.writerow(full)
        self.file.flush()
        self.stored[full["key"]] = full
        return full

    def fetch(self, row: dict, compute: Callable[[], dict]) -> dict:
        """The stored row of `row["key"]`, or else `row | compute()`, appended."""
        stored = self.row(row["key"])
        return stored if stored is not None else self.append(row | compute())

    def _rewrite(self, rows: list[dict]):
        with replacing(self.path) as partial, open(partial, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=self.columns, extrasaction="ignore")
            writer.writeheader()
            writer.writerows({c: r.get(c, "") for c in self.columns} for r in rows)
