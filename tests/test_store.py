"""Stored results are keyed by content: what cannot be keyed by its content is
refused, so that two settings never share a stored result."""

import functools

import numpy as np
import pytest

import jaxchain as jc
import jaxchain._sweeps.sweep as sweep_module
from jaxchain._sweeps.result_store import canonical, settings_key
from helpers import SWEEP_BATCH, SWEEP_N_OSC, SWEEP_T_END, SWEEP_TRANSIENT


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
    monkeypatch.setattr(sweep_module, "run_lanes", nothing)
    by_name = jc.sweep(params, [0.0, 0.01], ics, options=options, where="eta_c",
                       batch_size=SWEEP_BATCH, store=store, resume=True, progress=False)
    assert by_lens.attrs["settings_key"] == by_name.attrs["settings_key"]
    assert np.array_equal(by_lens["amplitudes"].values, by_name["amplitudes"].values)
