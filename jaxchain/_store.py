"""Stored results keyed by everything that determines them, so that a resumed study
never reads back a result computed with other settings."""

import csv
import dataclasses
import functools
import hashlib
import inspect
import json
import os
from collections.abc import Callable
from pathlib import Path

import jax
import numpy as np
import xarray as xr

from ._results import save_dataset

#: Part of every key. Raise it whenever what a stored result holds, or how it is
#: computed, changes: every result stored before is then recomputed.
FORMAT_VERSION = 1


def canonical(obj):
    """`obj` as plain JSON data that depends only on its values.

    - Dataclasses, `eqx.Module`s included (parameters, options, solvers): their
        class and every field, static fields too.
    - NumPy and JAX arrays and scalars: their values (`tolist()`), so that a float
        and a 0-d float64 array of the same value give the same data.
    - Classes and functions defined at the top level of a module: their
        qualified name; `functools.partial`: its function and arguments; any other
        object with a `__dict__` (for example a sentinel): its class and
        attributes.
    - Dicts (keys as strings), lists and tuples, recursively; str, int, float,
        bool and None as they are.

    **Arguments:**

    - `obj`: the object.

    **Returns:**

    Nested dicts, lists, strings, numbers, booleans and None.

    **Raises:**

    `TypeError` for a traced value, a lambda, a closure or a function defined
    inside another (two of them share a name, not their content: two closures
    over different values would share one stored result), or an object of any
    other type: such a value cannot be keyed by its content.
    """
    if obj is None or isinstance(obj, (bool, int, float, str)):
        return obj
    if isinstance(obj, jax.core.Tracer):
        raise TypeError("a traced value cannot be part of a stored result's key")
    if isinstance(obj, (np.ndarray, np.generic, jax.Array)):
        return np.asarray(obj).tolist()
    if isinstance(obj, dict):
        return {str(k): canonical(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [canonical(v) for v in obj]
    if isinstance(obj, functools.partial):
        return {"partial": _name(obj.func), "args": canonical(obj.args),
                "keywords": canonical(obj.keywords)}
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {"class": _name(type(obj)),
                "fields": {f.name: canonical(getattr(obj, f.name))
                           for f in dataclasses.fields(obj)}}
    if callable(obj):
        _check_named(obj)
        return {"callable": _name(obj)}
    if hasattr(obj, "__dict__"):  # a plain object, for example a sentinel
        return {"class": _name(type(obj)), "attributes": canonical(vars(obj))}
    raise TypeError(f"cannot key a stored result by an object of type {type(obj).__name__}")


def _check_named(fn) -> None:
    """Raise `TypeError` unless the callable `fn` is what its qualified name says:
    a class, or a function defined at a module's top level, with no closure and
    not bound to an object."""
    if isinstance(fn, type):
        return
    qualname = getattr(fn, "__qualname__", None)
    if (qualname is None or "<lambda>" in qualname or "<locals>" in qualname
            or getattr(fn, "__closure__", None) or inspect.ismethod(fn)):
        raise TypeError(f"cannot key a stored result by the function {qualname or fn!r}: a "
                        "lambda, a closure, a bound method or a local function is known by "
                        "its name, not by what it computes; pass a parameter name, or a "
                        "function defined at a module's top level (with functools.partial "
                        "for its arguments)")


def _name(obj) -> str:
    return f"{getattr(obj, '__module__', '?')}.{getattr(obj, '__qualname__', repr(obj))}"


def settings_json(kind: str, **settings) -> str:
    """The canonical JSON of `settings` (sorted keys, no spaces), with `kind` and
    `FORMAT_VERSION`: the text that `settings_key` hashes."""
    data = {"kind": kind, "format_version": FORMAT_VERSION, "settings": canonical(settings)}
    return json.dumps(data, sort_keys=True, separators=(",", ":"), allow_nan=True)


def settings_key(kind: str, **settings) -> str:
    """The key of a stored result: the SHA-256 of `settings_json(kind, **settings)`.

    Two results share a key only when they are of the same kind and were computed
    from equal settings (`canonical` values) by the same `FORMAT_VERSION`.

    **Arguments:**

    - `kind`: what the result is, for example "crosscheck reference".
    - `settings`: everything that determines the result: parameters, initial state,
        options, solver.

    **Returns:**

    64 hexadecimal digits.

    **Raises:**

    `TypeError` for a setting that `canonical` cannot turn into data.
    """
    return hashlib.sha256(settings_json(kind, **settings).encode()).hexdigest()


def read_dataset(path: Path, kind: str, **settings) -> xr.Dataset | None:
    """The Dataset that `write_dataset` stored at `path` for these settings, loaded
    into memory.

    **Returns:**

    The Dataset, or None when there is no file, when it cannot be read, or when it
    was stored under another key (a result of other settings, to be recomputed).
    """
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
    file is written whole or not at all: an interrupted run leaves no partial file
    behind.

    **Returns:**

    The path written.
    """
    path = Path(path)
    ds = ds.assign_attrs(settings_key=settings_key(kind, **settings),
                         settings=settings_json(kind, **settings))
    partial = save_dataset(ds, path.with_name(path.name + ".partial"))
    os.replace(partial, path)
    return path


class CsvStore:
    """A CSV file of results, one row each, appended as they come and keyed by the
    column `key` (`settings_key` of the row's settings). Use as a context manager.

    A row is read back only for its own key (`row`); rows of other keys stay in
    the file and are never read back. A file of another layout (columns) is
    rewritten in `columns` first, with its rows kept and the missing columns left
    empty, so that its rows, without a key, are never read back either.

    **Arguments:**

    - `path`: the CSV file, created with its parent folder if missing.
    - `columns`: the columns, `key` among them.

    **Raises:**

    `ValueError` when `columns` has no `key`.
    """

    def __init__(self, path: Path, columns: tuple[str, ...]):
        if "key" not in columns:
            raise ValueError(f"CsvStore columns must include 'key', got {columns}")
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
        partial = self.path.with_name(self.path.name + ".partial")
        with open(partial, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=self.columns, extrasaction="ignore")
            writer.writeheader()
            writer.writerows({c: r.get(c, "") for c in self.columns} for r in rows)
        os.replace(partial, self.path)
