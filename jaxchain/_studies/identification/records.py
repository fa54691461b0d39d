"""Measured records of a rig: the motion of some of its oscillators at one belt
speed, read from a CSV file or an `xarray.Dataset` and checked before any fit."""

from __future__ import annotations

import csv
import re
from pathlib import Path

import equinox as eqx
import numpy as np

from ..._errors import ValidationError
from ..._physics.scales import Scales

#: The columns of a record: t, x<n> and v<n> (oscillator n, from 1, as in the
#: paper), and v_d.
_COLUMN = re.compile(r"^([xv])(\d+)$")


class Record(eqx.Module):
    """The measured motion of a rig at one belt speed, dimensionless (eqs. (4)-(6)).

    **Fields:**

    - `t`: sample times, strictly increasing, shape (m,).
    - `x`: measured displacements, shape (m, k): column j is oscillator
        `oscillators[j]`.
    - `oscillators`: the measured oscillators, numbered from 1 (static).
    - `v`: measured velocities of the same oscillators, shape (m, k), or None.
    - `v_d`: the belt speed.
    - `source`: where it was read (a file name, or "dataset").
    """

    t: np.ndarray
    x: np.ndarray
    oscillators: tuple = eqx.field(static=True)
    v: np.ndarray | None
    v_d: float = eqx.field(static=True)
    source: str = eqx.field(static=True)

    @property
    def n_samples(self) -> int:
        """The number of measured values (samples times measured columns)."""
        return int(self.x.size + (0 if self.v is None else self.v.size))

    def check(self, n_osc: int, n_parameters: int = 0) -> "Record":
        """The record, checked against a chain of `n_osc` oscillators and a fit of
        `n_parameters` unknowns.

        **Raises:** `ValidationError` naming the source and the column for an
        oscillator outside the chain, or fewer measured values than unknowns."""
        for n in self.oscillators:
            if not 1 <= n <= n_osc:
                raise ValidationError(f"{self.source}: column x{n}: the chain has {n_osc} "
                                      f"oscillators, numbered 1..{n_osc}")
        if self.n_samples < n_parameters:
            raise ValidationError(f"{self.source}: {self.n_samples} measured values for "
                                  f"{n_parameters} unknowns: a fit needs more samples")
        return self


def read_record(path: str | Path, v_d: float | None = None,
                scales: Scales | None = None) -> Record:
    """A record from a CSV file with a header: a column `t`, one column `x<n>` per
    measured oscillator (n from 1, as in the paper; any subset), optionally `v<n>`
    velocity columns of the same oscillators, and either a constant column `v_d` or
    the belt speed given here.

    **Arguments:**

    - `path`: the CSV file.
    - `v_d`: the belt speed, when the file has no `v_d` column (it must then not
        have one that disagrees).
    - `scales`: the `Scales` of a chain made by `from_physical` when the file is in
        SI units (s, m, m/s): the record is converted to the chain's dimensionless
        units. None: the file is dimensionless.

    **Returns:**

    A `Record`.

    **Raises:**

    `ValidationError` naming the file and the column for a file that cannot be read
    or is not UTF-8 text, no `t` column, no samples (a header alone), no `x<n>` column, an unknown column, a value that is not a number
    or is NaN, times that do not increase, a `v<n>` column without its `x<n>`, a
    `v_d` that is not constant or missing, or a belt speed <= 0.
    """
    path = Path(path)
    try:
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
    except OSError as err:
        raise ValidationError(f"{path}: cannot read it ({err.strerror})") from None
    except UnicodeDecodeError as err:
        raise ValidationError(f"{path}: not UTF-8 text (byte 0x{err.object[err.start]:02x} "
                              f"at offset {err.start}); save it as UTF-8") from None
    if not rows:
        raise ValidationError(f"{path}: empty file")
    header, body = [h.strip() for h in rows[0]], rows[1:]
    columns = {}
    for j, name in enumerate(header):
        values = []
        for i, row in enumerate(body, start=2):
            try:
                values.append(float(row[j]))
            except (IndexError, ValueError):
                raise ValidationError(f"{path}: column {name}, line {i}: "
                                      f"{row[j] if j < len(row) else 'nothing'!r} is "
                                      "not a number") from None
        columns[name] = np.asarray(values)
    return _record(columns, str(path), v_d, scales)


