"""The forced mistuned ring: how much random stiffness mistuning magnifies the
largest forced response of a ring under an engine-order force, over draws and
mistuning strengths, with and without friction dampers (the belt at rest); by
harmonic balance vmapped over the draws, with the derivative of the mean
magnification in the friction coefficient.

The amplitude magnification factor of a draw is its largest first-harmonic
amplitude over the ring and the forcing frequency divided by the tuned ring's
(Whitehead, J. Mech. Eng. Sci. 8 (1966) 15-21): on a linear ring it cannot exceed
(1 + sqrt(N)) / 2 (Whitehead, ASME J. Eng. Gas Turbines Power 120 (1998) 115-119),
and as a function of the mistuning strength it peaks where the mistuning is of the
order of the coupling (Castanier and Pierre, J. Propul. Power 22 (2006) 384-396)."""

import dataclasses
import time
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._bifurcation.harmonic_balance import HarmonicBalance
from .._engine.compat import checks_as_nan
from .._errors import ValidationError
from .._physics.mistuning import Mistuning
from .._physics.params import ChainParams, stack_chains, with_fields
from .._physics.record import chain_record


def whitehead_bound(n_osc: int) -> float:
    """(1 + sqrt(N)) / 2: the largest amplitude magnification that stiffness
    mistuning can give a linear ring of N oscillators under an engine-order force
    (Whitehead 1998, this module's docstring)."""
    return (1 + np.sqrt(n_osc)) / 2


@dataclasses.dataclass(frozen=True)
class Peaks:
    """The largest first-harmonic amplitude of each lane of a batch of chains over
    a frequency range, arrays over the lanes: `amplitude` and `frequency` at the
    peak, `oscillator` (0-based) that reaches it, `unknowns` there (harmonic
    balance's) and `converged` (every orbit of the lane's sweep and refinement)."""

    amplitude: np.ndarray
    frequency: np.ndarray
    oscillator: np.ndarray
    unknowns: np.ndarray
    converged: np.ndarray


def first_harmonic(method: HarmonicBalance, u) -> jax.Array:
    """The first-harmonic amplitude sqrt(a_1n^2 + b_1n^2) of each oscillator of the
    harmonic-balance unknowns u, shape (n_osc,)."""
    coefficients, _ = method._split(u)
    return jnp.hypot(coefficients[1], coefficients[method.harmonics + 1])


def response_peaks(chains: ChainParams, method: HarmonicBalance, frequencies, *,
                   refinements: int = 12, candidates: int = 3) -> Peaks:
    """The peak of each lane's forced response: harmonic balance at each frequency of
    `frequencies` in turn (each orbit started from the one before, from rest at the
    first), vmapped over the lanes; then, at each of the `candidates` largest local
    maxima of the grid's largest amplitude, the peak of the oscillator that reaches
    it: the root of its amplitude's slope in the frequency (central differences of
    orbits) between the grid points beside it, by `refinements` steps of the
    Illinois variant of regula falsi (Dowell and Jarratt, BIT 11 (1971) 168-174);
    the largest of the peaks found. A resonance narrower than the grid's spacing
    can hide between two points: space the grid by half the damping ratio or less.

    **Arguments:**

    - `chains`: forced chains stacked into lanes (`stack_chains`), each lane's
        forcing of shape (lanes, ...).
    - `method`: the harmonic balance.
    - `frequencies`: the forcing frequencies, increasing, at least 3.

    **Returns:** a `Peaks` over the lanes.

    **Raises:** `ValidationError` for fewer than 3 or non-increasing frequencies.
    """
    frequencies = np.asarray(frequencies, dtype=float)
    if frequencies.ndim != 1 or frequencies.size < 3 or np.any(np.diff(frequencies) <= 0):
        raise ValidationError("frequencies must be at least 3 increasing forcing frequencies")
    lanes = np.shape(chains.forcing.frequency)[0]
    size = chains.n_osc * (2 * method.harmonics + 1) + 1
    u0 = jnp.zeros((lanes, size)).at[:, -1].set(2 * np.pi / frequencies[0])
    us, amplitudes, ok = _sweep(method, chains, jnp.asarray(frequencies), u0)
    found = [[np.asarray(a) for a in _refine(method, chains, jnp.asarray(frequencies), us,
                                             amplitudes, ok, refinements, rank)]
             for rank in range(min(candidates, frequencies.size))]
    best = np.argmax(np.stack([f[0] for f in found]), axis=0)
    lanes = np.arange(best.size)
    return Peaks(*(np.stack([f[i] for f in found])[best, lanes] for i in range(5)))


