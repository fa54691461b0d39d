"""Deflation (Farrell, Birkisson and Funke 2015) on the ring of three at v_d = 1.5,
where simulation from eq. (8) with one and with two excited oscillators ends on two
different stable states: repeated deflation from one start finds the state that
simulation finds from it, then further periodic orbits that are none of its
symmetric copies, each a periodic orbit of an independent integrator (scipy)."""

import numpy as np
import jax
import jax.numpy as jnp
import pytest
import xarray as xr
from scipy.integrate import solve_ivp

import jaxchain as jc
from jaxchain._bifurcation.deflation import chain_symmetries, deflation

from helpers import internal, reference_rhs, replace_internal

RING = jc.ChainParams(n_osc=3, v_d=1.5)
#: The starts settle within 1500 time units on three oscillators.
START = jc.SimulationOptions(t_end=2000.0, transient=1500.0)
SHOOTING = jc.Shooting(root_finder="levenberg-marquardt", phase_oscillator=1)


@pytest.fixture(scope="module")
def simulated():
    """The states that simulation reaches from eq. (8) with k = 1 and 2 excited,
    refined by shooting: {k: PeriodicOrbit}."""
    found = internal("snake start orbits")(RING, (1, 2), options=START)
    assert all(reason is None for _, _, reason in found.values())
    return {k: orbit for k, (orbit, _, _) in found.items()}


def packed(y0, period):
    """Shooting unknowns (x_1..x_N, x_1'..x_N', T)."""
    return jnp.concatenate([jnp.ravel(jnp.asarray(y0)), jnp.atleast_1d(period)])


def eq8_start(k):
    """Eq. (8) with k excited and T = 2 pi, the phase oscillator's velocity 0."""
    y0 = jnp.asarray(jc.OutOfPhaseExcitation.eq8(jc.excited_block(3, k))(RING))
    return packed(y0.at[1, SHOOTING.phase_oscillator].set(0.0), 2 * np.pi)


def scipy_return(u) -> float:
    """max |y(T) - y(0)| of the orbit u = (y0, T) integrated by scipy's DOP853 on eq.
    (5) written out independently (`reference_rhs`)."""
    y0, period = np.asarray(u[:-1]), float(u[-1])
    sol = solve_ivp(reference_rhs(RING), (0.0, period), y0, method="DOP853", rtol=1e-11,
                    atol=1e-12)
    return float(np.max(np.abs(sol.y[:, -1] - y0)))


def copies_distance(a, b) -> float:
    """The deflation distance of orbit b from orbit a and its symmetric copies."""
    problem = jc.cycle_problem(_orbit(a), SHOOTING)
    return float(deflation(problem, [a]).distances(b)[0])


def _orbit(u):
    return jc.periodic_orbit(RING, (jnp.reshape(u[:-1], (2, -1)), float(u[-1])), SHOOTING)


@pytest.mark.numerics
@pytest.mark.parametrize("scale", [0.0, 1e-6, 1e-4])
def test_repeated_deflation_from_one_start_finds_distinct_orbits(simulated, scale):
    """From eq. (8) with two excited (perturbed by a relative `scale`, with the phase
    condition kept), nothing known: first the two-site state that simulation
    reaches from that start (the same period to 1e-7, two solves at Newton's
    tolerance 1e-9), then, with it and all six
    of its copies under the ring's rotations and reflections deflated, from the
    same start, two more orbits: periodic for scipy to 1e-6, none a copy of
    another or of the states found before, and not stable (simulation does not
    show them)."""
    start = eq8_start(2)
    noise = np.random.default_rng(1).standard_normal(start.shape)
    start = (start * (1 + scale * noise)).at[3 + SHOOTING.phase_oscillator].set(0.0)
    problem = jc.cycle_problem(simulated[1], SHOOTING)
    found = jc.distinct_orbits(problem, start, count=3)
    assert len(found) == 3
    assert abs(float(found[0][-1]) - float(simulated[2].period)) < 1e-7  # two Newton solves
    assert copies_distance(packed(simulated[2].y0, simulated[2].period),
                           found[0]) < 1e-6
    for u in found[1:]:
        assert scipy_return(u) < 1e-6
        assert not bool(_orbit(u).stable)
    for i in range(3):
        for j in range(i):
            assert copies_distance(found[j], found[i]) > 1e-2


