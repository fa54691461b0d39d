"""`localized_branches`: every start's branch, the branches that deflation and
branch switching find, stored as they are found and read back on resuming, and
checked."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from ..._bifurcation.continuation import ContinuationOptions
from ..._bifurcation.shooting import pack
from ..._engine.options import SimulationOptions
from ..._errors import ValidationError
from ..._physics.params import ChainParams, chain_or_default
from ..._physics.record import chain_record
from ..._bifurcation.branches import SLIDING_PASSES, FollowedBranch, follow_branch
from .branch import BRANCH_METHOD, SNAKE_CONTINUATION, branch_dataset
from .checks import _stable_range_checks
from .deflated import _deflated_orbits, _on_followed_branch, _stored_orbits
from .orbits import snake_orbits
from ..pool import Followers
from .starts import (
    RECURRENCES,
    RETRY_VD,
    SNAKE_START,
    SYMMETRIC_CHUNK,
    _start_label,
    _start_orbits,
    check_starts,
    start_mask,
)
from .store import BranchStore, deflation_known, repeats_attribute
from .summary import _branches_summary


def localized_branches(params: ChainParams | None = None, sites=None, *,
                       method=None, engine=None,
                       continuation_options: ContinuationOptions = SNAKE_CONTINUATION,
                       start_options: SimulationOptions = SNAKE_START, switch: bool = True,
                       deflate: int = 0, simulation_check: bool = True,
                       out: Path | None = None, progress: bool = False, workers: int = 1
                       ) -> dict:
    """The snake: each localized periodic state that simulation finds at
    `params.v_d` (eq. (8) with k excited, for k in `sites`), refined by shooting,
    continued over v_d both ways by pseudo-arclength through its folds, with its
    Floquet multipliers, bifurcations (`locate_bifurcations`), stable ranges, the
    branches it meets and, optionally, direct simulation just inside and outside each
    end of each stable range.

    **Arguments:**

    - `params`: the chain (any chain of `ChainParams`); `params.v_d` is where the
        states are found (1.5 by default, inside the paper's bistable range).
    - `sites`: the starts: numbers of excited oscillators (eq. (8)'s block or a
        graph's patch) or named one-site starts (`start_site`); `default_starts`
        by default (the corner, edge and interior one-site states on a lattice).
    - `method`: the orbit method of every orbit, branch and multiplier:
        `Shooting(Smoothed(eps=...).for_orbits())` (eq. (5) with tanh(v_rel/eps))
        or `Shooting(Exact().for_orbits())` (the stick/slip switch model: exact
        Floquet multipliers); `Shooting.from_simulations(Smoothed())` by default.
        Stored branches are read back only for an equal method.
    - `engine`: the engine of every simulation (starts and checks), of the
        method's model, its horizon replaced by each simulation's; the method's
        engine `simulating` (default solver and tolerances) by default.
    - `continuation_options`: `ContinuationOptions` (direction is set both ways).
    - `start_options`: the horizon of the starting simulations.
    - `switch`: at each branch point of a branch, switch onto the other branch
        through it and follow that too (`switch_branch`: the kernel direction that
        the followed branch does not take; where that fails, as at the branch
        points of a symmetric ring, every orbit that `switch_by_deflation` finds
        beside it; labelled "k=<k> switched <j>").
    - `deflate`: at `params.v_d`, up to this many further periodic orbits from the
        eq. (8) state of each start by deflation (`distinct_orbits`), every orbit
        found so far deflated; each is followed as a branch of its own, labelled
        "k=<k> deflated <j>", unless it lies on a branch already followed (a branch
        with folds crosses v_d more than once): that one is reported in
        `deflated_on_followed` (0: none).
    - `simulation_check`: check every stable range by direct simulation.
    - `out`: a folder: each branch is stored there as `branch_k<k>.nc` (or
        `branch_<name>.nc`) with the key
        of its settings (`write_dataset`) as it finishes, and read back on a later
        call with equal settings (resume); the starts not stored are computed, and
        with `deflate` their deflation deflates the stored starts' orbits too, as
        the whole run would.
    - `progress`: progress bars.
    - `workers`: the number of processes that follow the starts' branches side by
        side (1: one after another, in this process). The branches are the same
        either way (each is the same computation), and so is what is stored;
        with more, a deflated orbit's branch may be followed and then dropped,
        where it lies on a branch followed before it.

    **Returns:**

    A dict with `summary` (JSON-ready: `branches`, a list of objects with `label`,
    `excited`, `sites`, `stable_ranges`, `bifurcations`, `connects_to`, ...;
    `not_periodic`, the starts without a periodic orbit and why;
    `deflated_on_followed`, the deflated orbits found on a branch already followed,
    each with its `start`, `energy`, `n_halc` and the branch it lies `on`; and
    `sites_connections`, for n = 0 ... N - 1 whether the orbits with n and n + 1
    sites on the HALC connect, stable ones included, `_sites_connections`) and
    `datasets` (label -> the branch's `xarray.Dataset`).

    **Raises:**

    `ValidationError` for bad sites or options, or a method or engine of another
    kind.
    """
    params, sites, orbits = _check_branches(params, sites, method, engine, deflate, workers)
    found = _find_branches(orbits, params, sites, continuation_options, start_options, switch,
                           deflate, out, progress, workers)
    checks = _stable_range_checks(orbits, params, found.datasets, simulation_check, progress)
    return _branches_summary(found.datasets, found.starts, found.failed, found.repeated,
                             checks, params.n_osc)


@dataclasses.dataclass(frozen=True)
class NoBranch:
    """A start whose branch could not be followed, and why."""

    reason: str


@dataclasses.dataclass(frozen=True)
class FoundBranches:
    """What the snake found, in the order of its starts.

    **Fields:** `datasets` (label -> the stored form of a branch,
    `branch_dataset`); `starts` (start -> its simulation's n_HALC and energy);
    `failed` (start -> `NoBranch`: why it has no periodic orbit or no branch); `repeated` (the
    deflated orbits that lie on a branch already followed, from starts without a
    branch of their own; those of the others are their branch's attribute
    `deflated_repeats`)."""

    datasets: dict = dataclasses.field(default_factory=dict)
    starts: dict = dataclasses.field(default_factory=dict)
    failed: dict = dataclasses.field(default_factory=dict)
    repeated: list = dataclasses.field(default_factory=list)

    def __or__(self, other: FoundBranches) -> FoundBranches:
        """Both, `self`'s first."""
        return FoundBranches(self.datasets | other.datasets, self.starts | other.starts,
                             self.failed | other.failed, self.repeated + other.repeated)


def _check_branches(params: ChainParams | None, sites, method, engine, deflate, workers
                    ) -> tuple:
    """The chain (the paper's ring where None), the starts (`check_starts`) and the
    orbits (`snake_orbits`, which checks the method and engine), with `deflate` and
    `workers` checked."""
    if not (isinstance(deflate, int) and deflate >= 0):
        raise ValidationError(f"deflate must be a whole number >= 0, got {deflate!r}")
    if not (isinstance(workers, int) and workers >= 1):
        raise ValidationError(f"workers must be a whole number >= 1, got {workers!r}")
    params = chain_or_default(params)
    orbits = snake_orbits(method, engine)
    return params, check_starts(params.graph, sites), orbits


def _find_branches(orbits, params: ChainParams, sites: tuple, continuation_options,
                   start_options, switch, deflate, out, progress, workers: int = 1
                   ) -> FoundBranches:
    """The branch of each start, with `deflate` the branches of the further orbits
    that deflation finds from its eq. (8) state (`_deflated_orbits`; one on a branch
    already followed is reported, `_on_followed_branch`, not followed again), and
    with `switch` the branches switched onto at their branch points: read back from
    `out` where stored with the same settings, else started by simulation and
    shooting (`start_orbits`), continued (`_follow_start`) and stored. A start
    without a branch of its own is stored as a record of why (`_read_branches`), so
    that a resumed run does not compute it again."""

    datasets, starts, failed, repeated, known = {}, {}, {}, [], []
    store = BranchStore(out, {
        "chain": chain_record(params), **orbits.settings(),
        "continuation": continuation_options, "start": start_options, "switch": bool(switch),
        "deflate": int(deflate), "sliding_passes": SLIDING_PASSES,
        "branch_method": BRANCH_METHOD, "retry_vd": list(RETRY_VD),
        "recurrences": RECURRENCES, "symmetric_chunk": SYMMETRIC_CHUNK})
    todo = []
    for k in sites:
        stored = store.read(k)
        if stored is None:
            todo.append(k)
            continue
        known += _stored_orbits(stored, float(params.v_d))
        if stored.no_branch is not None:  # a start without a branch of its own
            failed[k], starts[k] = NoBranch(stored.no_branch), stored.simulation
            repeated += stored.repeats
        datasets |= stored.branches
    before = FoundBranches(datasets, starts, failed, repeated)
    if not todo:
        return before
    lo, hi = continuation_options.p_min, continuation_options.p_max
    retry = tuple(d for d in RETRY_VD if lo < float(params.v_d) + d < hi)
    found = _start_orbits(orbits, params, todo, start_options, progress, retry)
    # a resumed run deflates the stored starts' orbits too, as the run it resumes did
    deflated = _deflated_orbits(orbits, params, found, deflate, stored=known
                                ) if deflate else {}
    with Followers(workers) as pool:
        # every branch asked for at once, each from its start (a deflated orbit's may
        # go unused, where it lies on a branch followed before it); with one worker
        # each is computed when the loop below asks for it, as the sequential run did
        follow = dict(orbits=orbits, continuation_options=continuation_options,
                      switch=switch, progress=progress and workers <= 1)
        jobs = {}
        for k, (orbit, sim, _) in found.items():
            mask = start_mask(params.graph, k)
            if orbit is not None:
                jobs[k] = pool.submit(_follow_start, orbit, sim["phase_oscillator"],
                                      mask, **follow)
            for i, (o, m, _) in enumerate(deflated.get(k, [])):
                if o is not None:
                    jobs[k, i] = pool.submit(_follow_start, o, m, mask, **follow)
        return before | _take_branches(orbits, params, found, deflated, jobs, store,
                                       before.datasets)


def _take_branches(orbits, params: ChainParams, found: dict, deflated: dict, jobs: dict,
                   store: BranchStore, before: dict) -> FoundBranches:
    """The branches of `jobs` (`_find_branches`), in the order of the starts: each
    start's own, then those of its deflated orbits not on a branch followed before
    (`_on_followed_branch`: among `before`, the branches read back, and those taken
    already), labelled and stored."""
    datasets, starts, failed, repeated = {}, {}, {}, []
    for k, (orbit, sim, reason) in found.items():
        starts[k] = sim
        own, mask = _start_label(k), start_mask(params.graph, k)
        # a start whose simulated state is not periodic keeps its reason, and the
        # orbits that deflation finds from its eq. (8) state are followed still
        if orbit is None:
            failed[k] = NoBranch(reason)
        mine = {} if orbit is None else _labelled(own, orbit, mask, jobs[k].result())
        if isinstance(mine, NoBranch):
            starts[k], failed[k], mine = sim, mine, {}
        followed, repeats, j = {}, [], 0
        for i, (o, m, _) in enumerate(deflated.get(k, [])):
            if o is None:  # shooting from deflation's solution did not converge
                continue
            on = _on_followed_branch(orbits, params, o, before | datasets | mine | followed)
            if on is not None:
                repeats.append({"start": own, "energy": float(o.energy),
                                "n_halc": int(o.n_halc), "on": on})
                continue
            j += 1
            label = f"{own} deflated {j}"
            branches = _labelled(label, o, mask, jobs[k, i].result())
            if isinstance(branches, NoBranch):
                starts[label], failed[label] = sim, branches
                continue
            store.write(k, branches, deflated=j)
            followed |= branches
        # every orbit this start gave deflation (`_deflated_orbits`), for a resumed run
        gave = ([] if orbit is None or float(orbit.params.v_d) != float(params.v_d)
                else [pack(orbit.y0, orbit.period)])
        gave += [u for _, _, u in deflated.get(k, [])]
        if own in mine:  # stored last: its attributes count the deflated branches
            mine[own] = mine[own].assign_attrs(deflated=j, **repeats_attribute(repeats),
                                               start_symmetric=int(bool(sim.get("symmetric"))),
                                               **deflation_known(gave))
            store.write(k, mine)
        else:
            repeated += repeats
            store.write_no_branch(k, failed[k].reason, sim, j, repeats, gave)
        datasets |= mine | followed
    return FoundBranches(datasets, starts, failed, repeated)


def _follow_start(start, phase_oscillator: int, mask, *, orbits, continuation_options,
                  switch, progress) -> FollowedBranch | NoBranch:
    """The branch through the periodic orbit `start` and the branches switched onto
    from it (`follow_branch`), or why its continuation failed. Run in a worker
    process where `workers` > 1."""
    try:
        followed = follow_branch(start, orbits.method.with_phase_oscillator(phase_oscillator),
                                 continuation_options, switch=switch, progress=progress)
    except (ValueError, RuntimeError) as err:  # flagged; the other branches go on
        return NoBranch(f"continuation failed: {err}")
    # what is stored, without the continuations' problems (from a worker, pickled)
    return dataclasses.replace(followed, pieces=(), switched=tuple(
        dataclasses.replace(sw, pieces=()) for sw in followed.switched))


def _labelled(label: str, start, mask, followed: FollowedBranch | NoBranch) -> dict | NoBranch:
    """The branches of `_follow_start` from `start` in their stored form
    (`branch_dataset`), labelled `label` and "<label> switched <j>" (label ->
    dataset), or why its continuation failed."""
    if isinstance(followed, NoBranch):
        return followed
    k = int(mask.sum())
    ds = branch_dataset(dataclasses.replace(followed, switched=()), k)
    switched = [branch_dataset(sw, k) for sw in followed.switched]
    first = ds.assign_attrs(start_vd=float(start.params.v_d), start_energy=float(start.energy),
                            start_n_halc=int(start.n_halc), switched=len(switched), deflated=0,
                            **repeats_attribute([]))
    branches = [first] + [sw.assign_attrs(start_vd=sw.attrs["switched_from_vd"],
                                          start_energy=float(sw["energy"].values[0]),
                                          start_n_halc=int(sw["n_halc"].values[0]))
                          for sw in switched]
    return {label if j == 0 else f"{label} switched {j}":
            b.assign_attrs(start=label, start_sites=np.flatnonzero(mask).tolist())
            for j, b in enumerate(branches)}
