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
from helpers import (JAXCHAIN, SHORT, SWEEP_BATCH as BATCH, SWEEP_RESULTS, assert_cf_compliant,
                     batch_writes, batches_done, held, hold_env, kill, release, small_sweep,
                     sweep_cli)

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


@pytest.mark.study
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


def test_sweeping_eta_c_through_a_lens_equals_separate_runs(tmp_path):
    """eta_c swept by `where=lambda p: p.eta_c` equals one ensemble per value (the
    same compiled run per trajectory: equal to the last bit). The engine never gets
    more trajectories than a batch: each batch the store receives holds at most
    batch_size of them."""
    sizes = []

    def record(write, sweep_store, index, start, batch):
        sizes.append(batch.sizes["trajectory"])
        write(sweep_store, index, start, batch)

    params, ics = jc.ChainParams(n_osc=3, v_d=1.5), jc.localized_family(3)
    eta_c = [0.0, 0.01, 0.2]
    with batch_writes(record):
        ds = jc.sweep(params, eta_c, ics, options=SHORT, where=lambda p: p.eta_c,
                      batch_size=4, store=tmp_path / "eta_c.zarr", progress=False)
    assert max(sizes) <= 4 and sum(sizes) == 9
    assert ds.attrs["batch_size"] == 4 and ds.attrs["batches_total"] == len(sizes) == 3
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


def _synthetic(n_halc, halves, excited, status=None, v_d=(1.0, 1.5)):
    n_halc = np.asarray(n_halc)
    return xr.Dataset(
        {"n_halc": (("v_d", "ic"), n_halc),
         "n_halc_halves": (("v_d", "ic", "half"), np.asarray(halves)),
         "status": (("v_d", "ic"), np.zeros_like(n_halc) if status is None else status),
         "energy": (("v_d", "ic"), 0.1 * n_halc),
         "amplitudes": (("v_d", "ic", "osc"), np.zeros((*n_halc.shape, 5)))},
        coords={"v_d": list(v_d), "n_excited": ("ic", excited)})


#: The colours of the fronts in the bifurcation diagram: red where stick-slip
#: invades, blue where it recedes (`plot_bifurcation_diagram`).
FRONT_COLOURS = {1: "tab:red", -1: "tab:blue"}


def _drawn_fronts(ds) -> dict:
    """What `jc.plot_bifurcation_diagram` draws of the fronts of each kind: the
    values it shades (the cell of each value, halfway to its neighbours) and where
    its dashed lines bounding the ranges of fronts stand."""
    import matplotlib.pyplot as plt
    from matplotlib.colors import same_color

    fig = jc.plot_bifurcation_diagram(ds)
    try:
        ax = fig.axes[0]
        values = np.sort(np.asarray(ds["v_d"], dtype=float))
        drawn = {}
        for sign, colour in FRONT_COLOURS.items():
            centres = [p.get_bbox().x0 + 0.5 * p.get_bbox().width for p in ax.patches
                       if same_color(p.get_facecolor()[:3], colour)]
            shaded = sorted(float(values[np.argmin(np.abs(values - c))]) for c in centres)
            lines = sorted(round(float(line.get_xdata()[0]), 12) for line in ax.lines
                           if line.get_linestyle() == "--" and same_color(line.get_color(),
                                                                          colour))
            drawn[sign] = (shaded, lines)
        return drawn
    finally:
        plt.close(fig)


def test_fronts_follow_their_definition():
    """Invading: more on the HALC in the second half, or more than excited;
    receding: fewer; a failed run and an initial condition without n_excited
    (-1) flag nothing beyond the halves. The diagram shades both values for
    invading fronts, one range over the whole grid (no dashed bound), and 1.5 alone
    for receding ones, bounded halfway to 1.0."""
    ds = _synthetic(n_halc=[[3, 1, 2, 2], [5, 2, 4, 2]],
                    halves=[[[2, 3], [1, 1], [2, 2], [2, 2]],
                            [[5, 5], [2, 1], [4, 4], [2, 2]]],
                    excited=[2, 1, 2, -1], status=[[0, 0, 0, 0], [0, 0, 3, 0]])
    front = jc.propagating_fronts(ds).values
    assert front.tolist() == [[1, 0, 0, 0], [1, -1, 0, 0]]
    drawn = _drawn_fronts(ds.assign(front=(("v_d", "ic"), front)))
    assert drawn == {1: ([1.0, 1.5], []), -1: ([1.5], [1.25])}


def test_front_ranges_are_runs_of_consecutive_values():
    """The ranges of fronts that the diagram bounds by dashed lines are the runs of
    consecutive values (sorted) with a front, each bounded halfway to the nearest
    value without one, and not beyond the ends of the grid."""
    values = [1.2, 1.0, 1.1, 1.3, 1.4, 1.5]
    flags = np.array([False, True, True, False, True, True])
    n = len(values)
    front = np.where(flags, 1, 0)[:, None]  # invading where flagged, one ic
    ds = _synthetic(n_halc=np.ones((n, 1), int), halves=np.ones((n, 1, 2), int),
                    excited=[1], v_d=values).assign(front=(("v_d", "ic"), front))
    # the runs (1.0, 1.1) and (1.4, 1.5): bounded at 1.15 and 1.35 only
    assert _drawn_fronts(ds) == {1: ([1.0, 1.1, 1.4, 1.5], [1.15, 1.35]), -1: ([], [])}
    none = ds.assign(front=(("v_d", "ic"), np.zeros((n, 1), int)))
    assert _drawn_fronts(none) == {1: ([], []), -1: ([], [])}


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
