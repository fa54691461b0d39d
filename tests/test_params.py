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
    ("mu_st", 0.4), ("v0", 0.0), ("eta_c", -0.01),
    ("xi", math.nan), ("v_d", math.inf), ("eta_c", math.nan), ("mu_st", math.inf),
    ("v0", -math.inf), ("v_d", 0.0), ("v_d", -1.5),
])
def test_invalid_parameter_raises_value_error_naming_field(field, value):
    owner = "ExponentialDecay" if field in ("mu_st", "mu_d", "v0") else "ChainParams"
    with pytest.raises(ValueError, match=f"{owner}.{field}"):
        jc.ChainParams(**{field: value})


@pytest.mark.parametrize("value", [0.0, -1e-3, math.nan, math.inf, [1e-3, 2e-3]])
def test_invalid_eps_raises_value_error_naming_the_smoothed_engine(value):
    with pytest.raises(ValueError, match="Smoothed.eps"):
        jc.Smoothed(eps=value)


def test_eps_given_to_the_chain_says_where_it_went(tmp_path):
    """eps is the smoothed engine's: given to the chain (as an argument, by name to
    `with_parameter`, or in a chain file) it raises, naming where it went."""
    moved = "eps is a setting of the smoothed engine, not of the chain"
    with pytest.raises(ValueError, match=moved):
        jc.ChainParams(eps=1e-3)
    with pytest.raises(ValueError, match=moved):
        jc.with_parameter(jc.ChainParams(), "eps", 1e-3)
    chain_file = tmp_path / "chain.toml"
    chain_file.write_text("n_osc = 3\neps = 0.01\n")
    with pytest.raises(ValueError, match=moved):
        jc.chain_from_file(chain_file)


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
