"""The whole snake of the ring of eight on the exact model, as `jaxchain snake
--engine exact --n-osc 8 --sites all --deflate 1` computes it (about 5 min on two
cores): every start k = 1 ... 8 has a branch, every end of a stable range agrees
with direct simulation, the two-site branch point lies where shooting at fixed v_d
on either side puts the crossing of its multiplier, the branch switched there
breaks the two sites' symmetry and turns at a sliding point onto orbits without
the weaker site's stick phase, and a branch that deflation finds is an isola.

Marked `study` and `long`: the default run leaves it out (pyproject.toml, addopts),
so that the suite keeps within 10 minutes, and so does CI (.ci/run), to keep its
whole run within its time; `python -m pytest -m long` runs it here."""

import json

import numpy as np
import pytest
import xarray as xr

import jaxchain as jc

pytestmark = [pytest.mark.study, pytest.mark.long]

N = 8
#: Shooting on the exact stick/slip model (the snake's on the exact engine); its
#: engine's flow at the reference tolerances (Tsit5 at rtol = atol = 1e-12).
EXACT = jc.Shooting(jc.Exact().for_orbits())


@pytest.fixture(scope="module")
def ring8(tmp_path_factory):
    out = tmp_path_factory.mktemp("ring8")
    # two worker processes: the branches are the same (each is the same computation),
    # and the study run's other tests leave a core idle for much of this one
    argv = ["snake", "--engine", "exact", "--n-osc", str(N), "--sites", "all",
            "--deflate", "1", "--workers", "2", "--out", str(out), "--json", "--no-progress"]
    assert jc.main(argv) == 0
    doc = json.loads((out / "snake.json").read_text())
    return doc, {b["label"]: b for b in doc["branches"]}, out / "snake"


def test_every_start_has_a_branch(ring8):
    """Each k = 1 ... 8 gives at least one branch: from its simulated state where
    that is periodic, else by deflation from its eq. (8) state."""
    doc, branches, _ = ring8
    assert {b["excited"] for b in doc["branches"]} == set(range(1, N + 1))
    for start in doc["not_periodic"]:
        assert any(b["excited"] == start["excited"] and "deflated" in b["label"]
                   for b in doc["branches"])


def test_every_start_has_a_branch_of_its_own_number_of_sites(ring8):
    """Each start k = 1 ... 8 is followed from an orbit with k sites on the HALC:
    the five-site state of eq. (8) is periodic at 1.4 only (with the damped Newton
    method), and the seven-site one, which reaches the whole ring at 1.5, keeps
    its seven sites at 1.6 (a start that loses its pattern is tried there). Each
    start orbit, read from its stored branch, returns to itself after one period
    on the exact engine's own flow (`Exact.flow`, no Newton iteration), to
    1e-8, and exactly k oscillators stick on it (x_n' = v_d at a sample of that
    flow)."""
    _, branches, folder = ring8
    for k in range(1, N + 1):
        start = branches[f"k={k}"]["start"]
        assert start["n_halc"] == k
        ds = xr.load_dataset(folder / f"branch_k{k}.nc")
        u = ds["u"].values[np.argmin(np.abs(ds["v_d"].values - start["v_d"]))]
        params = jc.with_parameter(jc.ChainParams(n_osc=N), "v_d", start["v_d"])
        y0 = u[:-1].reshape(2, -1)
        ts = u[-1] * np.linspace(0.0, 1.0, 2001)[1:]
        ys = np.asarray(EXACT.engine.flow(params, y0, ts))
        assert np.all(np.isfinite(ys))  # the run's status: NaN where it failed
        assert np.max(np.abs(ys[-1] - y0)) < 1e-8, k
        assert int(np.sum(np.any(ys[:, 1] == start["v_d"], axis=0))) == k


def test_every_end_of_a_stable_range_agrees_with_direct_simulation(ring8):
    """At both ends of the stable ranges of the one-, two-, four- and eight-site
    starts, the exact engine's simulation keeps the state just inside and loses it
    just outside; no check anywhere disagrees (an undecided one, where the
    perturbation cannot grow enough within the horizon, is allowed)."""
    _, branches, _ = ring8
    for label in ("k=1", "k=2", "k=4", "k=8"):
        ends = [e["v_d"] for pair in branches[label]["stable_range_ends"] for e in pair
                if e["type"] != "end of branch"]
        agreeing = {(c["end_v_d"], c["side"]) for c in branches[label]["simulation_check"]
                    if c["agrees"]}
        assert ends and agreeing >= {(v, side) for v in ends for side in ("inside", "outside")}
    assert not any(c["agrees"] is False for b in branches.values()
                   for c in b["simulation_check"])


