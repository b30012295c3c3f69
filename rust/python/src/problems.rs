//! The problems the core solves, as Python classes: a chain ([`Chain`]) or a net ([`Net`]) in the
//! problem's units, and a problem in the solver's units for tests of the iteration's derivatives
//! ([`Network`]).

use std::cell::RefCell;
use std::rc::Rc;

use funicular_core::catenary::{exact_start, hanging_span as core_hanging_span};
use funicular_core::chain::{network_at, solve};
use funicular_core::driver::{dense_newton_matrix, Guess, SolveError, Solved as CoreSolved};
use funicular_core::evaluate::Point;
use funicular_core::net::{hanging_start, solve as solve_net};
use funicular_core::presolve::presolve;
use funicular_core::problem::{
    Chain as CoreChain, Formulation, Net as CoreNet, Network as CoreNetwork, NodeField,
    Obstacles as CoreObstacles, OneByOne, Quadratics as CoreQuadratics, ScaledObstacles, Setup, Statistics,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::errors::{core_error, guarded, Pending};
use crate::fields::{setup, PythonNodes};
use crate::types::{
    array, floats, index_array, indices, optional_floats, statistics, Evaluated, Floats, Hanging, Indices,
    Obstacles, Presolved, Quadratics, Settings, Solved, Start,
};

/// At least one support, ascending node indices below `n`, with `dim` coordinates each.
fn supports_valid(supports: &[usize], positions: &[f64], n: usize, dim: usize) -> bool {
    !supports.is_empty()
        && supports.windows(2).all(|p| p[0] < p[1])
        && supports[supports.len() - 1] < n
        && positions.len() == supports.len() * dim
}

/// Asked before every step: false (with the exception waiting in `pending`) once Python has a
/// signal to raise (Ctrl-C).
fn signals<'a>(py: Python<'a>, pending: &'a Pending) -> impl FnMut() -> bool + 'a {
    move || match py.check_signals() {
        Ok(()) => true,
        Err(error) => {
            *pending.borrow_mut() = Some(error);
            false
        }
    }
}

/// A whole solve as Python runs it: Ctrl-C asked about between steps, a panic and the core's errors
/// turned into Python's exceptions, the answer converted.
fn run(
    py: Python<'_>,
    pending: &Pending,
    solve: impl FnOnce(&mut dyn FnMut() -> bool) -> Result<CoreSolved, SolveError>,
) -> PyResult<Solved> {
    let mut check = signals(py, pending);
    let solved = guarded(py, || solve(&mut check))?.map_err(|error| core_error(py, pending, error))?;
    Solved::new(py, solved)
}

/// A chain in the problem's units: masses (N), link lengths (N - 1), gravity, supports ascending
/// with their positions (S d), the formulation (`squared`), its obstacles, and each link's axial
/// stiffness EA if any is elastic (N - 1, infinite for an inextensible link).
#[pyclass(unsendable, module = "funicular._core")]
pub struct Chain {
    inner: CoreChain,
    setup: Setup,
    pending: Pending,
}

impl Chain {
    fn shapes(&self) -> OneByOne<'_> {
        OneByOne {
            dim: self.inner.dim,
            obstacles: &self.setup.obstacles,
        }
    }

    fn size(&self) -> usize {
        self.inner.n_nodes() * self.inner.dim
    }

    /// `start` as the core's guess, its arrays checked against the chain.
    fn guess(&self, start: &Start) -> PyResult<Guess> {
        let n = self.inner.n_nodes();
        let columns = if self.setup.links_contact { n - 1 } else { n };
        let sizes_match = start.positions.len() == self.size()
            && start.link_multipliers.as_ref().is_none_or(|m| m.len() == n - 1)
            && start
                .obstacle_multipliers
                .as_ref()
                .is_none_or(|m| m.len() == self.setup.obstacles.count * columns);
        if !sizes_match {
            return Err(PyValueError::new_err(
                "solve: the start's arrays do not match the chain",
            ));
        }
        Ok(Guess {
            positions: start.positions.clone(),
            link_multipliers: start.link_multipliers.clone(),
            obstacle_multipliers: start.obstacle_multipliers.clone(),
            settled: start.settled,
            statistics: Statistics::default(),
        })
    }
}

