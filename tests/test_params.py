import math

import pytest

import jaxchain as jc


def test_defaults_are_eq7_with_paper_chain():
    p = jc.ChainParams()
    assert (p.n_osc, p.xi, p.friction.mu_d, p.friction.mu_st, p.friction.v0, p.eta_c, p.v_d) == (
        20, 0.05, 0.5, 1.0, 0.5, 0.01, 1.5)
    assert p.friction.mu_st / p.friction.mu_d == 2


@pytest.mark.parametrize("field, value", [
    ("n_osc", 0), ("n_osc", 2.5), ("xi", -0.1), ("mu_d", 0.0), ("mu_d", -1.0),
    ("mu_st", 0.4), ("v0", 0.0), ("eta_c", -0.01), ("eps", 0.0), ("eps", -1e-3),
    ("xi", math.nan), ("v_d", math.inf), ("eta_c", math.nan), ("mu_st", math.inf),
    ("v0", -math.inf), ("v_d", 0.0), ("v_d", -1.5),
])
def test_invalid_parameter_raises_value_error_naming_field(field, value):
    owner = "ExponentialDecay" if field in ("mu_st", "mu_d", "v0") else "ChainParams"
    with pytest.raises(ValueError, match=f"{owner}.{field}"):
        jc.ChainParams(**{field: value})


@pytest.mark.parametrize("kwargs, field", [
    ({"t_end": 0.0}, "t_end"), ({"transient": -1.0}, "transient"),
    ({"t_end": 100.0, "transient": 100.0}, "transient"), ({"rtol": 0.0}, "rtol"),
    ({"atol": math.nan}, "atol"), ({"sample_dt": -0.1}, "sample_dt"),
    ({"max_steps": 0}, "max_steps"), ({"controller": "pid"}, "controller"),
])
def test_invalid_option_raises_value_error_naming_field(kwargs, field):
    with pytest.raises(ValueError, match=f"SimulationOptions.{field}"):
        jc.SimulationOptions(**kwargs)


def test_parameter_name_of_a_lens_or_a_name():
    assert jc.parameter_name(lambda p: p.eta_c) == "eta_c"
    assert jc.parameter_name(lambda p: p.v_d) == jc.parameter_name("v_d") == "v_d"
    for bad, says in ((lambda p: p.n_osc, "n_osc cannot be swept"),
                      (lambda p: 2 * p.xi, "one field"), (lambda p: p.nope, "one field"),
                      ("nope", "unknown parameter")):
        with pytest.raises(ValueError, match=says):
            jc.parameter_name(bad)
