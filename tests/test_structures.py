"""Any structure a user brings: coupling graphs and 2-D lattices, masses, measured
friction tables and physical units, each against an independent reference (closed
forms, scipy's eigensolvers and integrators, a Jacobian written here)."""

import io
from pathlib import Path

import numpy as np
import pytest
import scipy.integrate
import scipy.interpolate
import scipy.linalg
import scipy.optimize
from tqdm import tqdm

import jaxchain as jc
from helpers import assert_usage_error

ETA = 0.3


def _line_laplacian_eigenvalues(n: int, boundary: str) -> np.ndarray:
    """Closed form: the eigenvalues of the graph Laplacian of a line of n sites."""
    if boundary == "periodic":
        k = np.arange(n)
        return 2 - 2 * np.cos(2 * np.pi * k / n)
    if boundary == "fixed":  # Dirichlet: both ends tied to the ground
        k = np.arange(1, n + 1)
        return 2 - 2 * np.cos(np.pi * k / (n + 1))
    k = np.arange(n)  # free: Neumann
    return 2 - 2 * np.cos(np.pi * k / n)


@pytest.mark.parametrize("boundary", ["free", "fixed", "periodic"])
def test_linear_modes_of_a_lattice_are_products_of_line_modes(boundary):
    """K = 1 + eta_c (L_rows (+) L_cols): its eigenvalues are 1 + eta_c (a_i + b_j),
    a, b the closed-form eigenvalues of the two lines."""
    rows, cols = 3, 5
    params = jc.ChainParams(graph=jc.Graph.lattice(rows, cols, boundary), eta_c=ETA)
    got = np.linalg.eigvalsh(np.asarray(jc.stiffness_matrix(params)))
    a = _line_laplacian_eigenvalues(rows, boundary)
    b = _line_laplacian_eigenvalues(cols, boundary)
    expected = np.sort((1 + ETA * (a[:, None] + b[None, :])).ravel())
    np.testing.assert_allclose(got, expected, rtol=1e-13, atol=1e-13)


def _unequal_lattice(**kw):
    rng = np.random.default_rng(4)
    return jc.ChainParams(graph=jc.Graph.lattice(2, 3, "free"), eta_c=ETA,
                          mass=rng.uniform(0.5, 2.0, 6), **kw)


def test_lattice_with_masses_has_the_modes_of_the_generalised_eigenproblem():
    """Undamped, with Coulomb friction (no slope at steady sliding): the Jacobian's
    eigenvalues are +-i omega, omega^2 the eigenvalues of K phi = omega^2 M phi
    (`scipy.linalg.eigh(K, M)`)."""
    params = _unequal_lattice(xi=0.0, friction=jc.Coulomb(mu=0.5))
    k = np.asarray(jc.stiffness_matrix(params))
    omega2 = scipy.linalg.eigh(k, np.diag(np.asarray(params.mass)), eigvals_only=True)
    values = np.linalg.eigvals(np.asarray(jc.Smoothed().jacobian(params)))
    np.testing.assert_allclose(np.sort(values.imag[values.imag > 0]), np.sqrt(omega2),
                               rtol=1e-10)
    assert np.max(np.abs(values.real)) < 1e-10


def _mu(v, law, xp=np):
    """Eq. (1) of `law`'s coefficients, in NumPy (or `xp`, for example jax.numpy)."""
    return law.mu_d + (law.mu_st - law.mu_d) * xp.exp(-xp.abs(v) / law.v0)


