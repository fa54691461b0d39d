"""Sweeps: batches stored as they finish, resumed after a kill without recomputing a
stored batch, never resumed with other settings; a parameter swept through a lens
gives the runs made one by one; propagating fronts are flagged."""

import json
import signal
import subprocess

import numpy as np
import pytest
import xarray as xr

import jaxchain as jc
from jaxchain._analysis.fronts import front_ranges
from helpers import (JAXCHAIN, SHORT, SWEEP_BATCH as BATCH, SWEEP_RESULTS, assert_cf_compliant,
                     batch_writes, batches_done, held, hold_env, internal, kill, release,
                     replace_internal, small_sweep, sweep_cli)

#: The grid of the kill-and-resume tests: 2 belt speeds x eq. (8) with k = 1..3 on
#: a ring of 3, in 3 batches of 2 (`small_sweep`).
VD = "1.4:1.6:2"
CLI = sweep_cli(VD)
RESULTS = SWEEP_RESULTS


def _api_sweep(**kw):
    return small_sweep(VD, **kw)


@pytest.fixture(scope="module")
def uninterrupted():
    """The sweep run in one go, in memory."""
    return _api_sweep().load()


def _chunk_times(store, batches) -> dict:
    """Modification times of the stored chunks of `batches` (every variable)."""
    return {p: p.stat().st_mtime_ns for b in batches
            for p in store.glob(f"*/c/{b}") if p.is_file()}