def _critical(v_d: float, u: np.ndarray, phase_oscillator: int) -> tuple[float, float]:
    """(|critical multiplier| - 1, amplitude split of sites 4 and 5) of the exact
    orbit at v_d by shooting from u (no continuation)."""
    params = jc.with_parameter(jc.ChainParams(n_osc=N), "v_d", v_d)
    orbit = jc.periodic_orbit(params, (u[:-1].reshape(2, -1), float(u[-1])),
                              EXACT.with_phase_oscillator(phase_oscillator))
    return float(abs(orbit.critical_multiplier)) - 1, float(
        abs(orbit.amplitudes[4] - orbit.amplitudes[5]))


def test_the_two_site_branch_point_is_where_shooting_at_fixed_v_d_crosses(ring8):
    """The branch point that ends the two-site state's stable range (located along
    the branch by regula falsi, where the corrector fails around it) against
    shooting at v_d = v_b - 0.003, v_b + 0.003 and v_b + 0.006 from the stored orbit
    nearest it, no continuation: the critical multiplier lies inside the unit
    circle below and outside above, the orbit keeps its two sites' symmetry, and
    the zero of the parabola through |mu| - 1 at the three is v_b within 5e-6 (a
    straight line through the first two would be off by |f''/2f'| 0.003^2, 3e-5;
    the bisection's old stop at the edge of the corrector's failures, 5e-4)."""
    _, branches, folder = ring8
    (point,) = [b for b in branches["k=2"]["bifurcations"] if b["type"] == "branch point"
                and b["v_d"] == branches["k=2"]["stable_ranges"][0][1]]
    v_b = point["v_d"]
    ds = xr.load_dataset(folder / "branch_k2.nc")
    u = ds["u"].values[point["after"]]  # the orbit before it along the branch
    offsets = np.array([-0.003, 0.003, 0.006])
    f, split = np.transpose([_critical(v_b + d, u, int(ds.attrs["phase_oscillator"]))
                             for d in offsets])
    assert f[0] < 0 < f[1] < f[2] and np.max(split) < 1e-8
    roots = np.roots(np.polyfit(offsets, f, 2))
    assert np.min(np.abs(roots)) < 5e-6


def _switched_at_the_stable_end(branches: dict, folder) -> xr.Dataset:
    """The branch switched onto from the two-site branch at the branch point that
    ends its stable range (its other branch points, on unstable parts of it, have
    branches of their own)."""
    v_b = branches["k=2"]["stable_ranges"][0][1]
    (label,) = [b["label"] for b in branches.values()
                if b["label"].startswith("k=2 switched") and b["switched_from_vd"] == v_b]
    return xr.load_dataset(folder / f"branch_k2_switched{label.rsplit(' ', 1)[1]}.nc")


def test_the_branch_switched_at_the_two_site_branch_point_breaks_the_symmetry(ring8):
    """The other branch through the two-site branch point: its two sites' amplitudes
    differ, by more the further it runs from the branch point (a pitchfork), while
    on the followed branch they are equal."""
    _, branches, folder = ring8
    followed = xr.load_dataset(folder / "branch_k2.nc")["amplitudes"].values
    assert np.max(np.abs(followed[:, 4] - followed[:, 5])) < 1e-8  # symmetric throughout
    switched = _switched_at_the_stable_end(branches, folder)
    a = switched["amplitudes"].values
    split = np.abs(a[:, 4] - a[:, 5])
    end = json.loads(switched.attrs["bifurcations"])[0]["after"]
    assert split[0] > 1e-5 and split[end] > 10 * split[0]


def _stick_count(u: np.ndarray, v_d: float) -> int:
    params = jc.with_parameter(jc.ChainParams(n_osc=N), "v_d", v_d)
    return int(np.isfinite(EXACT.engine.stick_phases(params, u[:-1].reshape(2, -1),
                                                     float(u[-1]))).sum())


def test_the_switched_branch_turns_at_its_sliding_point_onto_orbits_without_that_stick(
        ring8):
    """The switched branch runs down to where the weaker site's stick phase
    vanishes (a sliding point) and goes on through it: the points either side both
    lie above it in v_d (the branch turns there, a non-smooth fold), the orbits
    before it have two stick phases and the one after one (read from the exact
    engine's switch log over each orbit, `stick_phases`). Before the turn the
    branch passes the v_d of the point after it between two orbits with two stick
    phases: two orbits at one v_d, one each side of the turn. (Newton's method
    from the orbit before, at that v_d, reaches the orbit without the stick phase:
    near the turn the two lie closer to each other than the stick-slip orbits
    along their square-root branch.)"""
    _, branches, folder = ring8
    switched = _switched_at_the_stable_end(branches, folder)
    sliding = next(b for b in json.loads(switched.attrs["bifurcations"])
                   if b["type"] == "sliding")
    i = sliding["after"]
    v, u = switched["v_d"].values, switched["u"].values
    assert v[i] > sliding["v_d"] and v[i + 1] > sliding["v_d"] and i + 1 < v.size - 1
    assert _stick_count(u[i], v[i]) == 2 and _stick_count(u[i + 1], v[i + 1]) == 1
    (j,) = np.flatnonzero((v[:i - 1] > v[i + 1]) & (v[1:i] <= v[i + 1]))
    assert _stick_count(u[j], v[j]) == 2 and _stick_count(u[j + 1], v[j + 1]) == 2


