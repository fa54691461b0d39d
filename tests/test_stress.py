"""The stress matrix: every case ends verified or failed with a specific status, the
physics checks agree with analytic results, and failures carry specific hints."""

import dataclasses
import json

import jax.numpy as jnp
import numpy as np
import pytest

import jaxchain as jc
from helpers import assert_usage_error, scipy_slip_arc

#: The reduced matrix of `jaxchain stress --quick` (its --help and docs/stress.md),
#: in order: one thing varied at a time, to the edges of the model.
QUICK = [("eps", 1e-1), ("eps", 1e-5), ("n_osc", 1), ("v_d", 1e-3), ("v_d", 1.1513),
         ("v_d", 10.0), ("eta_c", 100.0), ("xi", 0.0), ("xi", 1.0), ("mu_st/mu_d", 1.0),
         ("v0", 1e-3), ("ics", "steady sliding"), ("ics", "x ± 1e3"), ("ics", "x' ± 50")]


@pytest.mark.numerics
@pytest.mark.study
@pytest.mark.long
def test_quick_matrix_verifies_every_case_on_the_default_solver(tmp_path, capsys):
    """`jaxchain stress --quick` on the default path: every case of the reduced
    matrix, the edges of the model included (eps = 1e-5, v_d = 1e-3, eta_c = 100,
    xi = 0, x ± 1e3), is verified by its physics checks. A case that fails, even
    with a specific status, is a regression of the default solver. A second run
    with the same --out reads every row back and runs no case: the store only
    appends the rows it computes, so its CSV is left as it was."""
    argv = ["stress", "--quick", "--solver", "ros34pw2", "--out", str(tmp_path), "--json",
            "--no-progress"]
    assert jc.main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["outputs"]) == {"stress.csv", "stress.md"}
    cases = out["cases"]
    assert [(c["what"], c["value"]) for c in cases] == QUICK
    assert set(cases[0]) == {"what", "value", "solver", "outcome", "status", "check", "hint"}
    for case in cases:
        assert case["outcome"] == "verified" and case["status"] == "ok", case
        assert "energy balance" in case["check"] and not case["hint"], case
    assert out["defects"] == 0
    # The checks that apply did apply: the steady slide at v_d = 10, the Hopf point.
    by = {(c["what"], c["value"]): c for c in cases}
    assert "slides to steady sliding" in by["v_d", 10.0]["check"]
    assert "Hopf point" in by["v_d", 1.1513]["check"]
    assert "stays at steady sliding" in by["ics", "steady sliding"]["check"]
    assert (tmp_path / "stress.md").read_text().count("| eps |") == sum(
        what == "eps" for what, _ in QUICK)
    # Resumed: the same rows, read back, and no case run again (a case run would
    # append its row, with its own wall time, to the CSV).
    stored = tmp_path / "stress.csv"
    written, mtime = stored.read_bytes(), stored.stat().st_mtime_ns
    assert jc.main([*argv, "--resume"]) == 0
    again = json.loads(capsys.readouterr().out)
    assert again["cases"] == cases and again["defects"] == 0
    assert stored.read_bytes() == written and stored.stat().st_mtime_ns == mtime


@pytest.mark.study
def test_an_explicit_solver_at_tiny_eps_fails_with_a_specific_hint(tmp_path, capsys):
    """Tsit5 with a step budget far below mu_st/eps fails with max_steps, and the hint
    names the stiffness and the solver that copes: `jaxchain stress --quick --what
    eps` (eps = 1e-1 and 1e-5) with 2000 steps per chunk. A failure with a specific
    status is an outcome, not a defect: the command succeeds."""
    assert jc.main(["stress", "--quick", "--what", "eps", "--solver", "tsit5",
                    "--max-steps", "2000", "--out", str(tmp_path), "--json",
                    "--no-progress"]) == 0
    cases = json.loads(capsys.readouterr().out)["cases"]
    assert [(c["what"], c["value"], c["solver"]) for c in cases] == [
        ("eps", 1e-1, "tsit5"), ("eps", 1e-5, "tsit5")]
    row = cases[1]
    assert row["outcome"] == "failed" and row["status"] == jc.Status.max_steps_reached.name
    assert "eps = 1e-05 makes the stick phase stiff" in row["hint"]
    assert "solver='ros34pw2'" in row["hint"]


