"""What jaxchain's XLA flag (`jc.XLA_FLAGS`: `xla_cpu_small_while_loop_byte_threshold`,
which `jc.configure()` sets) changes in the values XLA computes, for an upstream
report and a recheck on each JAX release. Each case runs in two fresh processes,
with the flag and without (XLA reads XLA_FLAGS when its backend starts).

1. The minimal program: `jnp.tan` and `jnp.cbrt` of the same 100000 inputs, inside
   a `lax.fori_loop` of one iteration and outside it, in one `jax.jit`. With the
   flag the loop is compiled as one kernel (XLA's small-while-loop hoisting) whose
   tan and cbrt round differently from the same operations outside it (jaxlib
   0.10.2: 31961 and 59064 inputs differ, by up to 2 and 3 units in the last
   place); without it the two agree bit for bit. Printed for each: the inputs
   where inside and outside differ, and the largest distance of each from NumPy's
   value in units in the last place.
2. The engine: the gradient in xi of sum(W * y(6)) on tests/test_saltation.py's
   ring of four, reverse mode (`adjoint="reverse"`) under `jax.jit`, at the
   reference tolerances, with the engine's workaround taken out (it evaluates
   the vector field through a LAPACK call in reverse mode, which keeps XLA from
   hoisting the loops; jaxchain/_engine/exact/stepping.py). Without the flag
   it is 7.7775, as central differences of the engine give with or without it;
   with the flag (jaxlib 0.10.2, an x86-64 CPU with AVX2 and FMA) 8.1122: the
   forward pass and the checkpointed recomputation of the backward pass differ
   by rounding (case 1's kind of difference, compounded through the step size
   control and the switches) and the gradient follows a path the forward pass
   did not take. With --xla_cpu_max_isa=SSE4_2, with the flag or without, the
   bits agree and so does the gradient.

The engine case could not be reduced further: diffrax's Runge-Kutta step loop
alone, with the same nested checkpointed loops and the chain's vector field, gives
the same bits with and without the flag.

Run: `python benchmarks/xla_loop_flag.py` (about 1 minute; `--minimal` only case
1, a few seconds). Exits with status 1 while the flag changes a value.
"""

import json
import os
import subprocess
import sys

FLAG = ("--xla_backend_extra_options="
        "xla_cpu_small_while_loop_byte_threshold=1000000000")

MINIMAL = r"""
import json, jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
x = jnp.asarray(np.random.default_rng(0).uniform(-50, 5, 100000))

def both(fn, n):  # n = 1, a traced bound, so that XLA keeps the loop
    return jax.lax.fori_loop(0, n, lambda i, y: fn(y), x), fn(x)

out = {}
for name, fn, ref in (("tan", jnp.tan, np.tan), ("cbrt", jnp.cbrt, np.cbrt)):
    inside, outside = map(np.asarray, jax.jit(both, static_argnums=0)(fn, 1))
    ulp = lambda v: float(np.max(np.abs(v - ref(x)) / np.spacing(np.abs(ref(x)))))
    out[name] = [int(np.sum(inside != outside)), ulp(inside), ulp(outside)]
print(json.dumps(out))
"""

ENGINE = r"""
import json, jax, jax.numpy as jnp, numpy as np
import jaxchain as jc
from jaxchain._engine.exact.solve import nonsmooth_flow
jc.configure()
from jaxchain._engine.exact import stepping
stepping._term = lambda options: stepping._TERM  # the workaround taken out
Y0 = jnp.array([[3.0, -0.5, 0.3, -1.0], [1.3, 0.2, 1.5, -0.4]])
W = jnp.array([[1.0, -0.7, 0.4, 0.2], [0.3, 0.5, -0.9, 0.6]])
options = jc.NonsmoothOptions.reference(t_end=6.0, transient=0.0, adjoint="reverse")

def f(xi):
    params = jc.ChainParams(n_osc=4, v_d=1.2, xi=xi)
    return jnp.sum(W * nonsmooth_flow(params, Y0, jnp.array([6.0]), options)[0][0])

print(json.dumps({"gradient in xi": float(jax.jit(jax.grad(f))(0.05))}))
"""


def run(code: str, flags: str) -> dict:
    env = dict(os.environ, XLA_FLAGS=flags)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, check=True)
    return json.loads(out.stdout)


def main() -> int:
    cases = [("minimal", MINIMAL)] + ([] if "--minimal" in sys.argv else [("engine", ENGINE)])
    changed = False
    for name, code in cases:
        with_flag, without = run(code, FLAG), run(code, "")
        print(f"{name}: with the flag {with_flag}\n{' ' * len(name)}  without it  {without}")
        if name == "minimal":
            changed |= any(v[0] > 0 for v in with_flag.values())
            changed |= any(v[0] > 0 for v in without.values())
        else:
            changed |= with_flag != without
    print("the flag changes values" if changed else "the flag changes no value")
    return int(changed)


if __name__ == "__main__":
    sys.exit(main())