def _at_frequency(chains: ChainParams, omega) -> ChainParams:
    return eqx.tree_at(lambda c: c.forcing.frequency, chains,
                       jnp.broadcast_to(omega, jnp.shape(chains.forcing.frequency)))


def _solve_at(method, chains, omega, u):
    """Harmonic balance at the frequencies omega (one per lane) from u."""
    u = u.at[:, -1].set(2 * jnp.pi / omega)
    return jax.vmap(method.solve)(_at_frequency(chains, omega), u)


@checks_as_nan
@eqx.filter_jit
def _sweep(method, chains, frequencies, u0):
    def step(u, omega):
        new, ok = _solve_at(method, chains, omega, u)
        kept = jnp.where(ok[:, None], new, u)
        return kept, (new, jax.vmap(lambda v: first_harmonic(method, v))(new), ok)

    _, (us, amplitudes, ok) = jax.lax.scan(step, u0, frequencies)
    return us, amplitudes, ok  # (F, lanes, n), (F, lanes, n_osc), (F, lanes)


@checks_as_nan
@eqx.filter_jit
def _refine(method, chains, frequencies, us, amplitudes, ok, refinements, rank):
    lanes = jnp.arange(us.shape[1])
    size = frequencies.shape[0]
    top = jnp.max(amplitudes, axis=2)  # (F, lanes)
    # the grid's local maxima, largest first: the rank-th of them
    padded = jnp.pad(top, ((1, 1), (0, 0)), constant_values=-jnp.inf)
    local = (top >= padded[:-2]) & (top >= padded[2:])
    score = jnp.where(local, top, -jnp.inf)
    grid_best = jnp.argsort(-score, axis=0)[rank]
    candidate = jnp.isfinite(score[grid_best, lanes])
    best = jnp.clip(grid_best, 1, size - 2)
    osc = jnp.argmax(amplitudes[grid_best, lanes], axis=1)
    u = us[best, lanes]

    def slope(omega, u):
        """(amplitude, its derivative in the frequency by central differences of
        orbits at omega (1 +- 1e-6), unknowns, converged)."""
        found = []
        for shift in (-1e-6, 0.0, 1e-6):
            new, converged = _solve_at(method, chains, omega * (1 + shift), u)
            amp = jax.vmap(lambda v, n: first_harmonic(method, v)[n])(new, osc)
            found.append((amp, new, converged))
        (low, _, ok_low), (amp, new, ok), (high, _, ok_high) = found
        return amp, (high - low) / (2e-6 * omega), new, ok & ok_low & ok_high

    # the peak: the root of the amplitude's slope between the grid points beside the
    # grid's largest, by the Illinois variant of regula falsi (Dowell and Jarratt,
    # BIT 11 (1971) 168-174): superlinear, and it keeps the bracket
    a, b = frequencies[best - 1], frequencies[best + 1]
    _, ga, _, ok_a = slope(a, u)
    amp_b, gb, u_b, ok_b = slope(b, u)
    converged = jnp.all(ok, axis=0) & ok_a & ok_b

    def step(carry, _):
        a, ga, b, gb, amp, u, converged = carry
        c = jnp.where(gb != ga, b - gb * (b - a) / jnp.where(gb != ga, gb - ga, 1.0),
                      0.5 * (a + b))
        c = jnp.clip(c, jnp.minimum(a, b), jnp.maximum(a, b))
        amp_c, gc, u_c, ok_c = slope(c, u)
        same = jnp.sign(gc) == jnp.sign(gb)
        # c replaces b; where it lands on b's side, a stays and its slope is halved
        a, ga = jnp.where(same, a, b), jnp.where(same, 0.5 * ga, gb)
        return (a, ga, c, gc, amp_c, jnp.where(ok_c[:, None], u_c, u),
                converged & ok_c), None

    carry = (a, ga, b, gb, amp_b, u_b, converged)
    (_, _, b, _, amp, u, converged), _ = jax.lax.scan(step, carry, None, length=refinements)
    # a grid peak at an end of the range has no stationary point beside it
    at_end = (grid_best == 0) | (grid_best == size - 1)
    return jnp.where(candidate, amp, -jnp.inf), b, osc, u, converged & ~at_end


