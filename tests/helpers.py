"""Small shared systems and references for the tests."""

import sys
import time
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import jaxchain as jc

#: A short horizon that still reaches the stick-slip cycle of one oscillator.
SHORT = jc.SimulationOptions(t_end=600.0, transient=300.0, chunk_length=100.0)


def reference_rhs(params: jc.ChainParams):
    """Eq. (5) written out oscillator by oscillator with NumPy, independently of
    `jc.vector_field`, for scipy and for comparison."""
    n = params.n_osc

    def rhs(t, y):
        x, v = y[:n], y[n:]
        a = np.empty(n)
        for i in range(n):
            left, right = x[(i - 1) % n], x[(i + 1) % n]
            v_rel = v[i] - params.v_d
            mu = eq1_mu(params)(abs(v_rel))
            force = -mu * np.tanh(v_rel / params.eps)
            a[i] = (-2 * params.xi * v[i] - x[i]
                    - params.eta_c * (2 * x[i] - left - right) + force)
        return np.concatenate([v, a])

    return rhs


def drift_bound(options: jc.SimulationOptions, num_steps, scale) -> float:
    """How far two differently compiled integrations of the same run (vmap and queue,
    two batch sizes, two solvers, two CPUs) may lie apart, in the state or in
    anything read off it at fixed times (extrema at the sample times, y_final).

    The step-size controller holds each accepted step's local error below
    rtol |y| + atol. Rounding that differs between two programs moves the
    accepted steps, so each result may move by up to the local errors it
    accumulated: on a non-expanding flow (the damped chains and stable cycles of
    these tests) at most their sum, num_steps (rtol scale + atol), where `scale`
    bounds |y| over the run. Two runs differ by at most twice that. A bound of
    the worst case: it grows with the horizon, through num_steps.

    **Arguments:**

    - `options`: the runs' `SimulationOptions` (rtol, atol).
    - `num_steps`: steps of the longer run (array-like, the largest is taken).
    - `scale`: a bound on |y| over the run.
    """
    return 2.0 * float(np.max(num_steps)) * (float(options.rtol) * float(np.max(scale))
                                             + float(options.atol))


