"""Test configuration for layerstack.

* float64 is enabled here, for the tests only (the package itself never touches
  ``jax_enable_x64``): interference-grade comparisons (1e-12) need it.
* A hypothesis profile for CI: no deadline (first calls compile), a modest number of
  examples, and derandomized so that a CI run is reproducible.  ``HYPOTHESIS_PROFILE=thorough``
  selects a longer, randomized profile for local exploration.
* Strict dtype promotion (``jax_numpy_dtype_promotion = "strict"``, as optimistix/equinox test):
  no implicit mixing of float32/float64/complex/int arrays in the library. Always on for the
  kernel test files (:data:`STRICT_MODULES`); for the whole suite with
  ``LAYERSTACK_STRICT_DTYPES=1`` (not yet the default: the rest of the suite has not been shown
  to pass under it); the ``strict_dtypes`` fixture turns it on for one test.
* ``tests/`` and the repository root are put on ``sys.path`` so that ``import reference`` and
  ``import layerstack_jax`` work from any working directory without an installed package.
"""

from __future__ import annotations

import os
import sys

import jax

jax.config.update("jax_enable_x64", True)
if os.environ.get("LAYERSTACK_STRICT_DTYPES", "0") == "1":
    jax.config.update("jax_numpy_dtype_promotion", "strict")

_HERE = os.path.dirname(os.path.abspath(__file__))
_ROOT = os.path.dirname(_HERE)
for _p in (_HERE, _ROOT):
    if _p not in sys.path:
        sys.path.insert(0, _p)

import pytest  # noqa: E402
from hypothesis import HealthCheck, settings  # noqa: E402

#: test files that always run under strict promotion: the kernels' own tests
STRICT_MODULES = frozenset({"test_coherent", "test_incoherent", "test_quadrature", "test_background",
                            "test_effective_medium", "test_oscillators", "test_dtypes", "test_shapes"})


@pytest.fixture(autouse=True)
def _strict_promotion_in_kernel_tests(request):
    if request.module.__name__ in STRICT_MODULES:
        with jax.numpy_dtype_promotion("strict"):
            yield
    else:
        yield


@pytest.fixture
def strict_dtypes():
    """Strict dtype promotion for one test (restored afterwards): an implicit float32/float64,
    real/complex or int/float mix inside the library raises instead of promoting silently."""
    with jax.numpy_dtype_promotion("strict"):
        yield


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