@pytest.mark.numerics
def test_deflating_the_state_of_a_start_leads_elsewhere(simulated):
    """Shooting from eq. (8) with one excited reaches the one-site state, as
    simulation does from there; with that state deflated (the other state,
    simulation's two-site one, not) the same start gives another orbit, periodic
    for scipy, that is no copy of the one-site state."""
    start = eq8_start(1)
    one = packed(simulated[1].y0, simulated[1].period)
    problem = jc.cycle_problem(simulated[1], SHOOTING)
    # Only the first orbit of each call is checked: it is the first solve, the same
    # whatever `count` (a free slot of the operator deflates nothing), and these counts
    # give the operator the two free slots of the solve that
    # test_repeated_deflation_from_one_start_finds_distinct_orbits compiled
    # (len(known) + count - 1 = 2) instead of two more compiled solves.
    plain = jc.distinct_orbits(problem, start, count=3)
    assert copies_distance(one, plain[0]) < 1e-6
    other = jc.distinct_orbits(problem, start, [one], count=2)[0]
    assert copies_distance(one, other) > 1e-2 and scipy_return(other) < 1e-6


def test_the_distance_from_an_orbit_is_to_the_nearest_point_of_its_copies(simulated):
    """`Deflation.distances` against the distance written out here: the closed
    polyline through the orbit's samples, each of its six copies built explicitly
    (y[:, perm]), every segment; the state near a copy of the orbit, near the orbit
    and far from both; its gradient against central differences."""
    one = packed(simulated[1].y0, simulated[1].period)
    problem = jc.cycle_problem(simulated[1], SHOOTING)
    operator = deflation(problem, [one], n_samples=64)
    samples = np.reshape(np.asarray(operator.curves[0]), (64, 2, 3))

    def written_out(u):
        y = np.asarray(u[:-1])
        best = np.inf
        for perm in np.asarray(chain_symmetries(RING)):
            a = np.reshape(samples[:, :, perm], (64, 6))
            edge = np.roll(a, -1, axis=0) - a
            t = np.clip(np.sum((y - a) * edge, -1) / np.sum(edge**2, -1), 0.0, 1.0)
            best = min(best, np.min(np.sum((y - a - t[:, None] * edge) ** 2, -1)))
        return np.sqrt(best + (float(u[-1]) - float(one[-1])) ** 2)

    rng = np.random.default_rng(3)
    copy = jnp.concatenate([jnp.ravel(jnp.asarray(samples[17])[:, ::-1]), one[-1:] + 0.01])
    for u in (copy + 1e-4 * rng.standard_normal(7), one + 0.05 * rng.standard_normal(7),
              one + 2.0 * rng.standard_normal(7)):
        d = float(operator.distances(u)[0])
        assert abs(d - written_out(u)) < 1e-12 * max(d, 1.0)
        v, h = rng.standard_normal(7), 1e-6
        central = (written_out(u + h * v) - written_out(u - h * v)) / (2 * h)
        slope = float(jax.jvp(lambda w: operator.distances(w)[0], (u,), (jnp.asarray(v),))[1])
        assert abs(slope - central) < 1e-6 * max(abs(central), 1.0)


def test_symmetries_of_the_ring_and_bad_arguments(simulated):
    """The dihedral group on the homogeneous ring (2N distinct permutations), the
    identity alone on a free line; clear errors for bad arguments."""
    perms = np.asarray(chain_symmetries(jc.ChainParams(n_osc=5)))
    assert perms.shape == (10, 5) and {tuple(sorted(p)) for p in perms} == {tuple(range(5))}
    assert np.asarray(chain_symmetries(jc.ChainParams(n_osc=5, boundary="free"))).shape \
        == (1, 5)
    problem = jc.cycle_problem(simulated[1], SHOOTING)
    with pytest.raises(ValueError, match="count"):
        jc.distinct_orbits(problem, problem.u0, count=0)
    with pytest.raises(ValueError, match="capacity"):
        jc.distinct_orbits(problem, problem.u0, count=2, capacity=0)
    with pytest.raises(ValueError, match="n_samples"):
        deflation(problem, n_samples=4)
    with pytest.raises(ValueError, match="deflate"):
        jc.localized_branches(RING, (1,), deflate=-1)


@pytest.mark.study
def test_the_snake_follows_the_orbits_that_deflation_finds(tmp_path):
    """`localized_branches(deflate=2)` from eq. (8) with two excited: besides the
    branch of the simulated state, the branches of two further orbits at the start's
    v_d, each a periodic orbit for scipy and no symmetric copy of the others; all
    stored and read back."""
    kwargs = dict(continuation_options=jc.ContinuationOptions(
        ds=0.02, ds_max=0.05, p_min=1.45, p_max=1.55, max_points=3),
        start_options=START, simulation_check=False, deflate=2, out=tmp_path)
    found = jc.localized_branches(RING, (2,), **kwargs)
    labels = ["k=2", "k=2 deflated 1", "k=2 deflated 2"]
    assert list(found["datasets"]) == labels
    starts = []
    for label in labels:
        ds = found["datasets"][label]
        starts.append(ds["u"].values[int(np.argmin(np.abs(ds["v_d"].values - 1.5)))])
    for u in starts[1:]:
        assert scipy_return(u) < 1e-6
    for i in range(3):
        for j in range(i):
            assert copies_distance(starts[j], starts[i]) > 1e-2
    again = jc.localized_branches(RING, (2,), **kwargs)
    assert list(again["datasets"]) == labels


