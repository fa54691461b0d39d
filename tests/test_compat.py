"""The private parts of diffrax and equinox that jaxchain uses (`jaxchain._engine.compat`,
the one module that touches them) are still there, with the layout it expects; a
change is reported with its name, not as a wrong step size deep in a run."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import pytest

from jaxchain._engine import compat as _compat


def test_the_installed_diffrax_and_equinox_match():
    _compat.check_compatible()


def test_a_changed_private_part_is_named(monkeypatch):
    monkeypatch.delattr(diffrax.PIDController, "_get_error_order")
    with pytest.raises(RuntimeError, match="_get_error_order is gone.*diffrax"):
        _compat.check_compatible()


def test_a_changed_controller_state_is_named(monkeypatch):
    """As if diffrax's controller carried a fourth part in its state."""
    init = diffrax.PIDController.init

    def init_with_four_parts(self, *args):
        t1, state = init(self, *args)
        return t1, (*state, state[0])

    monkeypatch.setattr(diffrax.PIDController, "init", init_with_four_parts)
    with pytest.raises(RuntimeError, match="three parts"):
        _compat.check_compatible()


def test_errors_as_nan_is_undone_on_exit():
    before = eqx._errors.EQX_ON_ERROR
    with _compat.errors_as_nan():
        assert eqx._errors.EQX_ON_ERROR == "nan"
    assert eqx._errors.EQX_ON_ERROR == before


#: What a failing check raises: equinox's error, or under `jax.jit` XLA's, which
#: carries its message.
RAISED = (eqx.EquinoxRuntimeError, jax.errors.JaxRuntimeError)


def _checked(x):
    return eqx.error_if(x, jnp.sum(x) > 100.0, "the sum is too large")


def test_a_check_traced_as_nan_raises_again_after_the_block():
    """A check traced inside `errors_as_nan` gives NaN there; the same check (same
    shapes, same message) traced after the block raises again, eagerly and under
    `jax.jit`, and one traced raising before the block gives NaN inside it."""
    big = jnp.full(3, 50.0)
    with pytest.raises(RAISED, match="too large"):
        jax.jit(_checked)(big)  # traced raising first
    with _compat.errors_as_nan():
        assert jnp.isnan(jax.jit(lambda x: _checked(x) + 0.0)(big)).all()
    with pytest.raises(RAISED, match="too large"):
        _checked(big)
    with pytest.raises(RAISED, match="too large"):
        jax.jit(lambda x: _checked(x) * 1.0)(big)
