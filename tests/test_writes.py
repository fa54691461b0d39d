"""Writes that lose nothing: every output file is written beside its place and
renamed into it, so that a process killed while it rewrites a file (netCDF, JSON,
CSV, figure) or overwrites a sweep store leaves the previous one whole; a sweep
never removes or resumes a folder that is not a jaxchain sweep store.

The kills land where the tests say: the writers' test hook (`hold_env`, `held`)
holds a writer just before it commits a write, and the test kills it there.

What is stored is keyed by what determines it: results by content (what cannot be
keyed by its content is refused, so that two settings never share a stored
result), and the traced programs kept on disk (`kept_program`: their key, and a
damaged file).

This file tests internal units, and imports them from jaxchain's private modules:
the atomic writers (`jaxchain._sweeps.atomic`), the CSV and sweep stores, the keys
of stored results (`_sweeps.result_store`) and the kept programs
(`_engine.programs`). The rest of the suite goes through the public names."""

import ast
import functools
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import xarray as xr

import jaxchain as jc
from helpers import (JAXCHAIN, SWEEP_BATCH, SWEEP_N_OSC, SWEEP_T_END, SWEEP_TRANSIENT,
                     held, hold_env, kill, release, replace_internal, small_sweep,
                     sweep_cli)
from jaxchain._engine import programs as _programs
from jaxchain._engine.programs import keep_programs, kept_program, _program_key
from jaxchain._sweeps.atomic import save_figure, write_text
from jaxchain._sweeps.result_store import (CsvStore, canonical, read_dataset, settings_key,
                                          write_dataset)
from jaxchain._sweeps.zarr_store import SweepStore


def _snapshot(folder: Path) -> dict:
    """Every entry under `folder` (or the file `folder`) by relative path: the
    bytes of a file, None for a folder; the temporary files of writes cut short
    (`*.partial`) and the folder's lock (`.jaxchain-lock`, an empty file, and the
    name of its last holder beside it: not results) left out."""
    folder = Path(folder)
    if folder.is_file():
        return {".": folder.read_bytes()}
    return {str(p.relative_to(folder)): (p.read_bytes() if p.is_file() else None)
            for p in sorted(folder.rglob("*")) if not p.name.endswith(".partial")
            and not p.name.startswith(".jaxchain-lock")}


#: Rewrites, in four threads of one process, a netCDF file (`save_dataset`, the
#: writer of every command's .nc), a JSON file (`write_text`), a CSV store whose
#: columns changed (`CsvStore`'s rewrite) and a figure (`save_figure`).
_REWRITE = """
import sys, threading
from pathlib import Path
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import xarray as xr
from jaxchain._sweeps.atomic import save_figure, write_text
from jaxchain._sweeps.datasets import save_dataset
from jaxchain._sweeps.result_store import CsvStore

out = Path(sys.argv[1])
fig, ax = plt.subplots()
ax.plot([0, 1], [1, 0])
writes = [
    lambda: save_dataset(xr.Dataset({"x": ("i", np.arange(4.0) + 1)}), out / "result.nc"),
    lambda: write_text(out / "result.json", '{"n_halc": [2, 3]}'),
    lambda: CsvStore(out / "table.csv", ("key", "value", "added")),
    lambda: save_figure(fig, out / "figure.png"),
]
threads = [threading.Thread(target=w) for w in writes]
for t in threads:
    t.start()
for t in threads:
    t.join()
"""