def test_hopf_point_of_a_lattice_with_unequal_masses_against_a_jacobian_written_here():
    """The Jacobian of M x'' = -2 xi x' - K x + P F(x' - v_d) at steady sliding,
    written here with NumPy (friction slope by central differences), and the root
    of its leading growth rate by `scipy.optimize.brentq`, against `hopf_point`."""
    params, eps = _unequal_lattice(xi=0.04), 0.01
    law, n = params.friction, params.n_osc
    m, k = np.asarray(params.mass), np.asarray(jc.stiffness_matrix(params))

    def force(v):
        return -_mu(v, law) * np.tanh(v / eps)

    def growth(v_d):
        h = 1e-6
        slope = (force(-v_d + h) - force(-v_d - h)) / (2 * h)
        jac = np.block([[np.zeros((n, n)), np.eye(n)],
                        [-k / m[:, None], np.diag((-2 * params.xi + slope) / m)]])
        return np.max(np.linalg.eigvals(jac).real)

    expected = scipy.optimize.brentq(growth, 0.3, 3.0, xtol=1e-13)
    got = float(jc.hopf_point(params, guess=1.0, engine=jc.Smoothed(eps=eps)).v_d[0])
    assert abs(got - expected) < 1e-6


def test_a_lattice_run_against_scipy_oscillator_by_oscillator():
    """A 2 x 3 free lattice with masses and per-link stiffnesses, integrated by
    jaxchain and by scipy's DOP853 of the equations written here, link by link: the
    final states agree to the tolerances (both tight)."""
    graph = jc.Graph.lattice(2, 3, "free")
    eta = np.linspace(0.05, 0.4, graph.n_links)
    params = jc.ChainParams(graph=graph, eta_c=eta, mass=np.linspace(0.7, 1.6, 6),
                            xi=0.03, v_d=1.2)
    eps = 0.05
    law, m = params.friction, np.asarray(params.mass)

    def rhs(t, y):
        x, v = y[:6], y[6:]
        a = -2 * 0.03 * v - x
        for (left, right), e in zip(graph.links, eta):
            a[left] += e * (x[right] - x[left])
            a[right] -= e * (x[right] - x[left])
        vr = v - 1.2
        a = (a - _mu(vr, law) * np.tanh(vr / eps)) / m
        return np.concatenate([v, a])

    y0 = np.concatenate([np.linspace(-1.0, 1.5, 6), np.zeros(6)])
    ref = scipy.integrate.solve_ivp(rhs, (0, 40.0), y0, method="DOP853", rtol=1e-11,
                                    atol=1e-12).y[:, -1]
    options = jc.SimulationOptions(t_end=40.0, transient=0.0, rtol=1e-10, atol=1e-12)
    got = np.asarray(jc.simulate(params, y0.reshape(2, 6),
                                 engine=jc.Smoothed(options=options, eps=eps)).y_final)
    np.testing.assert_allclose(got.ravel(), ref, atol=1e-6)


def test_energy_balance_on_a_lattice_with_masses():
    """d/dt (1/2 sum m_n x_n'^2 + elastic energy) = friction power - viscous
    dissipation, integrated beside the motion; the friction force is written here
    (eq. (1), `_mu`, smoothed as -mu tanh(v_rel/eps)), so that the balance checks
    the whole field."""
    import diffrax
    import jax.numpy as jnp

    params, eps = _unequal_lattice(xi=np.linspace(0.02, 0.07, 6)), 0.05

    def field(t, z, args):
        y, _ = z
        v = y[1]
        v_rel = v - params.v_d
        force = -_mu(v_rel, params.friction, jnp) * jnp.tanh(v_rel / eps)  # not m x''
        return jc.Smoothed(eps=eps).field(params, y), jnp.stack([jnp.sum(force * v),
                                                         jnp.sum(2 * params.xi * v**2)])

    y0 = jnp.stack([jnp.linspace(-1.0, 2.0, 6), jnp.zeros(6)])
    sol = diffrax.diffeqsolve(diffrax.ODETerm(field), diffrax.Dopri8(), 0.0, 40.0, 0.01,
                              (y0, jnp.zeros(2)),
                              stepsize_controller=diffrax.PIDController(rtol=1e-11, atol=1e-11),
                              max_steps=200_000)
    y1, (work, dissipated) = sol.ys[0][-1], sol.ys[1][-1]
    change = jc.mechanical_energy(params, y1) - jc.mechanical_energy(params, y0)
    assert abs(float(dissipated)) > 0.1
    assert abs(float(change - (work - dissipated))) < 1e-8


