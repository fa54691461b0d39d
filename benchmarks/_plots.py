"""The figures of benchmarks/run.py (comparisons 4 and 5)."""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; this script never shows a window
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def plot_n_osc(raw: dict, path: Path) -> Path:
    """Time per step and peak memory against the ring size (comparison 4), with the
    line proportional to n_osc through the n_osc = 20 point for reference."""
    res = raw["results"]
    n = np.array([r["n_osc"] for r in res], dtype=float)
    us = np.array([r["us_per_step"] for r in res])
    peak = np.array([r["peak_rss_mb"] for r in res])
    base = np.array([r["rss_after_import_mb"] for r in res])
    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.6), constrained_layout=True)
    a.loglog(n, us, "o-", label="jaxchain")
    a.loglog(n, us[0] * n / n[0], "k:", label="∝ n_osc")
    a.set(xlabel="n_osc", ylabel="µs per step",
          title=f"time per step (t_end {raw['t_end']:g})")
    a.legend()
    b.semilogx(n, peak, "o-", label="peak RSS")
    b.semilogx(n, base, "s--", label="RSS after import")
    b.set(xlabel="n_osc", ylabel="MiB", title="memory (own process)", ylim=(0, None))
    b.legend()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_sizes(raw: dict, path: Path) -> Path:
    """Wall time and throughput against the number of trajectories (comparison 5):
    measured points solid, an extrapolated size dashed and hollow, and the serial
    baseline (the steps at one trajectory's cost per step) dotted."""
    res = raw["results"]
    size = np.array([r["size"] for r in res], dtype=float)
    wall = np.array([r["wall_s"] for r in res])
    measured = np.array([r["measured"] for r in res])
    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.6), constrained_layout=True)
    for ax, y, label, plot in ((a, wall, "wall time (s)", "loglog"),
                               (b, size / wall, "trajectories per s", "semilogx")):
        getattr(ax, plot)(size[measured], y[measured], "o-", label="measured")
        if not measured.all():
            last = np.flatnonzero(measured)[-1]
            ext = np.r_[last, np.flatnonzero(~measured)]
            getattr(ax, plot)(size[ext], y[ext], "o--", mfc="none", color="C0",
                              label="extrapolated (linear)")
        ax.set(xlabel="trajectories", ylabel=label)
    b.set_ylim(0, None)
    serial = np.array([r["serial_s"] for r in res])
    a.loglog(size, serial, "k:", label="serial (1 trajectory's cost per step)")
    a.set_title(f"wall time (t_end {raw['t_end']:g})")
    b.set_title("throughput")
    a.legend(loc="upper left")
    b.legend()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
