"""Small shared systems and references for the tests."""

import contextlib
import inspect
import os
import signal
import sys
import time
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import jaxchain as jc
from jaxchain._sweeps.atomic import HOLD  # the writers' test hook (see `hold_env`)

#: The grids of `jc.bistable_range` (its defaults): xi, and mu_st / mu_d, of Fig. 3(a).
BISTABLE_XI_VALUES = inspect.signature(jc.bistable_range).parameters["xi_values"].default
BISTABLE_RATIO_VALUES = inspect.signature(jc.bistable_range).parameters["ratio_values"].default

#: A short horizon that still reaches the stick-slip cycle of one oscillator.
SHORT = jc.SimulationOptions(t_end=600.0, transient=300.0, chunk_length=100.0)


def reference_rhs(params: jc.ChainParams, eps: float = 1e-3):
    """Eq. (5) written out oscillator by oscillator with NumPy, independently of
    `jc.vector_field`, for scipy and for comparison, smoothed at `eps` (the
    smoothed engine's default, 1e-3, unless given), with the ground springs of
    `params.stiffness` (1 + delta_n)."""
    n = params.n_osc
    k = np.broadcast_to(np.asarray(params.stiffness, dtype=float), (n,))

    def rhs(t, y):
        x, v = y[:n], y[n:]
        a = np.empty(n)
        for i in range(n):
            left, right = x[(i - 1) % n], x[(i + 1) % n]
            v_rel = v[i] - params.v_d
            mu = eq1_mu(params)(abs(v_rel))
            force = -mu * np.tanh(v_rel / eps)
            a[i] = (-2 * params.xi * v[i] - k[i] * x[i]
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


def assert_within_drift(a, b, options: jc.SimulationOptions, num_steps, what: str = ""
                        ) -> float:
    """`a` and `b`, read off two differently compiled runs, agree within
    `drift_bound` (with |y| bounded by their largest entry, at least 1), and
    return that bound.

    Fails, as a defect of the test, where the comparison is vacuous: where the
    bound exceeds 1 % of the largest magnitude compared, an order-one error would
    pass. Tighten the tolerances or shorten the run until it does not (`TIGHT`)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    assert np.all(np.isfinite(a)) and np.all(np.isfinite(b)), what
    magnitude = max(np.abs(a).max(), np.abs(b).max())
    bound = drift_bound(options, num_steps, max(1.0, magnitude))
    assert bound <= 0.01 * magnitude, (
        f"{what}: a vacuous comparison: the drift bound {bound:.3g} exceeds 1 % of the "
        f"compared magnitude {magnitude:.3g}; tighten rtol and atol or shorten the run")
    assert np.max(np.abs(a - b)) <= bound, (what, np.max(np.abs(a - b)), bound)
    return bound


#: Options at which two compiled programs of the same stick-slip run can be compared
#: (`assert_within_drift`): 90k to 115k steps over [0, 150] on rings of 2 to 6, a
#: drift bound of 2e-4 to 5e-4, below 0.03 % of the amplitudes and states compared
#: (0.8 to 2.2). A run costs about half a second of integration on top of its
#: compilation, which is that of any other options.
TIGHT = jc.SimulationOptions(t_end=150.0, transient=100.0, chunk_length=50.0, rtol=1e-9,
                             atol=1e-11)


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


#: The simulations of the starts on the rings of two and three (`snake_start`):
#: their states settle within 1500 time units.
SETTLED = jc.SimulationOptions(t_end=2000.0, transient=1500.0)

#: The ring of two of the branch-switching tests: at v_d 1.5 its symmetric two-site
#: state (both oscillators on the HALC, equal amplitudes), which meets a
#: symmetry-breaking branch point above it (`branch_point`, tests/conftest.py).
RING_OF_TWO = jc.ChainParams(n_osc=2, v_d=1.5)
#: Shooting on the ring of two, the phase condition on its first oscillator.
SHOOTING_OF_TWO = jc.Shooting(root_finder="levenberg-marquardt", phase_oscillator=0)

#: The ring of three of the deflation tests: at v_d 1.5 simulation from eq. (8)
#: with one and with two excited ends on two different stable states
#: (`ring_of_three_states`, tests/conftest.py).
RING_OF_THREE = jc.ChainParams(n_osc=3, v_d=1.5)
#: Shooting on the ring of three, the phase condition on its middle oscillator (eq.
#: (8)'s excited one, the oscillator of largest amplitude of both states).
SHOOTING_OF_THREE = jc.Shooting(root_finder="levenberg-marquardt", phase_oscillator=1)
#: The symmetries of the (homogeneous) ring of three, written out: every permutation
#: of its oscillators, the rotations and the reflections (the dihedral group D_3).
RING_OF_THREE_SYMMETRIES = [(0, 1, 2), (1, 2, 0), (2, 0, 1), (0, 2, 1), (2, 1, 0), (1, 0, 2)]


def snake_start(params: jc.ChainParams, k: int, method=None,
                options: jc.SimulationOptions = SETTLED):
    """The periodic orbit that the snake starts its branch k from, through public
    names: eq. (8) with k excited simulated over `options` at `params.v_d`, shot from
    a turning point of its oscillator of largest amplitude (`jc.localized_branches`
    with `method`, no switching and no check by simulation, its branch only two
    points either way and its window v_d -+ 0.05, inside which the snake tries no
    other belt speed), then that orbit (the branch's point at its `start_vd`) shot
    again alone (`jc.periodic_orbit`, `method` or the snake's default
    `Shooting.from_simulations(Smoothed())`, with the branch's phase oscillator).

    Returns (the `PeriodicOrbit`, its phase oscillator); fails where the start
    gave no branch."""
    v_d = float(params.v_d)
    found = jc.localized_branches(
        params, (k,), method=method, start_options=options, switch=False,
        simulation_check=False, continuation_options=jc.ContinuationOptions(
            ds=0.02, max_points=2, p_min=v_d - 0.05, p_max=v_d + 0.05))
    assert f"k={k}" in found["datasets"], found["summary"]["not_periodic"]
    ds = found["datasets"][f"k={k}"]
    phase = int(ds.attrs["phase_oscillator"])
    (start,) = np.flatnonzero(ds["v_d"].values == ds.attrs["start_vd"])
    u = ds["u"].values[start]
    method = jc.Shooting.from_simulations(jc.Smoothed()) if method is None else method
    orbit = jc.periodic_orbit(params, (u[:-1].reshape(2, -1), float(u[-1])),
                              method.with_phase_oscillator(phase))
    return orbit, phase


def packed(y0, period) -> jnp.ndarray:
    """Shooting unknowns (x_1..x_N, x_1'..x_N', T)."""
    return jnp.concatenate([jnp.ravel(jnp.asarray(y0)), jnp.atleast_1d(period)])


def scipy_return(u, params: jc.ChainParams = RING_OF_THREE) -> float:
    """max |y(T) - y(0)| of the orbit u = (y0, T) integrated by scipy's DOP853 on eq.
    (5) written out independently (`reference_rhs`), on the ring of three by
    default."""
    y0, period = np.asarray(u[:-1]), float(u[-1])
    sol = solve_ivp(reference_rhs(params), (0.0, period), y0, method="DOP853", rtol=1e-11,
                    atol=1e-12)
    return float(np.max(np.abs(sol.y[:, -1] - y0)))


def copies_distance(a, b, samples: int = 4096) -> float:
    """The distance of orbit b from orbit a and its symmetric copies on the ring of
    three at v_d 1.5 (`RING_OF_THREE`), each orbit u = (y0, T) with y0 = (x, x'),
    written out independently of jaxchain: orbit a integrated over its period by
    scipy's DOP853 on eq. (5) (`reference_rhs`, rtol 1e-11); for each symmetry of
    `RING_OF_THREE_SYMMETRIES` (permuting the oscillators of every state of a), the
    distance d from b's state to the closest point of that copy (over `samples`
    equal steps of the period, then `minimize_scalar` within a step either side of
    the closest), combined with the periods' difference as
    sqrt(d^2 + (T_b - T_a)^2); the least over the symmetries."""
    from scipy.optimize import minimize_scalar

    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    period, y = float(a[-1]), b[:-1].reshape(2, 3)
    flow = solve_ivp(reference_rhs(RING_OF_THREE), (0.0, period), a[:-1], method="DOP853",
                     rtol=1e-11, atol=1e-12, dense_output=True).sol

    def state(t):  # a's state at t, one period repeating
        return flow(np.mod(t, period)).reshape(2, 3, *np.shape(t))

    ts, step = np.linspace(0.0, period, samples, endpoint=False), period / samples
    grid, best = state(ts), np.inf
    for perm in RING_OF_THREE_SYMMETRIES:
        perm = list(perm)
        d2 = np.sum((grid[:, perm] - y[:, :, None]) ** 2, axis=(0, 1))
        t = ts[int(np.argmin(d2))]
        near = minimize_scalar(lambda s, perm=perm: np.sum((state(s)[:, perm] - y) ** 2),
                               bounds=(t - step, t + step), method="bounded",
                               options={"xatol": 1e-12})
        best = min(best, float(np.min(d2)), float(near.fun))
    return float(np.sqrt(best + (float(b[-1]) - period) ** 2))


def start_residual(problem) -> float:
    """max |G| of a continuation problem at its start (u0 and its parameter)."""
    z = np.concatenate([np.asarray(problem.u0), [float(problem.value())]])
    return float(np.max(np.abs(np.asarray(problem(z)))))


def switched_on_ring_of_two(problem, branch, point, step):
    """`jc.switch_branch` at a branch point of the ring of two's branch (`branch_point`),
    `step` off it, and the branch switched onto continued from there: (its problem, its
    `Branch`; v_d in [1, 2], 8 points, steps up to 0.05)."""
    new, tangent = jc.switch_branch(problem, branch, point, step=step)
    return new, jc.continuation(new, options=jc.ContinuationOptions(
        ds=step, ds_max=0.05, p_min=1.0, p_max=2.0, max_points=8), tangent=tangent)


def assert_usage_error(argv: list[str], says: str, capsys) -> None:
    """`jaxchain ARGV` exits with status 2 and one line on stderr naming `says`."""
    with pytest.raises(SystemExit) as exc:
        sys.exit(jc.main(argv))
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and says in err


#: The small sweep of the store tests (test_sweep, test_dask): eq. (8) with k = 1..3
#: on a ring of 3, in batches of 2. A test kills a run at a batch of its choosing
#: through the writers' test hook (`hold_env`, `held`), so the batches can be short.
SWEEP_N_OSC, SWEEP_BATCH, SWEEP_T_END, SWEEP_TRANSIENT = 3, 2, 600.0, 300.0
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


def hold_env(folder) -> dict:
    """This process's environment with the writers' test hook on (`HOLD` of
    jaxchain._sweeps.atomic, see `hold` there): a process started with it holds before
    each write it commits (a file renamed into place, a sweep batch, the swap of
    an overwritten sweep store) until the test releases it (`release`) or kills
    it."""
    Path(folder).mkdir(parents=True, exist_ok=True)
    return os.environ | {HOLD: str(folder)}


def held(folder, n: int, proc=None, deadline_s: float = 300) -> tuple[str, int]:
    """Wait until a writer with the hook on (`hold_env(folder)`) holds at the n-th
    write held in `folder` (n = 1, 2, ...; the file `reached-<n>`), and return
    what it is writing (for example "sweep.zarr batch 1", "write basin.nc") and
    the id of the process holding. The writer stays held until `release`: a kill
    now lands exactly there. Fails at once if `proc` (a `subprocess.Popen`) ends
    first; `deadline_s` only bounds a hang."""
    reached = Path(folder) / f"reached-{n}"
    deadline = time.monotonic() + deadline_s
    while not reached.exists():
        if proc is not None and proc.poll() is not None:
            err = proc.stderr.read() if proc.stderr else ""
            raise AssertionError(f"the writer ended (status {proc.returncode}) before "
                                 f"hold {n}: {err}")
        if time.monotonic() > deadline:
            raise AssertionError(f"no writer reached hold {n} in {deadline_s} s")
        time.sleep(0.005)
    what, pid = reached.read_text().splitlines()
    return what, int(pid)


def release(folder, n: int | None = None) -> None:
    """Let the writer held at hold n go on (`held`), or, with n None, every writer
    holding in `folder`, now and later."""
    (Path(folder) / ("release" if n is None else f"release-{n}")).touch()


def kill(proc) -> None:
    """SIGKILL `proc` (a `subprocess.Popen`) and wait for it; a no-op if it has
    ended."""
    proc.send_signal(signal.SIGKILL)
    proc.wait()


# --- Internals that the tests reach into, in one place ------------------------------
# Each test of an internal (a sweep store's batch flags, a kill between two batch
# writes, a study that must read a stored result back instead of computing it)
# reaches jaxchain's private modules through these few lines only: a module that
# moves changes them, and no test.

#: The command line in a process of its own (`jaxchain.main`).
JAXCHAIN = [sys.executable, "-c", "import sys, jaxchain; sys.exit(jaxchain.main())"]


def batches_done(store) -> list[bool]:
    """The batch flags of a sweep store (a sweep's, or basin stability's)."""
    from jaxchain._sweeps.zarr_store import SweepStore

    return SweepStore(store).done().tolist()


@contextlib.contextmanager
def batch_writes(wrapper):
    """Within the block, each batch a sweep store writes goes through
    `wrapper(write, store, index, start, batch)`, `write` being the store's own: a
    test kills the run (raises) before or after a chosen batch."""
    from jaxchain._sweeps.zarr_store import SweepStore

    write = SweepStore.write
    SweepStore.write = lambda self, *args: wrapper(write, self, *args)
    try:
        yield
    finally:
        SweepStore.write = write


def dask_client(scheduler: str, **kwargs):
    """The Dask client of a command's --scheduler (a context manager)."""
    from jaxchain._engine.cluster import connect

    return connect(scheduler, **kwargs)


def scheduler_workers(scheduler: str) -> int | None:
    """The workers a --scheduler "local:N" asks for (None for an address)."""
    from jaxchain._engine.cluster import local_workers

    return local_workers(scheduler)


#: A record of the example rig (examples/records), for the command lines of identify.
EXAMPLE_RECORD = str(Path(__file__).resolve().parent.parent / "examples" / "records"
                     / "rig_vd0.4.csv")

#: Functions of jaxchain's internals that tests replace or call, by what they do:
#: (module, name). A resumed study must read back instead of computing again.
_COMPUTES = {"sweep batch": ("jaxchain._sweeps.sweep", "run_lanes"),
             # building blocks of public studies, tested on their own
             "snake start orbits": ("jaxchain._studies.snake.starts", "start_orbits"),
             "snake starts": ("jaxchain._studies.snake.run", "_start_orbits"),
             "snake starts at speeds": ("jaxchain._studies.snake.starts", "_shoot_starts"),
             "snake symmetric orbit": ("jaxchain._studies.snake.starts", "_symmetric_orbit"),
             "snake summary lines": ("jaxchain._cli.snake", "_print_summary"),
             "snake deflated orbits": ("jaxchain._studies.snake.run", "_deflated_orbits"),
             "snake deflation": ("jaxchain._studies.snake.deflated", "distinct_orbits"),
             "snake sites connections": ("jaxchain._studies.snake.summary", "_sites_connections"),
             "snake branch": ("jaxchain._studies.snake.run", "follow_branch"),
             "snake switched branch": ("jaxchain._bifurcation.branches", "_switched_branches"),
             "snake switch along axes": ("jaxchain._bifurcation.branches", "_switch_along_axes"),
             "snake orbits": ("jaxchain._studies.snake.orbits", "snake_orbits"),
             # jitted entry points, whose traces a test counts (test_compile_once.py)
             "simulation program": ("jaxchain._engine.simulate", "_run_jit"),
             "Jacobian program": ("jaxchain._physics.model", "_jacobian"),
             "Hopf modes": ("jaxchain._bifurcation.hopf", "_hopf_modes"),
             "shooting solve": ("jaxchain._bifurcation.shooting", "_root"),
             "continuation corrector": ("jaxchain._bifurcation.continuation", "_correct"),
             "continuation tangent": ("jaxchain._bifurcation.continuation", "_tangent"),
             "continuation records": ("jaxchain._bifurcation.continuation", "describe_point"),
             "shooting records": ("jaxchain._bifurcation.periodic_orbit", "describe_point"),
             "slip arc peak": ("jaxchain._bifurcation.existence", "_peak")}


def internal_module(what: str):
    """The module of the function that computes `what` (a key of `_COMPUTES`), for
    a test of its internals (its tables and helpers)."""
    import importlib

    return importlib.import_module(_COMPUTES[what][0])


def internal(what: str):
    """The function that computes `what` (a key of `_COMPUTES`)."""
    import importlib

    module, name = _COMPUTES[what]
    return getattr(importlib.import_module(module), name)


def internal_name(what: str) -> str:
    """The name, in its module, of the function that computes `what` (a key of
    `_COMPUTES`)."""
    return _COMPUTES[what][1]


def replace_internal(monkeypatch, what: str, replacement) -> None:
    """Replace the function that computes `what` (a key of `_COMPUTES`) for the
    rest of the test: with one that raises, to prove a result was read back."""
    import importlib

    module, name = _COMPUTES[what]
    monkeypatch.setattr(importlib.import_module(module), name, replacement)


def assert_cf_compliant(path) -> None:
    """The IOOS compliance checker's CF test (`compliance-checker --test cf`)
    reports no error on the netCDF file at `path`: its high-priority count is 0."""
    import json
    import tempfile

    from compliance_checker.runner import CheckSuite, ComplianceChecker

    CheckSuite.load_all_available_checkers()
    with tempfile.TemporaryDirectory() as folder:
        report = Path(folder) / "cf.json"
        ComplianceChecker.run_checker(str(path), ["cf"], 0, "normal",
                                      output_filename=str(report), output_format="json")
        (result,) = json.loads(report.read_text()).values()
    errors = [p["name"] + ": " + "; ".join(p["msgs"]) for p in result["high_priorities"]
              if p["value"][0] < p["value"][1]]
    assert result["high_count"] == 0 and not errors, errors
