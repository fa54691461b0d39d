"""The zarr store of a sweep: one flat `trajectory` axis cut in chunks of one batch,
a completion flag per batch, and the key of every setting that made it."""

from __future__ import annotations

from typing import TYPE_CHECKING

import json
import os
import shutil
from pathlib import Path

import numpy as np

from .atomic import hold, partial_path
from .datasets import cf_dataset
from .._errors import ValidationError

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr

#: Unwritten entries of a batch that has not finished, as they are read back.
_MISSING = {"f": np.nan, "i": -1, "u": 0, "b": False}


class SweepStore:
    """A sweep's results at `path` (a zarr store, written with xarray).

    - `create` writes the layout once: every variable along `trajectory` in chunks
        of one batch, the flags `batch_done` (one chunk per batch), the grid's
        coordinates, and the attributes `settings_key` and `settings`. It writes
        to a temporary folder that is renamed into place, so that a store is
        complete or absent, and two hosts creating it at once make one.
    - `write` writes a batch into its own chunks (`to_zarr(region=...)`), then
        flags it done. zarr writes each chunk to a temporary file renamed into
        place, so a flag is either set or not; a batch whose writing was cut
        short is unflagged, and is redone.
    - An overwrite never removes a store before its replacement is complete: the
        new sweep is built in `pending` (`<name>.overwrite`, beside it), and
        `swap_in` puts it in place once every batch is flagged. A kill at any
        point leaves the old store whole at `path`, or, between the two renames
        of the swap, whole at `<name>.replaced` beside the complete new one
        (`recover` finishes that swap).
    - Only a jaxchain sweep store is ever resumed, overwritten or removed
        (`require_sweep`): a zarr group without the attributes `settings_key`
        and `swept` and the flags `batch_done` is left untouched.

    **Arguments:**

    - `path`: the store's folder, conventionally `*.zarr`.
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)

    def exists(self) -> bool:
        """Whether a zarr group is at `path` (a sweep store or any other)."""
        return (self.path / "zarr.json").exists() or (self.path / ".zgroup").exists()

    def occupied(self) -> bool:
        """Whether anything but an empty folder is at `path`."""
        return self.path.is_symlink() or (self.path.exists() and not (
            self.path.is_dir() and not any(self.path.iterdir())))

    def is_sweep(self) -> bool:
        """Whether `path` holds a jaxchain sweep store: a zarr group with the
        attributes `settings_key` and `swept` and the flags `batch_done`."""
        import zarr

        if not self.exists():
            return False
        try:
            group = zarr.open_group(str(self.path), mode="r")
            return ("settings_key" in group.attrs and "swept" in group.attrs
                    and "batch_done" in group)
        except (OSError, ValueError, KeyError):
            return False

    def require_sweep(self, action: str) -> None:
        """**Raises:** `ValidationError` naming `path` when something other than a
        jaxchain sweep store (`is_sweep`) or an empty folder is there: it is
        not ours to `action` (resume, overwrite, ...), and is left untouched."""
        if self.occupied() and not self.is_sweep():
            raise ValidationError(
                f"store {self.path} exists and is not a jaxchain sweep store (a zarr "
                "group with the attributes settings_key and swept and the flags "
                f"batch_done): refusing to {action} it, it is left untouched; choose "
                "another store")

    def key(self) -> str | None:
        """The `settings_key` of the sweep stored here, or None if there is none."""
        return self.settings()[0] if self.is_sweep() else None

    def pending(self) -> "SweepStore":
        """The store that an overwrite of this one builds beside it,
        `<name>.overwrite`, until `swap_in` puts it in place."""
        return SweepStore(self.path.with_name(self.path.name + ".overwrite"))

    def _replaced(self) -> Path:
        return self.path.with_name(self.path.name + ".replaced")

    def swap_in(self, new: "SweepStore") -> None:
        """Put the complete store `new` (`pending`) in place of this one: this one
        is renamed to `<name>.replaced`, `new` to `path`, then the old one is
        removed. Each step is a rename or comes after them, so that a kill leaves
        a whole store at `path`, or the two whole stores that `recover` sorts
        out."""
        hold(f"swap {self.path.name}")
        replaced = self._replaced()
        if self.path.exists():
            os.rename(self.path, replaced)
        os.rename(new.path, self.path)
        shutil.rmtree(replaced, ignore_errors=True)

    def recover(self) -> None:
        """Finish a `swap_in` cut short by a kill. With `path` missing and the old
        store at `<name>.replaced`: the new one (`pending`) is renamed into place,
        or, if there is none, the old one is put back. With `path` present, a
        leftover `<name>.replaced` (the old store, partly removed) is removed.
        `sweep` calls it before it plans a run; a reader (`open_sweep`) does not,
        and finds no sweep at `path` in that state."""
        replaced = self._replaced()
        if not replaced.exists():
            return
        if not self.path.exists():
            pending = self.pending()
            os.rename(pending.path if pending.is_sweep() else replaced, self.path)
        shutil.rmtree(replaced, ignore_errors=True)

    def settings(self) -> tuple[str, dict]:
        """The key and the settings (as JSON data) that made the store."""
        import xarray as xr

        attrs = xr.open_zarr(self.path, consolidated=False).attrs
        return attrs["settings_key"], json.loads(attrs["settings"])

    def check(self, key: str, settings: str) -> None:
        """**Raises:** `ValidationError`, in one line naming the settings that differ,
        when the store was made with settings other than those of `key`."""
        stored_key, stored = self.settings()
        if stored_key == key:
            return
        new = json.loads(settings)
        differ = sorted(_differences(stored, new)) or ["the format version"]
        raise ValidationError(f"{self.path} holds a sweep made with other settings "
                              f"({', '.join(differ)} differ): choose another store, or "
                              "overwrite it")

    def remove(self) -> None:
        """Remove the sweep store at `path`.

        **Raises:**

        `ValidationError` (`require_sweep`) when `path` holds anything else."""
        self.require_sweep("remove")
        shutil.rmtree(self.path)

    def create(self, batch: xr.Dataset, n_trajectories: int, batch_size: int,
               coords: dict, attrs: dict) -> None:
        """Write the layout of a store of `n_trajectories`, taking each variable's
        trailing shape and dtype from the finished `batch` (dims `trajectory`, ...),
        unless the store exists already (another host made it). Nothing is
        computed or held for the whole grid: the variables are lazy dask arrays of
        which only the metadata is written."""
        import dask.array as da
        import xarray as xr

        n_batches = -(-n_trajectories // batch_size)
        data = {}
        for name, var in batch.data_vars.items():
            shape = (n_trajectories, *var.shape[1:])
            data[name] = (var.dims, da.full(shape, _MISSING[var.dtype.kind],
                                            dtype=var.dtype,
                                            chunks=(batch_size, *var.shape[1:])),
                          var.attrs)
        data["batch_done"] = ("batch", da.zeros(n_batches, dtype=np.uint8, chunks=1))
        template = cf_dataset(xr.Dataset(data, coords=coords, attrs=attrs))
        partial = partial_path(self.path)
        template.to_zarr(partial, mode="w", compute=False, consolidated=False)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            os.rename(partial, self.path)
        except OSError:  # made meanwhile by another host
            shutil.rmtree(partial, ignore_errors=True)
            if not self.exists():
                raise

    def done(self) -> np.ndarray:
        """Whether each batch has finished, shape (n_batches,). Read here, without
        Dask: with a `distributed.Client` active, a Dask array would be read by
        the cluster's workers, a task per flag."""
        import xarray as xr

        flags = xr.open_zarr(self.path, consolidated=False, chunks=None)["batch_done"]
        return flags.values == 1

    def write(self, index: int, start: int, batch: xr.Dataset) -> None:
        """Write `batch` (trajectories start, start + 1, ...) into its region, then
        flag batch `index` done."""
        import xarray as xr

        hold(f"{self.path.name} batch {index}")
        region = {"trajectory": slice(start, start + batch.sizes["trajectory"])}
        batch.to_zarr(self.path, region=region, consolidated=False)
        flag = xr.Dataset({"batch_done": ("batch", np.ones(1, dtype=np.uint8))})
        flag.to_zarr(self.path, region={"batch": slice(index, index + 1)},
                     consolidated=False)

    def open(self) -> xr.Dataset:
        """The stored Dataset, lazily (dask arrays), with the entries of unfinished
        batches replaced by NaN, -1 or False."""
        import xarray as xr

        ds = xr.open_zarr(self.path, consolidated=False)
        done = self.done()
        ds["batch_done"] = ("batch", done.astype(np.uint8))
        if done.all():
            return ds
        per_trajectory = xr.DataArray(np.repeat(done, ds.attrs["batch_size"])
                                      [:ds.sizes["trajectory"]], dims="trajectory")
        for name, var in ds.data_vars.items():
            if "trajectory" in var.dims:
                ds[name] = var.where(per_trajectory, _MISSING[var.dtype.kind])
        return ds


def _leaves(obj, path: tuple = ()) -> dict:
    """Settings JSON data as {path: value}; the wrappers "settings" and "fields"
    (`settings_json`, `canonical`) are left out of the paths."""
    if not isinstance(obj, dict):
        return {path: obj}
    out = {}
    for k, v in obj.items():
        out |= _leaves(v, path if k in ("settings", "fields") else (*path, k))
    return out


def _differences(old: dict, new: dict) -> list[str]:
    """The settings (`engine.eps`, `options.t_end`, `ics.eq10`, ...) at which two
    differ, named to two levels."""
    old, new = _leaves(old), _leaves(new)
    return list({".".join(p[:2]) for p in set(old) | set(new) if old.get(p) != new.get(p)})
