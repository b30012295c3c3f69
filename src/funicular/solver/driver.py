"""The interior-point loop of ``ipm._iterate`` compiled in one piece, for chains whose every
per-iteration term has a compiled kernel: node contact, obstacles that are all disks, ellipses or
half-planes (or none), the default linear solver.

Why: a Newton step of the Python driver makes some hundred numpy and kernel calls, 0.15-0.2 ms
whatever the chain's size, so a 50-node chain over a disk spent 3 ms of its 8 ms in the driver.
Here a step costs what its arithmetic costs (about 25 us at 50 nodes). The formulas are the
Python driver's, in the same order (``ipm._interior_point_step``, the two line searches,
``_recentred``, ``_factor``'s inertia correction, ``_kkt_error``), and the loops are
``fused``'s and ``compiled``'s own kernels; only the order of a few sums differs (dot products
here are plain loops, numpy's are blocked), so the iterates agree to rounding, which the tests
check on the built-in scenarios.

The loop stops where the Python driver would act: the polish (``POLISH``: an active-set Newton
step is ready to be tried; ``ipm`` runs it and, if it fails, resumes here with ``check_polish``
off), the tolerance, the iteration limit, a non-finite iterate, a stalled line search. The
constants come from ``ipm`` as arguments, so there is one place to change them.

numba is imported with this module (``compiled.driver()`` imports it for a compiled solve only). numba's
on-disk cache of :func:`interior_point_steps` does not notice edits to the kernels it calls in
other files (``fused``, ``compiled``, ``curvature.penalty_and_shift`` and the constants it reads):
after changing those, delete ``__pycache__/driver.*.nb*``.

:func:`escape_curvature` is ``curvature.escape_test`` compiled in one piece likewise (its numpy
steps cost a 50-node saddle 0.3 ms, a fifth of its solve).
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np

from funicular.solver import compiled, curvature, fused

_njit = numba.njit(cache=True, nogil=True, error_model="numpy")
_link_terms = _njit(fused.link_terms)
_quadratic_contacts = _njit(fused.quadratic_contacts)
_kkt_parts = _njit(fused.kkt_parts)
_link_blocks = _njit(fused.link_blocks)
_newton_rhs = _njit(fused.newton_rhs)
_newton_update = _njit(fused.newton_update)
_step_to_boundary = _njit(fused.step_to_boundary)
_factor_blocks = _njit(compiled.factor_blocks)
_solve_blocks = _njit(compiled.solve_blocks)
_polish_solve = _njit(fused.polish_solve)
_median = _njit(fused.median)
_penalty_and_shift = _njit(curvature.penalty_and_shift)

# What the loop stopped for (``ipm`` maps these onto its statuses and the polish). POLISH and
# STALLED ask ``ipm`` for its polish: the compiled one met a block its elimination cannot take (or
# the loop stalled before any polish), and ``ipm.polish_step`` falls back to the banded LU.
# STUCK: stalled, and the compiled polish gave up too.
OPTIMAL, POLISH, MAX_ITERATIONS, NONFINITE, STALLED, NOT_FACTORED, STEPPED, POLISHED, STUCK = range(9)
# What the compiled polish ended with: met the tolerance, gave up, or must be left to ``ipm``.
_DONE, _GAVE_UP, _NOT_ELIMINATED = range(3)

# ``numbers``, read and written: the iteration, KKT error and previous error, merit penalty,
# inertia correction, the polish's steps (POLISHED); the constants of ``ipm`` that the loop needs
# come in ``settings``.
ITERATION, ERROR, PREVIOUS_ERROR, PENALTY, REGULARIZATION, POLISH_TAKEN = range(6)
(
    TOL,
    POLISH_FROM,
    POLISH_STALLED,
    MAX_ITER,
    PENALTY_DECAY,
    STEP_TO_BOUNDARY,
    CENTRING_FLOOR,
    CENTRALITY,
    ARMIJO,
    MAX_BACKTRACKS,
    TINY,
    FAILED_ERROR,
    FLOOR,
    POLISH_STEPS,
    POLISH_PATIENCE,
    POLISH_CORRECTING,
    POLISH_DIVERGENCE,
    PROXIMAL,
    INITIAL_MULTIPLIER,
    MIN_INITIAL_SLACK,
    SETTINGS,  # (their number)
) = range(21)
CHAIN_FIELDS = ("squared", "positions", "free", "links", "lengths", "load", "free_index", "link_row")


@_njit
def evaluate(chain: Any, quadratic: Any, z: Any, mu: Any) -> Any:  # pragma: no cover - compiled
    """``chain.evaluate`` (node contact, quadratic obstacles): positions, c, q, gradients of phi,
    dual residual. (``chain.evaluate`` calls it for every chain the driver covers.)"""
    squared, positions0, free, links, lengths, load = chain[0], chain[1], chain[2], chain[3], chain[4], chain[5]
    centres, values, gradients, hessians = quadratic
    n, n_obstacles = free.shape[0], centres.shape[0]
    positions = positions0.copy()
    for f in range(n):
        positions[free[f], 0], positions[free[f], 1] = z[2 * f], z[2 * f + 1]
    n_links = links.shape[0]
    c = np.empty(n_links + n_obstacles * n)
    q, force = np.zeros((positions.shape[0] - 1, 2)), np.zeros_like(positions)
    _link_terms(squared, positions, lengths, links, mu, c[:n_links], q, force)
    dual = np.empty((n, 2))
    for f in range(n):
        dual[f, 0], dual[f, 1] = force[free[f], 0], force[free[f], 1] + load[free[f]]
    gradient = np.empty((n_obstacles, n, 2))
    if n_obstacles:
        _quadratic_contacts(positions, free, n_links, centres, values, gradients, hessians, mu, c, gradient, dual)
    return positions, c, q, gradient, dual


@_njit
def _energy(load: Any, positions: Any) -> float:  # pragma: no cover - compiled
    total = 0.0
    for i in range(positions.shape[0]):
        total += load[i] * positions[i, 1]
    return total


@_njit
def _squared_norm(values: Any) -> float:  # pragma: no cover - compiled
    total = 0.0
    for v in values.ravel():
        total += v * v
    return total


@_njit
def _forces_and_lengths(chain: Any, n_obstacles: int, point: Any, mu: Any) -> Any:  # pragma: no cover
    """``ipm._kkt_parts`` (compiled branch): the largest residual in units of force, and of length."""
    squared, links, lengths = chain[0], chain[3], chain[4]
    stationarity, net0, net1, primal, negative, complementarity = _kkt_parts(
        squared, point[4], point[1], mu, lengths, links
    )
    net = 0.0 if n_obstacles else max(abs(net0), abs(net1))
    return max(stationarity, net, negative, complementarity), primal


@_njit
def _kkt_error(chain: Any, n_obstacles: int, point: Any, mu: Any) -> float:  # pragma: no cover - compiled
    """``ipm._kkt_error``: NaN if any residual is."""
    forces, lengths = _forces_and_lengths(chain, n_obstacles, point, mu)
    if math.isnan(lengths):  # (``_kkt_parts`` makes every part NaN if one is; max might skip one)
        return math.nan
    return float(max(forces, lengths))


@_njit
def _newton_matrix(chain: Any, quadratic: Any, point: Any, mu: Any, sigma: Any) -> Any:  # pragma: no cover
    """``chain.newton_matrix`` (node contact, constant obstacle Hessians): diagonal and off-diagonal blocks."""
    squared, free, links, lengths, free_index = chain[0], chain[2], chain[3], chain[4], chain[6]
    hessians = quadratic[3]
    positions, q, gradient = point[0], point[2], point[3]
    n, n_links = free.shape[0], links.shape[0]
    diagonal, off_diagonal = np.zeros((n, 2, 2)), np.zeros((max(n - 1, 0), 2, 2))
    _link_blocks(
        squared, positions, lengths, links, mu[:n_links], sigma[:n_links], q, free_index, diagonal, off_diagonal
    )
    for j in range(gradient.shape[0]):  # (fused.contact_blocks with the Hessian held constant)
        h00, h01, h10, h11 = hessians[j, 0, 0], hessians[j, 0, 1], hessians[j, 1, 0], hessians[j, 1, 1]
        for f in range(n):
            row = n_links + j * n + f
            nu, w = mu[row], sigma[row]
            g0, g1 = gradient[j, f, 0], gradient[j, f, 1]
            diagonal[f, 0, 0] += nu * h00 + w * g0 * g0
            diagonal[f, 0, 1] += nu * h01 + w * g0 * g1
            diagonal[f, 1, 0] += nu * h10 + w * g1 * g0
            diagonal[f, 1, 1] += nu * h11 + w * g1 * g1
    return diagonal, off_diagonal


@_njit
def _factor(diagonal: Any, off_diagonal: Any, previous: float) -> Any:  # pragma: no cover - compiled
    """``ipm._factor``: the factors of ``matrix + delta I`` for the smallest delta (growing tenfold)
    that makes it positive definite, and the delta to carry on with; ``ok`` False if none up to
    1e20 times the largest diagonal entry does."""
    n = diagonal.shape[0]
    largest = 0.0
    for f in range(n):
        largest = max(largest, abs(diagonal[f, 0, 0]), abs(diagonal[f, 1, 1]))
    scale = max(largest, 1e-300)
    delta = 0.0 if previous == 0.0 else previous / 4.0
    lower, coupling = np.empty((n, 3)), np.empty((max(n - 1, 0), 2, 2))
    shifted = diagonal.copy()
    while True:
        shift = delta + 1e-14 * scale
        for f in range(n):
            shifted[f, 0, 0], shifted[f, 1, 1] = diagonal[f, 0, 0] + shift, diagonal[f, 1, 1] + shift
        if _factor_blocks(shifted, off_diagonal, lower, coupling) < 0:
            return lower, coupling, (0.0 if delta < 1e-12 * scale else delta), True
        delta = max(1e-10 * scale, 10.0 * delta)
        if not delta <= 1e20 * scale:
            return lower, coupling, delta, False


@_njit
def _direction(chain: Any, point: Any, factors: Any, s: Any, mu: Any, r_c: Any) -> Any:  # pragma: no cover
    """``ipm._newton_direction`` (compiled node-contact branch): dz, ds, dmu."""
    free, links, free_index, link_row = chain[2], chain[3], chain[6], chain[7]
    q, gradient, dual, c = point[2], point[3], point[4], point[1]
    rhs = np.empty(2 * free.shape[0])
    _newton_rhs(q, link_row, free, gradient, dual, c, s, mu, r_c, rhs)
    dz = np.empty_like(rhs)
    _solve_blocks(factors[0], factors[1], rhs, dz)
    dmu, ds = np.empty_like(mu), np.empty_like(mu)
    _newton_update(q, links, free_index, gradient, dz, c, s, mu, r_c, dmu, ds)
    return dz, ds, dmu


@_njit
def _merit(load: Any, point: Any, s: Any, tau: Any, penalty: float, infeasibility: float) -> float:  # pragma: no cover
    """``ipm._merit``."""
    barrier = 0.0
    for i in range(s.shape[0]):
        barrier += tau[i] * math.log(s[i])
    return _energy(load, point[0]) - barrier + 0.5 * penalty * infeasibility


@_njit
def _infeasibility_of(c: Any, s: Any) -> float:  # pragma: no cover - compiled
    """``||c + s||^2``."""
    total = 0.0
    for i in range(s.shape[0]):
        total += (c[i] + s[i]) * (c[i] + s[i])
    return total


@_njit
def _barrier_line_search(
    chain: Any, quadratic: Any, settings: Any, state: Any, step: Any, tau: Any, penalty: float
) -> Any:  # pragma: no cover - compiled
    """``ipm._barrier_line_search``: (accepted, new state, penalty)."""
    load, free = chain[5], chain[2]
    z, s, mu, point = state
    dz, ds, dmu = step
    fraction_to_boundary = settings[STEP_TO_BOUNDARY]
    alpha_p = _step_to_boundary(s, ds, fraction_to_boundary)
    alpha_d = _step_to_boundary(mu, dmu, fraction_to_boundary)
    infeasibility = _infeasibility_of(point[1], s)
    slope_barrier = 0.0
    for f in range(free.shape[0]):
        slope_barrier += load[free[f]] * dz[2 * f + 1]
    barrier_slope = 0.0
    for i in range(s.shape[0]):
        barrier_slope += tau[i] * (ds[i] / s[i])
    slope_barrier -= barrier_slope
    if slope_barrier > 0.0 and infeasibility > 0.0:  # raise the penalty until we descend
        penalty = max(penalty, 10.0 * slope_barrier / infeasibility)
    slope = slope_barrier - penalty * infeasibility
    current = _merit(load, point, s, tau, penalty, infeasibility)
    mu_new = mu + alpha_d * dmu
    fraction = 1.0
    for _ in range(int(settings[MAX_BACKTRACKS])):
        alpha = fraction * alpha_p
        z_new, s_new = z + alpha * dz, np.maximum(s + alpha * ds, settings[TINY])
        trial = evaluate(chain, quadratic, z_new, mu_new)
        value = _merit(load, trial, s_new, tau, penalty, _infeasibility_of(trial[1], s_new))
        if math.isfinite(value) and value <= current + settings[ARMIJO] * alpha * min(slope, 0.0):
            return True, (z_new, s_new, mu_new, trial), penalty
        fraction *= 0.5
    return False, state, penalty


@_njit
def _residual_merit(point: Any, s: Any, mu: Any, target: Any) -> float:  # pragma: no cover - compiled
    """``ipm._residual_merit``."""
    complementarity = 0.0
    for i in range(s.shape[0]):
        complementarity += (s[i] * mu[i] - target[i]) ** 2
    return _squared_norm(point[4]) + _infeasibility_of(point[1], s) + complementarity


@_njit
def _residual_line_search(
    chain: Any, quadratic: Any, settings: Any, state: Any, step: Any, target: Any, penalty: float
) -> Any:  # pragma: no cover - compiled
    """``ipm._residual_line_search``: (accepted, new state, penalty)."""
    z, s, mu, point = state
    dz, ds, dmu = step
    alpha_p = _step_to_boundary(s, ds, settings[STEP_TO_BOUNDARY])
    alpha_d = _step_to_boundary(mu, dmu, settings[STEP_TO_BOUNDARY])
    current = _residual_merit(point, s, mu, target)
    fraction = 1.0
    for _ in range(int(settings[MAX_BACKTRACKS])):
        z_new = z + fraction * alpha_p * dz
        s_new = np.maximum(s + fraction * alpha_p * ds, settings[TINY])
        mu_new = mu + fraction * alpha_d * dmu
        trial = evaluate(chain, quadratic, z_new, mu_new)
        value = _residual_merit(trial, s_new, mu_new, target)
        if math.isfinite(value) and value <= (1.0 - settings[ARMIJO] * fraction) * current:
            return True, (z_new, s_new, mu_new, trial), penalty
        fraction *= 0.5
    return False, state, penalty


@_njit
def _all_finite(values: Any) -> bool:  # pragma: no cover - compiled
    for v in values.ravel():  # noqa: SIM110 (numba compiles no generator expressions)
        if not math.isfinite(v):
            return False
    return True


@_njit
def _step(
    chain: Any, quadratic: Any, settings: Any, state: Any, weight: Any, total_weight: float, numbers: Any
) -> Any:  # pragma: no cover - compiled
    """``ipm._interior_point_step``: (STEPPED or why not, new state); the penalty and the inertia
    correction are carried in ``numbers``."""
    s, mu, point = state[1], state[2], state[3]
    n_obstacles = quadratic[0].shape[0]
    sigma = mu / s
    if not _all_finite(sigma):
        return NONFINITE, state
    diagonal, off_diagonal = _newton_matrix(chain, quadratic, point, mu, sigma)
    if not (_all_finite(diagonal) and _all_finite(off_diagonal)):
        return NONFINITE, state
    lower, coupling, regularization, factored = _factor(diagonal, off_diagonal, numbers[REGULARIZATION])
    if not factored:
        return NOT_FACTORED, state
    numbers[REGULARIZATION] = regularization
    factors = (lower, coupling)
    tau = (s @ mu) / total_weight

    # Mehrotra predictor: the pure Newton (affine) step decides how much to centre.
    products = s * mu
    _, ds_a, dmu_a = _direction(chain, point, factors, s, mu, products)
    alpha_p = _step_to_boundary(s, ds_a, settings[STEP_TO_BOUNDARY])
    alpha_d = _step_to_boundary(mu, dmu_a, settings[STEP_TO_BOUNDARY])
    tau_affine = ((s + alpha_p * ds_a) @ (mu + alpha_d * dmu_a)) / total_weight
    target = min(1.0, (tau_affine / tau) ** 3) * tau if tau > 0 else 0.0
    stationarity = 0.0
    for v in point[4].ravel():
        stationarity = max(stationarity, abs(v))
    largest_c = 0.0
    for v in point[1]:
        largest_c = max(largest_c, v)  # (skips a NaN like np.fmax)
    target = max(target, min(tau, settings[CENTRING_FLOOR] * max(stationarity, largest_c)))
    targets = target * weight

    penalty = numbers[PENALTY]
    for correction_on in (True, False):
        correction = ds_a * dmu_a if correction_on else np.zeros_like(s)
        step = _direction(chain, point, factors, s, mu, products + correction - targets)
        for barrier_first in (True, False):
            # With obstacles the barrier merit goes first, without them the residual (see ipm).
            if barrier_first == (n_obstacles > 0):
                accepted, new, penalty = _barrier_line_search(chain, quadratic, settings, state, step, targets, penalty)
            else:
                accepted, new, penalty = _residual_line_search(
                    chain, quadratic, settings, state, step, targets, penalty
                )
            if accepted:
                numbers[PENALTY] = penalty
                z_new, s_new, mu_new, point_new = new
                tau_new = (s_new @ mu_new) / total_weight
                low, high = (
                    weight * tau_new / (settings[CENTRALITY] * s_new),
                    settings[CENTRALITY] * weight * tau_new / s_new,
                )
                return STEPPED, (z_new, s_new, np.minimum(np.maximum(mu_new, low), high), point_new)
    numbers[PENALTY] = penalty
    return STALLED, state


@_njit
def _lifting_off(active: Any, nu: Any, leaving: Any) -> Any:  # pragma: no cover - compiled
    """``ipm._lifting_off``: (n_obstacles, rows) arrays, runs of touching nodes walked one by one."""
    lifting = leaving.copy()
    rows = active.shape[1]
    for j in range(active.shape[0]):
        f = 0
        while f < rows:
            if not active[j, f]:
                f += 1
                continue
            a = f
            while f < rows and active[j, f]:
                f += 1
            b = f - 1
            if not (a < b and (leaving[j, a] or leaving[j, b])):
                continue
            for from_first in (True, False):
                end = a if from_first else b
                inside = nu[j, a + 2 : min(a + 12, b + 1)] if from_first else nu[j, max(b - 11, a) : b - 1]
                reference = _median(inside) if inside.size else 0.0
                if leaving[j, end] and reference > 0.0:
                    drop = max(1, int(min(1.0 - nu[j, end] / reference, (b - a + 1) // 2)))
                    for i in range(drop):  # (at most half the run, as in ipm)
                        lifting[j, a + i if from_first else b - i] = True
    return lifting


@_njit
def _polish(
    chain: Any, quadratic: Any, settings: Any, polish_arrays: Any, z: Any, mu: Any, active: Any
) -> Any:  # pragma: no cover - compiled
    """``ipm._polish`` from the iterate (no ``start``, POLISH_STEPS): (how it ended, steps, state
    (z, mu, point)); _NOT_ELIMINATED where ``fused.polish_solve`` gives up on a step (``ipm`` then
    runs its own polish, whose banded LU takes such steps). ``polish_arrays``: the tolerance's row
    units, the contact Hessians at the free nodes and ``polish_solve``'s workspace."""
    squared, free, links, lengths, load = chain[0], chain[2], chain[3], chain[4], chain[5]
    row_units, contact_hessian, coupling, contact_coupling = polish_arrays
    n_obstacles, n_links = quadratic[0].shape[0], links.shape[0]
    plain = settings[TOL]
    active = active.copy()
    mu = np.where(active, mu, 0.0)
    point = evaluate(chain, quadratic, z, mu)
    start_error = _kkt_error(chain, n_obstacles, point, mu)
    best_error = math.inf
    diverging = settled = 0
    for steps in range(1, int(settings[POLISH_STEPS]) + 1):
        new_z, new_mu = np.empty(2 * free.shape[0]), np.empty_like(mu)
        failed = _polish_solve(
            squared,
            point[0],
            lengths,
            load,
            free,
            links,
            active,
            mu,
            point[1],
            point[3],
            contact_hessian,
            settings[PROXIMAL],
            new_z,
            new_mu,
            coupling,
            contact_coupling,
        )
        if failed >= 0:
            return _NOT_ELIMINATED, steps, (z, mu, point)
        z, mu = new_z, new_mu
        point = evaluate(chain, quadratic, z, mu)
        # ``ipm._Tolerance.check``
        forces, lengths_part = _forces_and_lengths(chain, n_obstacles, point, mu)
        error = max(forces, lengths_part)
        if not lengths_part <= plain or not forces > plain:
            done = error <= plain
        else:
            largest = 1.0
            for r in range(mu.shape[0]):
                largest = max(largest, abs(mu[r]) / row_units[r])
            done = math.isfinite(largest) and forces <= settings[FLOOR] * largest
        if done:
            return _DONE, steps, (z, mu, point)
        if error < best_error:
            best_error = error
        if steps >= settings[POLISH_CORRECTING] and not best_error < start_error:
            break
        c = point[1]
        leaving, joining = active & (mu < 0.0), ~active & (c > plain)
        if not np.any(leaving | joining):
            settled += 1
            diverging = diverging + 1 if not error < settings[POLISH_DIVERGENCE] * start_error else 0
            if diverging == 2 or (settled >= settings[POLISH_PATIENCE] and not best_error < start_error):
                break
        if n_obstacles and np.any(leaving[n_links:]):
            shape = (n_obstacles, free.shape[0])
            lifting = _lifting_off(
                active[n_links:].reshape(shape), mu[n_links:].reshape(shape), leaving[n_links:].reshape(shape)
            )
            leaving[n_links:] = lifting.ravel() & ~joining[n_links:]
        active = (active | joining) & ~leaving
        mu = np.where(active, mu, 0.0)
    return _GAVE_UP, 0, (z, mu, point)