@pytest.mark.study
def test_a_collapsing_step_size_is_its_own_status():
    """A run that spends its step budget on steps shorter than dtmin on average fails
    with the status "step size collapsed", not "max_steps reached"; with the same
    budget and a floor below its steps, it is "max_steps reached"."""
    params, y0 = jc.ChainParams(n_osc=2), jc.OutOfPhaseExcitation.eq8([True, False])
    budget = jc.SimulationOptions(t_end=150.0, transient=100.0, max_steps=300, dtmin=0.05)
    obs = jc.simulate(params, y0, options=budget, throw=False)
    collapsed = jc.Status.step_size_collapsed
    assert obs.status == collapsed and np.all(np.isnan(obs.amplitudes))
    assert collapsed.message.startswith("step size collapsed")
    assert "dtmin = 0.05" in jc.Smoothed(jc.SOLVERS["ros34pw2"](), budget).failure_hint(
        collapsed, params)
    with pytest.raises(RuntimeError, match="step_size_collapsed: eps = 0.001"):
        jc.simulate(params, y0, options=budget)
    floor = dataclasses.replace(budget, dtmin=1e-6)
    assert (jc.simulate(params, y0, options=floor, throw=False).status
            == jc.Status.max_steps_reached)


@pytest.mark.numerics
def test_energy_balance_and_decay_rate_of_the_damped_linear_oscillator():
    """With mu_st = mu_d and a fast belt the friction force is the constant mu_d, so
    x - mu_d is a damped linear oscillator: its state and energy at t_end, its
    decay rate -xi and the growth rate of steady sliding are known in closed form.
    The run is `jc.simulate` on the smoothed engine that the stress matrix runs."""
    xi, x0 = 0.05, 1.5
    params = jc.ChainParams(n_osc=1, xi=xi, mu_st=0.5, mu_d=0.5, v_d=10.0)
    y0 = jnp.array([[0.5 + x0], [0.0]])
    options = jc.SimulationOptions(t_end=60.0, transient=20.0, chunk_length=10.0,
                                   rtol=1e-9, atol=1e-11)
    out = jc.simulate(params, y0, engine=jc.Smoothed(jc.SOLVERS["tsit5"](), options))
    (x_end,), (v_end,) = np.asarray(out.y_final)
    wd = np.sqrt(1 - xi**2)
    t = options.t_end
    u = x0 * np.exp(-xi * t) * (np.cos(wd * t) + xi / wd * np.sin(wd * t))
    du = -x0 * np.exp(-xi * t) * (1 / wd) * np.sin(wd * t)
    energy_end = 0.5 * ((0.5 + u) ** 2 + du**2)
    assert 0.5 * (x_end**2 + v_end**2) == pytest.approx(energy_end, rel=1e-7)
    # the energy lost is the work of damping alone: the state itself follows the
    # closed form (a residual below 1e-7 of the initial amplitude)
    assert abs(x_end - 0.5 - u) < 1e-7 * x0 and abs(v_end - du) < 1e-7 * x0
    decay_rate = np.log(np.hypot(x_end - 0.5, v_end) / x0) / t
    assert decay_rate == pytest.approx(-xi, abs=2e-3)
    assert float(jnp.max(jc.growth_rates(params))) == pytest.approx(-xi, abs=1e-12)


@pytest.mark.numerics
def test_existence_limit_with_steep_friction():
    """At v0 = 1e-3 the slip arc's peak is still resolved: the limit agrees with
    scipy's slip arc (DOP853 on eq. (1) written in the test) to 1e-7, the arc
    returning to the belt speed just below the limit and not just above it."""
    params = jc.ChainParams(n_osc=1, v0=1e-3)
    limit = jc.stick_slip_existence_limit(params)
    for d, returns in ((-1e-7, True), (1e-7, False)):
        arc = scipy_slip_arc(jc.ChainParams(n_osc=1, v0=1e-3, v_d=limit + d))
        assert (arc.status == 1) == returns, d  # status 1: it came back to the belt


@pytest.mark.study
def test_auto_solver_is_explicit_only_where_the_stick_phase_is_not_stiff(tmp_path, capsys):
    """`--solver auto` at `--eps` takes Tsit5 where mu_st/eps <= 100 (eps = 0.1) and
    ROS34PW2 where the stick phase is stiff (eps = 1e-3): the engine its --json
    reports, and amplitudes equal to those of the solver named."""
    def localized(solver, eps):
        out = tmp_path / f"{solver}-{eps:g}"
        assert jc.main(["localized", "--n-osc", "2", "--t-end", "60", "--transient", "30",
                        "--solver", solver, "--eps", str(eps), "--json", "--no-progress",
                        "--out", str(out)]) == 0
        return json.loads(capsys.readouterr().out)

    for eps, name in ((0.1, "tsit5"), (1e-3, "ros34pw2")):
        auto, named = localized("auto", eps), localized(name, eps)
        assert auto["solver"] == type(jc.SOLVERS[name]()).__name__ == named["solver"]
        assert auto["eps"] == eps
        assert np.array_equal(auto["runs"][0]["amplitudes"], named["runs"][0]["amplitudes"])


@pytest.mark.parametrize("argv, says", [
    (["--what", "bogus"], "--what"),
    (["--solver", "euler"], "--solver"),
    (["--solver", ""], "--solver"),
    (["--what", ""], "--what"),
    (["--out", __file__], "--out"),
])
def test_stress_command_rejects_bad_input_in_one_line(argv, says, capsys):
    assert_usage_error(["stress", *argv], says, capsys)
