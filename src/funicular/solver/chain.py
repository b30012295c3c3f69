"""The scaled chain the iteration works on: constraint values, Jacobian products, Newton matrix.

Constraints, in this order: the optimised links (``links``), then for every obstacle j the
contact constraint ``phi_j(p_i) <= 0`` of every free node i (``n_obstacles * n_free`` rows).
A contact row touches one node only, so obstacles add only to the 2x2 diagonal blocks.
With ``contact = "links"`` the contact rows are instead ``psi_jk = phi_j(p*) <= 0`` for every
obstacle j and optimised link k, p* = (1-t) p_k + t p_{k+1} where phi_j is largest along the link
(``n_obstacles * n_links`` rows, see :func:`funicular.obstacles.link_contact`); such a row couples
nodes k and k+1, so it adds to both diagonal blocks and to the block between them: the matrix
stays block tridiagonal. Its Hessian is exact, including the maximiser's motion along the link.

Scaling: positions ``(p - origin) / length_unit``, forces / total weight, and obstacle j's phi
divided by ``scale_j * length_unit`` where ``scale_j`` is a typical ``|grad phi_j|``: multiplying
phi by a constant leaves every iterate unchanged.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from funicular.constraints import link_deltas, link_gradients, link_hessian_blocks, link_values
from funicular.model import FloatArray, Formulation, IntArray
from funicular.obstacles import Obstacle, Stacked, link_contact, repeated
from funicular.solver import fused
from funicular.solver.banded import BlockTridiagonal
from funicular.solver.compiled import HAVE_NUMBA, driver, jit

# The cached properties of a ScaledChain that do not depend on its positions (``ScaledChain.moved``).
MOVE_INDEPENDENT = (
    "link_row",
    "free_index",
    "n_contact_rows",
    "n_constraints",
    "quadratic_coefficients",
    "quadratic_hessians",
    "polish_workspace",
)
_NO_QUADRATICS = (np.zeros((0, 2)), np.zeros(0), np.zeros((0, 2)), np.zeros((0, 2, 2)))


@dataclass
class ScaledChain:
    """The scaled problem (free nodes, the links that touch them, obstacles)."""

    formulation: Formulation
    positions: FloatArray  # (N, 2) scaled; fixed nodes hold their final positions
    free: IntArray  # movable nodes
    links: IntArray  # links with at least one movable end
    lengths: FloatArray  # (N-1,) scaled link lengths
    load: FloatArray  # (N,) scaled weight of each node, g m_i / W
    both_free: FloatArray  # (n-1,) 1.0 where free node f and f+1 are joined by a link
    obstacles: tuple[Obstacle, ...]
    obstacle_scale: FloatArray  # (n_obstacles,) typical |grad phi_j|
    length_unit: float
    origin: FloatArray
    # The obstacles' phi as stacked quadratics in the problem's units (``Problem.quadratic_obstacles``):
    # None unless every obstacle is a disk, an ellipse or a half-plane.
    quadratics: Stacked | None
    contact_links: bool = False  # contact rows per (obstacle, optimised link) instead of per (obstacle, free node)
    contact_ends: tuple[FloatArray, np.ndarray] | None = None  # per link (N-1,): obstacles.link_contact_ends
    # The compiled loops of ``fused``: links' terms, the KKT error, quadratic obstacles' contact rows
    # when every obstacle is one, and (node contact) the Newton direction and the polish.
    compiled: bool = False

    def __post_init__(self) -> None:
        self.squared = self.formulation is Formulation.SQUARED
        # Indexing (n, 2) arrays with an index array copies element by element (ten times slower
        # than a slice at 10^5 nodes); the free nodes are usually one contiguous run.
        self.free_at: slice | IntArray = as_slice(self.free)
        contiguous = isinstance(self.free_at, slice)
        first = int(self.free[0]) if contiguous else 0
        self.free_pairs_at: slice | IntArray = (
            slice(first, first + self.free.size - 1) if contiguous else self.free[:-1]
        )  # (n-1,) links from each free node to the next node
        self.links_at: slice | IntArray = as_slice(self.links)

    def moved(self, positions: FloatArray) -> ScaledChain:
        """The same chain from other (scaled) positions, its fixed nodes where they were: everything
        that does not depend on the positions is shared (the obstacles' scales, their quadratics),
        not made again."""
        chain = object.__new__(ScaledChain)  # (dataclasses.replace: 30 us, __post_init__ again)
        chain.__dict__.update(self.__dict__)
        chain.positions = positions
        for name in _CACHED:
            if name not in MOVE_INDEPENDENT:
                chain.__dict__.pop(name, None)
        return chain

    @functools.cached_property
    def link_row(self) -> IntArray:
        """(N-1,) each link's constraint row, -1 for links not optimised."""
        row = np.full(self.positions.shape[0] - 1, -1, dtype=np.intp)
        row[self.links] = np.arange(self.links.size)
        return row

    @functools.cached_property
    def free_index(self) -> IntArray:
        """(N,) each node's place among the free nodes, -1 for fixed nodes."""
        index = np.full(self.positions.shape[0], -1, dtype=np.intp)
        index[self.free] = np.arange(self.free.size)
        return index

    @property
    def contact_rows(self) -> IntArray:
        """What each obstacle's contact rows stand for: its optimised links or its free nodes."""
        return self.links if self.contact_links else self.free

    @property
    def contact_rows_at(self) -> slice | IntArray:
        """``contact_rows`` as a slice where it is one (``free_at``, ``links_at``)."""
        return self.links_at if self.contact_links else self.free_at

    @functools.cached_property
    def n_contact_rows(self) -> int:
        """Contact rows per obstacle."""
        return int(self.contact_rows.size)

    @functools.cached_property
    def n_constraints(self) -> int:
        """(Once: every evaluation sizes its constraint vector by it.)"""
        return int(self.links.size + len(self.obstacles) * self.n_contact_rows)

    def physical(self, scaled_positions: FloatArray) -> FloatArray:
        return scaled_positions * self.length_unit + self.origin

    @functools.cached_property
    def driver_arrays(self) -> tuple[tuple[object, ...], tuple[FloatArray, ...]] | None:
        """What ``driver``'s kernels take of the chain (its fields ``driver.CHAIN_FIELDS``, and the
        quadratics), or None unless they cover it: compiled, node contact, obstacles none or all
        quadratic (``quadratic_coefficients``), numba installed."""
        if not (self.compiled and HAVE_NUMBA) or self.contact_links:
            return None
        quadratic = self.quadratic_coefficients if self.obstacles else _NO_QUADRATICS
        if quadratic is None:
            return None
        return tuple(getattr(self, name) for name in driver().CHAIN_FIELDS), quadratic

    @functools.cached_property
    def quadratic_hessians(self) -> FloatArray:
        """The scaled quadratics' constant Hessians at every free node (n_obstacles, n, 2, 2): a
        read-only view of one block per obstacle, made once (what ``np.broadcast_to`` makes, without
        its 20 us); (0, n, 2, 2) without obstacles."""
        if not self.obstacles:
            return np.zeros((0, self.free.size, 2, 2))
        assert self.quadratic_coefficients is not None
        return repeated(self.quadratic_coefficients[3], self.free.size)  # (n_obstacles, 2, 2) repeated

    @functools.cached_property
    def polish_workspace(self) -> tuple[FloatArray, FloatArray]:
        """``fused.polish_solve``'s workspace, kept from step to step: 96 MB at 10^6 nodes, whose
        fresh pages cost 15 ms a step to fault in."""
        n_nodes, n_free = self.positions.shape[0], self.free.size
        return np.empty((n_nodes, 3, 3)), np.empty((len(self.obstacles), n_free, 3))

    @functools.cached_property
    def quadratic_coefficients(self) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray] | None:
        """Every obstacle's scaled phi (over scaled positions) as a quadratic, stacked for
        ``fused.quadratic_contacts`` (centres, values, gradients, Hessians), or None unless every
        obstacle is a disk, an ellipse or a half-plane (``quadratics``)."""
        if self.quadratics is None or not self.obstacles:
            return None
        centres, values, gradients, hessians = self.quadratics
        # p = length_unit s + origin; phi / (scale length_unit) over s (scaled phi, see the module's docstring)
        unit, length = self.obstacle_scale, self.length_unit
        return (
            (centres - self.origin) / length,
            values / (unit * length),
            gradients / unit[:, None],
            hessians * (length / unit)[:, None, None],
        )


