"""Further periodic orbits of the snake by deflation (Farrell, Birkisson and
Funke 2015), from each start's eq. (8) state, and whether one lies on a branch
already followed."""

from __future__ import annotations


import jax.numpy as jnp
import numpy as np

from ..._bifurcation.branches import passes_through
from ..._bifurcation.deflation import distinct_orbits
from ..._bifurcation.shooting import pack, unpack
from ..._physics.initial import OutOfPhaseExcitation
from ..._physics.params import ChainParams
from ..._bifurcation.branch_file import stored_branch
from .starts import _turning_point, start_mask
from .store import StoredStart


def _on_followed_branch(orbits, params: ChainParams, orbit, branches: dict) -> str | None:
    """The label of a branch in `branches` that passes through the periodic orbit
    `orbit` at `params.v_d` (`passes_through`), or None."""
    return next((label for label, ds in branches.items()
                 if passes_through(orbits.method.with_phase_oscillator(
                     int(ds.attrs["phase_oscillator"])), params, orbit,
                     stored_branch(ds)) is not None), None)


def _stored_orbits(stored: StoredStart, v_d: float) -> list:
    """The orbits at `v_d` that one start gave deflation in the run that stored its
    branches (`BranchStore.read`), as the method's unknowns (x, x', T): its own
    orbit and every solution deflation found from it, as deflation had them
    (`StoredStart.known`). Files written before those were kept give the first
    point of the start's own and deflated branches instead (not a switched branch,
    nor one started at a neighbouring v_d)."""
    if stored.known is not None:
        return [jnp.asarray(u) for u in stored.known]
    out = []
    for label, ds in stored.branches.items():
        if " switched " in label or float(ds.attrs["start_vd"]) != v_d:
            continue
        i = int(np.argmin(np.abs(ds["v_d"].values - v_d)))
        if float(ds["v_d"].values[i]) == v_d:
            out.append(jnp.asarray(ds["u"].values[i]))
    return out


def _deflated_orbits(orbits, params: ChainParams, found: dict, count: int,
                     stored: list = ()) -> dict:
    """Further periodic orbits at `params.v_d` by deflation (`distinct_orbits`, Farrell,
    Birkisson and Funke 2015): from the eq. (8) state of each start k (T = 2 pi),
    those whose simulated state is not periodic included, with every orbit found so
    far deflated (the starts' own, those of earlier k, their symmetric copies,
    steady sliding), up to `count` each; each refined by
    shooting with the phase condition on its oscillator of largest amplitude.
    `stored`: the orbits of the starts that a resumed run read back
    (`_stored_orbits`), deflated too, so that resuming finds what the whole run
    would. Returns k -> [(orbit, its phase oscillator, the deflation's solution u),
    ...], the orbit None where shooting from u does not converge."""
    # the starts' orbits at params.v_d; one found at a neighbouring v_d
    # (`RETRY_VD`) is not a solution here, and its start is treated as not periodic
    here = {k: (o if o is not None and float(o.params.v_d) == float(params.v_d) else None,
                sim, why) for k, (o, sim, why) in found.items()}
    known = [pack(o.y0, o.period) for o, _, _ in here.values() if o is not None]
    known += list(stored)
    # the shooting problem of a start whose state is not periodic: another start's,
    # with the phase condition on its own oscillator (only the residual is used)
    template = next((o for o, _, _ in here.values() if o is not None), None)
    # slots for every orbit that can be found: one compiled solve for all starts
    capacity = len(known) + count * len(here)
    out = {}
    for k, (orbit, sim, _) in here.items():
        n = (sim or {}).get("phase_oscillator")
        if template is None or n is None:
            continue
        problem = orbits.problem(template if orbit is None else orbit, n)
        y0 = jnp.asarray(OutOfPhaseExcitation.eq8(start_mask(params.graph, k))(params))
        start = pack(y0.at[1, n].set(0.0), 2 * np.pi)
        new = distinct_orbits(problem, start, known, count=count, capacity=capacity)
        known += new
        out[k] = []
        for u in new:
            y, period = unpack(u)
            shot = orbits.shoot(params, y, period, n)
            m = int(np.argmax(np.asarray(shot.amplitudes)))
            if m != n:  # the phase condition on the oscillator that vibrates most
                guess = _turning_point(orbits, params, np.asarray(y), m)
                shot = None if guess is None else orbits.shoot(params, guess[0], guess[1], m)
            out[k].append((shot if shot is not None and bool(shot.converged) else None,
                           m, u))
    return out
