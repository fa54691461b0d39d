"""Basin stability: the single oscillator's known edges, the coverage of the Wilson
intervals, reproducibility from the key, and a killed run resumed."""

import json

import jax
import numpy as np
import pytest
import xarray as xr
from scipy.stats import binomtest

import jaxchain as jc
from helpers import assert_cf_compliant, assert_usage_error, batch_writes, batches_done


SHORT = jc.SimulationOptions(t_end=300.0, transient=200.0)
ONE = jc.ChainParams(n_osc=1)


@pytest.mark.numerics
@pytest.mark.study
def test_single_oscillator_stick_slip_is_certain_below_hopf_and_absent_above_fold():
    """Below the Hopf point steady sliding is unstable, so every sample ends in
    stick-slip; above the fold (the stick-slip existence limit) none does; between
    them both basins have weight. The edges come from `hopf_point` and
    `stick_slip_existence_limit`, not from the samples."""
    hopf = float(jc.hopf_point(ONE).v_d[0])
    fold = jc.stick_slip_existence_limit(ONE)
    v_d = [hopf - 0.25, 0.5 * (hopf + fold), fold + 0.15]
    ds = jc.basin_stability(ONE, v_d, 48, key=1, options=SHORT, n_check=0, progress=False)
    assert ds["class"].values.tolist() == ["steady sliding", "stick-slip", "failed"]
    stick_slip = ds["counts"].sel({"class": "stick-slip"}).values
    assert stick_slip.tolist()[0] == 48 and stick_slip.tolist()[2] == 0
    assert 0 < stick_slip[1] < 48
    assert np.all(ds["counts"].sel({"class": "failed"}).values == 0)
    # the 95 % Wilson intervals, against scipy's
    counts = ds["counts"].values
    for low, high, k in zip(ds["ci_low"].values.ravel(), ds["ci_high"].values.ravel(),
                            counts.ravel()):
        ci = binomtest(int(k), 48).proportion_ci(confidence_level=0.95, method="wilson")
        assert low == pytest.approx(ci.low, abs=1e-12)
        assert high == pytest.approx(ci.high, abs=1e-12)
    assert np.array_equal(ds["fraction"].values, counts / 48)


@pytest.mark.parametrize("n", [1, 2, 7, 48, 1000])
def test_wilson_interval_equals_scipys(n):
    """Every k of n, the ends k = 0 and k = n included, against scipy's Wilson
    interval (no continuity correction)."""
    k = np.arange(n + 1)
    low, high = jc.wilson_interval(k, n)
    for kk in k:
        ci = binomtest(int(kk), n).proportion_ci(confidence_level=0.95, method="wilson")
        assert low[kk] == pytest.approx(ci.low, abs=1e-12)
        assert high[kk] == pytest.approx(ci.high, abs=1e-12)


@pytest.mark.numerics
def test_wilson_intervals_cover_a_known_probability_at_the_nominal_rate():
    """A synthetic classifier with a known probability: a sample is in the class
    when x_1(0) lies in the lowest 30 % of the box. Over 2000 keys of 50 samples
    each, the 95 % Wilson interval covers 0.3 in 93-97 % of them (the standard
    error of the coverage is 0.5 %)."""
    box, p, n = jc.Box(), 0.3, 50
    keys = jax.random.split(jax.random.PRNGKey(7), 2000)
    x = jax.vmap(lambda k: jc.sample_states(k, box, n, 1)[:, 0, 0])(keys)
    hits = np.asarray((x < box.x[0] + p * (box.x[1] - box.x[0])).sum(1))
    low, high = jc.wilson_interval(hits, n)
    coverage = np.mean((low <= p) & (p <= high))
    assert 0.93 <= coverage <= 0.97
    assert abs(hits.mean() / n - p) < 0.005  # the sampler is uniform


def test_clusters_count_groups_across_the_ring_closure():
    on = np.array([[1, 1, 0, 0, 1, 0], [1, 0, 0, 0, 0, 1], [0] * 6, [1] * 6], dtype=bool)
    assert jc.Graph.line(6).clusters(on).tolist() == [2, 1, 0, 1]  # basin's n_clusters


@pytest.mark.study
def test_same_key_same_result_and_a_killed_run_resumes_to_the_same(tmp_path, monkeypatch):
    params = jc.ChainParams(n_osc=3)
    kwargs = dict(options=SHORT, n_check=2, batch_size=4, progress=False)
    a = jc.basin_stability(params, [1.5], 10, key=3, **kwargs)
    b = jc.basin_stability(params, [1.5], 10, key=jax.random.PRNGKey(3), **kwargs)
    xr.testing.assert_equal(a, b)
    other = jc.basin_stability(params, [1.5], 10, key=4, **kwargs)
    assert not np.array_equal(other["y0"].values, a["y0"].values)

    store = tmp_path / "basin.zarr"

    def killed_after_batch_0(write, sweep_store, index, start, batch):
        write(sweep_store, index, start, batch)
        if index == 0:
            raise KeyboardInterrupt("killed after batch 0")

    with batch_writes(killed_after_batch_0), pytest.raises(KeyboardInterrupt):
        jc.basin_stability(params, [1.5], 10, key=3, store=store, **kwargs)
    assert batches_done(store) == [True, False, False]
    resumed = jc.basin_stability(params, [1.5], 10, key=3, store=store, resume=True, **kwargs)
    xr.testing.assert_equal(resumed.drop_attrs(), a.drop_attrs())
    assert resumed.attrs["key"] == a.attrs["key"] == np.asarray(jax.random.PRNGKey(3)).tolist()


@pytest.mark.numerics
@pytest.mark.study
def test_basin_command_json_and_figures(tmp_path, capsys):
    argv = ["basin", "--n-osc", "1", "--vd", "1.0,2.1", "--samples", "12", "--t-end", "300",
            "--transient", "200", "--out", str(tmp_path), "--json", "--no-progress"]
    assert jc.main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["outputs"]) == {"basin.zarr", "basin.nc", "basin.png", "basin_halc.png"}
    assert out["classes"] == ["steady sliding", "stick-slip", "failed"]
    assert np.array(out["fractions"]).shape == (2, 3) and out["n_samples"] == 12
    assert out["fractions"][0][1] == 1.0 and out["fractions"][1][1] == 0.0
    assert all((tmp_path / f).stat().st_size > 0 for f in ("basin.nc", "basin.png",
                                                            "basin_halc.png"))
    assert_cf_compliant(tmp_path / "basin.nc")


@pytest.mark.parametrize("argv, says", [
    (["--samples", "0"], "--samples"),
    (["--x-range", "2,1"], "--x-range"),
    (["--v-range", "a,b"], "--v-range"),
    (["--vd", "-1"], "--vd"),
    (["--transient", "5000"], "--transient"),
    (["--out", __file__], "--out"),
])
def test_basin_command_rejects_bad_input_in_one_line(argv, says, capsys):
    assert_usage_error(["basin", *argv], says, capsys)
