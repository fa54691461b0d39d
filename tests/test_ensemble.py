import diffrax
import jax.numpy as jnp
import numpy as np
import xarray as xr

import jaxchain as jc
from helpers import SHORT, tree_allclose, tree_index


def test_ensemble_equals_runs_done_one_at_a_time():
    """3 initial conditions x 2 belt speeds, vmapped in one compiled function, give
    the same observables as 6 separate `simulate` calls."""
    p = jc.ChainParams(n_osc=4)
    masks = np.stack([jc.excited_block(4, k) for k in (1, 2, 4)])
    ics = jc.OutOfPhaseExcitation(excited=jnp.asarray(masks), velocity=jnp.zeros(3))
    v_d = [1.3, 1.6]
    obs = jc.ensemble(p, v_d, ics, options=SHORT, progress=False)
    assert obs.amplitudes.shape == (2, 3, 4) and obs.energy.shape == (2, 3)
    for i, vd in enumerate(v_d):
        for j, mask in enumerate(masks):
            single = jc.simulate(jc.ChainParams(n_osc=4, v_d=vd),
                                 jc.OutOfPhaseExcitation.eq8(mask), options=SHORT)
            lane = tree_index(obs, (i, j))
            assert tree_allclose(lane, single, rtol=1e-9, atol=1e-12)


def test_a_failing_trajectory_is_flagged_and_the_others_kept():
    p = jc.ChainParams(n_osc=2)
    good = jc.OutOfPhaseExcitation.eq8([True, False])(p)
    y0 = jnp.stack([good, good.at[0, 0].set(jnp.nan)])
    obs = jc.ensemble(p, [1.5], jc.GivenState(y0), options=SHORT, progress=False)
    assert obs.status.tolist() == [[0, 1]]
    assert np.all(np.isnan(obs.amplitudes[0, 1]))
    single = jc.simulate(p, good, options=SHORT)
    assert np.allclose(obs.amplitudes[0, 0], single.amplitudes, rtol=1e-9)


def test_dataset_round_trip_keeps_parameters(tmp_path):
    p = jc.ChainParams(n_osc=3, eps=2e-2)
    ics = jc.localized_family(3)
    obs = jc.ensemble(p, [1.5], ics, options=SHORT, progress=False)
    ds = jc.to_dataset(obs, p, [1.5], diffrax.Tsit5(), SHORT,
                       n_excited=[1, 2, 3], ics="eq8")
    path = jc.save_dataset(ds, tmp_path / "out" / "run.nc")
    back = xr.load_dataset(path)
    assert dict(back.sizes) == {"v_d": 1, "ic": 3, "osc": 3}
    assert back.attrs["eps"] == 2e-2 and back.attrs["n_osc"] == 3
    assert back.attrs["t_end"] == SHORT.t_end and back.attrs["solver"] == "Tsit5"
    assert back["n_excited"].values.tolist() == [1, 2, 3]
    assert np.allclose(back["energy"], 0.5 * (back["amplitudes"] ** 2).sum("osc"))
    assert np.array_equal(back["amplitudes"].values, np.asarray(obs.amplitudes))
