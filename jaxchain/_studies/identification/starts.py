"""Starting values from the records themselves: the states at each window's start,
and the static friction and damping from the breakaway positions."""

from __future__ import annotations

import numpy as np

from ..._physics.params import ChainParams
from .records import Record


def local_slopes(t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """dx/dt at every sample by the central difference on the (uneven) grid, one
    sided at the ends; x of shape (m,) or (m, k)."""
    return np.gradient(x, t, axis=0)


def _noise_level(x: np.ndarray) -> float:
    """The standard deviation of white measurement noise on a smooth signal, from the
    median absolute second difference (which is pure noise, variance 6 sigma^2,
    where the signal is linear, as in stick): median |d2x| / (0.6745 sqrt 6)."""
    d2 = np.abs(np.diff(x, n=2, axis=0))
    return float(np.median(d2) / (0.6745 * np.sqrt(6.0)))


def _breakaway_positions(record: Record, column: int = 0, min_samples: int = 3) -> np.ndarray:
    """The positions at which the measured oscillator leaves stick: the ends of the
    runs of samples that move with the belt (x' = v_d within three standard errors
    of the slope, for at least `min_samples` samples), each at the middle of its
    last sample interval.

    **Returns:** the breakaway positions, shape (runs,), possibly empty."""
    t, x = record.t, record.x[:, column]
    slope = local_slopes(t, x) if record.v is None else record.v[:, column]
    dt = np.median(np.diff(t))
    error = _noise_level(x) / dt if record.v is None else _noise_level(record.v[:, column])
    stick = np.abs(slope - record.v_d) < max(3 * error, 0.02 * record.v_d)
    # the runs of stick samples [i, j], from the rises and falls of the mask
    edges = np.diff(np.concatenate([[0], stick.astype(int), [0]]))
    ends = []
    for i, j in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1):
        if j - i + 1 >= min_samples and j + 1 < stick.size:
            z = x[i:j + 1] - record.v_d * t[i:j + 1]  # constant in stick
            ends.append(np.median(z) + record.v_d * 0.5 * (t[j] + t[j + 1]))
    return np.asarray(ends)


def breakaway_start(records: list[Record], params: ChainParams) -> dict:
    """mu(0) and xi from the breakaway positions of the records' first measured
    oscillator: at breakaway from stick x' = v_d, x'' = 0 and the friction force
    reaches mu(0), so x_b = mu(0) - 2 xi v_d - coupling (eq. (5) with unit mass,
    stiffness and load; the coupling is neglected). Two belt speeds or more give
    both by a straight line through (v_d, x_b); one gives mu(0) with the chain's
    xi.

    **Returns:** {"static": mu(0), "xi": xi} for what the records give (xi only
    from two speeds or more, and only when it comes out > 0); empty when no record
    shows stick."""
    speeds, positions = [], []
    for rec in records:
        ends = _breakaway_positions(rec)
        if ends.size:
            speeds.append(rec.v_d)
            positions.append(float(np.median(ends)))
    if not speeds:
        return {}
    speeds, positions = np.asarray(speeds), np.asarray(positions)
    xi = float(np.mean(np.asarray(params.xi)))
    if np.unique(speeds).size >= 2:
        slope, intercept = np.polyfit(speeds, positions, 1)
        if slope < 0:
            return {"static": float(intercept), "xi": float(-slope / 2)}
    return {"static": float(np.mean(positions + 2 * xi * speeds))}
