"""The public names of jaxchain, each imported from the module that defines it: what
type checkers and the documentation read, and what `jaxchain/__init__.py` loads on
first use (`lazy_loader.attach_stub`, SPEC 1 of the Scientific Python community)."""

from ._studies.basin.basin import basin_stability as basin_stability
from ._studies.basin.classes import (
    halc_clusters as halc_clusters, wilson_interval as wilson_interval,
)
from ._studies.basin.sampling import Box as Box, sample_states as sample_states
from ._bifurcation.bifurcations import (
    BIFURCATION_KINDS as BIFURCATION_KINDS, BifurcationPoint as BifurcationPoint,
    locate_bifurcations as locate_bifurcations,
)
from ._bifurcation.continuation import (
    Branch as Branch, continuation as continuation,
    ContinuationOptions as ContinuationOptions,
    ContinuationProblem as ContinuationProblem, PseudoArclength as PseudoArclength,
)
from ._bifurcation.damping_design import (
    DampingDesign as DampingDesign, smallest_damping as smallest_damping,
)
from ._bifurcation.fold import (
    fold_point as fold_point, FoldPoint as FoldPoint, solve_fold as solve_fold,
)
from ._bifurcation.hopf import (
    growth_rates as growth_rates, hopf_eps_correction as hopf_eps_correction,
    hopf_point as hopf_point, hopf_speed as hopf_speed, hopf_vd as hopf_vd,
    hopf_vd_analytic as hopf_vd_analytic,
    HopfPoint as HopfPoint, leading_growth_rate as leading_growth_rate,
    mode_eigenvalues as mode_eigenvalues,
    steady_sliding_eigenvalues as steady_sliding_eigenvalues,
)
from ._bifurcation.limit_cycles import (
    hopf_cycle as hopf_cycle, limit_cycle_problem as limit_cycle_problem,
)
from ._bifurcation.lyapunov_coefficient import (
    first_lyapunov_coefficient as first_lyapunov_coefficient,
)
from ._bifurcation.shooting import (
    floquet_multipliers as floquet_multipliers, monodromy as monodromy,
    periodic_orbit as periodic_orbit, PeriodicOrbit as PeriodicOrbit,
    shooting_residual as shooting_residual, ShootingOptions as ShootingOptions,
)
from ._bifurcation.two_parameter import (
    boundary_curves as boundary_curves, BoundaryCurves as BoundaryCurves,
    fold_and_derivative as fold_and_derivative, fold_curve as fold_curve,
    fold_curve_problem as fold_curve_problem,
)
from ._studies.crosscheck import crosscheck as crosscheck
from ._studies.identification.choice import compare_laws as compare_laws
from ._studies.identification.fit import (
    Identification as Identification, IdentifyOptions as IdentifyOptions,
    held_out_rms as held_out_rms, identify as identify,
)
from ._studies.identification.synthetic import (
    reference_record as reference_record, write_record as write_record,
)
from ._studies.identification.unknowns import unknowns_of as unknowns_of
from ._studies.identification.records import (
    Record as Record, read_record as read_record, record_from_dataset as record_from_dataset,
)
from ._analysis.classify import CLASSES as CLASSES, classify as classify
from ._analysis.delays import (
    delay_spread as delay_spread, reference_oscillator as reference_oscillator,
    time_delays as time_delays,
)
from ._studies.scenes import (
    PAPER_SOLUTIONS as PAPER_SOLUTIONS, observe_solutions as observe_solutions,
    orbit_diagram_scene as orbit_diagram_scene,
    phase_portrait_scene as phase_portrait_scene, time_delay_scene as time_delay_scene,
    time_series_scene as time_series_scene,
)
from ._sweeps.ensemble import ensemble as ensemble
from ._errors import ValidationError as ValidationError
from ._engine.status import (
    Status as Status, failure_hint as failure_hint, flag_attributes as flag_attributes,
)
from ._engine.lanes import lane_params as lane_params
from ._studies.mistuning.pattern_design import (
    intentional_mistuning as intentional_mistuning, MistuningDesign as MistuningDesign,
    pattern_deviations as pattern_deviations,
)
from ._studies.mistuning.design_study import design_study as design_study
from ._studies.mistuning.edges import (
    localized_fold as localized_fold, upper_edges as upper_edges,
)
from ._studies.mistuning.study import (
    mistuning_study as mistuning_study, study_chains as study_chains,
)
from ._nonsmooth.existence import (
    differentiable_existence_limit as differentiable_existence_limit,
    stick_slip_existence_limit as stick_slip_existence_limit,
)
from ._nonsmooth.options import NonsmoothOptions as NonsmoothOptions
from ._nonsmooth.solve import (
    NonsmoothObservables as NonsmoothObservables, nonsmooth_trajectory as nonsmooth_trajectory,
    simulate_nonsmooth as simulate_nonsmooth,
)
from ._nonsmooth.switching import SWITCH_KINDS as SWITCH_KINDS
from ._engine.observers.base import AbstractObserver as AbstractObserver, Chunk as Chunk
from ._engine.observers.crossings import (
    PeakTimes as PeakTimes, PoincareSection as PoincareSection,
)
from ._engine.observers.energy import Energy as Energy
from ._engine.observers.extrema import Extrema as Extrema
from ._engine.observers.lyapunov_exponent import LargestLyapunov as LargestLyapunov
from ._engine.observers.series import TimeSeries as TimeSeries
from ._engine.horizon import AbstractHorizon as AbstractHorizon
from ._engine.options import SimulationOptions as SimulationOptions
from ._physics.chain import (
    BOUNDARIES as BOUNDARIES, GROUND as GROUND, Graph as Graph,
    LATTICE_BOUNDARIES as LATTICE_BOUNDARIES, Mistuning as Mistuning,
)
from ._physics.forces import (
    coupling_force as coupling_force, friction_coefficient as friction_coefficient,
    slip_friction_force as slip_friction_force,
    smoothed_friction_force as smoothed_friction_force,
    static_friction as static_friction, stiffness_matrix as stiffness_matrix,
)
from ._physics.friction import (
    FRICTION_LAWS as FRICTION_LAWS, AbstractFrictionLaw as AbstractFrictionLaw,
    Coulomb as Coulomb, ExponentialDecay as ExponentialDecay, Polynomial as Polynomial,
    Stribeck as Stribeck, Tabulated as Tabulated,
)
from ._physics.initial import (
    AbstractInitialCondition as AbstractInitialCondition,
    excited_block as excited_block, GivenState as GivenState,
    localized_family as localized_family, OutOfPhaseExcitation as OutOfPhaseExcitation,
)
from ._analysis.localization import (
    damped_decay as damped_decay,
    inverse_participation_ratio as inverse_participation_ratio,
    localization_factor as localization_factor,
    passband_frequency as passband_frequency,
    weak_disorder_localization as weak_disorder_localization,
)
from ._physics.model import (
    jacobian as jacobian, mechanical_energy as mechanical_energy,
    split_vector_field as split_vector_field, steady_sliding as steady_sliding,
    stick_force as stick_force, vector_field as vector_field,
)
from ._physics.params import (
    ChainParams as ChainParams, mistune as mistune, parameter_name as parameter_name,
    parameter_value as parameter_value, single_oscillator as single_oscillator,
    stack_chains as stack_chains, with_fields as with_fields, with_parameter as with_parameter,
)
from ._physics.record import (
    chain_from_record as chain_from_record, chain_record as chain_record,
    check_recordable as check_recordable, chain_from_file as chain_from_file,
)
from ._sweeps.chain_files import write_chain_file as write_chain_file
from ._physics.stick import STICK_BAND as STICK_BAND, sticks as sticks
from ._physics.scales import Scales as Scales
from ._physics.units import from_physical as from_physical, to_physical as to_physical
from ._plots.basin import (
    plot_basin_stability as plot_basin_stability,
    plot_halc_histogram as plot_halc_histogram,
)
from ._plots.bifurcation import (
    plot_bistable_region as plot_bistable_region,
    plot_limit_cycle_branch as plot_limit_cycle_branch,
)
from ._plots.crosscheck import plot_crosscheck as plot_crosscheck
from ._plots.dynamics import (
    plot_orbit_diagram as plot_orbit_diagram,
    plot_phase_portraits as plot_phase_portraits,
    plot_states_and_orbits as plot_states_and_orbits,
    plot_time_delays as plot_time_delays, plot_time_series as plot_time_series,
)
from ._plots.identification import (
    plot_friction_band as plot_friction_band, plot_record_fits as plot_record_fits,
)
from ._plots.localized import plot_localized_states as plot_localized_states
from ._plots.mistuning import (
    plot_mistuned_states as plot_mistuned_states,
    plot_mistuning_design as plot_mistuning_design,
    plot_mistuning_study as plot_mistuning_study, plot_site_edges as plot_site_edges,
)
from ._plots.snake import plot_snake as plot_snake
from ._plots.sweep import plot_bifurcation_diagram as plot_bifurcation_diagram
from ._plots.work_precision import plot_work_precision as plot_work_precision
from ._sweeps.datasets import save_dataset as save_dataset, to_dataset as to_dataset
from ._setup import configure as configure
from ._engine.simulate import (
    integrate as integrate, Observables as Observables,
    observe as observe, simulate as simulate,
)
from ._studies.snake import (
    LATTICE_STARTS as LATTICE_STARTS, localized_branches as localized_branches,
    start_mask as start_mask, start_site as start_site,
)
from ._engine.solver.registry import (
    DEFAULT_SOLVER as DEFAULT_SOLVER, SOLVERS as SOLVERS, auto_solver as auto_solver,
)
from ._analysis.states import ClassTolerances as ClassTolerances, state_class as state_class
from ._studies.stress.cases import stress_cases as stress_cases
from ._studies.stress.run import stress as stress
from ._analysis.fronts import (
    front_fractions as front_fractions, front_ranges as front_ranges,
    propagating_fronts as propagating_fronts,
)
from ._sweeps.sweep import open_sweep as open_sweep, sweep as sweep
from ._studies.work_precision import work_precision as work_precision
from ._cli.main import main as main
from ._engine.lanes import run_lanes as run_lanes
from ._physics.record import read_chain_file as read_chain_file
from ._physics.stick import min_slip_speed as min_slip_speed
from ._bifurcation.two_parameter import hopf_vd_and_derivative as hopf_vd_and_derivative
from ._studies.bistable_range import (
    BISTABLE_RATIO_VALUES as BISTABLE_RATIO_VALUES,
    BISTABLE_XI_VALUES as BISTABLE_XI_VALUES, bistable_range as bistable_range,
)
from ._studies.scenes import PAPER_FIGURES as PAPER_FIGURES
from ._studies.mistuning.summary import (
    edge_correlations as edge_correlations, envelope_decay as envelope_decay,
    halc_correlation as halc_correlation, localization_table as localization_table,
    localized_fraction as localized_fraction, staircase_fraction as staircase_fraction,
    vibrating_fraction as vibrating_fraction,
)
from ._setup import XLA_FLAGS as XLA_FLAGS
