"""jaxchain: a differentiable JAX simulator of chains of friction-excited oscillators.

Implements eq. (5) of *Multiple spatially localized dynamical states in
friction-excited oscillator chains*. Importing jaxchain turns on float64 in JAX: the
long stick-slip integrations need it. On a CPU it also asks JAX for one device per
core, so that ensembles run side by side on all cores (see `_one_device_per_core`),
and lets XLA compile the step loop into one kernel (see `_compiled_step_loop`).
"""

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

from ._ensemble import ensemble as ensemble  # noqa: E402
from ._physics.friction import friction_coefficient as friction_coefficient  # noqa: E402
from ._physics.friction import slip_friction_force as slip_friction_force  # noqa: E402
from ._physics.friction import smoothed_friction_force as smoothed_friction_force  # noqa: E402
from ._physics.initial import AbstractInitialCondition as AbstractInitialCondition  # noqa: E402
from ._physics.initial import GivenState as GivenState  # noqa: E402
from ._physics.initial import OutOfPhaseExcitation as OutOfPhaseExcitation  # noqa: E402
from ._physics.initial import excited_block as excited_block  # noqa: E402
from ._physics.initial import localized_family as localized_family  # noqa: E402
from ._physics.model import jacobian as jacobian  # noqa: E402
from ._physics.model import mechanical_energy as mechanical_energy  # noqa: E402
from ._physics.model import stick_force as stick_force  # noqa: E402
from ._nonsmooth.existence import stick_slip_existence_limit as stick_slip_existence_limit  # noqa: E402,E501
from ._nonsmooth.options import NonsmoothOptions as NonsmoothOptions  # noqa: E402
from ._nonsmooth.solve import NONSMOOTH_STATUS as NONSMOOTH_STATUS  # noqa: E402
from ._nonsmooth.solve import NonsmoothObservables as NonsmoothObservables  # noqa: E402
from ._nonsmooth.solve import simulate_nonsmooth as simulate_nonsmooth  # noqa: E402
from ._nonsmooth.switching import SWITCH_KINDS as SWITCH_KINDS  # noqa: E402
from ._physics.model import split_vector_field as split_vector_field  # noqa: E402
from ._physics.model import steady_sliding as steady_sliding  # noqa: E402
from ._physics.model import vector_field as vector_field  # noqa: E402
from ._options import SimulationOptions as SimulationOptions  # noqa: E402
from ._physics.params import ChainParams as ChainParams  # noqa: E402
from ._physics.params import mistune as mistune  # noqa: E402
from ._physics.params import single_oscillator as single_oscillator  # noqa: E402
from ._physics.params import stack_chains as stack_chains  # noqa: E402
from ._physics.friction import AbstractFrictionLaw as AbstractFrictionLaw  # noqa: E402
from ._physics.friction import ExponentialDecay as ExponentialDecay  # noqa: E402
from ._physics.friction import Stribeck as Stribeck  # noqa: E402
from ._physics.friction import Polynomial as Polynomial  # noqa: E402
from ._physics.friction import Coulomb as Coulomb  # noqa: E402
from ._physics.friction import FRICTION_LAWS as FRICTION_LAWS  # noqa: E402
from ._physics.friction import static_friction as static_friction  # noqa: E402
from ._physics.chain import BOUNDARIES as BOUNDARIES  # noqa: E402
from ._physics.chain import Mistuning as Mistuning  # noqa: E402
from ._physics.chain import coupling_force as coupling_force  # noqa: E402
from ._physics.chain import stiffness_matrix as stiffness_matrix  # noqa: E402
from ._physics.record import chain_record as chain_record  # noqa: E402
from ._physics.record import chain_from_record as chain_from_record  # noqa: E402
from ._lanes import lane_params as lane_params  # noqa: E402
from ._physics.params import with_parameter as with_parameter  # noqa: E402
from ._physics.params import parameter_value as parameter_value  # noqa: E402
from ._plots.localized import plot_localized_states as plot_localized_states  # noqa: E402
from ._results import save_dataset as save_dataset  # noqa: E402
from ._results import to_dataset as to_dataset  # noqa: E402
from ._simulate import STATUS as STATUS  # noqa: E402
from ._simulate import Observables as Observables  # noqa: E402
from ._simulate import simulate as simulate  # noqa: E402
from ._solvers import SOLVERS as SOLVERS  # noqa: E402
from ._solvers import DEFAULT_SOLVER as DEFAULT_SOLVER  # noqa: E402
from ._physics.stick import STICK_BAND as STICK_BAND  # noqa: E402
from ._physics.stick import sticks as sticks  # noqa: E402
from ._crosscheck import crosscheck as crosscheck  # noqa: E402
from ._bifurcation.hopf import HopfPoint as HopfPoint  # noqa: E402
from ._bifurcation.hopf import growth_rates as growth_rates  # noqa: E402
from ._bifurcation.hopf import hopf_eps_correction as hopf_eps_correction  # noqa: E402
from ._bifurcation.hopf import hopf_point as hopf_point  # noqa: E402
from ._bifurcation.hopf import hopf_vd_analytic as hopf_vd_analytic  # noqa: E402
from ._bifurcation.hopf import mode_eigenvalues as mode_eigenvalues  # noqa: E402
from ._bifurcation.hopf import steady_sliding_eigenvalues as steady_sliding_eigenvalues  # noqa: E402,E501
from ._bifurcation.hopf import leading_growth_rate as leading_growth_rate  # noqa: E402
from ._bifurcation.lyapunov import first_lyapunov_coefficient as first_lyapunov_coefficient  # noqa: E402,E501
from ._bifurcation.shooting import PeriodicOrbit as PeriodicOrbit  # noqa: E402
from ._bifurcation.shooting import ShootingOptions as ShootingOptions  # noqa: E402
from ._bifurcation.shooting import floquet_multipliers as floquet_multipliers  # noqa: E402
from ._bifurcation.shooting import monodromy as monodromy  # noqa: E402
from ._bifurcation.shooting import periodic_orbit as periodic_orbit  # noqa: E402
from ._bifurcation.shooting import shooting_residual as shooting_residual  # noqa: E402
from ._bifurcation.continuation import Branch as Branch  # noqa: E402
from ._bifurcation.continuation import ContinuationOptions as ContinuationOptions  # noqa: E402
from ._bifurcation.continuation import ContinuationProblem as ContinuationProblem  # noqa: E402
from ._bifurcation.continuation import PseudoArclength as PseudoArclength  # noqa: E402
from ._bifurcation.continuation import continuation as continuation  # noqa: E402
from ._bifurcation.limit_cycles import hopf_cycle as hopf_cycle  # noqa: E402
from ._bifurcation.limit_cycles import limit_cycle_problem as limit_cycle_problem  # noqa: E402
from ._bifurcation.fold import FoldPoint as FoldPoint  # noqa: E402
from ._bifurcation.fold import fold_point as fold_point  # noqa: E402
from ._bifurcation.fold import solve_fold as solve_fold  # noqa: E402
from ._bifurcation.two_parameter import BoundaryCurves as BoundaryCurves  # noqa: E402
from ._bifurcation.two_parameter import boundary_curves as boundary_curves  # noqa: E402
from ._bifurcation.two_parameter import fold_and_derivative as fold_and_derivative  # noqa: E402
from ._bifurcation.two_parameter import fold_curve as fold_curve  # noqa: E402
from ._bifurcation.two_parameter import fold_curve_problem as fold_curve_problem  # noqa: E402,E501
from ._bifurcation.two_parameter import hopf_vd as hopf_vd  # noqa: E402
from ._bifurcation.design import DampingDesign as DampingDesign  # noqa: E402
from ._bifurcation.design import smallest_damping as smallest_damping  # noqa: E402
from ._work_precision import work_precision as work_precision  # noqa: E402
from ._sweep.sweep import open_sweep as open_sweep  # noqa: E402
from ._sweep.sweep import sweep as sweep  # noqa: E402
from ._sweep.fronts import front_fractions as front_fractions  # noqa: E402
from ._sweep.fronts import front_ranges as front_ranges  # noqa: E402
from ._sweep.fronts import propagating_fronts as propagating_fronts  # noqa: E402
from ._physics.params import parameter_name as parameter_name  # noqa: E402
from ._plots.sweep import plot_bifurcation_diagram as plot_bifurcation_diagram  # noqa: E402
from ._plots.bifurcation import plot_bistable_region as plot_bistable_region  # noqa: E402
from ._plots.bifurcation import plot_limit_cycle_branch as plot_limit_cycle_branch  # noqa: E402
from ._plots.crosscheck import plot_crosscheck as plot_crosscheck  # noqa: E402
from ._plots.work_precision import plot_work_precision as plot_work_precision  # noqa: E402
from ._simulate import integrate as integrate  # noqa: E402
from ._simulate import observe as observe  # noqa: E402
from ._observers.base import AbstractObserver as AbstractObserver  # noqa: E402
from ._observers.base import Chunk as Chunk  # noqa: E402
from ._observers.extrema import Extrema as Extrema  # noqa: E402
from ._observers.energy import Energy as Energy  # noqa: E402
from ._observers.crossings import PeakTimes as PeakTimes  # noqa: E402
from ._observers.crossings import PoincareSection as PoincareSection  # noqa: E402
from ._observers.series import TimeSeries as TimeSeries  # noqa: E402
from ._observers.lyapunov import LargestLyapunov as LargestLyapunov  # noqa: E402
from ._dynamics.delays import time_delays as time_delays  # noqa: E402
from ._dynamics.delays import delay_spread as delay_spread  # noqa: E402
from ._dynamics.delays import reference_oscillator as reference_oscillator  # noqa: E402
from ._dynamics.classify import CLASSES as CLASSES  # noqa: E402
from ._states import ClassTolerances as ClassTolerances  # noqa: E402
from ._states import state_class as state_class  # noqa: E402
from ._dynamics.classify import classify as classify  # noqa: E402
from ._dynamics.scenes import PAPER_SOLUTIONS as PAPER_SOLUTIONS  # noqa: E402
from ._dynamics.scenes import observe_solutions as observe_solutions  # noqa: E402
from ._dynamics.scenes import time_series_scene as time_series_scene  # noqa: E402
from ._dynamics.scenes import time_delay_scene as time_delay_scene  # noqa: E402
from ._dynamics.scenes import phase_portrait_scene as phase_portrait_scene  # noqa: E402
from ._dynamics.scenes import orbit_diagram_scene as orbit_diagram_scene  # noqa: E402
from ._plots.dynamics import plot_time_series as plot_time_series  # noqa: E402
from ._plots.dynamics import plot_time_delays as plot_time_delays  # noqa: E402
from ._plots.dynamics import plot_phase_portraits as plot_phase_portraits  # noqa: E402
from ._plots.dynamics import plot_orbit_diagram as plot_orbit_diagram  # noqa: E402
from ._plots.dynamics import plot_states_and_orbits as plot_states_and_orbits  # noqa: E402
from ._solvers import auto_solver as auto_solver  # noqa: E402
from ._hints import failure_hint as failure_hint  # noqa: E402
from ._stress.cases import stress_cases as stress_cases  # noqa: E402
from ._stress.run import stress as stress  # noqa: E402
from ._basin.sampling import Box as Box  # noqa: E402
from ._basin.sampling import sample_states as sample_states  # noqa: E402
from ._basin.classes import halc_clusters as halc_clusters  # noqa: E402
from ._basin.classes import wilson_interval as wilson_interval  # noqa: E402
from ._basin.basin import basin_stability as basin_stability  # noqa: E402
from ._plots.basin import plot_basin_stability as plot_basin_stability  # noqa: E402
from ._plots.basin import plot_halc_histogram as plot_halc_histogram  # noqa: E402