@_njit
def _cold_start(c: Any, weight: Any, unit: Any, n_links: int, settings: Any) -> Any:  # pragma: no cover
    """``ipm._cold_start``: slacks and multipliers from the constraint values ``c`` alone."""
    initial = settings[INITIAL_MULTIPLIER]
    mu = initial * unit
    s = np.maximum(-c, settings[MIN_INITIAL_SLACK] * weight / unit)
    if c.shape[0] > n_links:
        tau = _median((s * mu / weight)[:n_links]) if n_links else settings[MIN_INITIAL_SLACK]
        mu[n_links:] = np.minimum(initial, tau / s[n_links:])
    return s, mu


def interior_point_steps(
    chain: Any,
    quadratic: Any,
    settings: Any,
    weight: Any,
    total_weight: float,
    active_unit: Any,
    polish_arrays: Any,
    failed_active: Any,
    failed: bool,
    check_polish: bool,
    cold: bool,
    z: Any,
    s: Any,
    mu: Any,
    numbers: Any,
) -> Any:  # pragma: no cover - compiled
    """``ipm._iterate``'s loop, with its polish (``_polish``), from ``numbers[ITERATION]`` until
    it must stop: (what for, state).

    ``chain``: (squared, positions, free, links, lengths, load, free_index, link_row) as in
    ``ScaledChain``; ``quadratic``: its ``quadratic_coefficients`` (empty arrays without
    obstacles); the state (z, s, mu, point) starts from ``z, s, mu``; ``polish_arrays``: see
    ``_polish``. ``failed``: whether a polish has failed, from the active set ``failed_active``
    at the error ``settings[FAILED_ERROR]``; ``check_polish`` False resumes after a failed polish
    (``ipm``'s), at the same iteration; ``cold``: ``s`` and ``mu`` are made here (``_cold_start``)
    from the constraint values at ``z``. POLISHED: the polish met the tolerance, after
    ``numbers[POLISH_TAKEN]`` steps, at the state returned (its slacks those of the last iterate)."""
    n_obstacles = quadratic[0].shape[0]
    polish_from = settings[POLISH_FROM] if n_obstacles else 10.0 * settings[POLISH_FROM]
    max_iterations = int(settings[MAX_ITER])
    if cold:
        c = evaluate(chain, quadratic, z, np.zeros(weight.shape[0]))[1]
        s, mu = _cold_start(c, weight, polish_arrays[0], chain[3].shape[0], settings)
    state = (z, s, mu, evaluate(chain, quadratic, z, mu))
    while True:
        z, s, mu, point = state
        iteration = int(numbers[ITERATION])
        if not (_all_finite(z) and _all_finite(mu) and _all_finite(s)):
            return NONFINITE, state
        error = _kkt_error(chain, n_obstacles, point, mu)
        numbers[ERROR] = error
        if check_polish:
            changed = False
            for i in range(mu.shape[0]):
                if (mu[i] > s[i] * active_unit[i]) != failed_active[i]:
                    changed = True
                    break
            failed_error = settings[FAILED_ERROR]
            retry = not failed or error < failed_error / 2 or changed
            previous = numbers[PREVIOUS_ERROR]
            ready = error <= polish_from or (error <= settings[POLISH_STALLED] and error > 0.1 * previous)
            numbers[PREVIOUS_ERROR] = error
            if ready and retry:
                active = mu > s * active_unit
                how, steps, polished = _polish(chain, quadratic, settings, polish_arrays, z, mu, active)
                if how == _DONE:
                    numbers[POLISH_TAKEN] = steps
                    return POLISHED, (polished[0], s, polished[1], polished[2])
                if how == _NOT_ELIMINATED:
                    return POLISH, state
                # (ipm's polish failing: retry once the active set changes or the error halves)
                failed_active, failed, settings[FAILED_ERROR] = active, True, error
        check_polish = True
        if error <= settings[TOL]:
            return OPTIMAL, state
        if iteration == max_iterations:
            return MAX_ITERATIONS, state
        numbers[PENALTY] = max(1.0, numbers[PENALTY] / settings[PENALTY_DECAY])
        status, stepped = _step(chain, quadratic, settings, state, weight, total_weight, numbers)
        if status == STALLED:
            how, steps, polished = _polish(chain, quadratic, settings, polish_arrays, z, mu, mu > s * active_unit)
            if how == _DONE:
                numbers[POLISH_TAKEN] = steps
                return POLISHED, (polished[0], s, polished[1], polished[2])
            return (STALLED if how == _NOT_ELIMINATED else STUCK), state
        if status != STEPPED:
            return status, stepped
        state = stepped
        numbers[ITERATION] = iteration + 1


