"""Hypothesis profiles for the property and fuzz tests.

``default``: a few hundred examples in total, derandomized (the same examples on every run, so CI
is reproducible), no deadline (solve times vary with the machine's load). ``long``: roughly ten
times as many, with a fresh random draw each run; select it with ``--hypothesis-profile=long``.
Each property test asks for a multiple of ``settings().max_examples`` (see ``examples`` in
``tests/test_properties.py``), so both profiles keep the tests' relative weights.
"""

from __future__ import annotations

from hypothesis import HealthCheck, settings

_COMMON = {
    "deadline": None,
    "suppress_health_check": [HealthCheck.too_slow, HealthCheck.data_too_large],
    "print_blob": True,
}

settings.register_profile("default", max_examples=20, derandomize=True, **_COMMON)  # type: ignore[arg-type]
settings.register_profile("long", max_examples=250, derandomize=False, **_COMMON)  # type: ignore[arg-type]

# The hypothesis plugin loads a profile given as --hypothesis-profile before or after this file is
# imported, depending on whether pytest treats it as an initial conftest: only load ours if no other
# profile has been chosen yet.
if settings.get_current_profile_name() == "default":
    settings.load_profile("default")