#[pymethods]
impl Chain {
    #[new]
    #[pyo3(signature = (*, dim, masses, lengths, gravity, supports, support_positions, squared, obstacles, stiffness))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        dim: usize,
        masses: Floats<'_>,
        lengths: Floats<'_>,
        gravity: f64,
        supports: Indices<'_>,
        support_positions: Floats<'_>,
        squared: bool,
        obstacles: PyRef<'_, Obstacles>,
        stiffness: Option<Floats<'_>>,
    ) -> PyResult<Self> {
        let inner = CoreChain {
            dim,
            masses: floats(&masses, "masses")?,
            lengths: floats(&lengths, "lengths")?,
            gravity,
            supports: indices(&supports, "supports")?,
            support_positions: floats(&support_positions, "support_positions")?,
            stiffness: optional_floats(stiffness, "stiffness")?,
        };
        let n = inner.masses.len();
        let elastic = !inner.stiffness.is_empty();
        if !(1..=3).contains(&dim)
            || n < 2
            || inner.lengths.len() != n - 1
            || (elastic && (inner.stiffness.len() != n - 1 || squared || obstacles.links.is_some()))
            || !supports_valid(&inner.supports, &inner.support_positions, n, dim)
        {
            return Err(PyValueError::new_err(
                "a chain needs N >= 2 masses, N - 1 lengths and ascending supports with (S, d) positions; N - 1 stiffnesses if any, in the norm formulation with node contact",
            ));
        }
        let pending: Pending = Rc::new(RefCell::new(None));
        let setup = setup(py, dim, squared, &obstacles, &pending)?;
        Ok(Chain {
            inner,
            setup,
            pending,
        })
    }

    /// The presolve (see the core's `presolve`): from the built-in guess, or from `guess` (N d)
    /// (`settled`: a solved chain's).
    #[pyo3(signature = (*, guess, settled))]
    fn presolve(&self, py: Python<'_>, guess: Option<Floats<'_>>, settled: bool) -> PyResult<Presolved> {
        let guess = guess.map(|g| floats(&g, "guess")).transpose()?;
        if guess.as_ref().is_some_and(|g| g.len() != self.size()) {
            return Err(PyValueError::new_err(
                "presolve: the guess must hold N d coordinates",
            ));
        }
        let presolved = presolve(&self.inner, &mut self.shapes(), guess.as_deref(), settled)
            .map_err(|infeasible| core_error(py, &self.pending, SolveError::from(infeasible)))?;
        Ok(Presolved {
            positions: array(py, presolved.positions),
            movable: index_array(py, &presolved.movable),
            fixed_tension: array(py, presolved.fixed_tension),
            detached: index_array(py, &presolved.detached),
            attach: index_array(py, &presolved.attach),
            obstacle_gradients: presolved.gradients.map(|g| array(py, g)),
        })
    }

    /// The chain's equilibrium and link tensions if it touches no obstacle and every span is a
    /// discrete catenary (the core's `exact_start`), else None.
    fn exact_start(&self, py: Python<'_>) -> PyResult<Option<Hanging>> {
        match exact_start(&self.inner, &mut self.shapes()) {
            Ok(start) => Ok(start.map(|(positions, tensions)| Hanging {
                positions: array(py, positions),
                tensions: array(py, tensions),
            })),
            Err(_) => Err(core_error(py, &self.pending, SolveError::Interrupted)),
        }
    }

    /// The equilibrium with its forces (the core's `chain::solve`), from the built-in start or from
    /// `start`; `judge`: the second-order test at the result too.
    #[pyo3(signature = (*, settings, start, judge))]
    fn solve(
        &self,
        py: Python<'_>,
        settings: &Settings,
        start: Option<&Start>,
        judge: bool,
    ) -> PyResult<Solved> {
        let initial = start.map(|start| self.guess(start)).transpose()?;
        let options = settings.options();
        run(py, &self.pending, |check| {
            solve(&self.inner, &self.setup, &options, initial.as_ref(), judge, check)
        })
    }

    /// The network the iteration would start from at `guess` (N d), in the solver's units (for
    /// tests of the iteration's derivatives).
    #[pyo3(signature = (*, guess))]
    fn network(&self, py: Python<'_>, guess: Floats<'_>) -> PyResult<Network> {
        let guess = floats(&guess, "guess")?;
        if guess.len() != self.size() {
            return Err(PyValueError::new_err(
                "network: the guess must hold N d coordinates",
            ));
        }
        let inner = network_at(&self.inner, &self.setup, &guess)
            .map_err(|error| core_error(py, &self.pending, error))?;
        Ok(Network {
            inner,
            pending: self.pending.clone(),
        })
    }
}

