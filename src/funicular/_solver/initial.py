"""Presolve and exact start: what the solver core (``rust/core/src/presolve.rs`` and
``catenary.rs``) works out before the iteration, and how a problem reaches it.

The presolve checks that consecutive supports are no farther apart than the chain between them,
fixes exactly taut spans on their chord (with their tensions from force balance), rests massless
free ends on the node they hang from, and builds the initial guess: spans sag as parabolas, free
ends hang down, nodes inside an obstacle are pushed out. The exact start gives the equilibrium of a
chain that touches nothing (each span a discrete catenary) with its tensions.

The solve itself runs both (``_core.Chain.solve``); ``presolve`` is for the checks, the other
backends and the studies, which start from the same guess.
"""

from __future__ import annotations

import functools
import heapq
import math
from dataclasses import dataclass

import numpy as np

from funicular import _core
from funicular._constraints import link_distances
from funicular._solver.core_problem import core_chain, core_errors, core_net
from funicular.errors import InfeasibleError, ScenarioError
from funicular.model import FloatArray, IntArray, Problem


@dataclass(frozen=True)
class Presolve:
    """Positions to start from, which nodes the interior-point method may move, and known tensions."""

    positions: FloatArray  # (N, 2) initial guess; exact for fixed nodes
    movable: IntArray  # nodes the interior-point method moves, ascending
    fixed_tension: FloatArray  # (N-1,) tension of links between two fixed nodes (0 where undetermined)
    detached: IntArray  # massless free ends: no force reaches them; they rest on their neighbour
    attach: IntArray  # for each detached node, the node it rests on
    # Each obstacle's grad phi at the movable nodes (``positions[movable]``), where the push-out
    # evaluated them there and moved none (the solver's scaling needs them next), else None.
    obstacle_gradients: tuple[FloatArray, ...] | None = None

    @functools.cached_property
    def fixed(self) -> IntArray:
        """The nodes not in ``movable`` (supports, exactly taut spans, detached ends), ascending."""
        fixed = np.ones(self.positions.shape[0], dtype=bool)
        fixed[self.movable] = False
        return np.flatnonzero(fixed)


def _check_supports_outside(problem: Problem) -> None:
    """A support inside an obstacle makes the problem infeasible (on the surface is fine)."""
    surface = 1e-9 * float(problem.link_lengths.max())  # (relative to a link: on the surface)
    if not problem.obstacles or not (problem.support_depths > surface).any():  # (usually all: one pass)
        return
    for obstacle, inside_by in zip(problem.obstacles, problem.support_depths, strict=True):
        inside = np.flatnonzero(inside_by > surface)
        if inside.size:
            j = int(inside[0])
            node = int(problem.support_nodes[j])
            # (a depth to first order, phi / |grad phi|, is no length where phi is flat)
            deep = f" (about {inside_by[j]:.3g} deep)" if np.isfinite(inside_by[j]) else ""
            raise InfeasibleError(
                f"the support at node {node} {tuple(problem.support_positions[j].tolist())} is inside obstacle "
                f"{obstacle.name!r}{deep}; move the support or the obstacle."
            )


def _answer(problem: Problem, answer: _core.Presolved) -> Presolve:
    n, movable = problem.n_nodes, answer.movable
    stacked = None
    if answer.obstacle_gradients is not None:
        stacked = tuple(answer.obstacle_gradients.reshape(len(problem.obstacles), movable.size, problem.dimension))
    return Presolve(
        answer.positions.reshape(n, problem.dimension),
        movable.astype(np.intp),
        answer.fixed_tension,
        answer.detached.astype(np.intp),
        answer.attach.astype(np.intp),
        stacked,
    )


def checked_guess(problem: Problem, initial_positions: FloatArray | None) -> FloatArray | None:
    """``initial_positions`` as a float array, checked: (N, d) and finite."""
    if initial_positions is None:
        return None
    n, d = problem.n_nodes, problem.dimension
    guess = np.asarray(initial_positions, dtype=np.float64)
    if guess.shape != (n, d) or not np.isfinite(guess).all():
        what = "(x, y) pairs" if d == 2 else "(x, y, z) triples"
        raise ScenarioError(f"initial_positions must be {n} finite {what}, got an array of shape {guess.shape}.")
    return guess


REACH_CHECKED_UP_TO = 1000  # supports: a net with more is not checked pair by pair before solving
REACH_BY_PATHS_UP_TO = 32  # supports up to which the pairs are checked at once, without a shape first
# Links visited (searches times inextensible links) up to which the supports' shortest paths are
# searched in Python, about 0.4 us a link; beyond, by SciPy's graph routines, which take 0.1 s to
# import (a 100 x 100 grid hung from its corners: 3 searches of 19,800 links, 0.02 s in Python).
REACH_IN_PYTHON_UP_TO = 300_000


def check_net_reach(problem: Problem) -> None:
    """Two supports of a net must be no farther apart than the shortest path of inextensible links
    between them, or no shape of the net reaches both (:class:`InfeasibleError` naming them). An
    elastic link stretches as far as it is pulled: a path through one reaches any distance."""
    supports = problem.support_nodes
    if problem.solved_as_chain or not 2 <= supports.size <= REACH_CHECKED_UP_TO:
        return
    if supports.size > REACH_BY_PATHS_UP_TO and _start_within_lengths(problem):
        return  # a shape that keeps every link within its length joins every pair of supports
    positions = problem.support_positions
    apart = np.linalg.norm(positions[:, None, :] - positions[None, :, :], axis=2)
    reach = support_reach(problem, apart)
    a, b = np.unravel_index(np.argmax(apart - reach), apart.shape)
    if apart[a, b] > reach[a, b] * (1.0 + 1e-12):
        raise InfeasibleError(
            f"supports at nodes {supports[a]} {tuple(positions[a].tolist())} and {supports[b]} "
            f"{tuple(positions[b].tolist())} are {apart[a, b]:.6g} apart, but the shortest path of links between "
            f"them is only {reach[a, b]:.6g} long; move them closer or lengthen the links."
        )


