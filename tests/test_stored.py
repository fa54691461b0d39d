"""What is stored is keyed by what determines it: results by content (what cannot
be keyed by its content is refused, so that two settings never share a stored
result), and the traced programs kept on disk (`kept_program`: their key, and a
damaged file)."""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import xarray as xr

import jaxchain as jc
from helpers import SWEEP_BATCH, SWEEP_N_OSC, SWEEP_T_END, SWEEP_TRANSIENT, replace_internal
from jaxchain._engine import programs as _programs
from jaxchain._engine.programs import keep_programs, kept_program, program_key
from jaxchain._sweeps.result_store import (canonical, read_dataset, settings_key,
                                          write_dataset)


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
    return program_key(_scaled_sum, static, treedef, leaves)


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


@pytest.mark.numerics
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