# Every cached property of a ScaledChain (``moved`` keeps those in MOVE_INDEPENDENT).
_CACHED = tuple(name for name, value in vars(ScaledChain).items() if isinstance(value, functools.cached_property))


def as_slice(index: IntArray) -> slice | IntArray:
    """An ascending index array as the slice it is, if it is one (indexing with it copies element by element)."""
    if index.size and int(index[-1] - index[0]) + 1 == index.size:
        return slice(int(index[0]), int(index[-1]) + 1)
    return index


@dataclass
class SegmentRows:
    """Link-contact rows (``contact = "links"``) at one iterate, scaled like node contacts."""

    t: FloatArray  # (n_obstacles, n_links) where along link k the maximum of phi is
    gradient: FloatArray  # (n_obstacles, n_links, 2) scaled grad phi there
    hessian: FloatArray  # (n_obstacles, n_links, 4, 4) scaled Hessian of psi in (p_k, p_{k+1})


@dataclass(slots=True)  # (made at every evaluation: slots halve its construction, 1.4 -> 0.7 us)
class Point:
    """Everything evaluated at one iterate."""

    positions: FloatArray  # (N, 2) scaled
    c: FloatArray  # (m,) constraint values: links, then contacts obstacle by obstacle
    q: FloatArray  # (N-1, 2) link gradients w.r.t. p_k (zero for links not optimised)
    obstacle_gradient: FloatArray  # (n_obstacles, n, 2) scaled grad phi at the free nodes
    obstacle_hessian: FloatArray  # (n_obstacles, n, 2, 2) scaled Hessian of phi (read-only view if constant)
    dual_residual: FloatArray  # (n, 2) grad E + J^T mu at the free nodes
    segments: SegmentRows | None = None  # link-contact rows (contact = "links"; then the obstacle_* are empty)


