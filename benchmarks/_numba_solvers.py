"""Hand-written numba baselines for the cost of one integration step (benchmarks/run.py,
comparison 2): eq. (5) of the paper integrated by the same tableaux and the same
step-size controller as jaxchain, in plain compiled loops with no allocation in the
step loop. They answer "what would a careful hand-written loop cost per step?".

What is mirrored from jaxchain / diffrax 0.7 (read from their sources):

- the tableau: ROS34PW2 in the transformed variables u_i of `jaxchain._engine.solver.rosenbrock`
  (`_GAMMA`, `_A`, `_C`, `_M`, `_M_ERROR`, with W = diag(1/(h gamma) - min(d, 0))
  from the friction Jacobian's diagonal d at the step's start, f and d at the step's
  end reused by the next step), or diffrax's Bosh3 tableau (FSAL);
- diffrax's `PIDController` with its defaults, an I-controller: scaled error =
  RMS_i err_i / (atol + rtol max(|y0_i|, |y1_i|)), accepted if < 1, factor =
  0.9 (1/error)^(1/3) clipped to [1, 10] after an accepted and to [0.2, 0.9] after
  a rejected step; the last step of a span is clipped to its end (100 ULP floor);
- jaxchain's chunking: the run is integrated in chunks of about 250 time units
  (`SimulationOptions.chunks`), the solver state (f and d, or the FSAL f) carried
  across chunks and the first step size guessed anew at each chunk, as diffrax does
  (0.01 for ROS34PW2, whose terms are a `MultiTerm`; diffrax's
  `_select_initial_step` for Bosh3 on its `ODETerm`).

What is not mirrored: dense output. jaxchain samples the observed window every
`sample_dt` = 0.05 by Hermite interpolation; these loops take the extrema at the
accepted step ends only (amplitudes differ in the fourth digit). The step
counts of the two sides agree to a few per cent, not exactly: the trajectories are
the same to rounding, and rounding differences grow in the stick-slip dynamics.
"""

import math

import numpy as np
from numba import njit

from jaxchain._physics.forces import DEFAULT_EPS
from jaxchain._engine.solver.rosenbrock import _A, _C, _GAMMA, _M, _M_ERROR

# Bosh3 as in diffrax/_solver/bosh3.py.
_B3_A10, _B3_A21 = 1 / 2, 3 / 4
_B3_B = np.array([2 / 9, 1 / 3, 4 / 9, 0.0])
_B3_ERR = np.array([2 / 9 - 7 / 24, 1 / 3 - 1 / 4, 4 / 9 - 1 / 3, -1 / 8])

_SAFETY, _FACTORMIN, _FACTORMAX = 0.9, 0.2, 10.0


def params_vector(params, eps: float = DEFAULT_EPS) -> np.ndarray:
    """`ChainParams` and the smoothing `eps` (the smoothed engine's) as the float
    vector the loops take: (xi, mu_d, mu_st, v0, eta_c, v_d, eps)."""
    return np.array([float(params.xi), float(params.friction.mu_d), float(params.friction.mu_st),
                     float(params.friction.v0), float(params.eta_c), float(params.v_d),
                     float(eps)])


def chunk_bounds(options) -> tuple[np.ndarray, np.ndarray, float]:
    """Start and end of every chunk of a jaxchain run (`AbstractHorizon.phases`: the
    transient, then the observed window, each cut into equal chunks), the 100-ULP
    clip floor of each end (diffrax's `t1_clip_floor`), and the transient."""
    starts, ends = [], []
    for a, length, n, _ in options.phases():
        for i in range(n):
            t0 = a + length * i
            starts.append(t0)
            ends.append(t0 + length)
    ends = np.array(ends)
    floors = ends.copy()
    for _ in range(100):
        floors = np.nextafter(floors, -np.inf)
    return np.array(starts), np.column_stack([ends, floors]), options.transient


@njit(cache=True, inline="always")
def _friction(vr, mu_d, mu_st, v0, eps):
    """Smoothed friction F(vr) = -mu(vr) tanh(vr/eps) and dF/dvr."""
    e = math.exp(-abs(vr) / v0)
    mu = mu_d + (mu_st - mu_d) * e
    th = math.tanh(vr / eps)
    sign = 1.0 if vr > 0 else (-1.0 if vr < 0 else 0.0)
    dmu = -(mu_st - mu_d) / v0 * sign * e
    return -mu * th, -(dmu * th + mu * (1.0 - th * th) / eps)


