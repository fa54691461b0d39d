"""Traced programs kept on disk (`kept_program`): their key, and a damaged file."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxchain as jc
from jaxchain._engine import programs as _programs
from jaxchain._engine.programs import keep_programs, kept_program, program_key


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
    files[0].write_bytes(b"not a program")  # damaged: traced again and rewritten
    again = kept_program(_scaled_sum, x, options)
    assert np.array_equal(again(x, options)["sum"], _scaled_sum(x, options)["sum"])
    assert files[0].read_bytes() != b"not a program"


def test_nothing_is_kept_unless_asked(tmp_path):
    assert _programs.program_folder() is None
    assert kept_program(_scaled_sum, jnp.arange(3.0), jc.SimulationOptions()) is None