def mistuned_lanes(params: ChainParams, sigma: float, draws: int) -> ChainParams:
    """The tuned chain `params` (lane 0) and its `draws` stiffness mistunings of
    strength sigma (lanes 1..draws: draw d with seed d, `Mistuning`, so that every
    sigma takes the same normal numbers), stacked (`stack_chains`)."""
    normal = [Mistuning(sigma=1.0, seed=d).deviations(params.n_osc) for d in range(draws)]
    return stack_chains([params] + [with_fields(params, stiffness=params.stiffness + sigma * z)
                                    for z in normal])


def _checked(params: ChainParams, sigmas, draws: int, frequencies):
    if params.forcing is None:
        raise ValidationError("the magnification study needs a forced chain: give "
                              "ChainParams(forcing=jaxchain.Forcing.engine_order(...))")
    if not (np.ndim(params.stiffness) == 0 and np.ndim(params.forcing.frequency) == 0):
        raise ValidationError("the magnification study needs a tuned chain (one stiffness, "
                              "one forcing): it draws the mistuning itself")
    if any(not (np.isfinite(s) and s >= 0) for s in sigmas) or not len(sigmas):
        raise ValidationError(f"sigmas must be finite and >= 0, got {list(sigmas)!r}")
    if not (isinstance(draws, (int, np.integer)) and draws >= 1):
        raise ValidationError(f"draws must be an integer >= 1, got {draws!r}")


