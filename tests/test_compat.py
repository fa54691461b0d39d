"""The private parts of diffrax and equinox that jaxchain uses (`jaxchain._engine.compat`,
the one module that touches them) are still there, with the layout it expects; a
change is reported with its name, not as a wrong step size deep in a run."""

import diffrax
import equinox as eqx
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
