"""Where the snake keeps its branches: one netCDF file per branch in a folder,
under the key of the settings that made it (`write_dataset`), read back by a
resumed run only where every setting matches. A start without a branch of its own
is kept as a record of why, so that a resumed run does not compute it again."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from ..._sweeps.result_store import read_dataset, write_dataset
from .starts import _start_label


@dataclasses.dataclass(frozen=True)
class StoredStart:
    """What a folder holds of one start: its branches (label -> dataset: its own,
    those switched onto, the deflated ones with theirs), and, where it has no branch
    of its own, why (`no_branch`), its simulation's n_HALC and energy, and the
    deflated orbits that lay on a branch already followed (`repeats`); `known`,
    every orbit the start gave deflation (the method's unknowns), or None in files
    written before they were kept."""

    branches: dict
    no_branch: str | None = None
    simulation: dict | None = None
    repeats: tuple = ()
    known: list | None = None


@dataclasses.dataclass(frozen=True)
class BranchStore:
    """The snake's files in the folder `out` (None: nothing is kept), keyed by
    `settings` (a dict of everything that shapes a branch)."""

    out: Path | None
    settings: dict

    def path(self, k) -> Path | None:
        """The file of start k's own branch (`branch_k<k>.nc`, `branch_<name>.nc`)."""
        if self.out is None:
            return None
        name = f"branch_{k}.nc" if isinstance(k, str) else f"branch_k{k}.nc"
        return Path(self.out) / name.replace(":", "")

    def read(self, k) -> StoredStart | None:
        """Start k as stored with these settings, or None if anything of it is
        missing or was made with other settings."""
        if self.out is None:
            return None
        label = _start_label(k)
        branches = self._read(self.path(k), k, label)
        if branches is None:
            return None
        record = branches[label]
        known = (json.loads(record.attrs["deflation_known"])
                 if "deflation_known" in record.attrs else None)
        if "no_branch" not in record.attrs:
            return StoredStart(branches, known=known)
        del branches[label]
        return StoredStart(branches, record.attrs["no_branch"],
                           json.loads(record.attrs["simulation"]),
                           tuple(deflated_repeats(record)), known)

    def write(self, k, branches: dict, deflated: int = 0) -> None:
        """Write a start's branch (`deflated` 0) or its `deflated`-th deflated
        branch, and the branches switched onto from it, each with the key."""
        if self.out is None:
            return
        Path(self.out).mkdir(parents=True, exist_ok=True)
        path = _numbered(self.path(k), "deflated", deflated)
        label = next(iter(branches))
        for j, b in enumerate(branches.values()):
            write_dataset(b, _numbered(path, "switched", j), "snake branch", k=k, label=label,
                          switched=j, **self.settings)

    def write_no_branch(self, k, why: str, simulation: dict, deflated: int, repeats: list,
                        known: list) -> None:
        """Keep start k without a branch of its own: why, its simulation, how many
        deflated branches it has, the deflated orbits on branches already followed
        and every orbit it gave deflation (`known`, the method's unknowns)."""
        import xarray as xr

        self.write(k, {_start_label(k): xr.Dataset(attrs={
            "no_branch": why, "simulation": json.dumps(simulation), "switched": 0,
            "deflated": deflated, **repeats_attribute(repeats),
            **deflation_known(known)})})

    def _read(self, path: Path, k, label: str) -> dict | None:
        first = read_dataset(path, "snake branch", k=k, label=label, switched=0,
                             **self.settings)
        if first is None:
            return None
        out = {label: first}
        for j in range(1, int(first.attrs.get("switched", 0)) + 1):
            out[f"{label} switched {j}"] = read_dataset(
                _numbered(path, "switched", j), "snake branch", k=k, label=label, switched=j,
                **self.settings)
        if any(ds is None for ds in out.values()):
            return None
        for j in range(1, int(first.attrs.get("deflated", 0)) + 1):
            deflated = self._read(_numbered(path, "deflated", j), k, f"{label} deflated {j}")
            if deflated is None:
                return None
            out |= deflated
        return out


def repeats_attribute(repeats: list) -> dict:
    """The attribute that keeps a start's deflated orbits that lay on a branch
    already followed (records of start, energy, n_halc and the branch `on`)."""
    return {"deflated_repeats": json.dumps(repeats)}


def deflated_repeats(ds) -> list:
    """The records that `repeats_attribute` kept on the stored branch `ds` ([] for a
    branch without them: a switched or deflated one)."""
    return json.loads(ds.attrs.get("deflated_repeats", "[]"))


def deflation_known(known: list) -> dict:
    """The attribute that keeps every orbit a start gave deflation (the method's
    unknowns), for a resumed run to deflate them again."""
    return {"deflation_known": json.dumps([np.asarray(u, dtype=float).tolist()
                                           for u in known])}


def _numbered(path: Path | None, what: str, j: int) -> Path | None:
    """The file of the j-th branch of kind `what` (switched, deflated) beside the
    branch stored at `path` (j = 0: that branch)."""
    return path if path is None or j == 0 else path.with_name(f"{path.stem}_{what}{j}.nc")
