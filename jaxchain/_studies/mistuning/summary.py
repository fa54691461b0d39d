"""What a `mistuning_study` found, as numbers: the staircase fraction, basin
stability, where the vibration sits, and the fitted localization of the states."""

import numpy as np

from ..basin.classes import wilson_interval
from ..._physics.chain import neighbours
from ..._engine.status import Status


def envelope_decay(amplitudes: np.ndarray, n_halc: np.ndarray, boundary: str = "ring",
                   distances=(1, 2, 3)) -> np.ndarray:
    """The decay per cell kappa of the amplitude envelope of single-site states:
    log A(m) = c - kappa m fitted by least squares over the oscillators at
    `distances` m on both sides of the oscillator of largest amplitude (averaged
    over the two sides). NaN where n_halc != 1.

    **Arguments:**

    - `amplitudes`: shape (..., n_osc); `n_halc`: shape (...).

    **Returns:**

    kappa, shape (...): the amplitude falls as exp(-kappa m).
    """
    amplitudes = np.asarray(amplitudes, dtype=float)
    n = amplitudes.shape[-1]
    m = np.asarray(distances, dtype=float)
    out = np.full(amplitudes.shape[:-1], np.nan)
    for index in np.ndindex(out.shape):
        a = amplitudes[index]
        if n_halc[index] != 1 or not np.all(np.isfinite(a)):
            continue
        s = int(np.argmax(a))
        sides = []
        for sign in (-1, 1):
            j = s + sign * m.astype(int)
            if boundary == "ring":
                j %= n
            elif j.min() < 0 or j.max() >= n:
                continue
            sides.append(np.log(a[j]))
        if sides:
            slope = np.polyfit(m, np.mean(sides, axis=0), 1)[0]
            out[index] = -slope
    return out


def staircase_fraction(study) -> dict:
    """The share of eq. (8) starts with k excited that end with n_HALC = k, over
    draws and k, per (sigma, v_d), with 95 % Wilson intervals (runs that failed
    left out): arrays of shape (n_sigma, n_vd) under `fraction`, `low`, `high`,
    `count`, `total`."""
    ok = study["staircase_status"].values == Status.ok
    hit = ok & (study["staircase_n_halc"].values == study["k"].values)
    return _share(hit.sum((1, 3)), ok.sum((1, 3)))


def _vibrating_fraction(study) -> dict:
    """Basin stability of the vibrating states: the share of random initial
    states that end with n_HALC >= 1, per (sigma, v_d), with Wilson intervals."""
    ok = study["basin_status"].values == Status.ok
    hit = ok & (study["basin_n_halc"].values > 0)
    return _share(hit.sum((1, 3)), ok.sum((1, 3)))


def localized_fraction(study) -> dict:
    """Basin stability of the localized states: the share of random initial states
    that end with 0 < n_HALC < N (neither steady sliding nor the whole chain in
    stick-slip), per (sigma, v_d), with Wilson intervals."""
    ok = study["basin_status"].values == Status.ok
    n_halc = study["basin_n_halc"].values
    hit = ok & (n_halc > 0) & (n_halc < study.sizes["osc"])
    return _share(hit.sum((1, 3)), ok.sum((1, 3)))


def _share(k, n) -> dict:
    k, n = np.asarray(k), np.asarray(n)
    with np.errstate(invalid="ignore", divide="ignore"):
        low, high = wilson_interval(k, np.maximum(n, 1))
        fraction = np.where(n > 0, k / np.maximum(n, 1), np.nan)
    return {"fraction": fraction, "low": np.where(n > 0, low, np.nan),
            "high": np.where(n > 0, high, np.nan), "count": k, "total": n}