def test_a_process_killed_as_it_rewrites_each_kind_of_file_leaves_the_previous_ones(
        tmp_path):
    """The previous files are written here; a process rewrites all four with other
    content and is killed (SIGKILL) while each write holds just before its
    rename. Every previous file is byte-identical, and still reads back."""
    import matplotlib.pyplot as plt

    out, hooks = tmp_path / "out", tmp_path / "hooks"
    ds = xr.Dataset({"x": ("i", np.arange(3.0))}, attrs={"note": "previous"})
    jc.save_dataset(ds, out / "result.nc")
    write_text(out / "result.json", '{"n_halc": [1]}')
    with CsvStore(out / "table.csv", ("key", "value")) as table:
        table.append({"key": "a", "value": 1.5})
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    save_figure(fig, out / "figure.png")
    before = _snapshot(out)
    assert sorted(before) == ["figure.png", "result.json", "result.nc", "table.csv"]

    proc = subprocess.Popen([sys.executable, "-c", _REWRITE, str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            env=hold_env(hooks))
    try:
        writing = {held(hooks, n, proc)[0] for n in (1, 2, 3, 4)}
    finally:
        kill(proc)
    assert writing == {"write result.nc", "write result.json", "write table.csv",
                       "write figure.png"}
    assert len(list(out.glob("*.partial"))) == 4, "each new file was written beside"
    assert _snapshot(out) == before
    xr.testing.assert_equal(xr.load_dataset(out / "result.nc"), ds)  # the earlier file
    assert json.loads((out / "result.json").read_text()) == {"n_halc": [1]}
    with CsvStore(out / "table.csv", ("key", "value")) as table:
        assert table.row("a") == {"key": "a", "value": "1.5"}


@pytest.mark.study
def test_a_command_killed_as_it_replaces_its_dataset_leaves_the_previous_one(tmp_path):
    """`jaxchain localized` in its own process, over the files of an earlier run,
    killed (SIGKILL) as it holds before renaming its new netCDF file into place:
    the folder (the .nc and the figure) is byte-identical."""
    out, hooks = tmp_path / "out", tmp_path / "hooks"
    jc.save_dataset(xr.Dataset({"energy": ("ic", [1.0, 2.0])}), out / "localized_vd1.5.nc")
    (out / "localized_vd1.5.png").write_bytes(b"an earlier figure")
    before = _snapshot(out)
    proc = subprocess.Popen(
        [*JAXCHAIN, "localized", "--n-osc", "3",
         "--t-end", "400", "--transient", "200", "--no-progress", "--overwrite", "--out", str(out)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=hold_env(hooks))
    try:
        assert held(hooks, 1, proc)[0] == "write localized_vd1.5.nc"
    finally:
        kill(proc)
    assert _snapshot(out) == before


#: In one process (one program traced): `jaxchain sweep` at v_d = 1.5 with the
#: hook off, a hold once it is stored, then `jaxchain sweep --overwrite` at 1.6.
_OVERWRITE = """
import os, sys
import jaxchain as jc
from jaxchain._sweeps.atomic import HOLD, hold

hooks = os.environ.pop(HOLD)
assert jc.main([*sys.argv[2:], "--vd", "1.5", "--out", sys.argv[1]]) == 0
os.environ[HOLD] = hooks
hold("old store written")
jc.main([*sys.argv[2:], "--vd", "1.6", "--overwrite", "--out", sys.argv[1]])
"""


@pytest.mark.study
def test_a_sweep_overwrite_killed_at_any_batch_or_before_its_swap_leaves_the_old_store(
        tmp_path):
    """`jaxchain sweep --overwrite` with another belt speed builds its store beside
    the old one: while it holds at each of its batches and before the swap, the
    old store is byte-identical, and after a kill (SIGKILL) before the swap it
    still reads back as the old sweep. `resume=True` with the new settings then
    finishes the overwrite (no batch run again) and swaps it in, leaving no other
    folder. A kill between the two renames of a swap (the old store at
    <store>.replaced, the complete new one at <store>.overwrite, nothing at the
    store) is finished by the next sweep; with no new one beside, the old one is
    put back."""
    out, hooks = tmp_path / "out", tmp_path / "hooks"
    store = out / "sweep.zarr"
    replaced, pending = out / "sweep.zarr.replaced", out / "sweep.zarr.overwrite"
    vd = sweep_cli("1.5").index("--vd")
    cli = [a for i, a in enumerate(sweep_cli("1.5")) if i not in (vd, vd + 1)]
    proc = subprocess.Popen([sys.executable, "-c", _OVERWRITE, str(out), *cli],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            env=hold_env(hooks))
    try:
        assert held(hooks, 1, proc)[0] == "old store written"
        before, old = _snapshot(store), jc.open_sweep(store).load()
        release(hooks, 1)
        for n, what in enumerate(("sweep.zarr.overwrite batch 0",
                                  "sweep.zarr.overwrite batch 1", "swap sweep.zarr"), 2):
            assert held(hooks, n, proc)[0] == what
            assert _snapshot(store) == before, what
            if what != "swap sweep.zarr":
                release(hooks, n)
    finally:
        kill(proc)  # held before the swap
    assert _snapshot(store) == before
    assert old["v_d"].values.tolist() == [1.5]
    xr.testing.assert_identical(jc.open_sweep(store).load(), old)
    shutil.copytree(store, tmp_path / "old.zarr")  # for the swaps cut short below

    new = small_sweep("1.6", store=store, resume=True)
    assert new.attrs["batches_run"] == 0
    assert new.attrs["batches_done"] == new.attrs["batches_total"] == 2
    assert new["v_d"].values.tolist() == [1.6]
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(
        ".jaxchain-lock")) == [".jaxchain-results.json", "sweep.png", "sweep.zarr"]
    # and the manifest (the folder's lock and the killed command's name beside it aside)

    os.rename(store, pending)  # a complete overwrite killed in its swap: the new
    os.rename(tmp_path / "old.zarr", replaced)  # store beside, the old one renamed
    again = small_sweep("1.6", store=store, resume=True)
    assert again.attrs["batches_run"] == 0 and again["v_d"].values.tolist() == [1.6]
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(
        ".jaxchain-lock")) == [".jaxchain-results.json", "sweep.png", "sweep.zarr"]
    # and the manifest (the folder's lock and the killed command's name beside it aside)
    os.rename(store, replaced)  # the same, with no new store beside
    SweepStore(store).recover()
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(
        ".jaxchain-lock")) == [".jaxchain-results.json", "sweep.png", "sweep.zarr"]
    # and the manifest (the folder's lock and the killed command's name beside it aside)
    assert jc.open_sweep(store)["v_d"].values.tolist() == [1.6]