def test_sweep_killed_then_resumed_equals_an_uninterrupted_run(tmp_path, uninterrupted):
    """`jaxchain sweep` in its own process is killed (SIGKILL) while it holds
    before writing batch 1, batch 0 stored (the writers' test hook), then resumed
    (here through the API, with the same settings: the store's key admits it): the
    result equals the uninterrupted run, and only the batches not stored at the
    kill are computed again (their count, and the stored chunks of the others left
    untouched)."""
    out, store, hooks = tmp_path / "out", tmp_path / "out" / "sweep.zarr", tmp_path / "hooks"
    cmd = [*JAXCHAIN, *CLI, "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, env=hold_env(hooks))
    try:
        assert held(hooks, 1, proc)[0] == "sweep.zarr batch 0"
        release(hooks, 1)
        assert held(hooks, 2, proc)[0] == "sweep.zarr batch 1"
    finally:
        kill(proc)
    assert proc.returncode == -signal.SIGKILL
    done = np.array(batches_done(store))
    assert done.tolist() == [True, False, False], "killed with batch 0 alone stored"
    before = _chunk_times(store, np.flatnonzero(done))

    resumed = _api_sweep(store=store, resume=True).load()
    assert resumed.attrs["batches_run"] == done.size - done.sum()
    assert resumed.attrs["batches_done"] == resumed.attrs["batches_total"] == done.size
    assert _chunk_times(store, np.flatnonzero(done)) == before
    xr.testing.assert_equal(resumed[RESULTS], uninterrupted[RESULTS])
    xr.testing.assert_equal(jc.open_sweep(store).load()[RESULTS], uninterrupted[RESULTS])


def test_a_half_written_batch_is_redone(tmp_path, uninterrupted, monkeypatch):
    """The process dies while it writes batch 1: some of its variables are in the
    store, its flag is not. The resumed sweep redoes it (and it alone with the
    batches after it), and equals the uninterrupted run."""
    store = tmp_path / "sweep.zarr"

    def dies_in_batch_1(write, sweep_store, index, start, batch):
        if index == 1:
            half = list(batch.data_vars)[: len(batch.data_vars) // 2]
            garbage = batch[half].map(lambda v: v * 0 + 7)
            garbage.to_zarr(store, region={"trajectory": slice(start, start + BATCH)},
                            consolidated=False)
            raise KeyboardInterrupt("killed while writing batch 1")
        write(sweep_store, index, start, batch)

    with batch_writes(dies_in_batch_1), pytest.raises(KeyboardInterrupt):
        _api_sweep(store=store)
    assert batches_done(store) == [True, False, False]
    partial = jc.open_sweep(store)
    assert partial.attrs["batches_done"] == 1
    assert np.all(partial["status"].values.ravel()[BATCH:] == jc.Status.not_run)

    resumed = _api_sweep(store=store, resume=True)
    assert resumed.attrs["batches_run"] == 2
    xr.testing.assert_equal(resumed[RESULTS].load(), uninterrupted[RESULTS])


def test_a_store_of_other_settings_is_refused_with_status_2(tmp_path, capsys):
    out = tmp_path / "out"
    _api_sweep(store=out / "sweep.zarr", overwrite=True)
    before = _chunk_times(out / "sweep.zarr", range(3))
    argv = [*CLI, "--eps", "2e-3", "--resume", "--out", str(out)]
    assert jc.main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "other settings" in err and "eps" in err
    assert jc.main([*CLI, "--out", str(out)]) == 2  # exists: neither --resume nor --overwrite
    assert "exists" in capsys.readouterr().err
    assert _chunk_times(out / "sweep.zarr", range(3)) == before  # nothing lost
    # resumed with its own settings: every batch read back, one JSON document
    assert jc.main([*CLI, "--resume", "--json", "--no-progress", "--out", str(out)]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert set(doc["outputs"]) == {"sweep.zarr", "sweep.png"} and doc["batches_run"] == 0
    assert _chunk_times(out / "sweep.zarr", range(3)) == before
    _assert_cf_store(out / "sweep.zarr", tmp_path / "sweep.nc")


def _assert_cf_store(store, copy) -> None:
    """The zarr store carries the CF attributes (the compliance checker reads no
    zarr v3, so it checks a netCDF copy, written with xarray's defaults but no fill
    value on the coordinates, as CF wants)."""
    ds = xr.open_zarr(store, consolidated=False).load()
    assert ds.attrs["Conventions"].startswith("CF-") and ds.attrs["history"]
    assert ds.attrs["source"] == f"jaxchain {jc.__version__}"
    assert all("long_name" in v.attrs for v in ds.variables.values())
    ds.to_netcdf(copy, encoding={c: {"_FillValue": None} for c in ds.coords
                                 if ds[c].dtype.kind == "f"})
    assert_cf_compliant(copy)


def test_sweeping_eta_c_through_a_lens_equals_separate_runs(monkeypatch):
    """eta_c swept by `where=lambda p: p.eta_c` equals one ensemble per value (the
    same compiled run per trajectory: equal to the last bit). The engine never gets
    more trajectories than a batch."""
    sizes = []
    run_lanes = internal("sweep batch")
    replace_internal(monkeypatch, "sweep batch",
                     lambda p, y0, *a, **k: sizes.append(len(y0)) or run_lanes(p, y0, *a, **k))
    params, ics = jc.ChainParams(n_osc=3, v_d=1.5), jc.localized_family(3)
    eta_c = [0.0, 0.01, 0.2]
    ds = jc.sweep(params, eta_c, ics, options=SHORT, where=lambda p: p.eta_c,
                  batch_size=4, progress=False)
    assert max(sizes) <= 4 and sum(sizes) == 9
    assert ds["n_halc"].dims == ("eta_c", "ic") and ds.attrs["swept"] == "eta_c"
    for value in eta_c:
        one = jc.ensemble(jc.with_parameter(params, "eta_c", value), [1.5], ics,
                          options=SHORT, progress=False).isel(v_d=0)
        row = ds.sel(eta_c=value)
        for name in ("amplitudes", "energy", "n_halc", "n_halc_halves", "y_final",
                     "num_steps"):
            np.testing.assert_array_equal(row[name].values, one[name].values, name)


def test_sweeping_the_engine_s_eps_equals_separate_runs():
    """eps, the smoothed engine's setting (not a field of the chain), swept by name
    equals one ensemble per value with `Smoothed(eps=...)` (the same compiled run
    per trajectory: equal to the last bit); a batch that mixes two values runs
    each with its own eps, and the values do move the results."""
    params, ics = jc.ChainParams(n_osc=3, v_d=1.5), jc.localized_family(3)
    eps = [1e-2, 3e-3]
    ds = jc.sweep(params, eps, ics, options=SHORT, where="eps", batch_size=4,
                  progress=False)
    assert ds["n_halc"].dims == ("eps", "ic") and ds.attrs["swept"] == "eps"
    for value in eps:
        one = jc.ensemble(params, [1.5], ics, engine=jc.Smoothed(options=SHORT, eps=value),
                          progress=False).isel(v_d=0)
        row = ds.sel(eps=value)
        for name in ("amplitudes", "energy", "n_halc", "n_halc_halves", "y_final",
                     "num_steps"):
            np.testing.assert_array_equal(row[name].values, one[name].values, name)
    assert not np.array_equal(ds["num_steps"].values[0], ds["num_steps"].values[1])


def _synthetic(n_halc, halves, excited, status=None):
    n_halc = np.asarray(n_halc)
    return xr.Dataset(
        {"n_halc": (("v_d", "ic"), n_halc),
         "n_halc_halves": (("v_d", "ic", "half"), np.asarray(halves)),
         "status": (("v_d", "ic"), np.zeros_like(n_halc) if status is None else status)},
        coords={"v_d": [1.0, 1.5], "n_excited": ("ic", excited)})


def test_fronts_follow_their_definition():
    """Invading: more on the HALC in the second half, or more than excited;
    receding: fewer; a failed run and an initial condition without n_excited
    (-1) flag nothing beyond the halves."""
    ds = _synthetic(n_halc=[[3, 1, 2, 2], [5, 2, 4, 2]],
                    halves=[[[2, 3], [1, 1], [2, 2], [2, 2]],
                            [[5, 5], [2, 1], [4, 4], [2, 2]]],
                    excited=[2, 1, 2, -1], status=[[0, 0, 0, 0], [0, 0, 3, 0]])
    front = jc.propagating_fronts(ds).values
    assert front.tolist() == [[1, 0, 0, 0], [1, -1, 0, 0]]
    assert front_ranges([1.0, 1.5], (front != 0).any(1)) == [(1.0, 1.5)]


def test_front_ranges_are_runs_of_consecutive_values():
    values = np.array([1.2, 1.0, 1.1, 1.3, 1.4, 1.5])
    flags = np.array([False, True, True, False, True, True])
    assert front_ranges(values, flags) == [(1.0, 1.1), (1.4, 1.5)]
    assert front_ranges(values, np.zeros(6, bool)) == []


def test_bad_input_names_the_argument(tmp_path):
    params, ics = jc.ChainParams(n_osc=3), jc.localized_family(3)
    with pytest.raises(ValueError, match="v_d"):
        jc.sweep(params, [1.5, -1.0], ics, progress=False)
    with pytest.raises(ValueError, match="at least one value"):
        jc.sweep(params, [], ics, progress=False)
    with pytest.raises(ValueError, match="eta_c"):
        jc.sweep(params, [-0.1], ics, where="eta_c", progress=False)
    with pytest.raises(ValueError, match="n_osc cannot be swept"):
        jc.sweep(params, [4], ics, where=lambda p: p.n_osc, progress=False)
    with pytest.raises(ValueError, match="batch_size"):
        jc.sweep(params, [1.5], ics, batch_size=0, progress=False)
    with pytest.raises(ValueError, match="y0 must have shape"):
        jc.sweep(params, [1.5], jc.GivenState(np.zeros((2, 2, 4))), progress=False)
    with pytest.raises(ValueError, match="at least one family"):
        jc.sweep(params, [1.5], {}, progress=False)
    with pytest.raises(ValueError, match="holds no sweep"):
        jc.open_sweep(tmp_path / "nothing.zarr")