@pytest.mark.study
def test_a_start_that_is_not_periodic_is_deflated_from_its_eq8_state(tmp_path,
                                                                      monkeypatch):
    """A start whose simulated state is not periodic (here the one-site start, its
    orbit withheld) keeps its reason, and deflation still searches from its eq. (8)
    state (with the two-site start's orbit deflated, the problem borrowed from it):
    the orbit found is followed as "k=1 deflated 1". It is a periodic orbit for
    scipy, with one oscillator on the HALC, and no symmetric copy of the other
    branches' orbits."""
    starts = internal("snake starts")

    def one_site_not_periodic(*args, **kwargs):
        found = starts(*args, **kwargs)
        _, sim, _ = found[1]
        found[1] = (None, sim, "shooting did not converge: the simulated state is not "
                    "periodic")
        return found

    replace_internal(monkeypatch, "snake starts", one_site_not_periodic)
    found = jc.localized_branches(RING, (2, 1), continuation_options=jc.ContinuationOptions(
        ds=0.02, ds_max=0.05, p_min=1.45, p_max=1.55, max_points=3), start_options=START,
        simulation_check=False, deflate=1, out=tmp_path)
    labels = list(found["datasets"])
    assert "k=1 deflated 1" in labels and "k=1" not in labels and labels[0] == "k=2"
    assert [n["excited"] for n in found["summary"]["not_periodic"]] == [1]
    at = {}
    for label in labels:
        ds = found["datasets"][label]
        i = int(np.argmin(np.abs(ds["v_d"].values - 1.5)))
        at[label] = (ds["u"].values[i], int(ds["n_halc"].values[i]))
    u, n_halc = at.pop("k=1 deflated 1")
    assert scipy_return(u) < 1e-6 and n_halc == 1
    assert all(copies_distance(other, u) > 1e-2 for other, _ in at.values())


@pytest.mark.study
def test_a_deflated_orbit_on_a_branch_already_followed_is_reported_not_followed(
        tmp_path, monkeypatch, simulated):
    """Deflation's orbits replaced by two known ones: the two-site state rotated by
    one oscillator (a symmetric copy: on the start's own branch) and the one-site
    state (another branch). The copy is reported on "k=2" and not followed; the
    one-site state is followed as "k=2 deflated 1", one oscillator on the HALC at
    the start's v_d. A third solution of deflation, from which shooting did not
    converge, is neither. Read back, the report is the same, and a run resumed
    with a further start deflates from it every orbit the first run's deflation
    knew: the start's own orbit and the three solutions, to the last bit."""
    two = simulated[2]
    rotated = jnp.roll(jnp.asarray(two.y0), 1, axis=1)
    phase = int(np.argmax(np.roll(np.asarray(two.amplitudes), 1)))
    copy = jc.periodic_orbit(RING, (rotated, float(two.period)),
                             SHOOTING.with_phase_oscillator(phase))
    assert bool(copy.converged)
    one = (simulated[1], int(np.argmax(np.asarray(simulated[1].amplitudes))))
    # deflation's solutions stand apart from the shot orbits (phase conditions differ)
    given = [(o, m, jnp.append(jnp.ravel(o.y0), o.period) + 1e-3)
             for o, m in [(copy, phase), one]]
    given.append((None, 0, given[0][2] + 0.5))
    replace_internal(monkeypatch, "snake deflated orbits",
                     lambda orbits, params, found, count, stored: {2: given})
    kwargs = dict(continuation_options=jc.ContinuationOptions(
        ds=0.02, ds_max=0.05, p_min=1.45, p_max=1.55, max_points=3),
        start_options=START, simulation_check=False, deflate=2, out=tmp_path)
    found = jc.localized_branches(RING, (2,), **kwargs)
    assert list(found["datasets"]) == ["k=2", "k=2 deflated 1"]
    (repeat,) = found["summary"]["deflated_on_followed"]
    assert repeat["start"] == "k=2" and repeat["on"] == "k=2" and repeat["n_halc"] == 2
    ds = found["datasets"]["k=2 deflated 1"]
    assert int(ds["n_halc"].values[int(np.argmin(np.abs(ds["v_d"].values - 1.5)))]) == 1

    def computes(*args, **kwargs):
        raise AssertionError("the stored branches are read back")

    replace_internal(monkeypatch, "snake starts", computes)
    again = jc.localized_branches(RING, (2,), **kwargs)
    assert list(again["datasets"]) == ["k=2", "k=2 deflated 1"]
    assert again["summary"]["deflated_on_followed"] == [repeat]
    # resumed with the one-site start: its deflation (replaced by a spy) is given the
    # orbits the first run's deflation knew, read back from the stored records
    seen = []
    replace_internal(monkeypatch, "snake starts",
                     lambda *args: {1: (None, {}, "not periodic (replaced)")})
    replace_internal(monkeypatch, "snake deflated orbits",
                     lambda orbits, params, found, count, stored: seen.append(stored) or {})
    jc.localized_branches(RING, (2, 1), **kwargs)
    ((own, *deflated),) = seen
    assert all(np.array_equal(a, u) for a, (_, _, u) in zip(deflated, given, strict=True))
    start = found["datasets"]["k=2"]  # its first point: its start orbit, corrected again
    i = int(np.argmin(np.abs(start["v_d"].values - 1.5)))
    np.testing.assert_allclose(own, start["u"].values[i], rtol=0,
                               atol=10 * jc.Shooting().newton_tol)


