"""Keys of stored results and programs: the SHA-256 of everything that determines
them, as plain JSON data that depends only on values."""

import dataclasses
import functools
import hashlib
import inspect
import json

import jax
import numpy as np

#: Part of every key. Raise it whenever what a stored result holds, or how it is
#: computed, changes: every result stored before is then recomputed.
FORMAT_VERSION = 2


def canonical(obj):
    """`obj` as plain JSON data that depends only on its values.

    - Dataclasses, `eqx.Module`s included (parameters, options, solvers): their
        class and every field, static fields too.
    - NumPy and JAX arrays and scalars: their values (`tolist()`), so that a float
        and a 0-d float64 array of the same value give the same data.
    - Classes and functions defined at the top level of a module: their
        qualified name; `functools.partial`: its function and arguments; any other
        object with a `__dict__` (for example a sentinel): its class and
        attributes.
    - Dicts (keys as strings), lists and tuples, recursively; str, int, float,
        bool and None as they are.

    **Arguments:**

    - `obj`: the object.

    **Returns:**

    Nested dicts, lists, strings, numbers, booleans and None.

    **Raises:**

    `TypeError` for a traced value, a lambda, a closure or a function defined
    inside another (two of them share a name, not their content: two closures
    over different values would share one stored result), or an object of any
    other type: such a value cannot be keyed by its content.
    """
    if obj is None or isinstance(obj, (bool, int, float, str)):
        return obj
    if isinstance(obj, jax.core.Tracer):
        raise TypeError("a traced value cannot be part of a stored result's key")
    if isinstance(obj, (np.ndarray, np.generic, jax.Array)):
        return np.asarray(obj).tolist()
    if isinstance(obj, dict):
        return {str(k): canonical(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [canonical(v) for v in obj]
    if isinstance(obj, functools.partial):
        return {"partial": _name(obj.func), "args": canonical(obj.args),
                "keywords": canonical(obj.keywords)}
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {"class": _name(type(obj)),
                "fields": {f.name: canonical(getattr(obj, f.name))
                           for f in dataclasses.fields(obj)}}
    if callable(obj):
        _check_named(obj)
        return {"callable": _name(obj)}
    if hasattr(obj, "__dict__"):  # a plain object, for example a sentinel
        return {"class": _name(type(obj)), "attributes": canonical(vars(obj))}
    raise TypeError(f"cannot key a stored result by an object of type {type(obj).__name__}")


def _check_named(fn) -> None:
    """Raise `TypeError` unless the callable `fn` is what its qualified name says:
    a class, or a function defined at a module's top level, with no closure and
    not bound to an object."""
    if isinstance(fn, type):
        return
    qualname = getattr(fn, "__qualname__", None)
    if (qualname is None or "<lambda>" in qualname or "<locals>" in qualname
            or getattr(fn, "__closure__", None) or inspect.ismethod(fn)):
        raise TypeError(f"cannot key a stored result by the function {qualname or fn!r}: a "
                        "lambda, a closure, a bound method or a local function is known by "
                        "its name, not by what it computes; pass a parameter name, or a "
                        "function defined at a module's top level (with functools.partial "
                        "for its arguments)")


def _name(obj) -> str:
    return f"{getattr(obj, '__module__', '?')}.{getattr(obj, '__qualname__', repr(obj))}"


def settings_json(kind: str, **settings) -> str:
    """The canonical JSON of `settings` (sorted keys, no spaces), with `kind` and
    `FORMAT_VERSION`: the text that `settings_key` hashes."""
    data = {"kind": kind, "format_version": FORMAT_VERSION, "settings": canonical(settings)}
    return json.dumps(data, sort_keys=True, separators=(",", ":"), allow_nan=True)


def settings_key(kind: str, **settings) -> str:
    """The key of a stored result: the SHA-256 of `settings_json(kind, **settings)`.

    Two results share a key only when they are of the same kind and were computed
    from equal settings (`canonical` values) by the same `FORMAT_VERSION`.

    **Arguments:**

    - `kind`: what the result is, for example "crosscheck reference".
    - `settings`: everything that determines the result: parameters, initial state,
        options, solver.

    **Returns:**

    64 hexadecimal digits.

    **Raises:**

    `TypeError` for a setting that `canonical` cannot turn into data.
    """
    return hashlib.sha256(settings_json(kind, **settings).encode()).hexdigest()
