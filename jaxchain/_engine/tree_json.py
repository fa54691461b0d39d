"""The tree structure of a kept program's output as JSON (`programs.kept_program`):
data that names its nodes' types and holds their static data, read back without
running anything of the file's own. Pickle, which the kept programs used before,
runs whatever a file asks for as it loads it.

A tree is written only when it is made of tuples, lists, dicts, None and equinox
modules whose static data are numbers, strings, None and tuples or lists of them
(jaxchain's outputs: `Observables`, the observers' dicts, tuples of arrays), and only
when reading it back gives the same structure; anything else raises `TypeError`,
and the program is then not kept. Reading resolves a module's class among the
modules already imported, never importing one, and accepts only subclasses of
`eqx.Module`, whose structure equinox itself rebuilds (fields set, no `__init__`)."""

import sys

import equinox as eqx
import jax

_BUILTINS = {"tuple": tuple, "list": list, "dict": dict, "None": type(None)}
_NAMES = {cls: name for name, cls in _BUILTINS.items()}
_SCALARS = (type(None), bool, int, float, str)


class _Empty(eqx.Module):
    pass


def _missing():
    """equinox's marker of a module without extra attributes (or of an unset field),
    as its modules' tree structures hold it: the first item of their static data."""
    _, aux = jax.tree_util.tree_structure(_Empty()).node_data()
    return aux[0] if isinstance(aux, tuple) and len(aux) == 1 else None


_MISSING = _missing()


def to_json(treedef) -> object:
    """`treedef` as JSON data: "*" for a leaf, else `{"type", "aux", "children"}`.

    **Raises:**

    `TypeError` for a node or static datum that has no JSON form here, or a tree
    that does not come back the same from `from_json`.
    """
    data = _encode(treedef)
    if from_json(data) != treedef:
        raise TypeError(f"{treedef} does not survive its JSON form")
    return data


def from_json(data) -> jax.tree_util.PyTreeDef:
    """The tree structure that `to_json` wrote.

    **Raises:**

    `ValueError` (or `TypeError`) for data that `to_json` does not write, or that
    names a type that is neither a builtin container nor an `eqx.Module` subclass
    in a module already imported.
    """
    if data == "*":
        return jax.tree_util.tree_structure(0)
    if not (isinstance(data, dict) and set(data) == {"type", "aux", "children"}
            and isinstance(data["children"], list)):
        raise ValueError("not a tree structure")
    node = (_type(data["type"]), _decode(data["aux"]))
    children = [from_json(child) for child in data["children"]]
    return jax.tree_util.PyTreeDef.from_node_data_and_children(
        jax.tree_util.default_registry, node, children)


def _encode(treedef):
    node = treedef.node_data()
    if node is None:
        return "*"
    cls, aux = node
    if cls in _NAMES:
        name = _NAMES[cls]
    elif isinstance(cls, type) and issubclass(cls, eqx.Module):
        name = f"{cls.__module__}:{cls.__qualname__}"
    else:
        raise TypeError(f"no JSON form for a node of type {cls}")
    return {"type": name, "aux": _encode_aux(aux),
            "children": [_encode(child) for child in treedef.children()]}


def _encode_aux(x):
    if x is _MISSING and x is not None:
        return {"missing": True}
    if isinstance(x, (tuple, list)):
        return {type(x).__name__: [_encode_aux(item) for item in x]}
    if type(x) in _SCALARS:
        return x
    raise TypeError(f"no JSON form for static data of type {type(x).__name__}")


def _decode(x):
    if isinstance(x, dict):
        (kind, value), = x.items()
        if kind == "missing" and value is True and _MISSING is not None:
            return _MISSING
        if kind in ("tuple", "list") and isinstance(value, list):
            return _BUILTINS[kind](_decode(item) for item in value)
        raise ValueError(f"unknown static data {kind!r}")
    if type(x) in _SCALARS:
        return x
    raise ValueError(f"unknown static data {x!r}")


def _type(name):
    if not isinstance(name, str):
        raise ValueError("a node's type is a name")
    if name in _BUILTINS:
        return _BUILTINS[name]
    module, _, qualname = name.partition(":")
    cls = sys.modules.get(module)  # imported already: reading imports nothing
    for part in qualname.split("."):  # vars: no module or class __getattr__ runs
        cls = vars(cls).get(part) if hasattr(cls, "__dict__") else None
    if not (isinstance(cls, type) and issubclass(cls, eqx.Module)):
        raise ValueError(f"{name} is not an equinox module of an imported module")
    return cls
