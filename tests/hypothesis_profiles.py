"""Hypothesis profiles for the property and fuzz tests.

- ``ci`` (the default, what ``.ci/run`` runs): each test's own ``max_examples`` (written as
  ``examples(n)``), derandomized (the same examples every run, so a failure reproduces and the
  suite's time is fixed), no deadline (a shared two-core machine has slow moments).
- ``long`` (``GSGEO_HYPOTHESIS=long python -m pytest ...``, for a nightly or manual run): ten
  times the examples, drawn at random each run, no deadline.
"""

from __future__ import annotations

import os

from hypothesis import settings

PROFILE = os.environ.get("GSGEO_HYPOTHESIS", "ci")
FACTORS = {"ci": 1, "long": 10}
if PROFILE not in FACTORS:
    raise SystemExit(f"GSGEO_HYPOTHESIS={PROFILE!r}: use one of {', '.join(FACTORS)}")

settings.register_profile("ci", deadline=None, derandomize=True, print_blob=True)
settings.register_profile("long", deadline=None, derandomize=False, print_blob=True)
settings.load_profile(PROFILE)


def examples(n: int) -> int:
    """The number of examples of a test whose ``ci`` count is n under the loaded profile."""
    return n * FACTORS[PROFILE]