def record_from_dataset(ds, v_d: float | None = None, scales: Scales | None = None,
                        source: str = "dataset") -> Record:
    """A record from an `xarray.Dataset` with the variables of `read_record`'s
    columns (`t` a coordinate or a variable, `x<n>`, `v<n>`, `v_d`), each along
    one dimension.

    **Raises:** as `read_record`, naming `source`."""
    columns = {str(name): np.asarray(ds[name].values, dtype=float).reshape(-1)
               for name in list(ds.variables)}
    return _record(columns, source, v_d, scales)


def _record(columns: dict, source: str, v_d, scales: Scales | None) -> Record:
    if "t" not in columns:
        raise ValidationError(f"{source}: no column t (the sample times)")
    if columns["t"].size == 0:
        raise ValidationError(f"{source}: no samples (a header and no rows): a record "
                              "holds at least one row of measured values")
    measured = {}
    for name in columns:
        if name in ("t", "v_d"):
            continue
        match = _COLUMN.match(name)
        if match is None or int(match.group(2)) < 1:
            raise ValidationError(f"{source}: unknown column {name!r}: the columns are t, "
                                  "x<n> and v<n> (oscillator n from 1), v_d")
        measured[name] = (match.group(1), int(match.group(2)))
    for name, values in columns.items():
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise ValidationError(f"{source}: column {name}, sample {bad[0] + 1}: "
                                  f"{values[bad[0]]!r} is not a finite number")
    t = columns["t"]
    steps = np.diff(t)
    if np.any(steps <= 0):
        i = int(np.flatnonzero(steps <= 0)[0])
        raise ValidationError(f"{source}: column t must increase, but sample {i + 2} "
                              f"({t[i + 1]!r}) follows {t[i]!r}")
    oscillators = sorted(n for kind, n in measured.values() if kind == "x")
    if not oscillators:
        raise ValidationError(f"{source}: no column x<n>: a record measures at least one "
                              "oscillator's displacement")
    speeds = sorted(n for kind, n in measured.values() if kind == "v")
    if speeds and speeds != oscillators:
        missing = sorted(set(speeds) - set(oscillators)) or sorted(set(oscillators) -
                                                                   set(speeds))
        raise ValidationError(f"{source}: columns v<n> must be those of the x<n>; "
                              f"oscillator {missing[0]} has one and not the other")
    belt = _belt_speed(columns.get("v_d"), v_d, source)
    x = np.stack([columns[f"x{n}"] for n in oscillators], axis=1)
    v = np.stack([columns[f"v{n}"] for n in oscillators], axis=1) if speeds else None
    if scales is not None:
        t, x, belt = t / scales.time, x / scales.length, belt / scales.velocity
        v = None if v is None else v / scales.velocity
    return Record(t=t, x=x, oscillators=tuple(oscillators), v=v, v_d=float(belt),
                  source=source)


def _belt_speed(column, given, source: str) -> float:
    if column is not None:
        if not np.all(column == column[0]):
            raise ValidationError(f"{source}: column v_d must be constant (one belt speed "
                                  f"per record), got {column.min()!r} to {column.max()!r}")
        if given is not None and float(given) != float(column[0]):
            raise ValidationError(f"{source}: its column v_d is {column[0]!r}, but the belt "
                                  f"speed given is {given!r}")
        value = float(column[0])
    elif given is None:
        raise ValidationError(f"{source}: no column v_d and no belt speed given (--vd)")
    else:
        value = float(given)
    if not (np.isfinite(value) and value > 0):
        raise ValidationError(f"{source}: the belt speed must be > 0, got {value!r}")
    return value