@njit(cache=True)
def _rhs(y, p, out, d, with_d):
    """out = f(y) for the flat state y = (x_1..x_N, x_1'..x_N'); d (the friction
    Jacobian's diagonal, zero on the x rows) too when with_d. The ring's ends are
    written out so that the inner loop has no modulo."""
    xi, mu_d, mu_st, v0, eta, vd, eps = p[0], p[1], p[2], p[3], p[4], p[5], p[6]
    n = y.shape[0] // 2
    for i in range(n):
        force, dforce = _friction(y[n + i] - vd, mu_d, mu_st, v0, eps)
        out[n + i] = force
        if with_d:
            d[i] = 0.0
            d[n + i] = dforce
    c = 1.0 + 2.0 * eta
    for i in range(n):
        v = y[n + i]
        out[i] = v
        if 0 < i < n - 1:
            neighbours = y[i + 1] + y[i - 1]
        else:
            neighbours = y[(i + 1) % n] + y[(i - 1) % n]
        out[n + i] += -2.0 * xi * v - c * y[i] + eta * neighbours


@njit(cache=True)
def _scaled_error(y0, y1, err, rtol, atol):
    """diffrax's RMS norm of err / (atol + rtol max(|y0|, |y1|)); inf if not finite."""
    s = 0.0
    for i in range(y0.shape[0]):
        e = err[i]
        if math.isnan(e):
            return math.inf
        r = e / (atol + rtol * max(abs(y0[i]), abs(y1[i])))
        s += r * r
    return math.sqrt(s / y0.shape[0])


@njit(cache=True)
def _control(tprev, tnext, t1, floor, error):
    """One decision of diffrax's PIDController (I-control) and of its clipping to
    the span's end: (keep, next tprev, next tnext)."""
    keep = error < 1.0
    inv = 1.0 / error if error > 0 else math.inf
    factor = _SAFETY * inv ** (1.0 / 3.0)
    lo = 1.0 if keep else _FACTORMIN
    hi = _FACTORMAX if keep else _SAFETY
    factor = min(max(factor, lo), hi)
    dt = (tnext - tprev) * factor
    t0n = tnext if keep else tprev
    t1n = t0n + dt
    t0n = min(t0n, t1)
    if t1n > floor:
        t1n = t1 if keep else t0n + 0.5 * (t1 - t0n)
    return keep, t0n, t1n


@njit(cache=True)
def _observe(y, x_max, x_min):
    n = x_max.shape[0]
    for i in range(n):
        x_max[i] = max(x_max[i], y[i])
        x_min[i] = min(x_min[i], y[i])


@njit(cache=True)
def _finish_step(y, y1, err, rtol, atol, tprev, tnext, t1, floor, transient, x_max, x_min):
    """The end of every step, whatever the method: the scaled error, the
    controller's decision, and on acceptance y <- y1 and the extrema (if the step
    started after the transient). Returns (keep, next tprev, next tnext)."""
    error = _scaled_error(y, y1, err, rtol, atol)
    keep, tprev_new, tnext_new = _control(tprev, tnext, t1, floor, error)
    if keep:
        y[:] = y1
        if tprev >= transient:
            _observe(y, x_max, x_min)
    return keep, tprev_new, tnext_new


@njit(cache=True)
def integrate_ros34pw2(y0, p, starts, ends, transient, rtol, atol, max_steps):
    """ROS34PW2 over jaxchain's chunks. Returns (y_end, num_steps (accepted plus
    rejected), accepted, x_max, x_min at accepted step ends in [transient, end],
    status: 0 ok, 1 max_steps reached in a chunk)."""
    m = y0.shape[0]
    n = m // 2
    y = y0.copy()
    f0 = np.empty(m)
    d0 = np.empty(m)
    _rhs(y, p, f0, d0, True)
    u = np.empty((4, m))
    ys = np.empty(m)
    fs = np.empty(m)
    y1 = np.empty(m)
    err = np.empty(m)
    f1 = np.empty(m)
    d1 = np.empty(m)
    scale = np.empty(m)
    x_max = np.full(n, -np.inf)
    x_min = np.full(n, np.inf)
    steps = 0
    accepted = 0
    for c in range(starts.shape[0]):
        t0, t1, floor = starts[c], ends[c, 0], ends[c, 1]
        tprev = t0
        tnext = min(t0 + 0.01, t1)  # diffrax's first step for a MultiTerm
        chunk_steps = 0
        while tprev < t1:
            if chunk_steps >= max_steps:
                return y, steps, accepted, x_max, x_min, 1
            h = tnext - tprev
            for k in range(m):
                scale[k] = 1.0 / (h * _GAMMA) - min(d0[k], 0.0)
            for i in range(4):
                if i == 0:
                    for k in range(m):
                        u[0, k] = f0[k] / scale[k]
                    continue
                for k in range(m):
                    acc = y[k]
                    for j in range(i):
                        acc += _A[i, j] * u[j, k]
                    ys[k] = acc
                _rhs(ys, p, fs, d1, False)
                for k in range(m):
                    acc = fs[k]
                    for j in range(i):
                        acc += _C[i, j] / h * u[j, k]
                    u[i, k] = acc / scale[k]
            for k in range(m):
                a = y[k]
                e = 0.0
                for i in range(4):
                    a += _M[i] * u[i, k]
                    e += _M_ERROR[i] * u[i, k]
                y1[k] = a
                err[k] = e
            _rhs(y1, p, f1, d1, True)
            keep, tprev, tnext = _finish_step(y, y1, err, rtol, atol, tprev, tnext, t1,
                                              floor, transient, x_max, x_min)
            steps += 1
            chunk_steps += 1
            if keep:
                accepted += 1
                f0[:] = f1
                d0[:] = d1
    return y, steps, accepted, x_max, x_min, 0


