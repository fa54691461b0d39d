"""jaxchain: a differentiable JAX simulator of chains of friction-excited oscillators.

Implements eq. (5) of *Multiple spatially localized dynamical states in
friction-excited oscillator chains*. Importing jaxchain turns on float64 in JAX: the
long stick-slip integrations need it. On a CPU it also asks JAX for one device per
core, so that ensembles run side by side on all cores (see `_one_device_per_core`),
and lets XLA compile the step loop into one kernel (see `_compiled_step_loop`).
"""

import importlib
import os

import jax

jax.config.update("jax_enable_x64", True)


def _one_device_per_core() -> None:
    """Expose one JAX CPU device per usable core. XLA runs one vmapped integration
    on one core; `ensemble` and `crosscheck` spread their trajectories over the
    devices. Left alone when the user chose the device count (`jax_num_cpu_devices`
    or `--xla_force_host_platform_device_count` in XLA_FLAGS) and when JAX's
    backends are already running (then there is one CPU device)."""
    if (jax.config.jax_num_cpu_devices != -1
            or "xla_force_host_platform_device_count" in os.environ.get("XLA_FLAGS", "")):
        return
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    try:
        jax.config.update("jax_num_cpu_devices", max(1, cores or 1))
    except RuntimeError:  # backends already initialised
        pass


#: XLA's CPU backend runs a while loop op by op, through its runtime, unless the
#: loop's buffers are smaller than this threshold (in bytes). Raised, a diffrax step
#: loop compiles into one kernel: 0.85 us per step instead of 4.2 on the Fig. 4
#: chain (benchmarks/run.py).
XLA_FLAGS = ("--xla_backend_extra_options="
             "xla_cpu_small_while_loop_byte_threshold=1000000000")


def _compiled_step_loop() -> None:
    """Set `XLA_FLAGS` before JAX's backends start, unless the user set XLA_FLAGS
    (then theirs are kept as they are). Has no effect once a backend runs."""
    if "XLA_FLAGS" not in os.environ:
        os.environ["XLA_FLAGS"] = XLA_FLAGS


_one_device_per_core()
_compiled_step_loop()