def test_a_branch_found_by_deflation_is_an_isola(ring8):
    """The branch that deflation finds from the one-site start comes back through
    its start (both stops "closed") and meets no other branch: its two ends lie
    within one of its steps of each other (in v_d, period and amplitudes sorted by
    size), and it turns inside the range of its continuation."""
    _, branches, folder = ring8
    isola = branches["k=1 deflated 1"]
    assert isola["stop"] == {"low": "closed", "high": "closed"} and not isola["connects_to"]
    ds = xr.load_dataset(folder / "branch_k1_deflated1.nc")
    curve = np.column_stack([np.sort(ds["amplitudes"].values, axis=1), ds["period"].values,
                             ds["v_d"].values])
    steps = np.linalg.norm(np.diff(curve, axis=0), axis=1)
    assert np.linalg.norm(curve[0] - curve[-1]) <= steps.max()
    assert 1.0 < ds["v_d"].values.min() and ds["v_d"].values.max() < 2.0


def test_the_whole_ring_s_branch_goes_through_its_sliding_point_down_to_the_hopf_point(
        ring8):
    """The whole ring's branch (k = 8: neighbours in antiphase) goes on through its
    sliding point, where every site loses its stick phase at once (all held
    together), as the cycle without stick, down to the Hopf point of steady sliding.
    There mu'(v_d) = -2 xi whatever the mode's stiffness, so the closed form of
    `hopf_vd_analytic` holds for every mode of the ring; the branch meets it to 1e-6,
    is cut there (stop "hopf") and connects to steady sliding."""
    _, branches, _ = ring8
    ring = branches["k=8"]
    kinds = [b["type"] for b in ring["bifurcations"]]
    assert kinds.index("sliding") < kinds.index("Hopf") == len(kinds) - 1
    (hopf,) = [b["v_d"] for b in ring["bifurcations"] if b["type"] == "Hopf"]
    expected = float(jc.hopf_vd_analytic(jc.ChainParams(n_osc=N)))
    assert abs(hopf - expected) < 1e-6
    assert ring["stop"]["high"] == "hopf" and "steady sliding" in ring["connects_to"]


def test_the_one_site_branch_is_cut_where_it_retraces_itself(ring8):
    """Past its sliding point the one-site branch turns at a fold where the pattern
    is symmetric under a reflection of the ring, and beyond it runs back through the
    mirror images of its own orbits (before this was detected it listed the folds
    1.28327, 1.29218, 1.18389, 1.29218, 1.28327). It is cut at that fold (stop
    "retraced"): nothing of it lies beyond that fold (a branch point of the
    symmetric orbit may share its interval), and no two of its folds lie within
    1e-4 of each other in v_d."""
    _, branches, folder = ring8
    one = branches["k=1"]
    last = [b for b in one["bifurcations"] if b["type"] == "fold"][-1]
    assert one["stop"]["high"] == "retraced"
    assert all(b["after"] <= last["after"] for b in one["bifurcations"])
    folds = sorted(b["v_d"] for b in one["bifurcations"] if b["type"] == "fold")
    assert len(folds) >= 2 and np.all(np.diff(folds) > 1e-4)
    ds = xr.load_dataset(folder / "branch_k1.nc")
    assert ds["v_d"].values[-1] == pytest.approx(last["v_d"], abs=0.01)


def test_a_start_not_periodic_at_the_snake_s_v_d_is_followed_from_a_neighbouring_one(ring8):
    """The three-site state of eq. (8) is not periodic at v_d 1.5 (shooting from the
    simulated state does not converge) but is at 1.4 (`RETRY_VD`): its branch
    starts there, and its start orbit is periodic on the exact engine's own flow
    (`Exact.flow` over one period returns to the state within 1e-8, with no
    Newton iteration). Beyond the fold below it the branch runs back through the
    mirror images of its own orbits: it is cut there (stop "retraced") and its
    other way is followed, up past the snake's v_d. (Before the isola test took
    only the start itself, that mirror image closed the branch as an isola at 12
    points, and its upper part was never computed.)"""
    doc, branches, folder = ring8
    three = branches["k=3"]
    assert three["start"]["v_d"] == pytest.approx(1.4, abs=1e-12)
    assert three["stop"]["low"] == "retraced" and three["stop"]["high"] != "closed"
    assert three["v_d_computed"][1] > 1.5
    ds = xr.load_dataset(folder / "branch_k3.nc")
    u = ds["u"].values[np.argmin(np.abs(ds["v_d"].values - 1.4))]
    params = jc.with_parameter(jc.ChainParams(n_osc=N), "v_d", 1.4)
    y0 = u[:-1].reshape(2, -1)
    after = np.asarray(EXACT.engine.flow(params, y0, np.array([u[-1]])))
    assert np.all(np.isfinite(after)) and np.max(np.abs(after[0] - y0)) < 1e-8
