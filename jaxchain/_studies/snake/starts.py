"""The snake's starts: the sites of each start on its graph, and the periodic
orbits that simulation from eq. (8) leads to, with the retries at neighbouring belt
speeds, the close recurrences and the starts inside the fixed subspace of their
symmetry."""

from __future__ import annotations


import jax.numpy as jnp
import numpy as np

from ..._bifurcation.symmetry import isotropy
from ..._engine.observers.crossings import downward_crossings
from ..._engine.options import SimulationOptions
from ..._engine.status import Status
from ..._errors import ValidationError
from ..._physics.chain import Graph
from ..._physics.initial import OutOfPhaseExcitation, centre_site, excited_block
from ..._physics.params import ChainParams, with_parameter
from ..._sweeps.ensemble import ensemble
from .orbits import snake_orbits


def default_sites(n_osc: int) -> tuple[int, ...]:
    """The branches of `localized_branches` by default: eq. (8) with 1, 2, 4, ...
    oscillators excited (the powers of two up to half the chain) and the whole
    chain; 1, 2, 4, 8 and 20 on the paper's ring (its Figs. 4 and 8)."""
    sites = [2**i for i in range(n_osc.bit_length()) if 2**i <= n_osc // 2]
    return tuple(sites + [n_osc])


#: The one-site starts of a lattice by the number of their neighbours: a corner (2),
#: the middle of the top edge (3) and the centre (4; `centre_site`).
LATTICE_STARTS = ("corner", "edge", "interior")


def default_starts(graph: Graph) -> tuple:
    """The starts of `localized_branches` by default: `default_sites` on a line or
    any links, the one-site states of `LATTICE_STARTS` on a lattice."""
    return LATTICE_STARTS if graph.kind == "lattice" else default_sites(graph.n_osc)


def start_site(graph: Graph, name: str) -> int:
    """The oscillator (0-based) of a named one-site start: "corner" (0), "edge" (row
    0, column cols//2), "interior" (`centre_site`) on a lattice, or "site:N" (any
    graph).

    **Raises:** `ValidationError` for another name, a lattice name on another graph,
    or an oscillator outside the chain."""
    if name.startswith("site:"):
        try:
            n = int(name[5:])
        except ValueError:
            n = -1
        if not 0 <= n < graph.n_osc:
            raise ValidationError(f"start {name!r}: the oscillator must be in "
                                  f"0..{graph.n_osc - 1}")
        return n
    if name not in LATTICE_STARTS or graph.kind != "lattice":
        raise ValidationError(f"start {name!r}: give a number of excited oscillators, "
                              f"site:N, or on a lattice one of {', '.join(LATTICE_STARTS)}")
    cols = graph.shape[1]
    return {"corner": 0, "edge": cols // 2, "interior": centre_site(graph)}[name]


def start_mask(graph: Graph, start) -> np.ndarray:
    """The oscillators a start excites: k of them in the block or patch of
    `excited_block` for a number k, one for a named start (`start_site`)."""
    if isinstance(start, str):
        mask = np.zeros(graph.n_osc, dtype=bool)
        mask[start_site(graph, start)] = True
        return mask
    return excited_block(graph.n_osc, int(start), graph)


def _start_label(start) -> str:
    return start if isinstance(start, str) else f"k={start}"


def check_starts(graph: Graph, starts) -> tuple:
    """The starts (`default_starts` if None), each a number in 1..n_osc or a name of
    `start_site`.

    **Raises:** `ValidationError` naming a bad start."""
    starts = default_starts(graph) if starts is None else tuple(
        s if isinstance(s, str) else int(s) for s in starts)
    if not starts:
        raise ValidationError("sites must name at least one start")
    for s in starts:
        if isinstance(s, str):
            start_site(graph, s)
        elif not 1 <= s <= graph.n_osc:
            raise ValidationError(f"sites must be in 1..n_osc = {graph.n_osc}, got {starts}")
    return starts


#: The starting simulations: a chain of 20 settles slowly (the paper removes
#: 10^4 time units of transient); after 2500 the four- and eight-site states of
#: eq. (8) at v_d = 1.5 are not yet periodic to the shooting tolerance.
SNAKE_START = SimulationOptions(t_end=12_000.0, transient=11_500.0)


#: Where the simulated state of a start is not periodic at the snake's v_d (a torus
#: born at a Neimark-Sacker point of the branch, or an irregular state), eq. (8) is
#: simulated again at these offsets from it, in turn: on the ring of 20 the nine-site
#: state is periodic at 1.6 and the ten-site state at 1.4, neither at 1.5.
RETRY_VD = (-0.1, 0.1)


#: Where shooting from the first turning point of a start's simulated state fails,
#: it is tried from this many more, those where the state comes back closest after
#: one turn first (`_recurrences`): the ring of 20's nineteen-site state of eq. (8)
#: at v_d = 1.6 lingers near an unstable orbit (multiplier 1.02) without settling.
RECURRENCES = 4


#: A start that gives no orbit with as many sites on the HALC as it excites, at v_d
#: or at the offsets `RETRY_VD`, and whose eq. (8) state a symmetry of the chain
#: fixes (`isotropy`), is simulated again inside that symmetry's fixed subspace
#: (`symmetric_state`), projected back onto it every this many time units: the ring
#: of 20's nineteen-site orbit at v_d = 1.6 is unstable only across it (multiplier
#: 1.0206 a period of 6.23: rounding grows by less than a factor 1.5 within one).
SYMMETRIC_CHUNK = 100.0


def _downward_crossings(orbits, params: ChainParams, y, horizon: float = 40.0
                        ) -> tuple[np.ndarray, np.ndarray, list]:
    """The flow of the engine of `orbits` (`snake_orbits`) from `y`, sampled every
    1e-3 over `horizon`: (times, states, and for each oscillator the sample indices
    where x_n' passes from + to -, the intervals of `downward_crossings`)."""
    ts = np.linspace(0.0, horizon, int(round(horizon * 1000)) + 1)
    ys = orbits.samples(params, y, ts)
    mask, _ = downward_crossings(ts, ys[:, 0], ys[:, 1], np.ones(ts.size, dtype=bool))
    mask = np.asarray(mask)
    return ts, ys, [np.flatnonzero(mask[:, n]) for n in range(mask.shape[1])]


def _turning_point(orbits, params: ChainParams, y: np.ndarray, oscillator: int
                   ) -> tuple[np.ndarray, float] | None:
    """A state where x_n' passes from + to - (n = `oscillator`), and the time to the
    next such crossing (`_downward_crossings` on the engine of `orbits`)."""
    guesses = _recurrences(orbits, params, y, oscillator)
    return guesses[0] if guesses else None


def _recurrences(orbits, params: ChainParams, y: np.ndarray, oscillator: int,
                 horizon: float = 40.0) -> list[tuple[np.ndarray, float]]:
    """The states where x_n' passes from + to - (n = `oscillator`) over `horizon`
    from `y`, each with the time to the next such crossing: the first, then the
    others by how closely the state returns there (max-norm), closest first. A
    close recurrence lies near a periodic orbit, unstable ones included, that
    the flow passes (Auerbach et al. 1987, Phys. Rev. Lett. 58, 2387)."""
    ts, ys, down = _downward_crossings(orbits, params, y, horizon)
    return _closest_returns(ts, ys, down[oscillator])


def _closest_returns(ts, ys, down) -> list[tuple[np.ndarray, float]]:
    """`_recurrences` from the samples (ts, ys) and the indices `down` of one
    oscillator's turning points (`_downward_crossings`)."""
    gaps = [float(np.max(np.abs(ys[b] - ys[a]))) for a, b in zip(down[1:-1], down[2:])]
    order = [0] + [1 + i for i in np.argsort(gaps, kind="stable")]
    return [(ys[down[i]], float(ts[down[i + 1]] - ts[down[i]])) for i in order
            if i + 1 < down.size]


def start_orbits(params: ChainParams, sites=None, *, options: SimulationOptions = SNAKE_START,
                 method=None, engine=None, retry: tuple = RETRY_VD, progress: bool = False):
    """Periodic localized states of the chain at `params.v_d`, refined by shooting
    from direct simulation: eq. (8) with k oscillators excited (`excited_block`),
    integrated over `options`, then a turning point of the oscillator of largest
    amplitude (the phase condition's oscillator) and the time to the next one as the
    guesses of `periodic_orbit` (where it fails, from the `RECURRENCES` states of
    closest return, `_recurrences`). Where that state is not periodic (or steady
    sliding, or the simulation fails), or where its orbit has not as many sites on
    the HALC as the start excites, eq. (8) is simulated again at `params.v_d` + each
    offset of `retry` in turn, and the first periodic orbit that keeps the start's
    number of sites (else the first periodic one, else the orbit at `params.v_d`)
    is kept at its own v_d. A start that still has no orbit with its own number of
    sites, and whose eq. (8) state a symmetry of the chain fixes (`isotropy`), is
    simulated inside the fixed subspace of those symmetries (`symmetric_state`) at
    `params.v_d`, then at each offset, and shot from there: the first orbit with
    its own number of sites replaces the one it had.

    **Arguments:**

    - `params`: the chain; `params.v_d` is the belt speed of the start.
    - `sites`: the starts: numbers of excited oscillators, each in 1..n_osc, or
        named one-site starts (`start_site`: "corner", "edge", "interior" on a
        lattice, "site:N"); `default_starts` by default.
    - `options`: `SimulationOptions` of the simulations.
    - `method`: the orbit method (`Shooting`), its phase oscillator replaced;
        `Shooting.from_simulations(Smoothed())` by default (`snake_orbits`).
    - `engine`: the engine of the simulations, of the method's model (its horizon
        replaced by `options`'); the method's engine `simulating` by default.
    - `retry`: offsets of v_d, dimensionless, tried in turn for the starts that
        give no periodic orbit at `params.v_d`, or one with another number of
        sites on the HALC than they excite (`RETRY_VD`; () for none).
    - `progress`: progress bars.

    **Returns:**

    A dict k -> (`PeriodicOrbit` or None; the simulation's n_HALC,
    energy and `v_d`; why it failed or None). The orbit lies at `orbit.params.v_d`.
    A start fails when at every belt speed tried the simulated state is not
    periodic (irregular: shooting does not converge) or never turns.

    **Raises:**

    `ValidationError` for a k outside 1..n_osc, or a method or engine of another
    kind.
    """
    orbits = snake_orbits(method, engine)
    return _start_orbits(orbits, params, sites, options, progress, tuple(retry))


def _start_orbits(orbits, params: ChainParams, sites, options: SimulationOptions,
                  progress: bool, retry: tuple = RETRY_VD) -> dict:
    """`start_orbits` on the engine of `orbits` (`snake_orbits`): at `params.v_d`,
    then for each start that gives no periodic orbit there, or one that has lost
    the pattern it excites (another number of sites on the HALC: the ring of 20's
    nineteen-site start ends on the whole ring at 1.5), at the belt speeds
    `params.v_d` + `retry` in turn (`_shoot_starts`). The first orbit found with
    as many sites on the HALC as the start excites is kept, else the first orbit
    found; at its own v_d (`orbit.params`), its simulation record with `v_d`. A
    start that fails at every one keeps the reason of `params.v_d`. A start with no
    orbit of its own number of sites by then is tried inside the fixed subspace of
    its symmetries at the same speeds (`_symmetric_start`)."""
    sites = check_starts(params.graph, sites)
    v0 = float(params.v_d)
    vds = [v0 + d for d in retry]
    out = _shoot_starts(orbits, params, sites, [v0], options, progress)[v0]
    for k, (_, sim, _) in out.items():
        sim["v_d"] = v0

    def keeps(k, orbit) -> bool:
        return orbit is not None and int(orbit.n_halc) == int(start_mask(params.graph, k).sum())

    again_k = [k for k in sites if not keeps(k, out[k][0])]
    if again_k and retry:
        again = _shoot_starts(orbits, params, again_k, vds, options, progress)
        for k in again_k:
            tried = [again[v][k] + (v,) for v in vds]
            found = [(o, sim | {"v_d": v}, None) for o, sim, _, v in tried if o is not None]
            # an orbit that keeps the pattern; else, for a start with none, any orbit
            choice = [f for f in found if keeps(k, f[0])] or (
                found if out[k][0] is None else [])
            if choice:
                out[k] = choice[0]
            elif out[k][0] is None:
                out[k] = out[k][:2] + (out[k][2] + "; at v_d " + ", ".join(
                    f"{v:g}: {why}" for _, _, why, v in tried),)
    for k in [k for k in sites if not keeps(k, out[k][0])]:
        out[k] = _symmetric_start(orbits, params, k, [v0, *vds], options.t_end, out[k])
    return out


def _symmetric_start(orbits, params: ChainParams, k, vds: list, t_end: float, had: tuple
                     ) -> tuple:
    """The start k, which gave no orbit with its own number of sites, simulated
    inside the fixed subspace of its eq. (8) state's symmetries (`isotropy`,
    `_symmetric_orbit`) at each belt speed of `vds` in turn: the first orbit with
    the start's number of sites, with its record (`symmetric` True); else `had`
    (the reason of a start with no orbit extended)."""
    mask, whys = start_mask(params.graph, k), []

    def eq8(v):
        at = with_parameter(params, "v_d", v)
        return at, np.asarray(OutOfPhaseExcitation.eq8(mask)(at)).reshape(2, -1)

    perms = isotropy(*eq8(vds[0]))  # the same at every belt speed
    if len(perms) == 1:  # no symmetry: nothing to try
        return had
    for v in vds:
        at, start = eq8(v)
        orbit, why, m = _symmetric_orbit(orbits, at, start, perms, t_end)
        if orbit is not None and int(orbit.n_halc) == int(mask.sum()):
            return orbit, {"n_halc": int(orbit.n_halc), "energy": float(orbit.energy),
                           "phase_oscillator": m, "v_d": v, "symmetric": True}, None
        whys.append(f"{v:g}: " + (why or f"{int(orbit.n_halc)} sites on the HALC"))
    if had[0] is not None:
        return had
    return had[:2] + (had[2] + "; inside the fixed subspace of its symmetry, at v_d "
                      + ", ".join(whys),)


def _shoot_starts(orbits, params: ChainParams, sites: tuple, vds: list,
                  options: SimulationOptions, progress: bool) -> dict:
    """The starts `sites` simulated at each belt speed of `vds` (one ensemble) and
    refined by shooting: v_d -> k -> (the orbit or None, the simulation's n_HALC,
    energy and phase oscillator, why it failed or None)."""
    masks = np.stack([start_mask(params.graph, k) for k in sites])
    ics = OutOfPhaseExcitation(excited=jnp.asarray(masks),
                               velocity=jnp.zeros(len(sites)), base_sign=-1.0)
    ds = ensemble(params, vds, ics, engine=orbits.simulation(options, params),
                  progress=progress)
    out = {}
    for j, v in enumerate(vds):
        at, out[v] = with_parameter(params, "v_d", v), {}
        for i, k in enumerate(sites):
            amplitudes = ds["amplitudes"].values[j, i]
            sim = {"n_halc": int(ds["n_halc"].values[j, i]),
                   "energy": float(ds["energy"].values[j, i])}
            if int(ds["status"].values[j, i]) != Status.ok:
                out[v][k] = (None, sim, "the simulation failed")
                continue
            n = int(np.argmax(amplitudes))
            sim["phase_oscillator"] = n  # of the orbit's phase condition
            orbit, reason = _shoot_guesses(
                orbits, at, _recurrences(orbits, at, ds["y_final"].values[j, i], n), n)
            out[v][k] = (orbit, sim, reason)
    return out


def _symmetric_orbit(orbits, params: ChainParams, start, perms, t_end: float):
    """The start simulated inside the fixed subspace of `perms` (`symmetric_state`)
    and refined by shooting from its recurrences, projected onto it, with the
    oscillator of largest amplitude as the phase oscillator: (orbit or None, why
    none or None, that oscillator)."""
    y = symmetric_state(orbits, params, start, perms, t_end)
    if not np.all(np.isfinite(y)):
        return None, "the simulation failed", 0
    ts, ys, down = _downward_crossings(orbits, params, y)
    m = int(np.argmax(np.ptp(ys[:, 0], axis=0)))
    return (*_shoot_guesses(orbits, params, _closest_returns(ts, ys, down[m]), m, perms), m)


def _shoot_guesses(orbits, params: ChainParams, guesses: list, n: int, perms=None):
    """Shooting (`orbits.shoot`, phase oscillator n) from the first 1 + `RECURRENCES`
    of `guesses` (`_recurrences`) in turn, each first projected onto the fixed
    subspace of `perms` where given (`symmetric_state`): (the first converged orbit,
    None), or (None, why none)."""
    if not guesses:
        return None, "no turning point: steady sliding"
    for y, period in guesses[:1 + RECURRENCES]:
        orbit = orbits.shoot(params, y if perms is None else _projected(y, perms), period, n)
        if bool(orbit.converged):
            return orbit, None
    return None, (f"shooting did not converge (residual {float(orbit.residual):.2g}): the "
                  f"simulated state is not periodic")


def _projected(y, perms) -> np.ndarray:
    """The orthogonal projection of y, shape (2, n_osc), onto the states fixed by
    every permutation of `perms` (a group): the mean of its copies y[:, p]."""
    y = np.asarray(y)
    return np.mean([y[:, p] for p in perms], axis=0)


def symmetric_state(orbits, params: ChainParams, y, perms, t_end: float,
                    chunk: float = SYMMETRIC_CHUNK) -> np.ndarray:
    """The flow of the engine of `orbits` (`snake_orbits`) from y, shape (2, n_osc),
    over `t_end` (dimensionless time, eqs. (4)-(6)), projected back onto the fixed
    subspace of the group `perms` (`isotropy`) every `chunk`: the chain's
    equations commute with its symmetries, so that subspace is invariant, and the
    projection only removes the rounding errors that an instability across it
    would grow. A periodic orbit unstable only across the subspace is an attractor
    inside it (Golubitsky, Stewart and Schaeffer 1988, *Singularities and Groups in
    Bifurcation Theory* II, Ch. XIII, the fixed-point subspaces). Shape (2, n_osc);
    nan where the flow fails."""
    y = _projected(y, perms)
    for _ in range(int(np.ceil(t_end / chunk))):
        y = _projected(orbits.samples(params, y, np.array([0.0, chunk]))[-1], perms)
    return y
