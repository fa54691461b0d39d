"""The mistuning study (issue 26): the Hopf point of every draw against its closed
form, the stored study read back and resumed identically, its summaries on
synthetic data, and the command line."""

import contextlib
import io
import json
import shutil

import numpy as np
import pytest
import xarray as xr

import jaxchain as jc

from helpers import assert_usage_error, scipy_stick_slip_cycle

ARGS = ["mistuning", "--n-osc", "4", "--sigmas", "0,2", "--draws", "2", "--vd", "1.5",
        "--samples", "2", "--folds", "0", "--t-end", "300", "--transient", "200",
        "--edge-t-end", "300", "--json", "--no-progress"]


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    out = tmp_path_factory.mktemp("mistuning")
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert jc.main(ARGS + ["--out", str(out)]) in (0, None)
    doc = json.loads(printed.getvalue())  # one JSON document, the files it wrote
    assert set(doc["outputs"]) == {"mistuning.nc", "mistuning.png", "mistuning_edges.png",
                                   "mistuned_fig4.png", "mistuning.json"}
    return out


def _summary(out):
    s = json.loads((out / "mistuning.json").read_text())
    s.pop("wall_time_s")
    return s


@pytest.mark.numerics
@pytest.mark.study
def test_every_draw_keeps_the_hopf_point_and_its_own_stiffness(study):
    """With uniform damping and load every mode of steady sliding loses stability
    where 2 xi + mu'(v_d) = 0 whatever the stiffness: the Hopf point of every draw
    is the closed form of the homogeneous ring. The deviations are those of
    `mistune` (draw d: seed d)."""
    ds = xr.open_dataset(study / "mistuning.nc")
    hopf = ds["hopf_vd"].values
    expected = float(jc.hopf_vd_analytic(jc.ChainParams(n_osc=4)))
    np.testing.assert_allclose(hopf[np.isfinite(hopf)], expected, rtol=1e-9)
    assert np.isfinite(hopf).sum() == 3  # sigma 0 once, sigma 2 twice
    for d in range(2):
        chain = jc.mistune(jc.ChainParams(n_osc=4), 2 * 0.01, d)
        np.testing.assert_array_equal(ds["deviations"].values[1, d], chain.stiffness - 1)


def _transfer_matrix_exponents(eta_c, sigma, omega2, cells, batches=16, warmup=2000,
                               seed=1):
    """The Lyapunov exponent per cell of x_(n+1) = a_n x_n - x_(n-1), a_n = (1 + delta_n
    + 2 eta_c - omega2) / eta_c, delta_n ~ N(0, sigma^2): NumPy's generator and a
    loop over the cells, every (row, batch) a lane, independently of
    `jc.localization_factor`. sigma and omega2 of shape (rows,); returns the mean
    over `batches` independent estimates and its standard error, each (rows,)."""
    rng = np.random.default_rng(seed)
    sigma, omega2 = np.asarray(sigma, float)[:, None], np.asarray(omega2, float)[:, None]
    a0 = (1.0 + 2.0 * eta_c - omega2) / eta_c
    x, x_prev = np.ones((sigma.size, batches)), np.zeros((sigma.size, batches))
    logs = np.zeros_like(x)
    block = 1000
    for start in range(0, warmup + cells, block):
        deltas = sigma * rng.standard_normal((block,) + x.shape)
        for n, delta in enumerate(deltas, start):
            x_next = (a0 + delta / eta_c) * x - x_prev
            norm = np.hypot(x_next, x)
            x, x_prev = x_next / norm, x / norm
            if n >= warmup:
                logs += np.log(norm)
    estimates = logs / cells
    return estimates.mean(1), estimates.std(1, ddof=1) / np.sqrt(batches)


@pytest.mark.numerics
@pytest.mark.study
def test_the_json_gives_the_localization_factor_table(study):
    """The localization factor table against a second estimate, by NumPy
    (`_transfer_matrix_exponents`: its own random numbers, 40,000 cells), within
    5 combined standard errors, where each estimate's error is below 2 % of
    gamma; the weak-disorder column against sigma^2 / (8 eta_c^2 sin^2 theta)
    (Castanier & Pierre 1995), and the deviation column against it, which holds at
    sigma = eta_c / 4 away from the band centre, within 4 of the table's errors."""
    s = _summary(study)
    rows = s["localization_factor"]
    assert {(r["sigma_over_eta_c"], round(r["theta"], 6)) for r in rows} == {
        (x, round(t, 6)) for x in (0.25, 0.5, 1.0, 2.0, 4.0) for t in (np.pi / 2, np.pi / 3)}
    eta = float(jc.ChainParams().eta_c)
    ratio = np.array([r["sigma_over_eta_c"] for r in rows])
    theta = np.array([r["theta"] for r in rows])
    gamma, error = np.array([r["gamma"] for r in rows]), np.array([r["error"] for r in rows])
    expected, expected_error = _transfer_matrix_exponents(
        eta, ratio * eta, 1 + 2 * eta * (1 - np.cos(theta)), cells=40_000)
    assert np.all(error < 0.02 * gamma) and np.all(expected_error < 0.02 * expected)
    assert np.all(np.abs(gamma - expected) < 5 * np.hypot(error, expected_error))
    formula = (ratio * eta) ** 2 / (8 * eta**2 * np.sin(theta) ** 2)
    np.testing.assert_allclose([r["weak_disorder"] for r in rows], formula, rtol=1e-12)
    np.testing.assert_allclose([r["deviation_in_errors"] for r in rows],
                               (gamma - formula) / error, rtol=1e-9)
    weak = (ratio == 0.25) & (theta < 1.1)
    assert np.all(np.abs(gamma[weak] - formula[weak]) < 4 * error[weak])
    assert [r["sigma_over_eta_c"] for r in s["sigmas"]] == [0.0, 2.0]


