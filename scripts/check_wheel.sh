#!/usr/bin/env bash
# Install a built wheel the way a user would, into a fresh virtual environment with no Rust toolchain
# on PATH and its dependencies from the package registry, then run the program and the package from
# it: the wheel must carry the compiled core and everything else funicular needs.
# Usage: scripts/check_wheel.sh dist/funicular-VERSION-TAG.whl   (`make check-wheel` builds it first)
set -euo pipefail

wheel=$(realpath "${1:?usage: scripts/check_wheel.sh dist/funicular-VERSION-TAG.whl}")
python=$(command -v "${PYTHON:-python3}")
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
started=$SECONDS

step() { echo "check_wheel: $*"; }
fail() {
    echo "check_wheel: FAILED: $*" >&2
    exit 1
}
expect() { # expect NAME TEXT PATTERN: TEXT has a line matching the extended regular expression PATTERN
    grep -Eq -- "$3" <<<"$2" || fail "$1: no line matches '$3'"
    step "  $1: $(grep -E -m 1 -- "$3" <<<"$2" | sed 's/^ *//')"
}

step "wheel $(basename "$wheel") ($(du -k "$wheel" | cut -f1) KiB)"
"$python" -m venv "$work/venv"
# Only the new environment and the system's own directories: no cargo, no rustup, no pyenv, nothing
# from the source tree (PYTHONPATH) that could stand in for the installed package.
export PATH="$work/venv/bin:/usr/bin:/bin"
unset PYTHONPATH PYTHONHOME VIRTUAL_ENV CARGO_HOME RUSTUP_HOME
if command -v cargo >/dev/null 2>&1; then
    fail "cargo is on PATH ($(command -v cargo)): this check must run without a Rust toolchain"
fi
step "cargo is not on PATH; $(python --version) in a fresh environment"

python -m pip install --quiet --disable-pip-version-check "$wheel"
step "installed in $((SECONDS - started)) s: $(python -m pip list --disable-pip-version-check --format=freeze | tr '\n' ' ')"

cd "$work" # away from the source tree, so that only the installed package can be imported

solved=$(funicular solve two-supports) || fail "funicular solve two-supports exited with status $?"
expect "solve two-supports" "$solved" '^ +status +optimal '
expect "solve two-supports" "$solved" '^ +energy +-0\.2967089491 '
# the supports carry the chain's weight (mass 1, g = 1): force balance, whatever the solver did
expect "solve two-supports" "$solved" '^ +total +Fx = \S+ +Fy = +1 +\(weight 1\)$'

checked=$(funicular check two-supports) || fail "funicular check two-supports exited with status $?"
expect "check two-supports" "$checked" '^ +KKT residuals .*\(a KKT point at this tolerance\)$'
expect "check two-supports" "$checked" '^ +LICQ +holds'
expect "check two-supports" "$checked" '^ +second order +strict local minimum'

api=$(
    python - <<'PYTHON'
import pathlib

import numpy as np

import funicular
from funicular import Disk, Problem, solve

# the package and its compiled core come from the new environment, not from a source tree
for module in (funicular, funicular._core):
    assert pathlib.Path(module.__file__).is_relative_to(pathlib.Path.cwd()), module.__file__
problem = Problem.build(nodes=61, length=1.5, mass=1.0, gravity=1.0,
                        supports=[(0, (0.0, 0.0)), (-1, (1.0, 0.0))],
                        obstacles=[Disk(center=(0.5, -0.55), radius=0.25)])
solution = solve(problem)
assert solution.status == "optimal", solution.status
# the supports and the disk together carry the weight (0, -1): their forces add up to (0, 1)
carried = solution.support_reactions.sum(axis=0) + solution.contact_forces.sum(axis=0)
assert np.allclose(carried, [0.0, 1.0], atol=1e-9), carried
print(f"funicular {funicular.__version__} from {pathlib.Path(funicular._core.__file__).name}: "
      f"status {solution.status.value}, energy {solution.objective:.10f}, supports and disk carry {carried.round(12) + 0}")
PYTHON
) || fail "the Python API in the installed package"
expect "import funicular; solve(Problem.build(...))" "$api" 'status optimal, energy -0\.2565698104'

step "passed in $((SECONDS - started)) s"
