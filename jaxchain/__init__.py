"""jaxchain: a differentiable JAX simulator of chains of friction-excited oscillators.

Implements eq. (5) of *Multiple spatially localized dynamical states in
friction-excited oscillator chains*. Importing jaxchain changes nothing in JAX:
call `jaxchain.configure()` once, first, to turn on float64 (which jaxchain needs),
give JAX one CPU device per core and let XLA compile the step loop into one kernel.
The `jaxchain` command does it itself.

The public names are listed in `__init__.pyi`, each imported from the module that
defines it, and each is loaded on first use (`lazy_loader`, SPEC 1 of the
Scientific Python community): `import jaxchain` costs JAX alone, and a command
loads only the modules it uses. The heavy libraries (matplotlib, xarray, dask,
scipy) are imported inside the functions that use them.
"""

import lazy_loader

from ._setup import VERSION as __version__  # noqa: F401  (the package version)

#: Every public name of `__init__.pyi`, for `from jaxchain import *` and the
#: documentation; each is imported from its module when first used.
_public_getattr, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)


def __getattr__(name: str):
    """A public name, loaded on first use; or one of the previous release's orbit
    names, a deprecated alias for one release (`_studies/deprecated.py`)."""
    try:
        return _public_getattr(name)
    except AttributeError:
        from ._studies.deprecated import DEPRECATED
        if name in DEPRECATED:
            return DEPRECATED[name]
        raise