@pytest.mark.study
def test_tabulated_law_reproduces_the_stick_slip_cycle_of_its_closed_form():
    """eq. (1) sampled at 241 speeds and interpolated (PCHIP, equal to scipy's
    `PchipInterpolator` on even and uneven tables): its interpolation error is below
    1e-5, and the stick-slip cycle of the single oscillator (its
    amplitude) is that of eq. (1) within 1e-3 relative; the value beyond the table
    is held at the last sample."""
    law = jc.ExponentialDecay()
    v = np.linspace(0.0, 6.0, 241)
    table = jc.Tabulated(v=v, mu=_mu(v, law))
    fine = np.linspace(0.0, 6.0, 2001)
    error = np.max(np.abs(np.asarray(table(fine)) - _mu(fine, law)))
    assert error < 1e-5
    uneven = np.array([0.0, 0.1, 0.3, 0.7, 1.5, 3.0, 6.0])  # the search, not the division
    for speeds in (v, uneven):
        samples = _mu(speeds, law)
        pchip = scipy.interpolate.PchipInterpolator(speeds, samples)(fine)
        got = np.asarray(jc.Tabulated(v=speeds, mu=samples)(fine))
        np.testing.assert_allclose(got, pchip, rtol=0, atol=1e-14)
    assert float(table(10.0)) == pytest.approx(_mu(6.0, law), rel=1e-14)
    assert float(table(-0.7)) == pytest.approx(float(table(0.7)), rel=1e-14)
    options = jc.SimulationOptions(t_end=150.0, transient=100.0)
    y0 = np.array([[2.0], [0.0]])
    amp = [float(jc.simulate(jc.ChainParams(n_osc=1, v_d=1.0, friction=f), y0,
                             options=options).amplitudes[0]) for f in (law, table)]
    assert amp[0] > 1.0  # on the stick-slip cycle
    assert abs(amp[1] / amp[0] - 1) < 1e-3


def test_from_physical_against_a_dimensional_scipy_integration():
    """An SI oscillator (2 kg, 800 N/m, 4 N s/m, 40 N on a belt at 0.3 m/s, eq. (1)
    with v0 = 0.05 m/s), integrated in seconds and metres by scipy, against the
    converted jaxchain run; pint quantities in other units give the same chain."""
    pint = pytest.importorskip("pint")
    law = jc.ExponentialDecay(mu_st=1.0, mu_d=0.5, v0=0.05)
    params = jc.from_physical(mass=2.0, stiffness=800.0, damping=4.0, normal_load=40.0,
                              friction=law, belt_speed=0.3, n_osc=1)
    s = params.scales
    assert s.length == pytest.approx(0.05) and s.time == pytest.approx(0.05)
    ureg = pint.UnitRegistry()
    same = jc.from_physical(mass=2000 * ureg.g, stiffness=0.8 * ureg("N/mm"),
                            damping=4 * ureg("N*s/m"), normal_load=0.04 * ureg.kN,
                            friction=law, belt_speed=30 * ureg("cm/s"), n_osc=1)
    for name in ("xi", "v_d", "stiffness", "load"):
        assert float(getattr(same, name)) == pytest.approx(float(getattr(params, name)),
                                                           rel=1e-12)
    eps_si = 1e-2 * s.velocity

    def rhs(t, y):
        vr = y[1] - 0.3
        mu = 0.5 + 0.5 * np.exp(-abs(vr) / 0.05)
        return [y[1], (-4.0 * y[1] - 800.0 * y[0] - 40.0 * mu * np.tanh(vr / eps_si)) / 2.0]

    t_end, y0 = 1.5, [0.01, 0.0]
    ref = scipy.integrate.solve_ivp(rhs, (0, t_end), y0, method="Radau", rtol=1e-10,
                                    atol=1e-13).y[:, -1]
    options = jc.SimulationOptions(t_end=t_end / s.time, transient=0.0, rtol=1e-10,
                                   atol=1e-12)
    y0_dimless = np.array([[y0[0] / s.length], [y0[1] / s.velocity]])
    got = np.asarray(jc.simulate(params, y0_dimless,
                                 engine=jc.Smoothed(options=options, eps=1e-2)).y_final)[:, 0]
    assert abs(got[0] * s.length - ref[0]) < 1e-7
    assert abs(got[1] * s.velocity - ref[1]) < 1e-5
    with pytest.raises(ValueError, match="stiffness"):
        jc.from_physical(mass=2.0, stiffness=3 * ureg.kg, normal_load=40.0, friction=law,
                         belt_speed=0.3, n_osc=1)


