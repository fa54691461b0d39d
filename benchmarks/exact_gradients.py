"""Gradients through the exact engine over long horizons: one trajectory of the Fig. 4
ring (N = 20, v_d = 1.5, eq. (8) with k = 5 excited), the derivative of
sum(y(t_end)^2) in v_d. For each horizon, in a fresh process (so that its peak
memory is its own), under `jax.jit`: the value, the forward-mode derivative
(`jax.jacfwd`, `adjoint="forward"`) and the reverse-mode one (`jax.grad`,
`adjoint="reverse"`), each called twice (the second call compiled already).

At t_end 1000 and 15000, at the exact engine's defaults (rtol 1e-7): the wall time
of each second call, their ratios to the value's, and the process's peak resident
memory; bounded memory in reverse mode shows as nearly the same peak at both
horizons. The two modes take different steps (different compiled programs), so
over these horizons, where the state is irregular and the derivative grows, they
agree only as far as the tolerance carries. At t_end 100 at the reference
tolerances (rtol = atol = 1e-12), the relative difference between the two
derivatives. Run: `python benchmarks/exact_gradients.py`. Exits with status 1 if
the two modes differ there by more than 1e-8 relative.
"""

import json
import os
import subprocess
import sys
import time


def _peak_rss_mb() -> float:
    """Peak resident memory of this process in MiB (VmHWM, Linux)."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def child(t_end: float, reference: bool) -> dict:
    """Time the value and both derivatives at `t_end` in this process, at the
    reference tolerances if `reference`."""
    import jax
    import jax.numpy as jnp

    import jaxchain as jc
    from jaxchain._engine.exact.solve import nonsmooth_flow

    jc.configure()
    n = 20
    y0 = jnp.asarray(jc.OutOfPhaseExcitation.eq8(jc.excited_block(n, 5))(
        jc.ChainParams(n_osc=n, v_d=1.5)))

    def energy(v_d, options):
        ys, _ = nonsmooth_flow(jc.ChainParams(n_osc=n, v_d=v_d), y0,
                                  jnp.array([t_end]), options)
        return jnp.sum(ys[0] ** 2)

    make = jc.NonsmoothOptions.reference if reference else jc.NonsmoothOptions
    forward = make(t_end=t_end, transient=0.0)
    reverse = make(t_end=t_end, transient=0.0, adjoint="reverse")
    out = {"t_end": t_end}
    for name, fn, options in (("value", energy, forward),
                              ("forward", jax.jacfwd(energy), forward),
                              ("reverse", jax.grad(energy), reverse)):
        compiled = jax.jit(fn, static_argnums=1)
        walls = []
        for _ in range(2):
            start = time.perf_counter()
            result = float(compiled(1.5, options))
            walls.append(time.perf_counter() - start)
        out[name] = {"result": result, "first_s": walls[0], "wall_s": walls[1]}
    out["peak_rss_mb"] = _peak_rss_mb()
    return out


def main() -> int:
    failed = False
    for t_end, reference in ((100.0, True), (1000.0, False), (15000.0, False)):
        run = subprocess.run([sys.executable, __file__, "--child", str(t_end),
                              str(int(reference))],
                             capture_output=True, text=True, env=dict(os.environ))
        if run.returncode:
            print(run.stderr, file=sys.stderr)
            return 1
        r = json.loads(run.stdout.splitlines()[-1])
        value = r["value"]["wall_s"]
        fwd, rev = r["forward"]["result"], r["reverse"]["result"]
        difference = abs(rev - fwd) / abs(fwd)
        failed |= reference and difference > 1e-8
        tolerances = "rtol 1e-12" if reference else "defaults"
        print(f"t_end {t_end:g} ({tolerances}): value {value:.2f} s; forward-mode derivative "
              f"{r['forward']['wall_s']:.2f} s ({r['forward']['wall_s'] / value:.1f}x); "
              f"reverse-mode {r['reverse']['wall_s']:.2f} s "
              f"({r['reverse']['wall_s'] / value:.1f}x); the two differ by "
              f"{difference:.1e} relative; peak memory {r['peak_rss_mb']:.0f} MiB")
    return int(failed)


if __name__ == "__main__":
    if sys.argv[1:2] == ["--child"]:
        print(json.dumps(child(float(sys.argv[2]), bool(int(sys.argv[3])))))
        sys.exit(0)
    sys.exit(main())
