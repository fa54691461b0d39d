"""Every use of a private part of diffrax or equinox, in one place, and the check
that the installed versions still have them (`check_compatible`): when diffrax or
equinox changes these parts, one test names what changed instead of a wrong step
size or a host callback showing up somewhere in the engine."""

import contextlib
import functools
import threading
from collections.abc import Callable
from importlib.metadata import version

import diffrax
import equinox as eqx
import jax.numpy as jnp


def error_order(controller: diffrax.PIDController, solver_error_order) -> float:
    """The error order that diffrax's `PIDController` uses for a solver
    (`PIDController._get_error_order`, private: the solver's order, or the
    controller's own override)."""
    return controller._get_error_order(solver_error_order)


def pid_state(inv_error, prev_inv_error, at_dtmin):
    """diffrax's `PIDController` state, as its `init` returns it and its
    `adapt_step_size` takes it (private): the inverse scaled errors of the last two
    accepted steps and whether the last step was at dtmin."""
    return (inv_error, prev_inv_error, at_dtmin)


def unpack_pid_state(state) -> tuple:
    """The three parts of diffrax's `PIDController` state (`pid_state`)."""
    inv_error, prev_inv_error, at_dtmin = state
    return inv_error, prev_inv_error, at_dtmin


_errors_lock = threading.RLock()  # re-entrant: blocks nest (a traced function's own engine run)


@contextlib.contextmanager
def errors_as_nan():
    """Trace equinox's run-time errors (`eqx.error_if`, which diffrax uses to check
    its arguments) as NaN substitution instead of equinox's default, a host callback
    that raises. equinox reads its private `_errors.EQX_ON_ERROR` at trace time; it
    is set for the tracing inside the block and restored at once (under a lock, as
    devices may trace in parallel threads).

    equinox traces each check in a compiled function of its own
    (`_errors.branched_error_if_impl_jit`), whose trace JAX keeps by the check's
    shapes and message, not by the mode: its traces are dropped on entry (a check
    traced before, raising, would otherwise come back with its host callback) and
    on exit (a later check of the same shapes, in the user's code or jaxchain's,
    would otherwise return NaN instead of raising)."""
    with _errors_lock:
        before = eqx._errors.EQX_ON_ERROR
        _error_traces().clear_cache()
        eqx._errors.EQX_ON_ERROR = "nan"
        try:
            yield
        finally:
            eqx._errors.EQX_ON_ERROR = before
            _error_traces().clear_cache()


def checks_as_nan(program: Callable) -> Callable:
    """A compiled function of jaxchain (`checks_as_nan(eqx.filter_jit(fn))`), called
    inside `errors_as_nan`: traced, lowered and compiled with equinox's checks (in
    diffrax, lineax and optimistix) as NaN. Its failures are a status or NaN, never
    an exception. JAX keeps no program with a host callback, equinox's default
    check, in its persistent compilation cache: without this, every process (a
    command, a notebook, a test worker) compiled the bifurcation programs anew.
    The whole call is inside the block, not only the trace: lineax and
    optimistix's implicit derivatives build their checks when the program is
    lowered. `lower` lowers the program as a call does."""
    @functools.wraps(program)
    def call(*args, **kwargs):
        with errors_as_nan():
            return program(*args, **kwargs)

    def lower(*args, **kwargs):
        with errors_as_nan():
            return program.lower(*args, **kwargs)

    call.lower = lower
    return call


def _error_traces():
    """The compiled function in which equinox traces its checks (private)."""
    return eqx._errors.branched_error_if_impl_jit._cached


def check_compatible() -> None:
    """Check that the installed diffrax and equinox still have the private parts
    that this module uses, with the layout it expects.

    **Raises:**

    `RuntimeError` naming the part that changed and the installed versions.
    """
    versions = f"diffrax {version('diffrax')}, equinox {version('equinox')}"

    def fail(what: str):
        raise RuntimeError(f"jaxchain._engine.compat: {what} ({versions}); "
                           "update jaxchain/_engine/compat.py")

    if not callable(getattr(getattr(getattr(eqx._errors, "branched_error_if_impl_jit", None),
                                    "_cached", None), "clear_cache", None)):
        fail("equinox._errors.branched_error_if_impl_jit._cached.clear_cache is gone")
    controller = diffrax.PIDController(rtol=1e-6, atol=1e-6)
    if not callable(getattr(controller, "_get_error_order", None)):
        fail("diffrax.PIDController._get_error_order is gone")
    if error_order(controller, 3) != 3:
        fail("diffrax.PIDController._get_error_order no longer returns the solver's order")
    term = diffrax.ODETerm(lambda t, y, args: -y)
    y0 = jnp.ones(2)
    _, state = controller.init(term, 0.0, 1.0, y0, None, None,
                               lambda *a: diffrax.Tsit5().func(*a), 5)
    try:
        unpack_pid_state(state)
    except (TypeError, ValueError):
        fail(f"diffrax.PIDController's state is no longer three parts: {state!r}")
    if getattr(getattr(eqx, "_errors", None), "EQX_ON_ERROR", None) is None:
        fail("equinox._errors.EQX_ON_ERROR is gone")