@pytest.mark.numerics
@pytest.mark.study
def test_the_single_site_state_s_frequency_damping_and_linear_decay(study):
    """The numbers the study attaches to the single-site state: its period T, and
    omega^2 = (2 pi / T)^2 that of the single oscillator's non-smooth stick-slip
    cycle (scipy, `scipy_stick_slip_cycle`) on a ground stiffness raised by the
    coupling 2 eta_c of its two neighbours, to within eta_c / 2 (the smoothing
    moves the period by O(eps), the neighbours' small motion the coupling force);
    the damping of steady sliding 2 xi + mu'(v_d) of eq. (1); the decay per cell
    of the damped homogeneous chain at that frequency, against the envelope of the
    driven damped ring solved by NumPy (as in test_localization.py); and the linear
    localization factor there: exactly 0 without mistuning (omega^2 lies inside
    the passband [1, 1 + 4 eta_c]), as at the table's phases, and at sigma = 2
    eta_c the NumPy transfer-matrix estimate's within 5 combined errors."""
    ds = xr.load_dataset(study / "mistuning.nc")
    a = ds.attrs
    p = jc.ChainParams(n_osc=4, v_d=1.5)
    eta, xi = float(p.eta_c), float(p.xi)
    mu_st, mu_d, v0 = (float(p.friction.mu_st), float(p.friction.mu_d),
                       float(p.friction.v0))
    _, period = scipy_stick_slip_cycle(jc.ChainParams(n_osc=1, v_d=1.5))
    assert a["state_omega2"] == pytest.approx((2 * np.pi / a["state_period"]) ** 2,
                                              rel=1e-12)
    assert abs(a["state_omega2"] - (2 * np.pi / period) ** 2 - 2 * eta) < eta / 2
    assert 1 < a["state_omega2"] < 1 + 4 * eta
    slope = -(mu_st - mu_d) / v0 * np.exp(-1.5 / v0)  # mu'(v_d), eq. (1)
    assert a["sliding_damping"] == pytest.approx(2 * xi + slope, rel=1e-9)
    n = 201
    k = np.diag(np.full(n, 1 + 2 * eta)) - eta * (np.eye(n, k=1) + np.eye(n, k=-1))
    k[0, -1] = k[-1, 0] = -eta
    omega = np.sqrt(a["state_omega2"])
    force = np.zeros(n)
    force[0] = 1.0
    x = np.abs(np.linalg.solve(k - (omega**2 - 1j * omega * a["sliding_damping"])
                               * np.eye(n), force))
    assert abs(a["state_damped_decay"] - np.log(x[3] / x[4])) < 1e-6
    assert np.all(ds["gamma"].values[0] == 0) and np.all(ds["gamma_error"].values[0] == 0)
    assert ds["state_gamma"].values[0] == 0 and ds["state_gamma_error"].values[0] == 0
    expected, expected_error = _transfer_matrix_exponents(
        eta, [2 * eta], [a["state_omega2"]], cells=40_000)
    gamma, error = float(ds["state_gamma"].values[1]), float(ds["state_gamma_error"].values[1])
    assert error < 0.02 * gamma
    assert abs(gamma - expected[0]) < 5 * np.hypot(error, expected_error[0])


@pytest.mark.study
@pytest.mark.long
def test_resume_after_a_lost_chain_gives_the_same_study(study, tmp_path, capsys):
    """A run killed before its last chain (its store missing) and the study's
    files lost: --resume recomputes them, the lost chain on a Dask cluster, and the
    summary is identical. Without --resume an existing study is refused."""
    first = _summary(study)
    copy = tmp_path / "copy"
    shutil.copytree(study, copy)
    shutil.rmtree(copy / "chains" / "sigma2_draw1.zarr")
    (copy / "mistuning.nc").unlink()
    assert_usage_error(ARGS + ["--out", str(copy)], "--resume", capsys)
    # the lost chain on a cluster of two spawned workers (issue 27): the same bits
    assert jc.main(ARGS + ["--out", str(copy), "--resume", "--scheduler", "local:2"]) in (0, None)
    again = _summary(copy)
    assert again == first


