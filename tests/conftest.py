"""Hypothesis profiles for the property and fuzz tests (tests/test_properties.py, test_fuzz_scenarios.py).

``default``: a few hundred examples in total, derandomized (the same examples on every run, so CI
is reproducible), no deadline (solve times vary with the machine's load), and no shrinking: a
failing solve can take a second, and shrinking one can take minutes; the failing example is
printed as a ``Problem.build(...)`` call instead. ``long``: about twelve times as many examples,
freshly random on each run, shrunk to a minimal failing example; select it with
``--hypothesis-profile=long``. Each test asks for a multiple of ``settings().max_examples``, so
both profiles keep the tests' relative weights.
"""

from __future__ import annotations

from hypothesis import HealthCheck, Phase, settings

_COMMON = {
    "deadline": None,
    "suppress_health_check": [HealthCheck.too_slow, HealthCheck.data_too_large],
    "print_blob": True,
}

settings.register_profile(
    "default",
    max_examples=20,
    derandomize=True,
    database=None,
    phases=[Phase.explicit, Phase.generate, Phase.target],
    **_COMMON,  # type: ignore[arg-type]
)
settings.register_profile("long", max_examples=250, **_COMMON)  # type: ignore[arg-type]

# The hypothesis plugin loads a profile named by --hypothesis-profile before or after this file is
# imported, depending on whether pytest treats it as an initial conftest: load ours only if no
# other profile has been chosen. Hypothesis itself loads its built-in "ci" profile (100 examples,
# shrinking on) when the CI environment variable is set; CI must run the same examples as a
# developer's machine, so that one is replaced too.
if settings.get_current_profile_name() in ("default", "ci"):
    settings.load_profile("default")
