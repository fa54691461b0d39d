"""The one-site state's stable range over mistuning draws (`jaxchain
localized-ranges`): the draws' own procedure (harmonic balance, pseudo-arclength
marches, regula falsi on the critical multiplier, bisection at a fold's corner)
against the branch-following driver on the tuned ring, and against shooting on a
mistuned draw; bad input refused before any computation."""

import pytest

import jaxchain as jc

RING = jc.ChainParams(n_osc=20, v_d=1.5)
HB = jc.HarmonicBalance(eps=1e-2, harmonics=16, linear_solver="lu")


@pytest.mark.parametrize("params, kwargs, says", [
    (jc.ChainParams(n_osc=4, stiffness=[1.0, 1.01, 0.99, 1.0]), {}, "tuned chain"),
    (jc.ChainParams(n_osc=4, forcing=jc.Forcing.engine_order(4, 1, 0.1, 1.0)), {}, "forcing"),
    (jc.ChainParams(n_osc=4), {"sigmas": [-0.01]}, "sigmas"),
    (jc.ChainParams(n_osc=4), {"draws": 0}, "draws"),
    (jc.ChainParams(n_osc=4), {"lanes": 0}, "lanes"),
    (jc.ChainParams(n_osc=4), {"site": 4}, "site"),
])
def test_bad_input_is_refused_naming_it(params, kwargs, says):
    args = {"sigmas": [0.01], "draws": 2} | kwargs
    with pytest.raises(jc.ValidationError, match=says):
        jc.localized_ranges(params, args.pop("sigmas"), args.pop("draws"), HB, **args)


@pytest.mark.study
@pytest.mark.slow
def test_the_draws_procedure_agrees_with_the_driver_and_with_shooting(tmp_path):
    """On the ring of 20 at eps 1e-2: the tuned ring's range by the draws' own
    procedure (lane 0 of every group) against the driver's bisection of the
    multipliers and of the fold on the same harmonic-balance branch, to 1e-4; a
    mistuned draw's range against shooting's (the independent orbit method, the
    same driver), to 5e-3 (acceptance: H = 16 resolves the ends to that). Two
    groups of two lanes, in two worker processes: the pool's route."""
    sigma = RING.eta_c
    ds = jc.localized_ranges(RING, [sigma], 2, HB, lanes=2, workers=2, store=tmp_path)
    assert ds.attrs["tuned_low_kind"] == "Neimark-Sacker"
    assert ds.attrs["tuned_high_kind"] == "fold"
    assert abs(ds.attrs["tuned_low_lanes"] - ds.attrs["tuned_low"]) < 1e-4
    # the fold's corner by 6 bisections within 0.03 (BISECTIONS, FOLD_WIDTH): the
    # midpoint of an interval 0.03 / 2^6 wide, on top of the 1e-4 that this test
    # allowed when the interval was 0.03 / 2^9 (the driver's own location)
    assert abs(ds.attrs["tuned_high_lanes"] - ds.attrs["tuned_high"]) < 0.03 / 2**7 + 1e-4
    (shot,) = jc.shooting_ranges(RING, sigma, [1], eps=1e-2)
    part = ds.sel(sigma=sigma, draw=1)
    assert bool(part["found"])
    assert abs(float(part["low"]) - shot["low"]) < 5e-3
    assert abs(float(part["high"]) - shot["high"]) < 5e-3
    assert str(part["low_kind"].values) == shot["low_kind"]
