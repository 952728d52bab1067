"""Test configuration for layerstack.

* float64 is enabled here, for the tests only (the package itself never touches
  ``jax_enable_x64``): interference-grade comparisons (1e-12) need it.
* A hypothesis profile for CI: no deadline (first calls compile), a modest number of
  examples, and derandomized so that a CI run is reproducible.  ``HYPOTHESIS_PROFILE=thorough``
  selects a longer, randomized profile for local exploration.
* Strict dtype promotion (``jax_numpy_dtype_promotion = "strict"``, as optimistix/equinox test)
  for the whole suite: no implicit mixing of float32/float64/complex/int arrays in the library;
  the intended real → complex steps are written out (``layerstack_jax._base.numerics.as_complex``,
  ``complex_from``). Users keep JAX's standard promotion (the package never changes it).
* ``tests/`` and the repository root are put on ``sys.path`` so that ``import reference`` and
  ``import layerstack_jax`` work from any working directory without an installed package.
* JAX's compilation caches are emptied after each test module: every compiled XLA CPU program
  holds ~3 memory mappings for as long as it is cached, and a worker that compiles ~20,000
  programs reaches the kernel's ``vm.max_map_count`` (65,530), where LLVM's JIT memory manager
  crashes (a segfault inside ``backend_compile_and_load``, seen as "worker crashed").
"""

from __future__ import annotations

import os
import sys

import jax

jax.config.update("jax_enable_x64", True)
# the command line's persistent compilation cache stays off in the suite (in-process CLI calls
# would write to ~/.cache); tests/test_fitting_cli.py turns it on in a directory of its own
os.environ.setdefault("LAYERSTACK_CACHE_DIR", "")
jax.config.update("jax_numpy_dtype_promotion", "strict")

_HERE = os.path.dirname(os.path.abspath(__file__))
_ROOT = os.path.dirname(_HERE)
for _p in (_HERE, _ROOT):
    if _p not in sys.path:
        sys.path.insert(0, _p)

from hypothesis import HealthCheck, settings  # noqa: E402

settings.register_profile(
    "ci",
    deadline=None,
    max_examples=25,
    derandomize=True,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
settings.register_profile(
    "thorough",
    deadline=None,
    max_examples=500,
    derandomize=False,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

import gc  # noqa: E402

import pytest  # noqa: E402


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs():
    """Empty JAX's compilation caches after each test module (module docstring)."""
    yield
    jax.clear_caches()
    gc.collect()