/// A cable net in the problem's units: masses (N), links (L, 2) node pairs with their lengths (L),
/// gravity, supports ascending with their positions (S d), the formulation, its obstacles (node
/// contact), point loads (N d) if any and each link's axial stiffness EA if any is elastic (L,
/// infinite for an inextensible link).
#[pyclass(unsendable, module = "funicular._core")]
pub struct Net {
    inner: CoreNet,
    setup: Setup,
    pending: Pending,
}

#[pymethods]
impl Net {
    #[new]
    #[pyo3(signature = (*, dim, masses, links, lengths, gravity, supports, support_positions, squared, obstacles, loads, stiffness))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        dim: usize,
        masses: Floats<'_>,
        links: Indices<'_>,
        lengths: Floats<'_>,
        gravity: f64,
        supports: Indices<'_>,
        support_positions: Floats<'_>,
        squared: bool,
        obstacles: PyRef<'_, Obstacles>,
        loads: Option<Floats<'_>>,
        stiffness: Option<Floats<'_>>,
    ) -> PyResult<Self> {
        let ends = indices(&links, "links")?;
        let inner = CoreNet {
            dim,
            masses: floats(&masses, "masses")?,
            links: ends.chunks_exact(2).map(|pair| [pair[0], pair[1]]).collect(),
            lengths: floats(&lengths, "lengths")?,
            gravity,
            supports: indices(&supports, "supports")?,
            support_positions: floats(&support_positions, "support_positions")?,
            loads: optional_floats(loads, "loads")?,
            stiffness: optional_floats(stiffness, "stiffness")?,
        };
        let n = inner.n_nodes();
        let valid = (2..=3).contains(&dim)
            && (inner.loads.is_empty() || inner.loads.len() == n * dim)
            && ends.len() % 2 == 0
            && inner.lengths.len() == inner.links.len()
            && (inner.stiffness.is_empty() || inner.stiffness.len() == inner.links.len())
            && inner.links.iter().all(|&[a, b]| a < n && b < n && a != b)
            && supports_valid(&inner.supports, &inner.support_positions, n, dim);
        if !valid || obstacles.links.is_some() {
            return Err(PyValueError::new_err(
                "a net needs (L, 2) links between distinct nodes with L lengths, ascending supports with (S, d) positions, (N, d) loads if any, L stiffnesses if any, and node contact",
            ));
        }
        let pending: Pending = Rc::new(RefCell::new(None));
        let setup = setup(py, dim, squared, &obstacles, &pending)?;
        Ok(Net {
            inner,
            setup,
            pending,
        })
    }

    /// The force-density start (the core's `net::hanging_start`): positions (N d), or None where a
    /// node reaches no support.
    fn hanging_start(&self, py: Python<'_>) -> PyResult<Option<Py<numpy::PyArray1<f64>>>> {
        match hanging_start(&self.inner, &self.setup) {
            Ok(start) => Ok(start.map(|positions| array(py, positions))),
            Err(_) => Err(core_error(py, &self.pending, SolveError::Interrupted)),
        }
    }

    /// The equilibrium with its forces (the core's `net::solve`), from the force-density start or
    /// from `start`'s positions (its multipliers are not used); `judge`: the second-order test at
    /// the result too.
    #[pyo3(signature = (*, settings, start, judge))]
    fn solve(
        &self,
        py: Python<'_>,
        settings: &Settings,
        start: Option<&Start>,
        judge: bool,
    ) -> PyResult<Solved> {
        if start.is_some_and(|start| start.positions.len() != self.inner.n_nodes() * self.inner.dim) {
            return Err(PyValueError::new_err(
                "solve: the start must hold N d coordinates",
            ));
        }
        let initial = start.map(|start| Guess {
            positions: start.positions.clone(),
            ..Guess::default()
        });
        let options = settings.options();
        run(py, &self.pending, |check| {
            solve_net(&self.inner, &self.setup, &options, initial.as_ref(), judge, check)
        })
    }
}