@pytest.mark.study
@pytest.mark.numerics
def test_a_resumed_run_deflates_the_orbits_of_the_starts_it_read_back(tmp_path,
                                                                       monkeypatch):
    """`localized_branches(deflate=1)` from the two- and the one-site start, then again
    with the one-site start's files removed, as after a run stopped once its first
    start was stored: deflation from the one-site start has every orbit deflated
    that it had in the whole run (the two-site start's own and the orbit deflation
    found from it, read back from the two-site start's record, to the last bit),
    and the resumed run ends with the whole run's branches."""
    real, seen = internal("snake deflation"), []

    def spy(problem, start, known, **kwargs):
        seen.append([np.asarray(u) for u in known])
        return real(problem, start, known, **kwargs)

    replace_internal(monkeypatch, "snake deflation", spy)
    kwargs = dict(continuation_options=jc.ContinuationOptions(
        ds=0.02, ds_max=0.05, p_min=1.45, p_max=1.55, max_points=3),
        start_options=START, simulation_check=False, deflate=1, out=tmp_path)
    whole = jc.localized_branches(RING, (2, 1), **kwargs)
    whole_known = seen[-1]
    seen.clear()
    for path in tmp_path.glob("branch_k1*.nc"):
        path.unlink()
    resumed = jc.localized_branches(RING, (2, 1), **kwargs)
    (known,) = seen  # deflation from the one-site start alone
    assert len(known) == len(whole_known) == 3
    # the same orbits: the one-site start's own is shot again in the resumed run
    # (Newton's tolerance 1e-9)
    assert all(min(copies_distance(u, v) for v in known) < 1e-6 for u in whole_known)
    # the two read back (the two-site start's own orbit and deflation's solution from
    # it) are the whole run's to the last bit
    assert sum(any(np.array_equal(u, v) for v in known) for u in whole_known) >= 2
    assert list(resumed["datasets"]) == list(whole["datasets"])
    # orbits of one residual, each to Newton's tolerance (1e-9, shooting and the
    # continuation's corrector alike) from its root
    tol = 10 * jc.Shooting().newton_tol
    for label, ds in whole["datasets"].items():
        np.testing.assert_allclose(resumed["datasets"][label]["u"].values, ds["u"].values,
                                   rtol=0, atol=tol, err_msg=label)


@pytest.mark.study
def test_branches_followed_by_two_workers_are_those_of_one(tmp_path):
    """`localized_branches(workers=2)`: the starts' branches, and those of the
    orbits deflation finds, followed in two processes side by side, are the
    branches of the sequential run to the last bit (each is the same compiled
    program), labelled and stored alike, and read back by a sequential call."""
    kwargs = dict(continuation_options=jc.ContinuationOptions(
        ds=0.02, ds_max=0.05, p_min=1.45, p_max=1.55, max_points=3),
        start_options=START, simulation_check=False, deflate=1)
    one = jc.localized_branches(RING, (2, 1), **kwargs, out=tmp_path / "one")
    two = jc.localized_branches(RING, (2, 1), **kwargs, out=tmp_path / "two", workers=2)
    assert list(two["datasets"]) == list(one["datasets"]) == [
        "k=2", "k=2 deflated 1", "k=1", "k=1 deflated 1"]
    for label, ds in one["datasets"].items():
        xr.testing.assert_identical(two["datasets"][label], ds)
    assert two["summary"]["deflated_on_followed"] == one["summary"]["deflated_on_followed"]
    back = jc.localized_branches(RING, (2, 1), **kwargs, out=tmp_path / "two")
    assert list(back["datasets"]) == list(one["datasets"])
    with pytest.raises(ValueError, match="workers"):
        jc.localized_branches(RING, (2,), **kwargs, workers=0)