def magnification_study(params: ChainParams, sigmas, draws: int, frequencies,
                        method: HarmonicBalance, *, friction_coefficients=None,
                        lanes: int = 256, progress: bool = False, store=None):
    """The amplitude magnification factor of stiffness mistuning over draws and
    strengths (this module's docstring): for each friction coefficient and each
    sigma, the tuned ring and `draws` mistuned ones (`mistuned_lanes`), each one's
    response peak over `frequencies` (`response_peaks`), and each draw's peak over
    the tuned ring's.

    **Arguments:**

    - `params`: the tuned forced chain (one stiffness; `Forcing.engine_order` for a
        bladed disk), its belt at rest (v_d = 0) for friction dampers.
    - `sigmas`: the mistuning strengths (standard deviations of delta_n, >= 0).
    - `draws`: mistuned rings per strength (>= 1).
    - `frequencies`: the forcing frequencies swept (increasing, >= 3), wide enough to
        hold every draw's resonances, fine enough to separate them (a spacing of
        about the damping ratio).
    - `method`: the harmonic balance (H = 1 gives a linear chain exactly).
    - `friction_coefficients`: values of the friction law's `mu` (Coulomb's law),
        each a study of its own (0: the linear ring); the chain's own if None.
    - `lanes`: chains solved together (`jax.vmap`); `progress`: a progress bar.
    - `store`: a folder where each (mu, sigma) is written as it finishes
        (`write_dataset`) and from which a part is read back where every setting
        that produced it matches (`read_dataset`): a killed study resumes.

    **Returns:** an `xarray.Dataset` over `mu`, `sigma`, `draw`: `magnification`,
    `peak_frequency`, `peak_oscillator` (1..N), `converged`; over `mu`:
    `tuned_amplitude`, `tuned_frequency`; attributes: `whitehead_bound`, the chain
    (`chain_record`), the method's settings, the frequency grid and the wall time.
    Dimensionless (eqs. (4)-(6)).

    **Raises:** `ValidationError` for an unforced or mistuned chain, a negative sigma,
    a bad count or frequency grid, or a friction law without `mu`.
    """
    import xarray as xr
    from tqdm.auto import tqdm

    from .._physics.params import with_parameter
    from .response import method_settings

    _checked(params, sigmas, draws, frequencies)
    mus = (np.atleast_1d(np.asarray(params.friction.mu, dtype=float))
           if friction_coefficients is None else np.asarray(friction_coefficients, dtype=float))
    began = time.perf_counter()
    shape = (len(mus), len(sigmas), draws)
    out = {k: np.zeros(shape) for k in ("magnification", "peak_frequency")}
    out["peak_oscillator"] = np.zeros(shape, dtype=int)
    out["converged"] = np.zeros(shape, dtype=bool)
    tuned = np.zeros((len(mus), 2))
    bar = tqdm(total=len(mus) * len(sigmas) * draws, disable=not progress, unit="draw")
    for i, mu in enumerate(mus):
        chain = with_parameter(params, "mu", float(mu))
        for j, sigma in enumerate(sigmas):
            part = _part(chain, float(sigma), draws, frequencies, method, lanes, bar, store)
            tuned[i] = part.attrs["tuned_amplitude"], part.attrs["tuned_frequency"]
            for k in out:
                out[k][i, j] = part[k].values
    bar.close()
    bar.close()
    dims = ("mu", "sigma", "draw")
    attrs = chain_record(params) | method_settings(method) | {
        "whitehead_bound": whitehead_bound(params.n_osc),
        "frequencies": [float(f) for f in frequencies],
        "amplitude": "first harmonic", "wall_time_s": time.perf_counter() - began,
        "units": "dimensionless, eqs. (4)-(6) of the paper"}
    return xr.Dataset(
        {k: (dims, v) for k, v in out.items()}
        | {"tuned_amplitude": ("mu", tuned[:, 0]), "tuned_frequency": ("mu", tuned[:, 1])},
        coords={"mu": mus, "sigma": np.asarray(sigmas, dtype=float),
                "sigma_over_eta_c": ("sigma", np.asarray(sigmas) / float(params.eta_c)),
                "draw": np.arange(draws)},
        attrs=attrs)


def _part(chain: ChainParams, sigma: float, draws: int, frequencies, method, lanes: int,
          bar, store):
    """One (mu, sigma) of `magnification_study` as a Dataset over `draw`, read back
    from `store` where it holds the same settings' part, computed and written
    there otherwise."""
    import xarray as xr

    from .._sweeps.result_store import read_dataset, write_dataset
    from .response import method_settings

    settings = {"chain": chain_record(chain), "method": method_settings(method),
                "sigma": sigma, "draws": draws,
                "frequencies": [float(f) for f in frequencies]}
    path = None
    if store is not None:
        mu = float(chain.friction.mu)
        path = Path(store) / f"mu{mu:.6g}_sigma{sigma:.6g}.nc"
        stored = read_dataset(path, "magnification", **settings)
        if stored is not None:
            bar.update(draws)
            return stored
    peaks = _peaks_in_lanes(mistuned_lanes(chain, sigma, draws), method, frequencies,
                            lanes, bar)
    part = xr.Dataset(
        {"magnification": ("draw", peaks.amplitude[1:] / peaks.amplitude[0]),
         "peak_frequency": ("draw", peaks.frequency[1:]),
         "peak_oscillator": ("draw", peaks.oscillator[1:] + 1),
         "converged": ("draw", peaks.converged[1:] & peaks.converged[0])},
        attrs={"tuned_amplitude": float(peaks.amplitude[0]),
               "tuned_frequency": float(peaks.frequency[0])})
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_dataset(part, path, "magnification", **settings)
    return part