@pytest.mark.parametrize("make, message", [
    (lambda: jc.Graph.from_matrix([[0.2, -0.1], [-0.2, 0.2]]), "not symmetric"),
    (lambda: jc.Graph.from_matrix([[-0.1, 0.1], [0.1, -0.1]]), "positive off-diagonal"),
    (lambda: jc.Graph.from_links(3, [(0, 1), (1, 5)]), "does not exist"),
    (lambda: jc.ChainParams(n_osc=3, mass=[1.0, -1.0, 1.0]), "ChainParams.mass"),
    (lambda: jc.Tabulated(v=[0.0, 2.0, 1.0], mu=[1.0, 0.8, 0.6]), "strictly increasing"),
    (lambda: jc.Tabulated(v=[0.0, 1.0], mu=[1.0, np.nan]), "Tabulated.mu"),
    (lambda: jc.ChainParams(graph=jc.Graph.lattice(2, 2), boundary="free"), "graph or boundary"),
])
def test_bad_structures_are_refused_naming_what_is_wrong(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_a_coupling_matrix_gives_back_its_graph():
    """`Graph.from_matrix` of a lattice's coupling part (with a ground link) gives a
    chain of the same stiffness matrix."""
    params = jc.ChainParams(graph=jc.Graph.lattice(3, 3, ("fixed", "periodic")), eta_c=0.2)
    coupling = np.asarray(jc.stiffness_matrix(params)) - np.eye(9)
    graph, eta = jc.Graph.from_matrix(coupling)
    rebuilt = jc.ChainParams(graph=graph, eta_c=eta)
    np.testing.assert_allclose(jc.stiffness_matrix(rebuilt), jc.stiffness_matrix(params),
                               atol=1e-15)


def test_a_law_that_cannot_be_recorded_is_refused_before_the_run():
    """A user's law (a subclass of the abstract law) runs in `simulate`, and
    `ensemble` refuses it before integrating anything, naming the law."""
    import equinox as eqx

    class Linear(jc.AbstractFrictionLaw):
        mu: float = eqx.field(converter=np.asarray, default=0.6)

        @classmethod
        def rules(cls):
            return {}

        def __call__(self, v_rel):
            return self.mu + 0.0 * v_rel

        def static(self):
            return self.mu

    params = jc.ChainParams(n_osc=2, friction=Linear())
    assert np.isfinite(float(jc.simulate(params, np.ones((2, 2)), options=jc.SimulationOptions(
        t_end=5.0, transient=0.0)).energy))
    # a bar of the trajectories integrated, which the run would advance by 2
    bar = tqdm(total=2, file=io.StringIO())
    with pytest.raises(ValueError, match="Linear cannot be recorded"):
        jc.ensemble(params, [1.5], jc.localized_family(2), progress=bar)
    assert bar.n == 0


def test_bad_lattice_or_table_on_the_command_line_exits_2_in_one_line(tmp_path, capsys):
    table = tmp_path / "mu.csv"
    table.write_text("v,mu\n0,1.0\n1,nan\n")
    assert_usage_error(["localized", "--lattice", "4by5", "--out", str(tmp_path / "a")],
                       "--lattice", capsys)
    assert_usage_error(["localized", "--friction", f"table:{table}", "--out",
                        str(tmp_path / "b")], "mu", capsys)


CHAINS = sorted((Path(__file__).parents[1] / "examples" / "chains").glob("*.toml"))


@pytest.mark.parametrize("path", CHAINS, ids=lambda p: p.stem)
def test_example_chain_files_round_trip(path, tmp_path):
    """Each example chain file read, written and read back gives the same chain
    (every leaf equal, the same graph, law, masses and scales)."""
    import jax

    chain = jc.chain_from_file(path)
    jc.write_chain_file(chain, tmp_path / "again.toml")
    again = jc.chain_from_file(tmp_path / "again.toml")
    leaves, tree = jax.tree_util.tree_flatten(chain)
    leaves_again, tree_again = jax.tree_util.tree_flatten(again)
    assert tree == tree_again
    for a, b in zip(leaves, leaves_again):
        np.testing.assert_array_equal(a, b)


@pytest.mark.study
def test_the_si_brake_pad_runs_from_its_chain_file(tmp_path, capsys):
    """`jaxchain localized --chain` of the SI pad (a lattice, masses, a measured
    table) runs at the file's belt speed and records its scales."""
    import json

    import xarray as xr

    path = next(p for p in CHAINS if p.stem == "brake_pad_si")
    out = tmp_path / "out"
    assert jc.main(["localized", "--chain", str(path), "--t-end", "200", "--transient",
                    "100", "--json", "--no-progress", "--out", str(out)]) == 0
    doc = json.loads(capsys.readouterr().out)
    chain = jc.chain_from_file(path)
    assert doc["runs"][0]["v_d"] == pytest.approx(float(chain.v_d))
    (nc,) = [p for p in doc["outputs"].values() if p.endswith(".nc")]
    ds = xr.open_dataset(nc)
    assert list(ds.attrs["lattice"]) == [2, 3]
    si = jc.to_physical(ds)
    np.testing.assert_allclose(si["amplitudes"], ds["amplitudes"] * chain.scales.length)
    assert si["v_d"].item() == pytest.approx(0.1)


@pytest.mark.study
@pytest.mark.long
def test_a_mass_and_a_table_through_hopf_point_and_shooting():
    """A single oscillator of mass 1.7 with eq. (1) sampled into a table: its Hopf
    point is eq. (1)'s (the trace 2 xi - mu'(v_d) vanishes whatever the mass), within
    the interpolation and smoothing errors; shooting finds the stick-slip cycle
    whose period and amplitude a long simulation (another program) measures."""
    law = jc.ExponentialDecay()
    v = np.linspace(0.0, 6.0, 241)
    params, eps = jc.ChainParams(n_osc=1, mass=1.7, v_d=1.0,
                                 friction=jc.Tabulated(v=v, mu=_mu(v, law))), 0.01
    exact = float(jc.hopf_vd_analytic(jc.ChainParams(n_osc=1)))
    hopf = jc.hopf_point(params, guess=1.2, engine=jc.Smoothed(eps=eps))
    assert abs(float(hopf.v_d[0]) - exact) < 1e-3
    options = jc.SimulationOptions(t_end=200.0, transient=150.0, rtol=1e-8, atol=1e-10)
    y0 = np.array([[2.0], [0.0]])
    peaks = jc.observe(params, y0, [jc.PeakTimes(), jc.Extrema()],
                       engine=jc.Smoothed(options=options, eps=eps))
    times = np.asarray(peaks["peak_times"])[0]
    period = float(np.median(np.diff(times[np.isfinite(times)])))
    orbit = jc.periodic_orbit(params, (np.asarray(peaks["y_final"]), period),
                              jc.Shooting(jc.Smoothed(eps=eps).for_orbits(),
                                          root_finder="levenberg-marquardt"))
    assert bool(orbit.converged)
    assert abs(float(orbit.period) / period - 1) < 2e-3
    assert abs(float(orbit.amplitudes[0]) / float(peaks["amplitudes"][0]) - 1) < 2e-3


def test_named_one_site_starts_of_a_lattice():
    """The corner, edge and interior starts of the 4 x 5 pad excite one site each,
    with 2, 3 and 4 neighbours; site:N names any oscillator; a bad name is refused."""
    graph = jc.Graph.lattice(4, 5, "free")
    sites = [jc.start_site(graph, name) for name in ("corner", "edge", "interior")]
    assert [int(graph.degree()[s]) for s in sites] == [2, 3, 4]
    assert jc.start_site(graph, "site:7") == 7
    with pytest.raises(ValueError, match="corner"):
        jc.start_site(jc.Graph.line(20), "corner")


def test_halc_clusters_follow_the_graph_and_a_1d_study_says_so(tmp_path, capsys):
    """On a 3 x 3 lattice the four corners are four groups and a plus sign is one;
    the mistuning study (1-D by nature) refuses a lattice in one line."""
    graph = jc.Graph.lattice(3, 3, "free")
    corners = np.zeros(9, dtype=bool)
    corners[[0, 2, 6, 8]] = True
    plus = np.zeros(9, dtype=bool)
    plus[[1, 3, 4, 5, 7]] = True
    assert graph.clusters(np.stack([corners, plus])).tolist() == [4, 1]
    assert_usage_error(["mistuning", "--lattice", "2x2", "--out", str(tmp_path / "m")],
                       "1-D by nature", capsys)


@pytest.mark.study
def test_the_nonsmooth_reference_with_masses_on_a_lattice_against_the_smoothed_model():
    """A 1 x 2 lattice (two sectors, one link) with unequal masses and a table: the
    event-driven reference and the smoothed model (eps = 1e-4) reach the same
    stick-slip cycle, amplitudes within the smoothing error (1e-2 relative)."""
    law = jc.ExponentialDecay()
    v = np.linspace(0.0, 6.0, 241)
    params = jc.ChainParams(graph=jc.Graph.lattice(1, 2, "free"), mass=[1.0, 1.6],
                            eta_c=0.05, v_d=1.0,
                            friction=jc.Tabulated(v=v, mu=_mu(v, law)))
    y0 = np.array([[2.0, -1.0], [0.0, 0.0]])
    smoothed = jc.simulate(params, y0, engine=jc.Smoothed(
        options=jc.SimulationOptions(t_end=150.0, transient=100.0), eps=1e-4))
    reference = jc.simulate(params, y0, engine=jc.Exact(jc.NonsmoothOptions.reference(t_end=150.0,
                                                                      transient=100.0)))
    a, b = np.asarray(smoothed.amplitudes), np.asarray(reference.amplitudes)
    assert np.all(b > 0.5)  # both on stick-slip
    np.testing.assert_allclose(a, b, rtol=1e-2)


def test_a_lattice_couples_as_its_list_of_links():
    """The lattice's shifts (one eta_c) and per-axis tensions (one per link) give the
    force of the same links taken one by one through the incidence matrix: each
    boundary in each direction, on a 4 x 5 lattice and a 2 x 2 one (where periodic
    links double)."""
    import jax.numpy as jnp

    rng = np.random.default_rng(1)
    for shape, boundary in [((4, 5), ("fixed", "periodic")), ((4, 5), ("periodic", "free")),
                            ((4, 5), ("free", "fixed")), ((2, 2), ("periodic", "periodic"))]:
        graph = jc.Graph.lattice(*shape, boundary)
        links = jc.Graph.from_links(graph.n_osc, graph.links)
        x = jnp.asarray(rng.normal(size=graph.n_osc))
        for eta in (0.3, rng.uniform(0.1, 1.0, graph.n_links)):
            got = jc.coupling_force(jc.ChainParams(graph=graph, eta_c=eta), x)
            expected = jc.coupling_force(jc.ChainParams(graph=links, eta_c=eta), x)
            np.testing.assert_allclose(got, expected, rtol=0, atol=1e-14)
