"""The public names of jaxchain, each imported from the module that defines it: what
type checkers and the documentation read, and what `jaxchain/__init__.py` loads on
first use (`lazy_loader.attach_stub`, SPEC 1 of the Scientific Python community).

They are grouped by what a user does, in the order of the documentation; each
section is a page of the API reference (`docs/api/`)."""

# --- The chain and friction laws: parameters, topology, forcing, mistuning, eq. (5) ---
from ._physics.params import (
    ChainParams as ChainParams, with_parameter as with_parameter,
    parameter_name as parameter_name,
    single_oscillator as single_oscillator,
    stack_chains as stack_chains,
)
from ._physics.chain import Graph as Graph
from ._physics.forcing import Forcing as Forcing
from ._physics.mistuning import mistune as mistune, Mistuning as Mistuning
from ._physics.friction import (
    ExponentialDecay as ExponentialDecay, Stribeck as Stribeck,
    Polynomial as Polynomial, Coulomb as Coulomb, Tabulated as Tabulated,
    AbstractFrictionLaw as AbstractFrictionLaw,
)
from ._physics.model import (
    mechanical_energy as mechanical_energy, stick_force as stick_force,
)
from ._physics.forces import (
    coupling_force as coupling_force,
    stiffness_matrix as stiffness_matrix,
    friction_coefficient as friction_coefficient,
)

# --- Initial conditions: eqs. (8) and (10), localized families, a given state ---
from ._physics.initial import (
    OutOfPhaseExcitation as OutOfPhaseExcitation, GivenState as GivenState,
    localized_family as localized_family, excited_block as excited_block,
    AbstractInitialCondition as AbstractInitialCondition,
)

# --- Simulating and observing: simulate, options, solvers, observers, statuses ---
from ._engine.simulate import simulate as simulate, observe as observe
from ._engine.engines import (
    AbstractEngine as AbstractEngine, Smoothed as Smoothed, Exact as Exact,
)
from ._engine.observables import Observables as Observables
from ._engine.options import SimulationOptions as SimulationOptions
from ._engine.solver.registry import SOLVERS as SOLVERS
from ._engine.observers.extrema import Extrema as Extrema
from ._engine.observers.energy import Energy as Energy
from ._engine.observers.series import TimeSeries as TimeSeries
from ._engine.observers.crossings import (
    PeakTimes as PeakTimes, PoincareSection as PoincareSection,
)
from ._engine.observers.lyapunov_exponent import LargestLyapunov as LargestLyapunov
from ._engine.observers.base import AbstractObserver as AbstractObserver, Chunk as Chunk
from ._engine.status import Status as Status
from ._engine.exact.options import NonsmoothOptions as NonsmoothOptions
from ._engine.exact.switching import (
    SWITCH_KINDS as SWITCH_KINDS, saltation_matrix as saltation_matrix,
)
from ._bifurcation.existence import (
    stick_slip_existence_limit as stick_slip_existence_limit,
    differentiable_existence_limit as differentiable_existence_limit,
)
from ._engine.horizon import AbstractHorizon as AbstractHorizon

# --- Ensembles, sweeps and stores: many trajectories, datasets, resumable sweeps ---
from ._sweeps.ensemble import ensemble as ensemble
from ._sweeps.sweep import sweep as sweep, open_sweep as open_sweep
from ._sweeps.datasets import save_dataset as save_dataset
from ._engine.lanes import run_lanes as run_lanes, lane_params as lane_params

# --- Analysis: state classes, time delays, fronts, localization ---
from ._analysis.classify import classify as classify
from ._analysis.states import (
    state_class as state_class, ClassTolerances as ClassTolerances,
)
from ._analysis.delays import time_delays as time_delays
from ._analysis.fronts import propagating_fronts as propagating_fronts
from ._analysis.localization import (
    localization_factor as localization_factor,
    inverse_participation_ratio as inverse_participation_ratio,
    damped_decay as damped_decay,
)

# --- Bifurcations and continuation: Hopf point, periodic orbits, branches, folds ---
from ._bifurcation.hopf import (
    hopf_point as hopf_point, HopfPoint as HopfPoint, hopf_vd as hopf_vd,
    hopf_vd_analytic as hopf_vd_analytic, growth_rates as growth_rates,
    steady_sliding_eigenvalues as steady_sliding_eigenvalues,
)
from ._bifurcation.lyapunov_coefficient import first_lyapunov_coefficient as first_lyapunov_coefficient
from ._bifurcation.orbit_method import (
    PeriodicOrbit as PeriodicOrbit, AbstractOrbitMethod as AbstractOrbitMethod,
    orbit_record as orbit_record, deflated_multipliers as deflated_multipliers,
)
from ._bifurcation.periodic_orbit import (
    periodic_orbit as periodic_orbit, cycle_problem as cycle_problem,
)
from ._bifurcation.shooting import Shooting as Shooting
from ._bifurcation.harmonic_balance import HarmonicBalance as HarmonicBalance
from ._bifurcation.deflation import distinct_orbits as distinct_orbits
from ._bifurcation.branch_switching import switch_branch as switch_branch
from ._bifurcation.grazing import (
    stick_slip_grazing as stick_slip_grazing, grazing_curve as grazing_curve,
    grazing_slope as grazing_slope, GrazingPoint as GrazingPoint,
)
from ._bifurcation.sliding import (
    locate_sliding as locate_sliding, SlidingPoint as SlidingPoint,
    sliding_curve as sliding_curve,
)
from ._bifurcation.continuation import (
    continuation as continuation, ContinuationProblem as ContinuationProblem,
    PseudoArclength as PseudoArclength, ContinuationOptions as ContinuationOptions,
    Branch as Branch,
)
from ._bifurcation.bifurcations import (
    locate_bifurcations as locate_bifurcations, BifurcationPoint as BifurcationPoint,
)
from ._bifurcation.limit_cycles import hopf_cycle as hopf_cycle
from ._bifurcation.branches import (
    follow_branch as follow_branch, FollowedBranch as FollowedBranch,
)
from ._bifurcation.fold import (
    fold_point as fold_point, FoldPoint as FoldPoint, solve_fold as solve_fold,
)
from ._bifurcation.two_parameter import (
    boundary_curves as boundary_curves, BoundaryCurves as BoundaryCurves,
    fold_curve as fold_curve,
)
from ._bifurcation.damping_design import (
    smallest_damping as smallest_damping, DampingDesign as DampingDesign,
)