@pytest.mark.study
def test_envelope_decay_is_the_least_squares_decay_of_the_single_site_state(study):
    """The study's `envelope_decay`: kappa of log A(m) = c - kappa m by least squares
    over m = 1, 2, 3 cells on both sides of the largest amplitude (the sides
    averaged), from the staircase's k = 1 state at v_d = 1.5; NaN where that run
    did not end with one oscillator on the HALC."""
    ds = xr.load_dataset(study / "mistuning.nc", engine="h5netcdf")
    amplitudes = ds["staircase_amplitudes"].sel(v_d=1.5, k=1).values  # (sigma, draw, osc)
    n_halc = ds["staircase_n_halc"].sel(v_d=1.5, k=1).values
    m = np.array([1.0, 2.0, 3.0])
    found = 0
    for index in np.ndindex(n_halc.shape):
        a, kappa = amplitudes[index], float(ds["envelope_decay"].values[index])
        if n_halc[index] != 1 or not np.all(np.isfinite(a)):
            assert np.isnan(kappa)
            continue
        s, n = int(np.argmax(a)), a.size
        log_a = 0.5 * (np.log(a[(s - m.astype(int)) % n]) + np.log(a[(s + m.astype(int)) % n]))
        slope = np.sum((m - m.mean()) * (log_a - log_a.mean())) / np.sum((m - m.mean()) ** 2)
        assert kappa == pytest.approx(-slope, rel=1e-10, abs=1e-12)
        found += 1
    assert found > 0


def _synthetic_study(dev, on, n_halc) -> xr.Dataset:
    """A `mistuning_study` dataset holding the random starts `on`, `n_halc` of the
    chains of deviations `dev` (sigma 0 and 2, one belt speed), everything else
    empty: what `study_summary` reads."""
    n_sigma, n_draws, n = dev.shape
    nan = lambda *shape: np.full(shape, np.nan)  # noqa: E731
    stair = ("sigma", "draw", "v_d", "k")
    return xr.Dataset(
        {"deviations": (("sigma", "draw", "osc"), dev),
         "basin_on_halc": (("sigma", "draw", "v_d", "sample", "osc"), on),
         "basin_n_halc": (("sigma", "draw", "v_d", "sample"), n_halc),
         "basin_status": (("sigma", "draw", "v_d", "sample"), np.zeros_like(n_halc)),
         "staircase_n_halc": (stair, np.full((n_sigma, n_draws, 1, n), -1)),
         "staircase_status": (stair, np.full((n_sigma, n_draws, 1, n),
                                             int(jc.Status.not_run))),
         **{name: (("sigma", "draw"), nan(n_sigma, n_draws))
            for name in ("hopf_vd", "upper_edge", "fold_vd", "fold_site", "envelope_decay")},
         "site_edge": (("sigma", "draw", "osc"), nan(n_sigma, n_draws, n)),
         "state_gamma": ("sigma", nan(n_sigma)), "state_gamma_error": ("sigma", nan(n_sigma))},
        coords={"sigma": [0.0, 2.0], "v_d": [1.5], "k": np.arange(1, n + 1)},
        attrs={"eta_c": 0.01, "state_period": np.nan, "state_omega2": np.nan,
               "sliding_damping": np.nan, "state_damped_decay": np.nan,
               "edge_resolution": np.nan, "n_draws": n_draws, "n_samples": on.shape[3],
               "t_end": 1.0, "transient": 0.5})


def test_halc_correlation_sees_which_oscillators_vibrate():
    """Synthetic study: the oscillators with delta_n > 0 are on the HALC. The
    correlation (`study_summary`'s `halc_deviation_correlation`) is positive, and
    their mean deviation is that of the positive half of the draws."""
    rng = np.random.default_rng(0)
    dev = 0.02 * rng.standard_normal((2, 3, 6))
    dev[0] = np.nan
    on = np.broadcast_to((dev > 0)[:, :, None, None, :], (2, 3, 1, 4, 6))
    n_halc = on.sum(-1)
    rows = jc.study_summary(_synthetic_study(dev, on, n_halc))["sigmas"]
    assert np.isnan(rows[0]["halc_deviation_correlation"][0])
    assert rows[1]["halc_deviation_correlation"][0] > 0.5
    keep = (n_halc[1, :, 0, 0] > 0) & (n_halc[1, :, 0, 0] < 6)
    expected = dev[1][keep][dev[1][keep] > 0].mean() / 0.02
    assert abs(rows[1]["mean_deviation_on_halc_over_sigma"][0] - expected) < 1e-12


def test_bad_options(tmp_path, capsys):
    assert_usage_error(["mistuning", "--sigmas", "-1", "--out", str(tmp_path)], "sigmas", capsys)
    assert_usage_error(["mistuning", "--draws", "0"], "--draws", capsys)
