"""Time delays, the periodic/irregular classification and the scenes of Figs. 4-10,
against synthetic signals with known answers, the eq. (8)/(10) initial states and
the plain engine's run of the same chains."""

import json
import sys

import numpy as np
import pytest
import xarray as xr

import jaxchain as jc


def synthetic_peaks(n_peaks, period, delays, jitter=0.0, seed=0):
    """Peak times of oscillators that peak at k T + delay_i(k)."""
    k = np.arange(n_peaks) * period
    rng = np.random.default_rng(seed)
    return np.stack([k + d + jitter * rng.standard_normal(n_peaks) for d in delays])


def test_time_delays_pair_each_reference_peak_with_the_next_one():
    period = 6.3
    peaks = synthetic_peaks(40, period, [0.0, -0.2, period / 2, 1.0])
    peaks[3, -1] = np.nan  # its last peak is missing
    tau, phi = jc.time_delays(peaks, ref=0)
    assert np.array_equal(tau, peaks[0])
    assert np.allclose(phi[0], 0) and np.allclose(phi[1], -0.2)  # in [-T/4, 3T/4)
    assert np.allclose(phi[2], period / 2) and np.allclose(phi[3, :-1], 1.0)
    assert np.isnan(phi[3, -1])


def _delay_spread(peaks, t_from=0.0):
    """`classify`'s delay spread and its period m, of oscillator 0's delays to the
    reference of two oscillators on the HALC (oscillator 1, N // 2)."""
    out = jc.classify(peaks, np.ones(2, bool), 2, 0, -1.0, 1e-3, t_from)
    assert out["ref"] == 1
    return out["delay_spread"], out["delay_period"]


def test_delay_spread_finds_the_period_of_repeating_delays():
    period = 6.3
    alternating = np.tile([0.5, 1.5], 30)
    peaks = synthetic_peaks(60, period, [0.0, 0.0]) + np.stack([alternating, np.zeros(60)])
    spread, m = _delay_spread(peaks)
    assert m == 2 and spread < 1e-12
    drifting = synthetic_peaks(60, period, [0.0, 0.0]) + np.stack(
        [np.linspace(0, 3, 60) ** 2 / 3, np.zeros(60)])
    spread, _ = _delay_spread(drifting)
    assert spread > 0.05
    # too few peaks after t_from to tell
    assert _delay_spread(drifting, t_from=drifting[1, -10])[0] == np.inf


def test_classify_needs_both_signals_to_agree():
    peaks = synthetic_peaks(60, 6.3, [0.0, 3.1, 3.2], jitter=1e-6)
    on = np.array([True, True, True])
    same = jc.classify(peaks, on, 3, 0, 1e-5, 1e-4, 0.0)
    assert same["class"] == "periodic" and same["ref"] == 1  # N//2, 0-based
    chaotic = jc.classify(peaks, on, 3, 0, 0.02, 1e-3, 0.0)
    assert chaotic["class"] == "undecided"
    assert (chaotic["class_delays"], chaotic["class_lyapunov"]) == ("periodic", "irregular")
    wandering = synthetic_peaks(60, 6.3, [0.0, 3.1, 3.2], jitter=0.3)
    assert jc.classify(wandering, on, 3, 0, 0.02, 1e-3, 0.0)["class"] == "irregular"
    assert jc.classify(peaks, ~on, 0, 0, -0.02, 1e-3, 0.0)["class"] == "steady sliding"
    assert jc.classify(peaks, on, -1, 2, np.nan, np.nan, 0.0)["class"] == "failed"
    with pytest.raises(ValueError, match="delay"):
        jc.ClassTolerances(delay=0.0)


def test_reference_is_the_11th_or_the_nearest_halc_oscillator():
    peaks = synthetic_peaks(20, 6.3, np.zeros(20))
    on = np.zeros(20, dtype=bool)
    on[[2, 14, 17]] = True
    assert jc.classify(peaks, on, 3, 0, -1.0, 1e-3, 0.0)["ref"] == 14
    on[10] = True
    assert jc.classify(peaks, on, 4, 0, -1.0, 1e-3, 0.0)["ref"] == 10


