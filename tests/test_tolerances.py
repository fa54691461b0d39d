"""Tolerances that fit the model: the smoothed engine's follow eps where none is
given, tolerances that cannot resolve the stick band or lie outside (0, 1) are
refused, and a run whose energy balance fails is flagged, on both engines."""

import os
import subprocess
import sys
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

import jaxchain as jc


def _jaxchain(*args):
    """The `jaxchain` command of this environment, in its own process."""
    env = os.environ | {"JAXCHAIN_SERVER": "0"}
    return subprocess.run([str(Path(sys.executable).parent / "jaxchain"), *args],
                          capture_output=True, text=True, env=env, timeout=300)


def test_the_default_tolerances_are_unchanged_at_the_default_eps():
    options = jc.Smoothed().options
    assert (options.rtol, options.atol) == (3e-5, 3e-7)
    assert type(options.rtol) is float


def test_tolerances_follow_eps_where_none_is_given():
    options = jc.Smoothed(eps=1e-7).options
    assert options.rtol == pytest.approx(1e-7 / 30) and options.atol == pytest.approx(1e-7 / 3000)
    given = jc.Smoothed(options=jc.SimulationOptions(rtol=1e-6), eps=1e-5).options
    assert given.rtol == 1e-6 and given.atol == pytest.approx(1e-5 / 3000)


@pytest.mark.parametrize("tolerance", ["rtol", "atol"])
def test_tolerances_that_cannot_resolve_the_stick_band_are_refused(tolerance):
    with pytest.raises(ValueError, match=f"SimulationOptions.{tolerance} .*stick band"):
        jc.Smoothed(options=jc.SimulationOptions(**{tolerance: 3e-5}), eps=1e-8)
    with pytest.raises(ValueError, match="stick band"):
        jc.simulate(jc.ChainParams(n_osc=1), jnp.zeros((2, 1)), engine=jc.Smoothed(
            options=jc.SimulationOptions(**{tolerance: 3e-5}), eps=1e-8))


def test_the_command_line_refuses_a_tolerance_that_misses_the_stick_band(tmp_path):
    done = _jaxchain("localized", "--n-osc", "4", "--eps", "1e-7", "--rtol", "3e-5",
                     "--no-progress", "--out", str(tmp_path / "unused"))
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "--rtol" in lines[0] and "stick band" in lines[0]


@pytest.mark.parametrize("field", ["rtol", "atol"])
@pytest.mark.parametrize("options", [jc.SimulationOptions, jc.NonsmoothOptions])
def test_tolerances_outside_the_unit_interval_are_refused(options, field):
    for value in (10.0, 1.0):
        with pytest.raises(ValueError, match=f"{options.__name__}.{field} must be a number "
                                             r"in \(0, 1\)"):
            options(**{field: value})


@pytest.mark.parametrize("engine", ["smoothed", "exact"])
def test_the_command_line_refuses_rtol_10(engine, tmp_path):
    done = _jaxchain("localized", "--n-osc", "4", "--engine", engine, "--rtol", "10",
                     "--atol", "10", "--no-progress", "--out", str(tmp_path / "unused"))
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "--rtol" in lines[0] and "(0, 1)" in lines[0]


@pytest.mark.study
@pytest.mark.slow
def test_a_run_whose_energy_balance_fails_is_flagged_on_the_smoothed_engine():
    """rtol = 0.03 at eps = 1e-2 (allowed: within 100 eps) integrates a single
    oscillator from rest so loosely that its energy E is off by a factor 25 (E from
    the exact engine, an independent model, is 0.0122); the balance flags it, and
    the run at the default tolerances is ok and within 1 % of the exact E."""
    params, y0 = jc.ChainParams(n_osc=1), jnp.zeros((2, 1))
    loose = jc.SimulationOptions(t_end=100.0, transient=50.0, rtol=0.03, atol=3e-4)
    out = jc.simulate(params, y0, engine=jc.Smoothed(options=loose, eps=1e-2), throw=False)
    assert int(out.status) == jc.Status.energy_balance_failed
    assert np.isnan(out.energy)
    good = jc.simulate(params, y0, throw=False, engine=jc.Smoothed(
        options=jc.SimulationOptions(t_end=100.0, transient=50.0), eps=1e-2))
    exact = jc.simulate(params, y0, engine=jc.Exact(jc.NonsmoothOptions(t_end=100.0,
                                                                  transient=50.0)))
    assert int(good.status) == jc.Status.ok
    assert float(good.energy) == pytest.approx(float(exact.energy), rel=0.01)


def test_a_run_whose_energy_balance_fails_is_flagged_on_the_exact_engine():
    """rtol = atol = 0.1 gives this single oscillator from rest an energy of 4.8
    (0.0122 at the default tolerances) with a successful status before the
    balance is checked; the friction work and dissipation it reports miss the
    change of its mechanical energy, computed here independently."""
    params, y0 = jc.ChainParams(n_osc=1), jnp.zeros((2, 1))
    loose = jc.NonsmoothOptions(t_end=100.0, transient=50.0, rtol=0.1, atol=0.1)
    out = jc.simulate(params, y0, engine=jc.Exact(loose), throw=False)
    assert int(out.status) == jc.Status.energy_balance_failed
    good = jc.simulate(params, y0, engine=jc.Exact(jc.NonsmoothOptions(t_end=100.0,
                                                                 transient=50.0)))
    assert int(good.status) == jc.Status.ok
    x, v = np.asarray(good.y_final)
    change = 0.5 * float(np.sum(v**2 + x**2))  # one oscillator: no coupling, m = k = 1
    assert change == pytest.approx(float(good.friction_work - good.viscous_dissipation),
                                   rel=1e-4)


@pytest.mark.study
@pytest.mark.slow
def test_a_small_eps_follows_with_its_tolerances_to_the_right_n_halc():
    """Four oscillators excited 1 ... 4 at eps = 1e-7 (t_end 300): with rtol 3e-5
    (the fixed default before tolerances followed eps) n_HALC came out 0 2 2 4;
    with the tolerances that follow eps it is that of eps = 1e-5 at rtol eps/30,
    and of the exact engine."""
    n = 4
    params, ics = jc.ChainParams(n_osc=n), jc.localized_family(n)
    horizon = {"t_end": 300.0, "transient": 200.0}
    small = jc.ensemble(params, [1.5], ics, progress=False,
                        engine=jc.Smoothed(options=jc.SimulationOptions(**horizon), eps=1e-7))
    reference = jc.ensemble(params, [1.5], ics, progress=False, engine=jc.Smoothed(
        options=jc.SimulationOptions(**horizon, rtol=1e-5 / 30, atol=1e-5 / 3000), eps=1e-5))
    exact = jc.ensemble(params, [1.5], ics, progress=False,
                        engine=jc.Exact(jc.NonsmoothOptions(**horizon)))
    assert np.all(small.status.values == jc.Status.ok)
    np.testing.assert_array_equal(small.n_halc.values, reference.n_halc.values)
    np.testing.assert_array_equal(small.n_halc.values, exact.n_halc.values)