#: Public name -> the module that defines it. The names are imported on first use
#: (PEP 562), so that `import jaxchain` costs JAX alone and a command loads only
#: what it needs (diffrax, xarray, matplotlib and scipy are imported by the modules
#: that use them).
_EXPORTS = {
    "ValidationError": "._errors",
    "ensemble": "._ensemble",
    "friction_coefficient": "._physics.friction",
    "slip_friction_force": "._physics.friction",
    "smoothed_friction_force": "._physics.friction",
    "AbstractFrictionLaw": "._physics.friction",
    "ExponentialDecay": "._physics.friction",
    "Stribeck": "._physics.friction",
    "Polynomial": "._physics.friction",
    "Coulomb": "._physics.friction",
    "FRICTION_LAWS": "._physics.friction",
    "static_friction": "._physics.friction",
    "AbstractInitialCondition": "._physics.initial",
    "GivenState": "._physics.initial",
    "OutOfPhaseExcitation": "._physics.initial",
    "excited_block": "._physics.initial",
    "localized_family": "._physics.initial",
    "jacobian": "._physics.model",
    "mechanical_energy": "._physics.model",
    "stick_force": "._physics.model",
    "split_vector_field": "._physics.model",
    "steady_sliding": "._physics.model",
    "vector_field": "._physics.model",
    "stick_slip_existence_limit": "._nonsmooth.existence",
    "NonsmoothOptions": "._nonsmooth.options",
    "NONSMOOTH_STATUS": "._nonsmooth.solve",
    "NonsmoothObservables": "._nonsmooth.solve",
    "simulate_nonsmooth": "._nonsmooth.solve",
    "SWITCH_KINDS": "._nonsmooth.switching",
    "SimulationOptions": "._options",
    "ChainParams": "._physics.params",
    "mistune": "._physics.params",
    "single_oscillator": "._physics.params",
    "stack_chains": "._physics.params",
    "with_parameter": "._physics.params",
    "parameter_value": "._physics.params",
    "parameter_name": "._physics.params",
    "BOUNDARIES": "._physics.chain",
    "Mistuning": "._physics.chain",
    "coupling_force": "._physics.chain",
    "stiffness_matrix": "._physics.chain",
    "chain_record": "._physics.record",
    "chain_from_record": "._physics.record",
    "lane_params": "._lanes",
    "plot_localized_states": "._plots.localized",
    "save_dataset": "._results",
    "to_dataset": "._results",
    "STATUS": "._simulate",
    "Observables": "._simulate",
    "simulate": "._simulate",
    "integrate": "._simulate",
    "observe": "._simulate",
    "SOLVERS": "._solvers",
    "DEFAULT_SOLVER": "._solvers",
    "auto_solver": "._solvers",
    "STICK_BAND": "._physics.stick",
    "sticks": "._physics.stick",
    "crosscheck": "._crosscheck",
    "HopfPoint": "._bifurcation.hopf",
    "growth_rates": "._bifurcation.hopf",
    "hopf_eps_correction": "._bifurcation.hopf",
    "hopf_point": "._bifurcation.hopf",
    "hopf_vd_analytic": "._bifurcation.hopf",
    "mode_eigenvalues": "._bifurcation.hopf",
    "steady_sliding_eigenvalues": "._bifurcation.hopf",
    "leading_growth_rate": "._bifurcation.hopf",
    "first_lyapunov_coefficient": "._bifurcation.lyapunov",
    "PeriodicOrbit": "._bifurcation.shooting",
    "ShootingOptions": "._bifurcation.shooting",
    "floquet_multipliers": "._bifurcation.shooting",
    "monodromy": "._bifurcation.shooting",
    "periodic_orbit": "._bifurcation.shooting",
    "shooting_residual": "._bifurcation.shooting",
    "Branch": "._bifurcation.continuation",
    "ContinuationOptions": "._bifurcation.continuation",
    "ContinuationProblem": "._bifurcation.continuation",
    "PseudoArclength": "._bifurcation.continuation",
    "continuation": "._bifurcation.continuation",
    "hopf_cycle": "._bifurcation.limit_cycles",
    "BIFURCATION_KINDS": "._bifurcation.bifurcations",
    "BifurcationPoint": "._bifurcation.bifurcations",
    "locate_bifurcations": "._bifurcation.bifurcations",
    "localized_branches": "._snake",
    "localization_factor": "._physics.localization",
    "weak_disorder_localization": "._physics.localization",
    "passband_frequency": "._physics.localization",
    "inverse_participation_ratio": "._physics.localization",
    "damped_decay": "._physics.localization",
    "mistuning_study": "._mistuning.study",
    "study_chains": "._mistuning.study",
    "upper_edges": "._mistuning.edges",
    "localized_fold": "._mistuning.edges",
    "intentional_mistuning": "._mistuning.design",
    "MistuningDesign": "._mistuning.design",
    "pattern_deviations": "._mistuning.design",
    "plot_snake": "._plots.snake",
    "plot_mistuning_study": "._plots.mistuning",
    "plot_site_edges": "._plots.mistuning",
    "plot_mistuned_states": "._plots.mistuning",
    "plot_mistuning_design": "._plots.mistuning",
    "design_study": "._mistuning.design_study",
    "limit_cycle_problem": "._bifurcation.limit_cycles",
    "FoldPoint": "._bifurcation.fold",
    "fold_point": "._bifurcation.fold",
    "solve_fold": "._bifurcation.fold",
    "BoundaryCurves": "._bifurcation.two_parameter",
    "boundary_curves": "._bifurcation.two_parameter",
    "fold_and_derivative": "._bifurcation.two_parameter",
    "fold_curve": "._bifurcation.two_parameter",
    "fold_curve_problem": "._bifurcation.two_parameter",
    "hopf_vd": "._bifurcation.two_parameter",
    "DampingDesign": "._bifurcation.design",
    "smallest_damping": "._bifurcation.design",
    "work_precision": "._work_precision",
    "open_sweep": "._sweep.sweep",
    "sweep": "._sweep.sweep",
    "front_fractions": "._sweep.fronts",
    "front_ranges": "._sweep.fronts",
    "propagating_fronts": "._sweep.fronts",
    "plot_bifurcation_diagram": "._plots.sweep",
    "plot_bistable_region": "._plots.bifurcation",
    "plot_limit_cycle_branch": "._plots.bifurcation",
    "plot_crosscheck": "._plots.crosscheck",
    "plot_work_precision": "._plots.work_precision",
    "AbstractObserver": "._observers.base",
    "Chunk": "._observers.base",
    "Extrema": "._observers.extrema",
    "Energy": "._observers.energy",
    "PeakTimes": "._observers.crossings",
    "PoincareSection": "._observers.crossings",
    "TimeSeries": "._observers.series",
    "LargestLyapunov": "._observers.lyapunov",
    "time_delays": "._dynamics.delays",
    "delay_spread": "._dynamics.delays",
    "reference_oscillator": "._dynamics.delays",
    "CLASSES": "._dynamics.classify",
    "classify": "._dynamics.classify",
    "ClassTolerances": "._states",
    "state_class": "._states",
    "PAPER_SOLUTIONS": "._dynamics.scenes",
    "observe_solutions": "._dynamics.scenes",
    "time_series_scene": "._dynamics.scenes",
    "time_delay_scene": "._dynamics.scenes",
    "phase_portrait_scene": "._dynamics.scenes",
    "orbit_diagram_scene": "._dynamics.scenes",
    "plot_time_series": "._plots.dynamics",
    "plot_time_delays": "._plots.dynamics",
    "plot_phase_portraits": "._plots.dynamics",
    "plot_orbit_diagram": "._plots.dynamics",
    "plot_states_and_orbits": "._plots.dynamics",
    "failure_hint": "._hints",
    "stress_cases": "._stress.cases",
    "stress": "._stress.run",
    "Box": "._basin.sampling",
    "sample_states": "._basin.sampling",
    "halc_clusters": "._basin.classes",
    "wilson_interval": "._basin.classes",
    "basin_stability": "._basin.basin",
    "plot_basin_stability": "._plots.basin",
    "plot_halc_histogram": "._plots.basin",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'jaxchain' has no attribute {name!r}")
    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