def support_reach(problem: Problem, bound: FloatArray) -> FloatArray:
    """The length of the shortest path of inextensible links between every pair of supports (S, S),
    where it is no longer than ``bound`` (S, S, symmetric), else inf (as where no such path
    exists): a search stops at the longest bound. Of parallel links a path takes the shortest."""
    supports, rigid = problem.support_nodes, ~problem.elastic
    pairs, lengths = problem.link_nodes[rigid], problem.link_lengths[rigid]
    if (supports.size - 1) * lengths.size <= REACH_IN_PYTHON_UP_TO:
        reach = _reach_by_heap(problem.n_nodes, pairs, lengths, supports, bound)
    else:
        reach = _reach_by_scipy(problem.n_nodes, pairs, lengths, supports, bound)
    reach[reach > bound] = np.inf
    return reach


def _reach_by_heap(n: int, pairs: IntArray, lengths: FloatArray, supports: IntArray, bound: FloatArray) -> FloatArray:
    """:func:`support_reach` by Dijkstra's search with a heap, from each support to the ones after
    it, up to the farthest of those or the longest of their bounds, whichever comes first."""
    # Each node's neighbours and link lengths, as Python lists (the search reads them one by one).
    heads = np.concatenate([pairs[:, 0], pairs[:, 1]])
    order = np.argsort(heads, kind="stable")
    first = np.concatenate([[0], np.cumsum(np.bincount(heads, minlength=n))]).tolist()
    ends = np.concatenate([pairs[:, 1], pairs[:, 0]])[order].tolist()
    weights = np.concatenate([lengths, lengths])[order].tolist()
    nodes = supports.tolist()
    reach = np.full((len(nodes), len(nodes)), np.inf)
    np.fill_diagonal(reach, 0.0)
    for i, source in enumerate(nodes[:-1]):
        targets: dict[int, float | None] = dict.fromkeys(nodes[i + 1 :])
        left = len(targets)
        radius = float(bound[i, i + 1 :].max())
        distance = [math.inf] * n
        distance[source] = 0.0
        heap = [(0.0, source)]
        while heap:
            d, node = heapq.heappop(heap)
            if d > distance[node]:
                continue  # (an older entry: the node was reached by a shorter path since)
            if d > radius:
                break  # every path not yet found is longer than every bound
            if node in targets:
                targets[node] = d
                left -= 1
                if not left:
                    break
            for k in range(first[node], first[node + 1]):
                further = d + weights[k]
                if further < distance[ends[k]]:
                    distance[ends[k]] = further
                    heapq.heappush(heap, (further, ends[k]))
        for j, node in enumerate(nodes[i + 1 :], start=i + 1):
            found = targets[node]
            if found is not None:
                reach[i, j] = reach[j, i] = found
    return reach


def _reach_by_scipy(n: int, pairs: IntArray, lengths: FloatArray, supports: IntArray, bound: FloatArray) -> FloatArray:
    """:func:`support_reach` by SciPy's Dijkstra, one search per support (for many links and
    supports: it takes 0.1 s to import)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    # Each pair of nodes once, with its shortest link: a sparse matrix adds up repeated entries.
    pairs = np.sort(pairs, axis=1)
    order = np.lexsort((lengths, pairs[:, 1], pairs[:, 0]))
    pairs, lengths = pairs[order], lengths[order]
    once = np.ones(lengths.size, dtype=bool)
    once[1:] = np.any(pairs[1:] != pairs[:-1], axis=1)
    graph = coo_matrix((lengths[once], (pairs[once, 0], pairs[once, 1])), shape=(n, n)).tocsr()
    reach: FloatArray = dijkstra(graph, directed=False, indices=supports, limit=float(bound.max()))[:, supports]
    return reach


def _start_within_lengths(problem: Problem) -> bool:
    """Whether the net's force-density start (the solver's, one sparse factorization) keeps every
    link within its length: then every path of links is at least as long as the distance between
    its ends, and no pair of supports is too far apart. (One shortest-path search per support
    costs far more where many supports hold a net: 0.3 s at 396 supports of a 100 x 100 grid.)"""
    with core_errors(problem):
        start = core_net(problem).hanging_start()
    if start is None:
        return False
    positions = start.reshape(problem.n_nodes, problem.dimension)
    return bool(np.all(link_distances(positions, problem.links) <= problem.link_lengths * (1.0 + 1e-12)))


def presolve(problem: Problem, initial_positions: FloatArray | None = None) -> Presolve:
    """Check the supports, fix exactly taut spans, and build (or take) the initial guess."""
    _check_supports_outside(problem)
    guess = checked_guess(problem, initial_positions)
    with core_errors(problem):
        answer = core_chain(problem).presolve(
            guess=None if guess is None else np.ascontiguousarray(guess.ravel()), settled=False
        )
    return _answer(problem, answer)


def net_start(problem: Problem) -> FloatArray:
    """Where the solve of a net starts without a guess: its force-density shape (the core's
    ``hanging_start``), checked like a solve (supports outside the obstacles, within reach)."""
    _check_supports_outside(problem)
    check_net_reach(problem)
    with core_errors(problem):
        start = core_net(problem).hanging_start()
    if start is None:  # (the model has checked that every node reaches a support)
        raise InfeasibleError("the net has a node that reaches no support through links.")
    return start.reshape(problem.n_nodes, problem.dimension)
