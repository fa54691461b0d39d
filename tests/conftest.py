import os

import jax

# The command line's persistent compilation cache stays off in the tests (one test
# turns it on in a folder of its own), so that they never write to the user's cache.
os.environ.setdefault("JAXCHAIN_CACHE_DIR", "")

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")
