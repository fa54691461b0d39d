"""The process set-up that jaxchain needs, made only when asked (`configure`):
importing jaxchain changes nothing global. This module imports JAX only inside
the functions that use it, so that the command line's client
(`jaxchain._cli.warm`) can read the version and the source identity without it."""

import contextlib
import hashlib
import os
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path


def _installed_version() -> str:
    """jaxchain's version as installed (pyproject.toml), "unknown" when it is run
    from a source tree that pip has not installed."""
    try:
        return version("jaxchain")
    except PackageNotFoundError:
        return "unknown"


#: The version of jaxchain (`jaxchain.__version__`), written into every result.
VERSION = _installed_version()

#: XLA's CPU backend runs a while loop op by op, through its runtime, unless the
#: loop's buffers are smaller than this threshold (in bytes). Raised, a diffrax step
#: loop compiles into one kernel: 0.85 us per step instead of 4.2 on the Fig. 4
#: chain (benchmarks/run.py). Such a kernel rounds some operations differently
#: from the same operations outside it (benchmarks/xla_loop_flag.py), which once
#: made reverse-mode gradients of the exact engine wrong (docs/exact.md); every
#: kind of program that jaxchain builds is tested to compute the same with and
#: without it (tests/test_setup.py).
XLA_FLAGS = ("--xla_backend_extra_options="
             "xla_cpu_small_while_loop_byte_threshold=1000000000")


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where the system has one)."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


def _device_count_chosen() -> bool:
    """Whether the CPU device count was chosen before `configure`: by
    `jax.config.update("jax_num_cpu_devices", n)`, the environment variable
    JAX_NUM_CPU_DEVICES, or `--xla_force_host_platform_device_count` in XLA_FLAGS."""
    import jax

    return (jax.config.jax_num_cpu_devices != -1
            or "xla_force_host_platform_device_count" in os.environ.get("XLA_FLAGS", ""))


def configure(devices: int | None = None) -> None:
    """Set up this process for jaxchain, as the `jaxchain` command does. Call it once,
    before the first JAX computation of the process (a notebook's first cell):

    - float64 in JAX (`jax_enable_x64`): the long stick-slip integrations and the
        Newton solves of the boundaries need it, and every function that takes a
        `ChainParams` refuses to run without it;
    - on a CPU, one JAX device per usable core (or `devices`), so that ensembles,
        sweeps and basin stability run their trajectories side by side on every
        core (`run_lanes`); a count chosen before (`jax_num_cpu_devices`,
        JAX_NUM_CPU_DEVICES, `--xla_force_host_platform_device_count`) is kept
        unless `devices` is given;
    - the XLA flag `XLA_FLAGS` that lets XLA compile the step loop into one kernel
        (about 5x faster per step on a CPU), unless XLA_FLAGS is already set (then
        it is kept as it is). It holds for the whole process, the user's own JAX
        code included, and rounds some operations inside small loops differently
        (benchmarks/xla_loop_flag.py); to run without it, set XLA_FLAGS before
        (`os.environ["XLA_FLAGS"] = ""`, or `XLA_FLAGS= python ...`).

    The device count and the XLA flags take effect only before JAX's backends
    start (the first computation or `jax.devices()`); afterwards they are left as
    they are, and only float64 is turned on.

    **Arguments:**

    - `devices`: the number of CPU devices, by default one per usable core.

    **Raises:**

    `ValidationError` if `devices` is not a positive integer.
    """
    import jax

    from ._errors import ValidationError

    if devices is not None and (not isinstance(devices, int) or devices < 1):
        raise ValidationError(f"devices must be a positive integer, got {devices!r}")
    jax.config.update("jax_enable_x64", True)
    if "XLA_FLAGS" not in os.environ:
        os.environ["XLA_FLAGS"] = XLA_FLAGS
    if devices is None and _device_count_chosen():
        return
    with contextlib.suppress(RuntimeError):  # backends already started
        jax.config.update("jax_num_cpu_devices", devices or usable_cores())


def check_float64() -> None:
    """Refuse to build a chain without float64 in JAX.

    **Raises:**

    `RuntimeError` naming `jaxchain.configure()`, when `jax_enable_x64` is off.
    """
    import jax

    if not jax.config.jax_enable_x64:
        raise RuntimeError(
            "jaxchain needs float64 in JAX: call jaxchain.configure() once, before "
            "anything else (it also gives JAX one CPU device per core), or "
            "jax.config.update('jax_enable_x64', True)")


def source_identity() -> str:
    """The identity of jaxchain's source files (`*.py` and `*.pyi` of the package):
    the SHA-256 of their names, sizes and modification times (in nanoseconds),
    which a change of their content changes too. Reading their stat costs a few
    milliseconds, where hashing their content cost 0.1 s of every command's start
    (`benchmarks/fixed_cost.py`); a file rewritten with its old size and time
    forced back is the one change this misses. Part of the key of a kept program
    (`jaxchain._engine.programs.code_identity`) and of the warm process that serves
    the command line (`jaxchain._cli.warm`)."""
    package = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for path in sorted([*package.rglob("*.py"), *package.rglob("*.pyi")]):
        stat = path.stat()
        digest.update(f"{path.relative_to(package)}:{stat.st_size}:{stat.st_mtime_ns};".encode())
    return digest.hexdigest()