# What ``escape_curvature`` found (``curvature.Curvature``): a proven strict local minimum, a
# direction of negative curvature, or neither.
MINIMUM, DIRECTION, UNDECIDED = range(3)
# ``escape_curvature``'s ``search``: ``curvature``'s tolerances (arguments, so that the on-disk
# cache cannot keep old values).
ROW_FLOOR, MAX_SHIFTS, MAX_STEPS, VECTOR_TOL, BRACKET, CLOSER = range(6)


@_njit
def _lowest_eigenpair(diagonal: Any, off_diagonal: Any, below: float, above: float, start: Any, search: Any) -> Any:
    """``curvature.lowest_eigenpair`` with the block Cholesky: (found, eigenvalue, unit vector)."""
    n = diagonal.shape[0]
    lower, coupling = np.empty((n, 3)), np.empty((max(n - 1, 0), 2, 2))
    shifted, w = diagonal.copy(), np.empty(2 * n)
    bottom, top = below, above
    sigma, vector, value = below, start / math.sqrt(_squared_norm(start)), math.inf
    for _ in range(int(search[MAX_SHIFTS])):
        for f in range(n):
            shifted[f, 0, 0], shifted[f, 1, 1] = diagonal[f, 0, 0] + (-sigma), diagonal[f, 1, 1] + (-sigma)
        if _factor_blocks(shifted, off_diagonal, lower, coupling) >= 0:
            if sigma == below:
                return False, value, vector
            top = sigma
            sigma = bottom + 0.5 * (top - bottom)
            continue
        bottom, previous = sigma, math.inf
        for _ in range(int(search[MAX_STEPS])):
            # ``curvature._inverse_iteration``
            _solve_blocks(lower, coupling, vector, w)
            squared, along = 0.0, 0.0
            for i in range(w.shape[0]):
                squared += w[i] * w[i]
                along += w[i] * vector[i]
            length = math.sqrt(squared)
            cosine = min(abs(along) / length, 1.0)
            vector, value, change = w / length, sigma + along / squared, math.sqrt(2.0 * (1.0 - cosine))
            top = min(top, value)
            if change <= search[VECTOR_TOL]:
                return value < above, value, vector
            if change > 0.1 * previous:
                break
            previous = change
        if top - bottom <= search[BRACKET] * (above - below):
            break
        sigma = top - search[CLOSER] * (top - bottom)
    return value < above, value, vector


