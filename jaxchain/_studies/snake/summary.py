"""The snake's answer: where its branches meet, whether the orbits with n and
n + 1 sites on the HALC connect, and the summary of a run."""

from __future__ import annotations

import numpy as np

from ..._bifurcation.branch_file import (bifurcation_records, failed_switch_records,
                                          stored_branch)
from .store import deflated_repeats


def _connections(branches: dict, tol: float = 1e-3) -> dict:
    """Which branches meet: two branches connect when a point of one matches a point
    of the other at the same belt speed (within `tol`), with the same period (within
    `tol`, relative) and the same amplitudes sorted by size (within 10 `tol`): a
    signature that no rotation or reflection of the chain changes. A branch whose
    energy falls below 1e-4, or that ends at a Hopf point, ends on steady sliding."""
    out = {k: [] for k in branches}
    keys = list(branches)
    for a in keys:
        hopf = any(b.kind == "Hopf" for b in stored_branch(branches[a]).bifurcations)
        if hopf or float(branches[a]["energy"].min()) < 1e-4:
            out[a].append("steady sliding")
        for b in keys:
            if b == a:
                continue
            A, B = branches[a], branches[b]
            va, vb = A["v_d"].values, B["v_d"].values
            close = np.abs(va[:, None] - vb[None, :]) < tol
            period = np.abs(A["period"].values[:, None] / B["period"].values[None, :] - 1) < tol
            sa = np.sort(A["amplitudes"].values, axis=1)
            sb = np.sort(B["amplitudes"].values, axis=1)
            cand = np.argwhere(close & period)
            if any(np.max(np.abs(sa[i] - sb[j])) < 10 * tol for i, j in cand):
                out[a].append(b)
    return out


def _sites_connections(datasets: dict, links: dict, n_osc: int) -> list[dict]:
    """Whether the orbits with n and with n + 1 sites on the HALC connect, for n = 0
    ... n_osc - 1: the branches (labels of `datasets`, each with `n_halc` and
    `stable` at each point) are joined where they meet (`links`: label -> the
    labels it meets, `_connections` and the switched branches' parents) into
    connected sets, and n connects to n + 1 where one such set carries orbits with
    both numbers of sites (along one branch, through a sliding point, or across a
    point where two meet); `stable_connected` where one set carries stable orbits
    with both. One entry per n: sites [n, n + 1], the labels of the branches that
    carry each (`with_n`, `with_n_plus_1`), `connected`, `through` (each connected
    set that carries both, as sorted labels) and `stable_connected`."""
    parent = {label: label for label in datasets}

    def root(label):
        while parent[label] != label:
            label = parent[label]
        return label

    for a, met in links.items():
        for b in met:
            if a in parent and b in parent:
                parent[root(a)] = root(b)
    sets: dict = {}
    for label in datasets:
        sets.setdefault(root(label), []).append(label)
    on = {label: set(ds["n_halc"].values.astype(int).tolist())
          for label, ds in datasets.items()}
    stable = {label: set(ds["n_halc"].values[ds["stable"].values.astype(bool)].astype(int)
                         .tolist()) for label, ds in datasets.items()}
    out = []
    for n in range(n_osc):
        both = [sorted(ls) for ls in sets.values()
                if any(n in on[x] for x in ls) and any(n + 1 in on[x] for x in ls)]
        out.append({"sites": [n, n + 1],
                    "with_n": [x for x in datasets if n in on[x]],
                    "with_n_plus_1": [x for x in datasets if n + 1 in on[x]],
                    "connected": bool(both), "through": both,
                    "stable_connected": any(
                        any(n in stable[x] for x in ls) and any(n + 1 in stable[x] for x in ls)
                        for ls in sets.values())})
    return out


def _branches_summary(datasets: dict, starts: dict, failed: dict, repeated: list,
                      checks: dict, n_osc: int) -> dict:
    """The result of `localized_branches`: its JSON-ready summary, one entry per
    branch with what `_stable_range_checks` found, the deflated orbits that lie on
    branches already followed, and the datasets."""
    links = _connections(datasets)
    for label, ds in datasets.items():  # a switched branch meets its own at the branch point
        parent = ds.attrs["start"] if "switched" in label else None
        if parent in datasets:
            links[label].append(parent)
            links[parent].append(label)
    links = {label: list(dict.fromkeys(met)) for label, met in links.items()}
    branches = []
    for label, ds in datasets.items():
        ranges, followed = checks[label]["ranges"], stored_branch(ds)
        entry = {"label": label, "excited": int(ds.attrs["excited"]),
                 "start_sites": [int(i) for i in np.atleast_1d(ds.attrs.get(
                     "start_sites", []))],
                 "sites": (int(np.bincount(ds["n_halc"].values[ds["stable"].values]).argmax())
                           if ds["stable"].values.any() else None),
                 "stable_ranges": [r["v_d"] for r in ranges],
                 "stable_range_ends": [r["ends"] for r in ranges],
                 "bifurcations": bifurcation_records(followed),
                 "connects_to": links[label],
                 "v_d_computed": [float(ds["v_d"].min()), float(ds["v_d"].max())],
                 "points": int(ds.sizes["point"]),
                 "stop": followed.stops,
                 "start": {"v_d": ds.attrs["start_vd"], "energy": ds.attrs["start_energy"],
                           "n_halc": ds.attrs["start_n_halc"],
                           "symmetric": bool(ds.attrs.get("start_symmetric", 0))},
                 "switched_from_vd": ds.attrs.get("switched_from_vd"),
                 "failed_switches": failed_switch_records(followed),
                 "largest_trivial_multiplier_error": float(
                     ds["trivial_multiplier_error"].max())}
        entry |= {k: v for k, v in checks[label].items() if k != "ranges"}
        branches.append(entry)
    repeated = repeated + [r for ds in datasets.values() for r in deflated_repeats(ds)]
    summary = {"branches": branches,
               "not_periodic": [{"excited": k, "reason": r.reason, "simulation": starts[k]}
                                for k, r in failed.items()],
               "deflated_on_followed": repeated,
               "sites_connections": _sites_connections(datasets, links, n_osc)}
    return {"summary": summary, "datasets": datasets}