def node_sum(chain: ScaledChain, per_link: FloatArray) -> FloatArray:
    """Link quantities ``v_k q_k`` (N-1, 2) summed onto the free nodes (n, 2) with the signs of ``J^T``."""
    n_nodes = chain.positions.shape[0]
    total = np.zeros((n_nodes, 2))
    total[:-1] += per_link
    total[1:] -= per_link
    return total[chain.free_at]


def evaluate_obstacles(chain: ScaledChain, free_positions: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Scaled phi (n_obstacles, n), gradient (n_obstacles, n, 2), Hessian (n_obstacles, n, 2, 2).

    When every obstacle's Hessian is the same at all points (a disk, a half-plane: returned as a
    broadcast view), so is the result: a read-only view of one 2x2 block per obstacle instead of
    an array written out (32 MB per iterate at 10^6 nodes)."""
    k, n = len(chain.obstacles), free_positions.shape[0]
    if not k:
        return np.zeros((0, n)), np.zeros((0, n, 2)), np.zeros((0, n, 2, 2))
    # Through each obstacle's own evaluate, in physical units, also for the quadratic shapes that
    # the compiled path evaluates in the scaled frame (``quadratic_coefficients``): a 194-node chain
    # of the long hypothesis profile, on the edge of the iteration limit, took 246 steps with the
    # scaled frame's rounding on this path against 132 (the compiled path: 119).
    points = chain.physical(free_positions)
    phi, gradient = np.empty((k, n)), np.empty((k, n, 2))
    hessians: list[FloatArray] = []  # (n, 2, 2), or (1, 2, 2) where constant
    for j, obstacle in enumerate(chain.obstacles):
        value, grad, hess = obstacle.evaluate(points)
        unit = chain.obstacle_scale[j]
        np.divide(value, unit * chain.length_unit, out=phi[j])
        np.divide(grad, unit, out=gradient[j])
        hessians.append((hess[:1] if _constant(hess) else np.asarray(hess)) * (chain.length_unit / unit))
    if all(h.shape[0] == 1 for h in hessians):
        return phi, gradient, np.broadcast_to(np.stack(hessians), (k, n, 2, 2))
    return phi, gradient, np.stack([np.broadcast_to(h, (n, 2, 2)) for h in hessians])


def _constant(hessian: FloatArray) -> bool:
    """A Hessian returned as one 2x2 block broadcast to every point (or for one point)."""
    return hessian.ndim == 3 and (hessian.shape[0] == 1 or hessian.strides[0] == 0)


def evaluate_segments(chain: ScaledChain, positions: FloatArray) -> tuple[FloatArray, SegmentRows]:
    """Scaled psi (n_obstacles, n_links) of the optimised links and their derivatives."""
    assert chain.contact_ends is not None  # set whenever contact_links is
    end, pinned = chain.contact_ends
    k, n_obstacles = chain.links, len(chain.obstacles)
    points = chain.physical(positions)
    psi, t = np.zeros((n_obstacles, k.size)), np.zeros((n_obstacles, k.size))
    gradient, hessian = np.zeros((n_obstacles, k.size, 2)), np.zeros((n_obstacles, k.size, 4, 4))
    for j, obstacle in enumerate(chain.obstacles):
        segment = link_contact(obstacle, points[k], points[k + 1], end[k], pinned[k])
        unit = chain.obstacle_scale[j]
        psi[j] = segment.psi / (unit * chain.length_unit)
        t[j] = segment.t
        gradient[j] = segment.gradient / unit
        hessian[j] = segment.hessian * (chain.length_unit / unit)
    return psi, SegmentRows(t, gradient, hessian)


def segment_node_sum(chain: ScaledChain, rows: SegmentRows, v: FloatArray) -> FloatArray:
    """``J^T v`` of the link-contact rows (v: (n_obstacles, n_links)) on the free nodes (n, 2):
    row (j, k) puts ``(1-t) v grad phi`` on node k and ``t v grad phi`` on node k+1."""
    total = np.zeros_like(chain.positions)
    k = chain.links
    total[k] += np.einsum("jl,jl,jld->ld", v, 1.0 - rows.t, rows.gradient)
    total[k + 1] += np.einsum("jl,jl,jld->ld", v, rows.t, rows.gradient)
    result: FloatArray = total[chain.free]
    return result


def _link_terms(
    chain: ScaledChain, positions: FloatArray, mu: FloatArray, c_links: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """The optimised links' constraint values (written to ``c_links``), gradients q (N-1, 2) and
    ``grad E + J^T mu`` of the links on the free nodes (n, 2)."""
    k = chain.links
    if chain.compiled:
        q, force = np.zeros((positions.shape[0] - 1, 2)), np.zeros_like(positions)
        jit(fused.link_terms)(chain.squared, positions, chain.lengths, k, mu, c_links, q, force)
        dual = force[chain.free_at]
    else:
        mu_links = np.zeros(positions.shape[0] - 1)
        mu_links[k] = mu[: k.size]
        delta = link_deltas(positions)
        distances = np.hypot(delta[:, 0], delta[:, 1])
        q = np.zeros_like(delta)
        q[k] = link_gradients(chain.formulation, delta[k], distances[k], chain.lengths[k])
        c_links[:] = link_values(chain.formulation, distances[k], chain.lengths[k], smooth=True)
        dual = node_sum(chain, mu_links[:, None] * q)
    dual[:, 1] += chain.load[chain.free_at]
    return q, dual


def driver_point(chain: ScaledChain, values: tuple[FloatArray, ...]) -> Point:
    """``driver.evaluate``'s (positions, c, q, phi's gradients, dual residual) as a ``Point``."""
    positions, c, q, gradient, dual = values
    return Point(
        positions=positions,
        c=c,
        q=q,
        obstacle_gradient=gradient,
        obstacle_hessian=chain.quadratic_hessians,
        dual_residual=dual,
    )


def evaluate(chain: ScaledChain, z: FloatArray, mu: FloatArray) -> Point:
    if chain.driver_arrays is not None:  # one kernel call instead of a dozen numpy and kernel calls
        return driver_point(chain, jit(driver().evaluate)(*chain.driver_arrays, z, mu))
    positions = chain.positions.copy()
    positions[chain.free_at] = z.reshape(-1, 2)
    k, n_obstacles = chain.links, len(chain.obstacles)
    c = np.empty(chain.n_constraints)
    q, dual = _link_terms(chain, positions, mu, c[: k.size])
    if chain.contact_links:
        psi, rows = evaluate_segments(chain, positions)
        dual += segment_node_sum(chain, rows, mu[k.size :].reshape(psi.shape))
        c[k.size :] = psi.ravel()
        no_nodes, no_hessians = np.zeros((n_obstacles, 0, 2)), np.zeros((n_obstacles, 0, 2, 2))
        return Point(positions, c, q, no_nodes, no_hessians, dual, rows)
    quadratics = chain.quadratic_coefficients
    if chain.compiled and quadratics is not None:  # phi, its gradient and the contact forces in one pass
        gradient = np.empty((n_obstacles, chain.free.size, 2))
        jit(fused.quadratic_contacts)(positions, chain.free, k.size, *quadratics, mu, c, gradient, dual)
        hessian = chain.quadratic_hessians
    else:
        phi, gradient, hessian = evaluate_obstacles(chain, positions[chain.free_at])
        c[k.size :] = phi.ravel()
        if chain.obstacles:
            dual += np.einsum("jn,jnd->nd", mu[k.size :].reshape(phi.shape), gradient)
    return Point(
        positions=positions,
        c=c,
        q=q,
        obstacle_gradient=gradient,
        obstacle_hessian=hessian,
        dual_residual=dual,
    )


def jacobian_times(chain: ScaledChain, point: Point, dz: FloatArray) -> FloatArray:
    """``J dz`` for every constraint."""
    dp = np.zeros_like(point.positions)
    dp[chain.free_at] = dz.reshape(-1, 2)
    k = chain.links
    if chain.compiled:
        all_links = np.empty(point.q.shape[0])
        jit(fused.link_products)(point.q, dp, all_links)
        links = all_links[k]
    else:
        links = np.einsum("ij,ij->i", point.q[k], dp[k] - dp[k + 1])
    if point.segments is not None:
        rows = point.segments
        contacts = (1.0 - rows.t) * np.einsum("jld,ld->jl", rows.gradient, dp[k])
        contacts += rows.t * np.einsum("jld,ld->jl", rows.gradient, dp[k + 1])
        return np.concatenate((links, contacts.ravel()))
    contacts = np.einsum("jnd,nd->jn", point.obstacle_gradient, dp[chain.free_at])
    result: FloatArray = np.concatenate((links, contacts.ravel()))
    return result


def jacobian_transpose_times(chain: ScaledChain, point: Point, v: FloatArray) -> FloatArray:
    """``J^T v`` onto the free coordinates (flattened)."""
    k = chain.links
    if chain.compiled:
        v_links, nodes = np.zeros(point.q.shape[0]), np.zeros_like(point.positions)
        v_links[k] = v[: k.size]
        jit(fused.link_transpose_products)(point.q, v_links, nodes)
        total = nodes[chain.free_at]
    else:
        per_link = np.zeros_like(point.q)
        per_link[k] = v[: k.size, None] * point.q[k]
        total = node_sum(chain, per_link)
    if point.segments is not None:
        total += segment_node_sum(chain, point.segments, v[k.size :].reshape(point.segments.t.shape))
        return total.ravel()
    total += np.einsum("jn,jnd->nd", v[k.size :].reshape(point.obstacle_gradient.shape[:2]), point.obstacle_gradient)
    return total.ravel()


def newton_matrix(chain: ScaledChain, point: Point, mu: FloatArray, sigma: FloatArray) -> BlockTridiagonal:
    """``W + J^T Sigma J`` over the free coordinates, block tridiagonal."""
    k = chain.links
    mu_links, sigma_links = mu[: k.size], sigma[: k.size]
    n_nodes = point.positions.shape[0]
    if chain.compiled:
        # Blocks of the free nodes (or, with link-contact rows, of every node, for _links_mode_matrix).
        links_mode = point.segments is not None
        index = np.arange(n_nodes) if links_mode else chain.free_index
        n_blocks = n_nodes if links_mode else chain.free.size
        diagonal, off_diagonal = np.zeros((n_blocks, 2, 2)), np.zeros((max(n_blocks - 1, 0), 2, 2))
        jit(fused.link_blocks)(
            chain.squared,
            point.positions,
            chain.lengths,
            k,
            mu_links,
            sigma_links,
            point.q,
            index,
            diagonal,
            off_diagonal,
        )
        if point.segments is not None:
            return _links_mode_matrix(chain, point.segments, mu, sigma, diagonal, off_diagonal)
    else:
        delta = link_deltas(point.positions)
        distances = np.hypot(delta[:, 0], delta[:, 1])
        blocks = np.zeros((n_nodes - 1, 2, 2))
        q = point.q[k]
        blocks[k] = mu_links[:, None, None] * link_hessian_blocks(
            chain.formulation, delta[k], distances[k], chain.lengths[k], smooth=True
        )
        blocks[k] += sigma_links[:, None, None] * q[:, :, None] * q[:, None, :]
        per_node = np.zeros((n_nodes, 2, 2))
        per_node[:-1] += blocks
        per_node[1:] += blocks
        if point.segments is not None:
            return _links_mode_matrix(chain, point.segments, mu, sigma, per_node, -blocks)
        diagonal = per_node[chain.free_at]
        off_diagonal = -blocks[chain.free_pairs_at] * chain.both_free[:, None, None]
    shape = point.obstacle_gradient.shape[:2]
    nu, sigma_contacts = mu[k.size :].reshape(shape), sigma[k.size :].reshape(shape)
    g = point.obstacle_gradient
    if chain.compiled:
        jit(fused.contact_blocks)(nu, sigma_contacts, g, point.obstacle_hessian, diagonal)
    else:
        diagonal += np.einsum("jn,jnab->nab", nu, point.obstacle_hessian)
        diagonal += np.einsum("jn,jna,jnb->nab", sigma_contacts, g, g)
    return BlockTridiagonal(diagonal, off_diagonal)


def _links_mode_matrix(
    chain: ScaledChain, rows: SegmentRows, mu: FloatArray, sigma: FloatArray, per_node: FloatArray, coupling: FloatArray
) -> BlockTridiagonal:
    """The Newton matrix with link-contact rows: each adds the 4x4 block ``nu Hess psi + sigma r r^T``
    (``r = ((1-t) grad phi, t grad phi)``) over nodes k and k+1 to ``per_node`` (N, 2, 2) and to the
    node-to-next-node blocks ``coupling`` (N-1, 2, 2), both already holding the links' terms."""
    k = chain.links
    nu, sigma_contacts = mu[k.size :].reshape(rows.t.shape), sigma[k.size :].reshape(rows.t.shape)
    r = np.concatenate(((1.0 - rows.t)[..., None] * rows.gradient, rows.t[..., None] * rows.gradient), axis=2)
    block = np.einsum("jl,jlab->lab", nu, rows.hessian) + np.einsum("jl,jla,jlb->lab", sigma_contacts, r, r)
    per_node[k] += block[:, :2, :2]
    per_node[k + 1] += block[:, 2:, 2:]
    coupling[k] += block[:, :2, 2:]
    off_diagonal = coupling[chain.free[:-1]] * chain.both_free[:, None, None]
    return BlockTridiagonal(per_node[chain.free], off_diagonal)