@njit(cache=True)
def _initial_step_bosh3(y0, f0, p, rtol, atol, work, f1):
    """diffrax's `_select_initial_step` (Hairer, Norsett & Wanner), error order 3."""
    m = y0.shape[0]
    d0 = 0.0
    d1 = 0.0
    for k in range(m):
        s = atol + abs(y0[k]) * rtol
        d0 += (y0[k] / s) ** 2
        d1 += (f0[k] / s) ** 2
    d0 = math.sqrt(d0 / m)
    d1 = math.sqrt(d1 / m)
    if d0 < 1e-5 or d1 < 1e-5:
        h0 = 1e-6
    else:
        h0 = 0.01 * (d0 / d1)
    for k in range(m):
        work[k] = y0[k] + h0 * f0[k]
    _rhs(work, p, f1, work, False)
    d2 = 0.0
    for k in range(m):
        s = atol + abs(y0[k]) * rtol
        d2 += ((f1[k] - f0[k]) / s) ** 2
    d2 = math.sqrt(d2 / m) / h0
    max_d = max(d1, d2)
    if max_d <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max_d) ** (1.0 / 3.0)
    return min(100 * h0, h1)


@njit(cache=True)
def integrate_bosh3(y0, p, starts, ends, transient, rtol, atol, max_steps):
    """Bosh3 (FSAL) over jaxchain's chunks; returns as `integrate_ros34pw2`."""
    m = y0.shape[0]
    n = m // 2
    y = y0.copy()
    dummy = np.empty(m)
    k0 = np.empty(m)
    _rhs(y, p, k0, dummy, False)
    k1 = np.empty(m)
    k2 = np.empty(m)
    k3 = np.empty(m)
    ys = np.empty(m)
    y1 = np.empty(m)
    err = np.empty(m)
    work = np.empty(m)
    x_max = np.full(n, -np.inf)
    x_min = np.full(n, np.inf)
    steps = 0
    accepted = 0
    for c in range(starts.shape[0]):
        t0, t1, floor = starts[c], ends[c, 0], ends[c, 1]
        tprev = t0
        tnext = min(t0 + _initial_step_bosh3(y, k0, p, rtol, atol, work, k1), t1)
        chunk_steps = 0
        while tprev < t1:
            if chunk_steps >= max_steps:
                return y, steps, accepted, x_max, x_min, 1
            h = tnext - tprev
            for k in range(m):
                ys[k] = y[k] + h * (_B3_A10 * k0[k])
            _rhs(ys, p, k1, dummy, False)
            for k in range(m):
                ys[k] = y[k] + h * (_B3_A21 * k1[k])
            _rhs(ys, p, k2, dummy, False)
            for k in range(m):
                y1[k] = y[k] + h * (_B3_B[0] * k0[k] + _B3_B[1] * k1[k] + _B3_B[2] * k2[k])
            _rhs(y1, p, k3, dummy, False)
            for k in range(m):
                err[k] = h * (_B3_ERR[0] * k0[k] + _B3_ERR[1] * k1[k] + _B3_ERR[2] * k2[k]
                              + _B3_ERR[3] * k3[k])
            keep, tprev, tnext = _finish_step(y, y1, err, rtol, atol, tprev, tnext, t1,
                                              floor, transient, x_max, x_min)
            steps += 1
            chunk_steps += 1
            if keep:
                accepted += 1
                k0[:] = k3
    return y, steps, accepted, x_max, x_min, 0


INTEGRATORS = {"ros34pw2": integrate_ros34pw2, "bosh3": integrate_bosh3}


def integrate(name: str, y0: np.ndarray, params, options, eps: float = DEFAULT_EPS) -> dict:
    """Run the numba loop `name` ("ros34pw2" or "bosh3") on the flat state y0 with
    `ChainParams`, `SimulationOptions` (horizon, tolerances, chunks, max_steps) and
    the smoothing `eps` (the smoothed engine's, `DEFAULT_EPS` as jaxchain's default)."""
    starts, ends, transient = chunk_bounds(options)
    y, steps, accepted, x_max, x_min, status = INTEGRATORS[name](
        np.ascontiguousarray(y0, dtype=float), params_vector(params, eps), starts, ends,
        float(transient), float(options.rtol), float(options.atol), int(options.max_steps))
    amplitudes = 0.5 * (x_max - x_min)
    return dict(y=y, num_steps=int(steps), accepted=int(accepted), status=int(status),
                energy=float(0.5 * np.sum(amplitudes**2)))