def test_a_folder_that_is_not_a_sweep_store_is_refused_and_left_untouched(tmp_path,
                                                                          capsys):
    """A zarr group of other data, a folder of other files and a file, given as a
    sweep's store: overwrite, resume and a plain run are each refused with a
    `ValidationError` naming the path, before anything runs, and the folder is
    byte-identical; the command exits 2 with one line naming it."""
    group = tmp_path / "group.zarr"
    xr.Dataset({"x": ("i", np.arange(5.0))}, attrs={"note": "not a sweep"}).to_zarr(
        group, consolidated=False)
    folder = tmp_path / "folder.zarr"
    folder.mkdir()
    (folder / "notes.txt").write_text("mine")
    file = tmp_path / "file.zarr"
    file.write_text("mine")
    for path in (group, folder, file):
        before = _snapshot(path)
        for kw in ({"overwrite": True}, {"resume": True}, {}):
            with pytest.raises(jc.ValidationError, match=re.escape(str(path))):
                small_sweep("1.5", store=path, **kw)
            assert _snapshot(path) == before, (path, kw)
    with pytest.raises(jc.ValidationError, match="holds no sweep"):
        jc.open_sweep(group)

    out = tmp_path / "out"
    xr.Dataset({"y": ("j", np.ones(2))}).to_zarr(out / "sweep.zarr", consolidated=False)
    before = _snapshot(out)
    assert jc.main([*sweep_cli("1.5"), "--overwrite", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(out / "sweep.zarr") in err
    assert _snapshot(out) == before


#: The only calls in jaxchain/ that write a file, by module: each writes to a
#: temporary path renamed into place (`replacing`), or appends (a CSV store), or
#: is zarr's (a sweep store, written chunk by chunk), or is the compilation
#: cache's own temporary file.
_WRITERS = {
    "_sweeps/atomic.py": {"write_text": 2, "savefig": 1},
    "_sweeps/datasets.py": {"to_netcdf": 1},
    "_sweeps/result_store.py": {"open": 2},
    "_engine/programs.py": {"write_bytes": 1},
    "_sweeps/zarr_store.py": {"to_zarr": 3},
    "_cli/warm_process.py": {"open": 1},  # the warm process's log, appended
    "_cli/common.py": {"write_text": 1},  # an output folder's manifest, renamed into place
    "_cli/folder_lock.py": {"open": 1, "dump": 1},  # the lock's holder, renamed into place
}


def test_every_file_written_goes_through_the_writers():
    """No module of jaxchain writes a file but the writers above: every output of
    every command (`save_dataset`, `write_text`, `save_figure`) is renamed into
    place."""
    root = Path(jc.__file__).parent
    found = {}
    for path in sorted(root.rglob("*.py")):
        calls = {}
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.Call):
                continue
            if isinstance(node.func, ast.Name) and node.func.id == "open":
                name = "open"
                modes = [a.value for a in node.args[1:2] if isinstance(a, ast.Constant)]
                if not any(set(m) & set("wax") for m in modes):
                    continue
            elif isinstance(node.func, ast.Attribute) and node.func.attr in (
                    "to_netcdf", "to_zarr", "savefig", "write_text", "write_bytes",
                    "to_csv", "dump"):
                name = node.func.attr
            else:
                continue
            calls[name] = calls.get(name, 0) + 1
        if calls:
            found[str(path.relative_to(root))] = calls
    assert found == _WRITERS


def test_a_command_run_twice_replaces_its_own_results_and_nothing_else(tmp_path, capsys):
    """The same command with the same settings into the same folder: exit 0 both
    times, one set of results (a note says they were written again). Other
    settings, or a file the command did not make, are refused in one line and
    change nothing; --overwrite still replaces."""
    out = tmp_path / "out"
    args = ["localized", "--n-osc", "3", "--t-end", "400", "--transient", "200", "--json",
            "--no-progress", "--out", str(out)]
    assert jc.main(args) == 0
    first = _snapshot(out)
    capsys.readouterr()
    assert jc.main(args) == 0
    assert "same settings" in capsys.readouterr().err
    again = _snapshot(out)
    assert sorted(again) == sorted(first)
    assert again["localized_vd1.5.nc"] != first["localized_vd1.5.nc"]  # written anew

    for other in (["--eps", "0.002"], ["--t-end", "500"]):
        assert jc.main([*args, *other]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "other settings" in err and "--overwrite" in err
        assert _snapshot(out) == again
    assert jc.main([*args, "--eps", "0.002", "--overwrite"]) == 0
    assert jc.main(args) == 2  # now these are the other settings

    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "localized_vd1.5.nc").write_bytes(b"a user's own file")
    assert jc.main([*args[:-1], str(mine)]) == 2
    assert (mine / "localized_vd1.5.nc").read_bytes() == b"a user's own file"


def test_a_sweep_run_twice_keeps_its_store(tmp_path, capsys):
    """A sweep run again with the same settings reuses its finished store (no batch
    run again); with other settings it is refused and the store is unchanged."""
    out = tmp_path / "out"
    args = [*sweep_cli("1.5"), "--json", "--out", str(out)]
    assert jc.main(args) == 0
    capsys.readouterr()
    assert jc.main(args) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["batches_run"] == 0
    before = _snapshot(out / "sweep.zarr")
    assert jc.main([*sweep_cli("1.5,1.6"), "--json", "--out", str(out)]) == 2
    assert _snapshot(out / "sweep.zarr") == before


# --- Stored results and kept programs, keyed by what determines them ---------------

def _scaled(p, factor):
    return p.v_d * factor


def _closure_over(factor):
    def lens(p):
        return p.v_d * factor
    return lens


def test_two_closures_over_different_values_never_share_a_key():
    """Two closures of the same code over different values have the same qualified
    name: keyed by it they would share a stored result. They are refused, and so
    are lambdas and bound methods; a function of a module's top level and a partial
    of it over different values key apart."""
    for fn in (_closure_over(1.0), _closure_over(2.0), lambda p: p.v_d,
               jc.ChainParams().__repr__):
        with pytest.raises(TypeError, match="cannot key a stored result by the function"):
            settings_key("test", where=fn)
    a = settings_key("test", where=functools.partial(_scaled, factor=1.0))
    b = settings_key("test", where=functools.partial(_scaled, factor=2.0))
    assert a != b and settings_key("test", where=_scaled) not in (a, b)
    assert canonical(jc.ChainParams) == {"callable": "jaxchain._physics.params.ChainParams"}


def test_a_sweep_through_a_lambda_lens_is_stored_under_the_parameter_it_selects(
        tmp_path, monkeypatch):
    """The sweep resolves its lens to the name of the field it selects before keying:
    a lambda lens and the name give the same store, read back on resume without
    integrating anything."""
    # the ring, options and batches of the sweep tests (`small_sweep`): their program
    params = jc.ChainParams(n_osc=SWEEP_N_OSC, v_d=1.5)
    ics = jc.localized_family(SWEEP_N_OSC)
    options = jc.SimulationOptions(t_end=SWEEP_T_END, transient=SWEEP_TRANSIENT)
    store = tmp_path / "sweep.zarr"
    by_lens = jc.sweep(params, [0.0, 0.01], ics, options=options, where=lambda p: p.eta_c,
                       batch_size=SWEEP_BATCH, store=store, progress=False)

    def nothing(*args, **kwargs):
        raise AssertionError("the stored batches should have been read back")
    replace_internal(monkeypatch, "sweep batch", nothing)
    by_name = jc.sweep(params, [0.0, 0.01], ics, options=options, where="eta_c",
                       batch_size=SWEEP_BATCH, store=store, resume=True, progress=False)
    assert by_lens.attrs["settings_key"] == by_name.attrs["settings_key"]
    assert np.array_equal(by_lens["amplitudes"].values, by_name["amplitudes"].values)


_SMALL = jc.SimulationOptions(t_end=600.0, transient=300.0, chunk_length=150.0)


def test_a_stored_result_is_read_back_only_under_its_own_key(tmp_path):
    """Keys depend on values only (a float and a 0-d array of it agree) and change
    with any field; a file stored under another key, or unreadable, is not read."""
    p = jc.ChainParams(n_osc=2)
    key = settings_key("test", params=p, options=_SMALL)
    assert key == settings_key("test", params=jc.ChainParams(n_osc=2, xi=jnp.asarray(0.05)),
                                     options=_SMALL)
    for other in ({"params": jc.ChainParams(n_osc=3)}, {"params": jc.ChainParams(n_osc=2, v0=0.6)},
                  {"options": jc.SimulationOptions(t_end=600.0, transient=300.0)}):
        assert settings_key("test", **{"params": p, "options": _SMALL} | other) != key
    with pytest.raises(TypeError, match="traced"):
        jax.jit(lambda xi: settings_key("test", xi=xi))(0.1)
    path = tmp_path / "run.nc"
    write_dataset(xr.Dataset({"a": ("x", [1.0, 2.0])}), path, "test", params=p)
    assert read_dataset(path, "test", params=p)["a"].values.tolist() == [1.0, 2.0]
    assert read_dataset(path, "test", params=jc.ChainParams(n_osc=2, xi=0.1)) is None
    assert read_dataset(path, "other kind", params=p) is None
    path.write_bytes(b"not netCDF")
    assert read_dataset(path, "test", params=p) is None


@eqx.filter_jit
def _scaled_sum(x, options):
    return {"sum": jnp.sum(x) * options.t_end, "first": x[0]}


@pytest.fixture
def folder(tmp_path):
    keep_programs(tmp_path)
    yield tmp_path
    keep_programs(None)


def _key(x, options):
    dynamic, static = eqx.partition((x, options), eqx.is_array)
    leaves, treedef = jax.tree_util.tree_flatten(dynamic)
    return _program_key(_scaled_sum, static, treedef, leaves)


def test_key_changes_with_static_values_shapes_and_code(monkeypatch):
    x = jnp.arange(3.0)
    base = jc.SimulationOptions(t_end=50.0, transient=25.0)
    key = _key(x, base)
    assert _key(x + 1.0, base) == key  # array values are inputs, not part of the key
    assert _key(x, jc.SimulationOptions(t_end=60.0, transient=25.0)) != key
    assert _key(x, jc.SimulationOptions(t_end=50.0, transient=25.0, rtol=1e-6)) != key
    assert _key(x, jc.SimulationOptions(t_end=50.0, transient=25.0,
                                        controller="diffrax")) != key
    assert _key(jnp.arange(4.0), base) != key
    monkeypatch.setattr(_programs, "code_identity", lambda: {"jaxchain": "edited"})
    assert _key(x, base) != key


def test_kept_program_matches_the_function_and_survives_a_damaged_file(folder):
    options = jc.SimulationOptions(t_end=50.0, transient=25.0)
    x = jnp.arange(3.0)
    program = kept_program(_scaled_sum, x, options)
    files = sorted(folder.iterdir())
    assert [f.suffix for f in files] == [".jaxexport", ".tree"]
    expected = _scaled_sum(x + 2.0, options)
    got = program(x + 2.0, options)
    assert set(got) == {"sum", "first"}
    assert all(np.array_equal(got[k], expected[k]) for k in expected)
    assert kept_program(_scaled_sum, x, options) is program  # loaded once a process
    files[0].write_bytes(b"not a program")  # damaged: traced again and rewritten
    keep_programs(None)  # as a later process reads the folder
    keep_programs(folder)
    again = kept_program(_scaled_sum, x, options)
    assert np.array_equal(again(x, options)["sum"], _scaled_sum(x, options)["sum"])
    assert files[0].read_bytes() != b"not a program"


def test_nothing_is_kept_unless_asked(tmp_path):
    assert _programs.program_folder() is None
    assert kept_program(_scaled_sum, jnp.arange(3.0), jc.SimulationOptions()) is None