def _halc_correlation(study) -> dict:
    """Where the vibration sits: over the random starts that end localized
    (0 < n_HALC < N), the Pearson correlation between an oscillator being on the
    HALC and its stiffness deviation delta_n, and the mean delta_n / sigma of the
    oscillators on the HALC (> 0: the stiffer ones vibrate), per (sigma, v_d);
    NaN at sigma = 0."""
    dev = study["deviations"].values  # (sigma, draw, osc)
    on = study["basin_on_halc"].values  # (sigma, draw, v_d, sample, osc)
    n_halc = study["basin_n_halc"].values
    n = dev.shape[-1]
    sigmas = study["sigma"].values
    eta_c = float(study.attrs["eta_c"])
    r = np.full((sigmas.size, study.sizes["v_d"]), np.nan)
    z = np.full_like(r, np.nan)
    count = np.zeros(r.shape, dtype=int)
    for i in range(sigmas.size):
        if sigmas[i] == 0:
            continue
        for j in range(r.shape[1]):
            keep = (study["basin_status"].values[i, :, j] == Status.ok) & (n_halc[i, :, j] > 0) \
                & (n_halc[i, :, j] < n)  # (draw, sample)
            if not keep.any():
                continue
            d = np.broadcast_to(dev[i][:, None, :], on[i, :, j].shape)[keep].ravel()
            h = on[i, :, j][keep].ravel().astype(float)
            count[i, j] = int(keep.sum())
            r[i, j] = np.corrcoef(h, d)[0, 1]
            z[i, j] = d[h == 1].mean() / (sigmas[i] * eta_c)
    return {"correlation": r, "mean_deviation_on_halc": z, "localized_runs": count}


def localization_table(eta_c: float, sigmas, thetas, **kwargs) -> list[dict]:
    """The localization factor of the linear chain (`localization_factor`) at each
    sigma / eta_c and phase per cell theta, beside the weak-disorder formula: a
    list of dicts `sigma_over_eta_c`, `theta`, `gamma`, `error`,
    `weak_disorder`, `deviation_in_errors` ((gamma - formula) / error)."""
    from ..._analysis.localization import localization_factor, passband_frequency
    from ..._analysis.localization import weak_disorder_localization

    rows = []
    thetas = np.asarray(thetas, dtype=float)
    for s in sigmas:
        gamma, error = localization_factor(eta_c, s * eta_c, passband_frequency(eta_c, thetas),
                                           **kwargs)
        weak = weak_disorder_localization(s * eta_c, eta_c, thetas)
        for t, g, e, w in zip(thetas, np.asarray(gamma), np.asarray(error), weak):
            rows.append({"sigma_over_eta_c": float(s), "theta": float(t), "gamma": float(g),
                         "error": float(e), "weak_disorder": float(w),
                         "deviation_in_errors": float((g - w) / e)})
    return rows


def neighbour_detuning(deviations: np.ndarray, boundary: str = "ring") -> np.ndarray:
    """delta_n minus the mean of its neighbours' delta (one neighbour at the end of
    an open chain): how far oscillator n is tuned away from the oscillators it is
    coupled to. Shape of `deviations` (..., n_osc)."""
    d = np.asarray(deviations, dtype=float)
    left_of, right_of = neighbours(boundary, d.shape[-1])
    left = np.where(left_of >= 0, d[..., left_of], d[..., right_of])
    right = np.where(right_of >= 0, d[..., right_of], d[..., left_of])
    return d - 0.5 * (left + right)


def edge_correlations(study) -> dict:
    """Over every oscillator of every mistuned draw, the correlation of the upper
    edge of its single-site state with |delta_n| and with |neighbour_detuning|."""
    boundary = str(study.attrs.get("boundary", "ring"))
    dev = study["deviations"].values
    edge = study["site_edge"].values
    keep = np.isfinite(dev) & np.isfinite(edge) & (study["sigma"].values[:, None, None] > 0)
    if keep.sum() < 3:
        return {"own_deviation": None, "neighbour_detuning": None}
    det = np.abs(neighbour_detuning(dev, boundary))
    return {"own_deviation": float(np.corrcoef(np.abs(dev)[keep], edge[keep])[0, 1]),
            "neighbour_detuning": float(np.corrcoef(det[keep], edge[keep])[0, 1])}


def _stats(values) -> dict:
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if not v.size:
        return {"count": 0}
    return {"count": int(v.size), "mean": float(v.mean()), "std": float(v.std(ddof=1))
            if v.size > 1 else 0.0, "min": float(v.min()), "max": float(v.max())}