def in_groups(chains: ChainParams, total: int, lanes: int, compute, bar) -> dict:
    """`compute(group)`, a dict of arrays over a group's lanes, for the `total` lanes
    of `chains` (lane 0 the tuned chain, `mistuned_lanes`) in groups of equal size of
    at most `lanes` (the last padded with copies of its first, so that every group
    runs one program), concatenated; `bar` advanced by each group's draws."""
    parts = []
    for index, padded in lane_groups(total, lanes):
        out = compute(jax.tree_util.tree_map(lambda a: a[padded], chains))
        parts.append({k: np.asarray(v)[:index.size] for k, v in out.items()})
        bar.update(index.size - (index[0] == 0))
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def lane_groups(total: int, lanes: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """The groups of `in_groups`: (the lanes' indices, the same padded with copies of
    the first to the group size) for each group, the groups of equal size of at
    most `lanes`."""
    lanes = -(-total // -(-total // lanes))  # groups of equal size, none larger than asked
    groups = []
    for start in range(0, total, lanes):
        index = np.arange(start, min(start + lanes, total))
        groups.append((index, np.concatenate([index, np.full(lanes - index.size, index[0])])))
    return groups


def _peaks_in_lanes(chains: ChainParams, method, frequencies, lanes: int, bar) -> Peaks:
    """`response_peaks` of the lanes of `chains` in groups (`in_groups`)."""
    total = np.shape(chains.forcing.frequency)[0]
    return Peaks(**in_groups(chains, total, lanes, lambda group: dataclasses.asdict(
        response_peaks(group, method, frequencies)), bar))


def magnification_gradient(params: ChainParams, sigma: float, draws: int, frequencies,
                           method: HarmonicBalance, *, relative_step: float = 1e-4,
                           lanes: int = 256) -> dict:
    """The derivative of the mean amplitude magnification over `draws` draws at
    strength `sigma` in the friction coefficient `mu` of the chain's law, by
    `jax.grad` and by central differences.

    `jax.grad`: at each lane's peak the amplitude is stationary in the frequency
    (envelope theorem), so the peak's derivative in mu is the amplitude's at the
    peak's frequency held, through harmonic balance's implicit function theorem.
    Central differences: the whole study (sweep and refinement) again at mu (1 +-
    `relative_step`).

    **Returns:** a dict: `mean_magnification`, `gradient` (reverse mode), `forward`
    (the same by `jax.jvp`), `finite_difference`,
    `step`, `relative_error`.

    **Raises:** as `magnification_study`.
    """
    from .._physics.params import with_parameter

    _checked(params, [sigma], draws, frequencies)
    mu = float(params.friction.mu)
    chains = mistuned_lanes(params, float(sigma), draws)

    class _Quiet:
        def update(self, n):
            pass

    peaks = _peaks_in_lanes(chains, method, frequencies, lanes, _Quiet())

    def mean_magnification(value):
        moved = eqx.tree_at(lambda c: c.friction.mu, chains,
                            jnp.broadcast_to(value, np.shape(chains.friction.mu)))
        u, _ = _solve_at(method, moved, jnp.asarray(peaks.frequency), jnp.asarray(peaks.unknowns))
        amp = jax.vmap(lambda v, n: first_harmonic(method, v)[n])(u, jnp.asarray(peaks.oscillator))
        return jnp.mean(amp[1:]) / amp[0]

    gradient = float(checks_as_nan(eqx.filter_jit(jax.grad(mean_magnification)))(
        jnp.asarray(mu)))
    forward = float(checks_as_nan(eqx.filter_jit(lambda m: jax.jvp(
        mean_magnification, (m,), (jnp.ones_like(m),))[1]))(jnp.asarray(mu)))
    step = relative_step * mu
    values = []
    for value in (mu + step, mu - step):
        moved = with_parameter(params, "mu", value)
        p = _peaks_in_lanes(mistuned_lanes(moved, float(sigma), draws), method, frequencies,
                            lanes, _Quiet())
        values.append(np.mean(p.amplitude[1:]) / p.amplitude[0])
    fd = (values[0] - values[1]) / (2 * step)
    return {"mean_magnification": float(np.mean(peaks.amplitude[1:]) / peaks.amplitude[0]),
            "gradient": gradient, "forward": forward, "finite_difference": fd, "step": step,
            "relative_error": abs(gradient - fd) / abs(fd)}