/// A problem in the solver's units, for tests of the iteration's derivatives: positions (N d), free
/// nodes ascending, links (L, 2) node pairs with their lengths, each node's weight, the physical
/// origin in solver units, and quadratic obstacles if any. (`Chain.network` gives the network of a
/// whole problem, any obstacles included.)
#[pyclass(unsendable, module = "funicular._core")]
pub struct Network {
    inner: CoreNetwork,
    pending: Pending,
}

impl Network {
    fn point(&mut self, py: Python<'_>, z: &[f64], mu: &[f64]) -> PyResult<Point> {
        if z.len() != self.inner.n_free() * self.inner.dim || mu.len() != self.inner.n_constraints() {
            return Err(PyValueError::new_err(
                "z or mu does not match the network's free coordinates and rows",
            ));
        }
        let mut point = Point::default();
        self.inner
            .evaluate(z, mu, &mut point)
            .map_err(|_| core_error(py, &self.pending, SolveError::Interrupted))?;
        Ok(point)
    }
}

#[pymethods]
impl Network {
    #[new]
    #[pyo3(signature = (*, dim, squared, positions, free, links, lengths, load, origin, quadratics))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        dim: usize,
        squared: bool,
        positions: Floats<'_>,
        free: Indices<'_>,
        links: Indices<'_>,
        lengths: Floats<'_>,
        load: Floats<'_>,
        origin: Floats<'_>,
        quadratics: Option<PyRef<'_, Quadratics>>,
    ) -> PyResult<Self> {
        let obstacles = match quadratics {
            Some(q) => ScaledObstacles::Quadratic(CoreQuadratics {
                centres: q.centres.clone(),
                values: q.values.clone(),
                gradients: q.gradients.clone(),
                hessians: q.hessians.clone(),
            }),
            None => ScaledObstacles::none(),
        };
        let pairs = indices(&links, "links")?;
        if pairs.len() % 2 != 0 {
            return Err(PyValueError::new_err("links must be an (L, 2) array"));
        }
        let formulation = if squared {
            Formulation::Squared
        } else {
            Formulation::Norm
        };
        let inner = CoreNetwork::new(
            dim,
            formulation,
            floats(&positions, "positions")?,
            indices(&free, "free")?,
            pairs.chunks_exact(2).map(|p| [p[0], p[1]]).collect(),
            floats(&lengths, "lengths")?,
            floats(&load, "load")?,
            floats(&origin, "origin")?,
            obstacles,
        )
        .map_err(PyValueError::new_err)?;
        Ok(Network {
            inner,
            pending: Rc::new(RefCell::new(None)),
        })
    }

    /// The free nodes' coordinates (flat), where the iteration starts.
    fn free_coordinates(&self, py: Python<'_>) -> Py<numpy::PyArray1<f64>> {
        array(py, self.inner.free_coordinates())
    }

    /// The constraint values and the residual of stationarity at `(z, mu)`: what the iteration
    /// sees, for tests and diagnostics.
    #[pyo3(signature = (*, z, mu))]
    fn evaluate(&mut self, py: Python<'_>, z: Floats<'_>, mu: Floats<'_>) -> PyResult<Evaluated> {
        let point = self.point(py, &floats(&z, "z")?, &floats(&mu, "mu")?)?;
        Ok(Evaluated {
            c: array(py, point.c),
            dual: array(py, point.dual),
        })
    }

    /// `J dz` at `z` (every constraint row).
    #[pyo3(signature = (*, z, dz))]
    fn jacobian_times(
        &mut self,
        py: Python<'_>,
        z: Floats<'_>,
        dz: Floats<'_>,
    ) -> PyResult<Py<numpy::PyArray1<f64>>> {
        let m = self.inner.n_constraints();
        let point = self.point(py, &floats(&z, "z")?, &vec![0.0; m])?;
        let dz = floats(&dz, "dz")?;
        Ok(array(
            py,
            (0..m).map(|r| self.inner.row_times(&point, r, &dz)).collect(),
        ))
    }

    /// The Newton matrix `W + J^T diag(sigma) J` at `(z, mu)` as a dense (n d, n d) array, row by
    /// row (for tests on small problems).
    #[pyo3(signature = (*, z, mu, sigma))]
    fn newton_matrix(
        &mut self,
        py: Python<'_>,
        z: Floats<'_>,
        mu: Floats<'_>,
        sigma: Floats<'_>,
    ) -> PyResult<Py<numpy::PyArray1<f64>>> {
        let mu = floats(&mu, "mu")?;
        let point = self.point(py, &floats(&z, "z")?, &mu)?;
        let sigma = floats(&sigma, "sigma")?;
        Ok(array(py, dense_newton_matrix(&self.inner, &point, &mu, &sigma)))
    }

    /// What the iterations on this network spent (see `Solved.statistics`).
    #[getter]
    fn statistics(&self) -> std::collections::HashMap<&'static str, f64> {
        statistics(&self.inner.statistics)
    }

    /// Constraint rows: links, then every obstacle's contact rows.
    #[getter]
    fn n_constraints(&self) -> usize {
        self.inner.n_constraints()
    }
}

