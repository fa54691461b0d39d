"""Time delays between the peaks of the oscillators, and their spread (Section 3.3
of the paper)."""

import numpy as np
from jaxtyping import Bool, Float

from .._physics.chain import Graph, as_graph
from .._physics.initial import centre_site


def reference_oscillator(on_halc: Bool[np.ndarray, " n_osc"],
                         boundary: str | Graph = "ring") -> int:
    """The paper's reference oscillator: the 11th of 20 (0-based N//2), which is
    excited and on the HALC in every solution of Fig. 4; on a lattice its centre
    site (`centre_site`). When it is not on the HALC, the HALC oscillator nearest
    to it by graph distance (around the ring, along an open chain, across a
    lattice: `boundary`, a name of `BOUNDARIES` or the `Graph`), the lower index
    first; the centre when none is."""
    graph = as_graph(boundary, on_halc.size)
    centre = centre_site(graph)
    halc = np.flatnonzero(on_halc)
    if halc.size == 0 or on_halc[centre]:
        return centre
    distance = graph.distances()[centre][halc]
    return int(halc[np.argmin(distance)])


def time_delays(peak_times: Float[np.ndarray, "n_osc peaks"], ref: int
                ) -> tuple[Float[np.ndarray, " ref_peaks"], Float[np.ndarray, "n_osc ref_peaks"]]:
    """The time delays phi_i = tau_peak,i - tau_peak,ref of Section 3.3 of the paper.

    Each peak of the reference is paired with the first peak of oscillator i at or
    after tau_peak,ref - T/4 (T: the reference's median period), so that phi lies
    in [-T/4, 3T/4): in-phase oscillators sit near 0, out-of-phase ones near T/2
    (the paper's "0 or pi").

    **Arguments:**

    - `peak_times`: peak times of every oscillator, oldest first, NaN-padded,
        shape (n_osc, peaks) (`PeakTimes`); dimensionless time.
    - `ref`: 0-based index of the reference oscillator.

    **Returns:**

    (tau_ref, phi): the reference's peak times, shape (ref_peaks,), and the delays,
    shape (n_osc, ref_peaks), NaN where oscillator i has no peak to pair.
    """
    tau_ref = peak_times[ref][np.isfinite(peak_times[ref])]
    phi = np.full((peak_times.shape[0], tau_ref.size), np.nan)
    if tau_ref.size < 2:
        return tau_ref, phi
    margin = 0.25 * np.median(np.diff(tau_ref))
    for i, tau in enumerate(peak_times):
        tau = tau[np.isfinite(tau)]
        j = np.searchsorted(tau, tau_ref - margin)
        ok = j < tau.size
        phi[i, ok] = tau[j[ok]] - tau_ref[ok]
    return tau_ref, phi


def delay_spread(tau_ref: Float[np.ndarray, " ref_peaks"],
                 phi: Float[np.ndarray, "rows ref_peaks"], t_from: float,
                 max_period: int = 8) -> tuple[float, int]:
    """How far the time delays are from repeating: the paper's criterion, a state
    is periodic when phi settles to fixed values. Over the reference peaks at
    or after `t_from`, the rows of phi (the delays of the HALC oscillators, and the
    reference's own periods) are compared with themselves m peaks later:

        spread = min over m = 1..max_period of max_(i,k) |phi_i[k+m] - phi_i[k]|

    A period-m state (delays that repeat every m reference peaks) has a spread at
    the level of the peak-time error; an irregular one, of the order of its period.

    **Returns:**

    (spread, m): the spread (dimensionless time; inf with fewer than 2 max_period
    peaks, or when a pairing is missing) and the m that attains it.
    """
    keep = tau_ref >= t_from
    rows = np.vstack([np.diff(tau_ref, append=np.nan)[None], phi])[:, keep][:, :-1]
    best, period = np.inf, 0
    if rows.shape[1] < 2 * max_period:
        return best, period
    for m in range(1, max_period + 1):
        change = np.abs(rows[:, m:] - rows[:, :-m])
        worst = np.inf if np.isnan(change).any() else float(change.max())
        if worst < best:
            best, period = worst, m
    return best, period
