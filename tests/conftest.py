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


# Known solver and parser bugs, found by the robustness tests and not fixed yet. Each test stays in
# the suite as a strict xfail: it documents the failure, and it turns red the day the bug is fixed,
# so the mark gets removed. Listed in README ("Known limitations").
KNOWN_FAILURES = {
    f"tests/test_degenerate.py::test_long_profile_chains_that_do_not_converge_yet[{name}]": (
        "max_iterations on a random chain of the long hypothesis profile (README, Known limitations)"
    )
    for name in (
        "against_a_disks_side",
        "slope_and_disks",
        "between_two_disks_on_a_line",
        "squared_links_between_two_disks_and_a_half_plane",
    )
}
KNOWN_FAILURES["tests/test_degenerate.py::test_a_warm_start_from_a_solution_stays_there"] = (
    "a warm start lifts a nearly massless node off its obstacle (README, Known limitations)"
)


def pytest_collection_modifyitems(config: object, items: list) -> None:  # type: ignore[type-arg]
    import pytest

    for item in items:
        reason = KNOWN_FAILURES.get(item.nodeid)
        if reason is not None:
            item.add_marker(pytest.mark.xfail(strict=True, reason=f"known bug: {reason}"))