# --- Studies: crosscheck, work-precision, basins, stress, mistuning, snake, bistability, scenes ---
from ._studies.crosscheck import crosscheck as crosscheck
from ._studies.work_precision import work_precision as work_precision
from ._studies.response import frequency_response as frequency_response
from ._studies.magnification import magnification_gradient as magnification_gradient
from ._studies.magnification import magnification_study as magnification_study
from ._studies.magnification import (
    mistuned_lanes as mistuned_lanes, response_peaks as response_peaks,
    whitehead_bound as whitehead_bound,
)
from ._studies.localized_ranges import (
    localized_ranges as localized_ranges, shooting_ranges as shooting_ranges,
)
from ._studies.basin.basin import basin_stability as basin_stability
from ._studies.basin.sampling import Box as Box, sample_states as sample_states
from ._studies.basin.classes import wilson_interval as wilson_interval
from ._studies.stress.run import stress as stress
from ._studies.mistuning.study import mistuning_study as mistuning_study
from ._studies.mistuning.summary import (
    localization_table as localization_table, study_summary as study_summary,
)
from ._studies.mistuning.edges import (
    upper_edges as upper_edges, localized_fold as localized_fold,
)
from ._studies.mistuning.pattern_design import intentional_mistuning as intentional_mistuning
from ._studies.mistuning.design_study import design_study as design_study
from ._studies.snake.run import localized_branches as localized_branches
from ._studies.snake.starts import start_site as start_site
from ._studies.bistable_range import bistable_range as bistable_range
from ._studies.scenes import observe_solutions as observe_solutions

# --- Identification: friction laws and parameters from measured records ---
from ._studies.identification.fit import (
    identify as identify, IdentifyOptions as IdentifyOptions,
    Identification as Identification,
)
from ._studies.identification.records import (
    Record as Record, read_record as read_record,
    record_from_dataset as record_from_dataset,
)
from ._studies.identification.choice import compare_laws as compare_laws
from ._studies.identification.synthetic import (
    reference_record as reference_record, write_record as write_record,
)

# --- Units, files, plots, set-up and command line ---
from ._physics.scales import Scales as Scales
from ._physics.units import to_physical as to_physical, from_physical as from_physical
from ._physics.record import (
    chain_from_file as chain_from_file, chain_record as chain_record,
    chain_from_record as chain_from_record,
)
from ._sweeps.chain_files import write_chain_file as write_chain_file
from ._plots.localized import plot_localized_states as plot_localized_states
from ._plots.dynamics import (
    plot_time_series as plot_time_series, plot_phase_portraits as plot_phase_portraits,
    plot_time_delays as plot_time_delays, plot_orbit_diagram as plot_orbit_diagram,
    plot_states_and_orbits as plot_states_and_orbits,
)
from ._plots.sweep import plot_bifurcation_diagram as plot_bifurcation_diagram
from ._plots.response import plot_frequency_response as plot_frequency_response
from ._plots.magnification import plot_magnification as plot_magnification
from ._plots.localized_ranges import plot_localized_ranges as plot_localized_ranges
from ._plots.bifurcation import (
    plot_limit_cycle_branch as plot_limit_cycle_branch,
    plot_bistable_region as plot_bistable_region,
)
from ._plots.crosscheck import plot_crosscheck as plot_crosscheck
from ._plots.work_precision import plot_work_precision as plot_work_precision
from ._plots.basin import (
    plot_basin_stability as plot_basin_stability,
    plot_halc_histogram as plot_halc_histogram,
)
from ._plots.mistuning import (
    plot_mistuning_study as plot_mistuning_study, plot_site_edges as plot_site_edges,
    plot_mistuned_states as plot_mistuned_states,
    plot_mistuning_design as plot_mistuning_design,
)
from ._plots.snake import plot_snake as plot_snake
from ._plots.identification import (
    plot_record_fits as plot_record_fits, plot_friction_band as plot_friction_band,
)
from ._setup import configure as configure, XLA_FLAGS as XLA_FLAGS
from ._errors import ValidationError as ValidationError
from ._cli.main import main as main
