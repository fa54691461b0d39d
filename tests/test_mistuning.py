"""The mistuning study (issue 26): the Hopf point of every draw against its closed
form, the stored study read back and resumed identically, its summaries on
synthetic data, and the command line."""

import json
import shutil

import numpy as np
import pytest
import xarray as xr

import jaxchain as jc
from jaxchain._cli.main import main
from jaxchain._mistuning.summary import envelope_decay, halc_correlation

from helpers import assert_usage_error

ARGS = ["mistuning", "--n-osc", "4", "--sigmas", "0,2", "--draws", "2", "--vd", "1.5",
        "--samples", "2", "--folds", "0", "--t-end", "300", "--transient", "200",
        "--edge-t-end", "300", "--json", "--no-progress"]


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    out = tmp_path_factory.mktemp("mistuning")
    assert main(ARGS + ["--out", str(out)]) in (0, None)
    return out


def _summary(out):
    s = json.loads((out / "mistuning.json").read_text())
    s.pop("wall_time_s")
    return s


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


def test_the_json_gives_the_localization_factor_table(study):
    s = _summary(study)
    rows = s["localization_factor"]
    assert {(r["sigma_over_eta_c"], round(r["theta"], 6)) for r in rows} == {
        (x, round(t, 6)) for x in (0.25, 0.5, 1.0, 2.0, 4.0) for t in (np.pi / 2, np.pi / 3)}
    assert all(r["error"] > 0 and r["gamma"] > 0 for r in rows)
    # weak disorder holds at sigma = eta_c / 4 away from the band centre
    (weak,) = [r for r in rows if r["sigma_over_eta_c"] == 0.25 and r["theta"] < 1.1]
    assert abs(weak["deviation_in_errors"]) < 4
    assert [r["sigma_over_eta_c"] for r in s["sigmas"]] == [0.0, 2.0]


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
    assert main(ARGS + ["--out", str(copy), "--resume", "--scheduler", "local:2"]) in (0, None)
    again = _summary(copy)
    first.pop("figures"), again.pop("figures")
    assert again == first


def test_envelope_decay_recovers_an_exponential_profile():
    n, kappa = 20, 1.7
    m = np.minimum(np.arange(n), n - np.arange(n))
    profile = np.roll(2.0 * np.exp(-kappa * m), 7)
    assert abs(envelope_decay(profile[None], np.array([1]))[0] - kappa) < 1e-12
    assert np.isnan(envelope_decay(profile[None], np.array([2]))[0])


def test_halc_correlation_sees_which_oscillators_vibrate():
    """Synthetic study: the oscillators with delta_n > 0 are on the HALC. The
    correlation is positive, and their mean deviation is that of the positive
    half of the draws."""
    rng = np.random.default_rng(0)
    dev = 0.02 * rng.standard_normal((2, 3, 6))
    dev[0] = np.nan
    on = np.broadcast_to((dev > 0)[:, :, None, None, :], (2, 3, 1, 4, 6))
    n_halc = on.sum(-1)
    ds = xr.Dataset({"deviations": (("sigma", "draw", "osc"), dev),
                     "basin_on_halc": (("sigma", "draw", "v_d", "sample", "osc"), on),
                     "basin_n_halc": (("sigma", "draw", "v_d", "sample"), n_halc),
                     "basin_status": (("sigma", "draw", "v_d", "sample"),
                                      np.zeros_like(n_halc))},
                    coords={"sigma": [0.0, 2.0], "v_d": [1.5]}, attrs={"eta_c": 0.01})
    out = halc_correlation(ds)
    assert np.isnan(out["correlation"][0, 0])
    assert out["correlation"][1, 0] > 0.5
    keep = (n_halc[1, :, 0, 0] > 0) & (n_halc[1, :, 0, 0] < 6)
    expected = dev[1][keep][dev[1][keep] > 0].mean() / 0.02
    assert abs(out["mean_deviation_on_halc"][1, 0] - expected) < 1e-12


def test_bad_options(tmp_path, capsys):
    assert_usage_error(["mistuning", "--sigmas", "-1", "--out", str(tmp_path)], "sigmas", capsys)
    assert_usage_error(["mistuning", "--draws", "0"], "--draws", capsys)