def study_summary(study) -> dict:
    """The summary of a `mistuning_study`, what `jaxchain mistuning` prints and
    writes as JSON.

    **Arguments:**

    - `study`: the Dataset of `mistuning_study`.

    **Returns:**

    A dict of plain Python values. `sigmas` holds one row per sigma: `v_d` and,
    per belt speed, `staircase_fraction` (eq. (8) starts with k excited that end
    with n_HALC = k), `basin_stability_vibrating` (random starts that end with
    n_HALC >= 1) and `basin_stability_localized` (0 < n_HALC < N), each with its
    95 % Wilson interval (`*_ci`) and run count; `halc_deviation_correlation` (the
    Pearson correlation of being on the HALC with delta_n, over localized random
    starts; NaN at sigma = 0) and `mean_deviation_on_halc_over_sigma`; the
    distributions of the Hopf point, the upper edge and the envelope decay, the
    folds found by shooting, and the Anderson localization factor at the state's
    frequency. Beside it: the state's period and omega^2, the damped chain's
    decay, the correlation of the site edges with the neighbours' detuning
    (`site_edge_correlation`) and the study's sizes.
    """
    stair, basin, corr = staircase_fraction(study), _vibrating_fraction(study), \
        _halc_correlation(study)
    local = localized_fraction(study)
    n_halc = np.where(study["basin_status"].values == Status.ok,
                      study["basin_n_halc"].values, np.nan)
    rows = []
    for i, sigma in enumerate(study["sigma"].values):
        rows.append({
            "sigma_over_eta_c": float(sigma),
            "v_d": study["v_d"].values.tolist(),
            "staircase_fraction": stair["fraction"][i].tolist(),
            "staircase_ci": [stair["low"][i].tolist(), stair["high"][i].tolist()],
            "staircase_runs": stair["total"][i].tolist(),
            "basin_stability_vibrating": basin["fraction"][i].tolist(),
            "basin_ci": [basin["low"][i].tolist(), basin["high"][i].tolist()],
            "basin_runs": basin["total"][i].tolist(),
            "basin_stability_localized": local["fraction"][i].tolist(),
            "localized_ci": [local["low"][i].tolist(), local["high"][i].tolist()],
            "mean_n_halc_random_starts": np.nanmean(n_halc[i], axis=(0, 2)).tolist(),
            "halc_deviation_correlation": corr["correlation"][i].tolist(),
            "mean_deviation_on_halc_over_sigma": corr["mean_deviation_on_halc"][i].tolist(),
            "hopf_vd": _stats(study["hopf_vd"].values[i]),
            "upper_edge": _stats(study["upper_edge"].values[i]) | {
                "per_draw": study["upper_edge"].values[i].tolist()},
            "fold_by_shooting": [{"draw": int(d), "v_d": float(f), "site": int(j) + 1,
                                  "upper_edge_simulation": float(e)}
                                 for d, (f, j, e) in enumerate(zip(
                                     study["fold_vd"].values[i], study["fold_site"].values[i],
                                     study["upper_edge"].values[i])) if np.isfinite(f)],
            "envelope_decay": _stats(study["envelope_decay"].values[i]),
            "anderson_gamma_at_state_frequency": float(study["state_gamma"].values[i]),
            "anderson_gamma_at_state_frequency_error":
                float(study["state_gamma_error"].values[i])})
    a = study.attrs
    return {"sigmas": rows, "state_period": a["state_period"],
            "state_omega2": a["state_omega2"], "sliding_damping": a["sliding_damping"],
            "damped_chain_decay": a["state_damped_decay"],
            "edge_resolution": a["edge_resolution"],
            "site_edge_correlation": edge_correlations(study), "n_draws": a["n_draws"],
            "n_samples": a["n_samples"], "t_end": a["t_end"], "transient": a["transient"]}


def failed_runs(study) -> int:
    """The runs of a `mistuning_study` that failed (status neither `ok` nor
    `not_run`): the staircase and the random starts."""
    ran = (Status.ok, Status.not_run)
    return int(np.isin(study["staircase_status"].values, ran, invert=True).sum()
               + np.isin(study["basin_status"].values, ran, invert=True).sum())
