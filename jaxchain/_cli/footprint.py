"""What a run will hold in memory, estimated before anything is built, and the
refusal (exit status 2, one line with the estimate) of a run that this machine
cannot hold: a ring of ten million oscillators or a horizon of 1e12 time units
failed with `MemoryError` after a minute, or asked the allocator for 32 GB."""

import math
import os
import resource

from .parser import UsageError

#: Bytes of one float64.
_FLOAT = 8

#: Arrays of one oscillator's size that any run holds at least: the chain's
#: per-oscillator fields (stiffness, mass, damping, load, the links' coupling...)
#: and the states of a step (the state, its stages and error estimate, the
#: observers' running extrema).
_PER_OSCILLATOR = 32


def memory_limit() -> tuple[int, str]:
    """The memory this process can hold, in bytes, and what sets it: the least of
    the machine's physical memory, the limit of its control group (a container, a
    batch job) and the process's limits on its address space and data (ulimit -v,
    ulimit -d)."""
    limits = [(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"),
               "this machine's memory")]
    for path in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            with open(path) as f:
                limits.append((int(f.read().strip()), "the memory limit of its cgroup"))
        except (OSError, ValueError):  # no such cgroup, or "max"
            pass
    for name, what in (("RLIMIT_AS", "ulimit -v"), ("RLIMIT_DATA", "ulimit -d")):
        soft = resource.getrlimit(getattr(resource, name))[0]
        if soft != resource.RLIM_INFINITY:
            limits.append((soft, what))
    return min(limits)


def run_footprint(n_osc: int, horizon=None) -> list[tuple[int, str, str]]:
    """A lower bound of the memory of one run of `n_osc` oscillators over `horizon`
    (`SimulationOptions` or `NonsmoothOptions`; None: the chain alone), in parts:
    (bytes, what, the option that sets it). Each part is held at once by any run:
    the chain and the states of a step; the dense samples of one observed chunk
    (`sample_dt`), from which the observers take their extrema; the start times of
    a phase's chunks, which the integration scans over (proportional to t_end)."""
    parts = [(_PER_OSCILLATOR * _FLOAT * n_osc,
              f"{_PER_OSCILLATOR} arrays of {n_osc} oscillators", "n_osc")]
    if horizon is None:
        return parts
    phases = horizon.phases()
    sample_dt = getattr(horizon, "sample_dt", None)
    observed = [length for _, length, _, seen in phases if seen]
    if sample_dt is not None and observed:
        n_samples = math.ceil(max(observed) / sample_dt) + 1
        parts.append((n_samples * 2 * n_osc * _FLOAT,
                      f"the {n_samples} dense samples of one chunk, each of 2 x {n_osc} "
                      f"values", "n_osc"))
    chunks = max(count for _, _, count, _ in phases)
    parts.append((chunks * _FLOAT, f"the start times of its {chunks:.3g} chunks of "
                                   f"{horizon.chunk_length:g} time units", "t_end"))
    return parts


def check_footprint(n_osc: int, chain: str | None = None, horizon=None) -> None:
    """Refuse a run that needs more memory than this process can hold
    (`memory_limit`), before anything is built.

    **Arguments:**

    - `n_osc`: the number of oscillators.
    - `chain`: what set `n_osc`, named in the refusal ("--n-osc N" by default).
    - `horizon`: the run's options (`run_footprint`), or None for the chain alone.

    **Raises:**

    `UsageError` (exit status 2), one line naming the option of the largest part,
    the estimate and the limit.
    """
    parts = run_footprint(n_osc, horizon)
    total = sum(size for size, _, _ in parts)
    limit, what = memory_limit()
    if total <= limit:
        return
    size, part, field = max(parts)
    if field == "t_end":
        option, advice = f"--t-end {horizon.t_end:g}", "shorten --t-end"
    else:
        option, advice = chain or f"--n-osc {n_osc}", "use fewer oscillators"
    raise UsageError(f"{option}: the run would hold at least {_size(total)} ({_size(size)} "
                     f"for {part}), more than {what} ({_size(limit)}); {advice}")


def _size(n: float) -> str:
    """`n` bytes in words, in decimal units (1 GB = 1e9 bytes)."""
    unit = "B"
    for unit in ("B", "kB", "MB", "GB", "TB", "PB"):
        if n < 1000:
            break
        n /= 1000
    return f"{n:.3g} {unit}"