def assert_within_drift(a, b, options: jc.SimulationOptions, num_steps, what: str = ""):
    """`a` and `b`, read off two differently compiled runs, agree within
    `drift_bound` (with |y| bounded by their largest entry, at least 1)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    bound = drift_bound(options, num_steps, max(1.0, np.abs(a).max(), np.abs(b).max()))
    assert np.all(np.isfinite(a)) and np.all(np.isfinite(b)), what
    assert np.max(np.abs(a - b)) <= bound, (what, np.max(np.abs(a - b)), bound)


def flat(y) -> jnp.ndarray:
    return jnp.reshape(jnp.asarray(y), (-1,))


def eq1_mu(p: jc.ChainParams):
    """Eq. (1) of the paper as a function of the slip speed s = |v_rel| >= 0."""
    law = p.friction
    return lambda s: law.mu_d + (law.mu_st - law.mu_d) * np.exp(-s / law.v0)


def stribeck_mu(mu_s, mu_c, v_s, delta, viscous):
    """The Stribeck curve mu_c + (mu_s - mu_c) exp(-(s/v_s)^delta) + viscous s of
    the slip speed s >= 0, written here independently of jaxchain."""
    return lambda s: mu_c + (mu_s - mu_c) * np.exp(-(s / v_s) ** delta) + viscous * s


def scipy_slip_arc(params: jc.ChainParams, t_max: float = 50.0, mu=None):
    """The single oscillator's slip arc from the stick exit point, x = mu(0) -
    2 xi v_d, x' = v_d, with scipy (DOP853, rtol 1e-12): x'' = -2 xi x' - x +
    mu(v_d - x') while x' < v_d, ending when x' returns to v_d. Turning points
    (x' = 0) are recorded as events. `mu` is the friction law as a function of the
    slip speed (eq. (1) with `params`' coefficients if None)."""
    p = params
    mu = eq1_mu(p) if mu is None else mu

    def slip(t, y):
        return [y[1], -2 * p.xi * y[1] - y[0] + mu(p.v_d - y[1])]

    def back_to_belt(t, y):
        return y[1] - p.v_d
    back_to_belt.terminal, back_to_belt.direction = True, 1

    def turning(t, y):
        return y[1]

    return solve_ivp(slip, (0.0, t_max), [mu(0.0) - 2 * p.xi * p.v_d, p.v_d],
                     method="DOP853", rtol=1e-12, atol=1e-12,
                     events=[back_to_belt, turning])


def scipy_stick_slip_cycle(params: jc.ChainParams, mu=None) -> tuple[float, float]:
    """(amplitude, period) of the single oscillator's non-smooth stick-slip cycle,
    independently of jaxchain: the scipy slip arc, then stick at x' = v_d from the
    return point back to the exit point. The extrema lie at the arc's turning
    points. `mu` as for `scipy_slip_arc`."""
    arc = scipy_slip_arc(params, mu=mu)
    assert arc.status == 1  # it returned to the belt speed: the cycle exists
    x_turn = arc.y_events[1][:, 0]
    x_exit, x_return = arc.y[0, 0], arc.y[0, -1]
    amplitude = 0.5 * (max(x_turn.max(), x_exit) - min(x_turn.min(), x_return))
    period = arc.t[-1] + (x_exit - x_return) / params.v_d
    return amplitude, period


def assert_usage_error(argv: list[str], says: str, capsys) -> None:
    """`jaxchain ARGV` exits with status 2 and one line on stderr naming `says`."""
    from jaxchain._cli.main import main
    with pytest.raises(SystemExit) as exc:
        sys.exit(main(argv))
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and says in err


#: The small sweep of the store tests (test_sweep, test_dask): eq. (8) with k = 1..3
#: on a ring of 3, in batches of 2. The horizon makes a batch last about a second,
#: so that a run can be killed between two batches.
SWEEP_N_OSC, SWEEP_BATCH, SWEEP_T_END, SWEEP_TRANSIENT = 3, 2, 10000.0, 9000.0
#: What a sweep computes; the bookkeeping (batch flags, counts, store) is left out.
SWEEP_RESULTS = ["amplitudes", "energy", "n_halc", "n_halc_halves", "min_slip_speed",
                 "x_max", "x_min", "v_max", "y_initial", "y_final", "num_steps", "status",
                 "front"]


def sweep_cli(vd: str) -> list[str]:
    """`jaxchain sweep` arguments of the small sweep at the belt speeds `vd`."""
    return ["sweep", "--n-osc", str(SWEEP_N_OSC), "--vd", vd, "--ics", "eq8", "--t-end",
            str(SWEEP_T_END), "--transient", str(SWEEP_TRANSIENT), "--batch-size",
            str(SWEEP_BATCH), "--no-progress"]


def small_sweep(vd: str, **kw):
    """The small sweep at the belt speeds `vd` (as `--vd` reads them) through
    `jc.sweep`."""
    from jaxchain._cli.sweep import belt_speeds

    return jc.sweep(jc.ChainParams(n_osc=SWEEP_N_OSC), belt_speeds(vd),
                    {"eq8": jc.localized_family(SWEEP_N_OSC)},
                    options=jc.SimulationOptions(t_end=SWEEP_T_END,
                                                 transient=SWEEP_TRANSIENT),
                    batch_size=SWEEP_BATCH, progress=False, **kw)


def wait_for_a_batch(store, deadline_s: float = 300) -> int:
    """Block until the sweep store at `store` has at least one flagged batch (a
    written chunk of `batch_done`: the layout alone writes none), and return their
    count. Reads the folder, not the store, so that it sees a flag within
    milliseconds. zarr writes a chunk to a temporary `N.<uuid>.partial` file and
    renames it to `N`: only the renamed chunks count."""
    deadline = time.monotonic() + deadline_s
    while time.monotonic() < deadline:
        flags = [f for f in (Path(store) / "batch_done" / "c").glob("*")
                 if f.name.isdigit()]
        if flags:
            return len(flags)
        time.sleep(0.005)
    raise AssertionError("no batch was stored in time")