/// Interior node positions ((n - 1) d) and link tensions (n) of n links hanging between `left`
/// and `right` (d coordinates each) with every link taut (the core's `catenary::hanging_span`), or
/// None; obstacles as `field(points) -> NodeFields` of `n_obstacles` obstacles, if any.
#[pyfunction]
#[pyo3(signature = (*, interior_masses, lengths, gravity, left, right, field, n_obstacles))]
#[allow(clippy::too_many_arguments)]
pub fn hanging_span(
    py: Python<'_>,
    interior_masses: Floats<'_>,
    lengths: Floats<'_>,
    gravity: f64,
    left: Floats<'_>,
    right: Floats<'_>,
    field: Option<Py<PyAny>>,
    n_obstacles: usize,
) -> PyResult<Option<Hanging>> {
    let (masses, lengths) = (
        floats(&interior_masses, "interior_masses")?,
        floats(&lengths, "lengths")?,
    );
    let (left, right) = (floats(&left, "left")?, floats(&right, "right")?);
    let dim = left.len();
    if lengths.is_empty()
        || masses.len() + 1 != lengths.len()
        || right.len() != dim
        || !(2..=3).contains(&dim)
    {
        return Err(PyValueError::new_err(
            "hanging_span: n lengths, n - 1 masses and two points of 2 or 3 coordinates",
        ));
    }
    let pending: Pending = Rc::new(RefCell::new(None));
    let nodes = field.map(|function| -> Rc<RefCell<dyn NodeField>> {
        Rc::new(RefCell::new(PythonNodes {
            count: n_obstacles,
            dim,
            function,
            pending: pending.clone(),
        }))
    });
    let obstacles = CoreObstacles {
        count: if nodes.is_some() { n_obstacles } else { 0 },
        quadratics: None,
        nodes,
        segments: None,
    };
    let mut shapes = OneByOne {
        dim,
        obstacles: &obstacles,
    };
    match core_hanging_span(&masses, &lengths, gravity, &left, &right, &mut shapes) {
        Ok(span) => Ok(span.map(|(positions, tensions)| Hanging {
            positions: array(py, positions),
            tensions: array(py, tensions),
        })),
        Err(_) => Err(core_error(py, &pending, SolveError::Interrupted)),
    }
}