def escape_curvature(
    chain: Any,
    quadratic: Any,
    point: Any,
    mu: Any,
    tol: float,
    total_length: float,
    threshold: float,
    search: Any,
    start: Any,
) -> Any:  # pragma: no cover - compiled
    """``curvature.escape_test`` at the driver's ``point`` (its steps in the same order):
    (MINIMUM, DIRECTION or UNDECIDED, the curvature, the direction over the free coordinates).
    ``total_length``: the chain's (scaled); ``threshold``: ``curvature.zero_curvature``;
    ``start``: the eigenvalue search's first vector."""
    links = chain[3]
    c, q, gradient = point[1], point[2], point[3]
    n_links, n_obstacles, n_free = links.shape[0], gradient.shape[0], gradient.shape[1]
    m = mu.shape[0]
    norms = np.empty(m)
    for r in range(n_links):
        norms[r] = math.hypot(q[links[r], 0], q[links[r], 1])
    for j in range(n_obstacles):
        for f in range(n_free):
            norms[n_links + j * n_free + f] = math.hypot(gradient[j, f, 0], gradient[j, f, 1])
    # A row of (almost) no length has no direction: no penalty (see curvature).
    directed = norms > search[ROW_FLOOR]
    lowest_force, farthest = 0.0, -math.inf
    for r in range(m):
        if not directed[r]:
            norms[r] = search[ROW_FLOOR]
        lowest_force, farthest = min(lowest_force, mu[r] * norms[r]), max(farthest, c[r] / norms[r])
    if lowest_force < -tol or farthest > tol:
        return UNDECIDED, math.nan, np.zeros(2 * n_free)  # not dual feasible, or infeasible
    hessian = _newton_matrix(chain, quadratic, point, mu, np.zeros(m))
    stiffest = 0.0
    for v in hessian[0].ravel():
        stiffest = max(stiffest, abs(v))
    rho, shift = _penalty_and_shift(stiffest, 1.0 / total_length, n_obstacles, threshold)
    strict_sigma, active_sigma = np.zeros(m), np.zeros(m)
    for r in range(m):
        if directed[r] and c[r] / norms[r] >= -tol:  # active
            active_sigma[r] = rho / norms[r] ** 2
            if mu[r] * norms[r] > tol:  # strictly
                strict_sigma[r] = active_sigma[r]
    diagonal, off_diagonal = _newton_matrix(chain, quadratic, point, mu, strict_sigma)
    for f in range(diagonal.shape[0]):
        diagonal[f, 0, 0], diagonal[f, 1, 1] = diagonal[f, 0, 0] + (-shift), diagonal[f, 1, 1] + (-shift)
    lower, coupling = np.empty((n_free, 3)), np.empty((max(n_free - 1, 0), 2, 2))
    if _factor_blocks(diagonal, off_diagonal, lower, coupling) < 0:
        return MINIMUM, math.nan, np.zeros(2 * n_free)

    # Not proven: is there negative curvature beyond the threshold that keeps every active row active?
    margin = shift - threshold
    diagonal, off_diagonal = _newton_matrix(chain, quadratic, point, mu, active_sigma)
    lowest = 0.0  # ``curvature._lower_bound``: the contact terms' 2x2 blocks, node by node
    if n_obstacles:
        hessians = quadratic[3]
        for f in range(n_free):
            a, b, d = 0.0, 0.0, 0.0
            for j in range(n_obstacles):
                nu = max(mu[n_links + j * n_free + f], 0.0)
                a, b, d = a + nu * hessians[j, 0, 0], b + nu * hessians[j, 0, 1], d + nu * hessians[j, 1, 1]
            lowest = min(lowest, (a + d) / 2 - math.hypot((a - d) / 2, b))
    below = 1.1 * lowest - threshold - 2.0 * margin
    found, value, vector = _lowest_eigenpair(diagonal, off_diagonal, below, -threshold - margin, start, search)
    return (DIRECTION if found else UNDECIDED), value, vector