def run_figure(name, tmp_path, capsys):
    argv = ["figure", name, "--quick", "--json", "--no-progress", "--out", str(tmp_path)]
    with pytest.raises(SystemExit) as exc:
        sys.exit(jc.main(argv))
    assert exc.value.code == 0, capsys.readouterr().err
    report = json.loads(capsys.readouterr().out)
    assert (tmp_path / f"figure{name}.png").stat().st_size > 10_000
    assert set(report["outputs"]) == {f"figure{name}.nc", f"figure{name}.png"}
    return report, xr.open_dataset(report["outputs"][f"figure{name}.nc"])


@pytest.mark.numerics
@pytest.mark.study
@pytest.mark.long
def test_figure_command_quick_runs_every_scene_and_keeps_only_what_it_shows(tmp_path,
                                                                            capsys):
    """Each scene through the command, observing only what it shows; the states of
    Fig. 8 are those of Fig. 4's plain run, and its Lyapunov exponents are those
    of regular states."""
    reports, data = {}, {}
    for name in ("4", "5", "6", "7", "8", "9", "10"):  # every figure of `jaxchain figure`
        reports[name], data[name] = run_figure(name, tmp_path, capsys)
    shown = {"5": {"series"}, "7": {"series"}, "6": {"peak_times", "lyapunov", "amplitudes"},
             "8": {"peak_times", "lyapunov", "amplitudes"}}
    unshown = {"5": {"peak_times", "lyapunov", "amplitudes"},
               "7": {"peak_times", "lyapunov", "amplitudes"}, "6": {"series"},
               "8": {"series", "section_states"}}
    for name in shown:
        assert shown[name] <= set(data[name]) and not unshown[name] & set(data[name]), name
    # Fig. 5 starts from eq. (8) with 2 excited and shows the stick at x' = v_d
    params = jc.ChainParams(n_osc=8, v_d=1.5)
    y0 = jc.OutOfPhaseExcitation.eq8(jc.excited_block(8, 2))(params)
    series = data["5"]["series"].isel(solution=0).values
    assert np.allclose(series[0], y0) and abs(series[:, 1].max() - 1.5) < 0.05
    # Fig. 10 starts from eq. (10): x'(0) = 0.56
    assert np.allclose(data["10"]["y_initial"].sel(component="v").values, 0.56)
    # Fig. 7 shows oscillators 5, 6, 7 of 8 (the paper's 11, 12, 13 of 20)
    assert data["7"]["series_osc"].values.tolist() == [5, 6, 7]
    # The scenes with a Lyapunov exponent integrate the variational equation beside
    # the state, which changes the steps: the states must still be those of the
    # plain run of Fig. 4 (same chain and options). Irregular states part between
    # any two step sequences; a periodic one is an attractor that both runs reach,
    # so its n_HALC is the same and its amplitudes agree to the resolution asked of
    # them, a relative 1e-3 (`SimulationOptions.sample_dt`), or 1e-3 absolute for
    # the small amplitudes of quiet oscillators.
    fig4 = data["4"].isel(v_d=0)
    periodic = data["8"]["class"].values == "periodic"
    assert periodic.sum() >= 2
    assert np.array_equal(data["8"]["n_halc"].values[periodic],
                          fig4["n_halc"].values[periodic])
    assert np.allclose(data["8"]["amplitudes"].values[periodic],
                       fig4["amplitudes"].values[periodic], rtol=1e-3, atol=1e-3)
    for name in ("6", "8", "9", "10"):
        solutions, ds = reports[name]["runs"][0]["solutions"], data[name]
        assert [s["n_excited"] for s in solutions] == ds["solution"].values.tolist()
        for s, row in zip(solutions, (ds.isel(solution=i) for i in range(len(solutions)))):
            assert s["n_halc"] == int(row["n_halc"]) and s["class"] == str(row["class"].values)
            assert s["lyapunov"] == float(row["lyapunov"])
            assert s["lyapunov_error"] == float(row["lyapunov_error"])
            assert s["class"] == "undecided" or s["class_delays"] == s["class_lyapunov"]
            # A periodic stick-slip state (a limit cycle or a torus) has the largest
            # Lyapunov exponent 0, not the negative one of an equilibrium: within
            # twice its stated error, on either side.
            if s["class"] == "periodic":
                assert abs(s["lyapunov"]) < 2 * s["lyapunov_error"] < 0.02, (name, s)


def test_figure_command_rejects_unknown_figures(capsys):
    with pytest.raises(SystemExit) as exc:
        sys.exit(jc.main(["figure", "3"]))
    assert exc.value.code == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
