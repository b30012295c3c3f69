//! The Python module `funicular._core`: a thin front end to the solver core.
//!
//! `Chain` holds a chain in the problem's units (built by `funicular.solver.chain` from a
//! `Problem`); `solve` runs the whole solve, `presolve` and `exact_start` its first parts.
//! `Network` is a problem in the solver's units, for tests of the iteration's derivatives.
//! Obstacles that are not quadratics are evaluated by a Python function called once per
//! evaluation with every point at once.

mod json;
mod memory;

use std::cell::RefCell;
use std::rc::Rc;

use funicular_core::catenary::{exact_start, hanging_span as core_hanging_span};
use funicular_core::evaluate::Point;
use funicular_core::linalg::{NewtonMatrix, NewtonSystem};
use funicular_core::net::{hanging_start, solve_net, Net as CoreNet};
use funicular_core::network::{
    Formulation, Interrupted, Network as CoreNetwork, NodeField, Obstacles, Quadratics, Statistics,
    SMOOTH_RATIO,
};
use funicular_core::presolve::{presolve, Chain as CoreChain, Infeasible, Presolved};
use funicular_core::shapes::{NativeField, Shape};
use funicular_core::solve::{
    network_at, solve, Guess, Judged, Obstacles as CoreObstacles, OneByOne, Options, Segments, Setup,
    SolveError, Solved,
};
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

#[global_allocator]
static ALLOCATOR: memory::HugePages = memory::HugePages;

/// Where a Python function's exception waits while the core unwinds.
type Pending = Rc<RefCell<Option<PyErr>>>;
/// A float array from Python, and one handed back.
type Floats<'a> = PyReadonlyArrayDyn<'a, f64>;
type Vector<'py> = Bound<'py, PyArray1<f64>>;
fn floats(array: &Floats<'_>, name: &str) -> PyResult<Vec<f64>> {
    array
        .as_slice()
        .map(<[f64]>::to_vec)
        .map_err(|_| PyValueError::new_err(format!("{name} must be contiguous")))
}

fn indices(array: &PyReadonlyArrayDyn<'_, i64>, name: &str) -> PyResult<Vec<usize>> {
    let values = array
        .as_slice()
        .map_err(|_| PyValueError::new_err(format!("{name} must be contiguous")))?;
    values
        .iter()
        .map(|&v| usize::try_from(v).map_err(|_| PyValueError::new_err(format!("{name} holds {v}"))))
        .collect()
}

/// Copies a Python function's result array into the core's buffer.
fn fill(result: &Bound<'_, PyAny>, out: &mut [f64], name: &str) -> PyResult<()> {
    let array: Floats<'_> = result.extract()?;
    let values = array
        .as_slice()
        .map_err(|_| PyValueError::new_err(format!("{name} must be contiguous")))?;
    if values.len() != out.len() {
        return Err(PyValueError::new_err(format!(
            "{name} has {} values, expected {}",
            values.len(),
            out.len()
        )));
    }
    out.copy_from_slice(values);
    Ok(())
}

struct PythonNodes {
    count: usize,
    dim: usize,
    function: Py<PyAny>,
    pending: Pending,
}

impl NodeField for PythonNodes {
    fn count(&self) -> usize {
        self.count
    }

    fn evaluate(
        &mut self,
        points: &[f64],
        phi: &mut [f64],
        gradient: &mut [f64],
        hessian: &mut [f64],
    ) -> Result<(), Interrupted> {
        Python::attach(|py| -> PyResult<()> {
            let array = PyArray1::from_slice(py, points).reshape([points.len() / self.dim, self.dim])?;
            let result = self.function.bind(py).call1((array,))?;
            fill(&result.get_item(0)?, phi, "phi")?;
            fill(&result.get_item(1)?, gradient, "the gradient of phi")?;
            fill(&result.get_item(2)?, hessian, "the Hessian of phi")
        })
        .map_err(|error| {
            *self.pending.borrow_mut() = Some(error);
            Interrupted
        })
    }
}

/// A problem in the solver's units, for tests of the iteration's derivatives. Positions (N, d),
/// free nodes ascending, links (L, 2) node pairs with their lengths, each node's weight, the
/// physical origin in solver units; obstacles as stacked quadratics `(centres, values, gradients,
/// Hessians)`. (`Chain.network` gives the network of a whole problem, any obstacles included.)
#[pyclass(unsendable, module = "funicular._core")]
struct Network {
    inner: CoreNetwork,
    pending: Pending,
}

impl Network {
    fn point(&mut self, z: &[f64], mu: &[f64]) -> PyResult<Point> {
        if z.len() != self.inner.n_free() * self.inner.dim || mu.len() != self.inner.n_constraints() {
            return Err(PyValueError::new_err(
                "z or mu does not match the network's free coordinates and rows",
            ));
        }
        let mut point = Point::default();
        self.inner.evaluate(z, mu, &mut point).map_err(|_| {
            self.pending
                .borrow_mut()
                .take()
                .unwrap_or_else(|| PyValueError::new_err("the evaluation was stopped"))
        })?;
        Ok(point)
    }
}

#[pymethods]
impl Network {
    #[new]
    #[pyo3(signature = (dim, squared, positions, free, links, lengths, load, origin, quadratics=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        dim: usize,
        squared: bool,
        positions: Floats<'_>,
        free: PyReadonlyArrayDyn<'_, i64>,
        links: PyReadonlyArrayDyn<'_, i64>,
        lengths: Floats<'_>,
        load: Floats<'_>,
        origin: Floats<'_>,
        quadratics: Option<(Floats<'_>, Floats<'_>, Floats<'_>, Floats<'_>)>,
    ) -> PyResult<Self> {
        let obstacles = match quadratics {
            Some((centres, values, gradients, hessians)) => Obstacles::Quadratic(Quadratics {
                centres: floats(&centres, "centres")?,
                values: floats(&values, "values")?,
                gradients: floats(&gradients, "gradients")?,
                hessians: floats(&hessians, "hessians")?,
            }),
            None => Obstacles::none(),
        };
        let pairs = indices(&links, "links")?;
        if pairs.len() % 2 != 0 {
            return Err(PyValueError::new_err("links must be an (L, 2) array"));
        }
        let inner = CoreNetwork::new(
            dim,
            if squared {
                Formulation::Squared
            } else {
                Formulation::Norm
            },
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

    /// The constraint values and the residual of stationarity `grad E + J^T mu` (free
    /// coordinates, flat) at `(z, mu)`: what the iteration sees, for tests and diagnostics.
    fn evaluate<'py>(
        &mut self,
        py: Python<'py>,
        z: Floats<'_>,
        mu: Floats<'_>,
    ) -> PyResult<(Vector<'py>, Vector<'py>)> {
        let point = self.point(&floats(&z, "z")?, &floats(&mu, "mu")?)?;
        Ok((
            PyArray1::from_vec(py, point.c),
            PyArray1::from_vec(py, point.dual),
        ))
    }

    /// `J dz` at `z` (every constraint row).
    fn jacobian_times<'py>(
        &mut self,
        py: Python<'py>,
        z: Floats<'_>,
        dz: Floats<'_>,
    ) -> PyResult<Vector<'py>> {
        let m = self.inner.n_constraints();
        let point = self.point(&floats(&z, "z")?, &vec![0.0; m])?;
        let dz = floats(&dz, "dz")?;
        Ok(PyArray1::from_vec(
            py,
            (0..m).map(|r| self.inner.row_times(&point, r, &dz)).collect(),
        ))
    }

    /// The Newton matrix `W + J^T diag(sigma) J` at `(z, mu)` as a dense (n d, n d) array, row by
    /// row (for tests on small problems).
    fn newton_matrix<'py>(
        &mut self,
        py: Python<'py>,
        z: Floats<'_>,
        mu: Floats<'_>,
        sigma: Floats<'_>,
    ) -> PyResult<Vector<'py>> {
        let mu = floats(&mu, "mu")?;
        let point = self.point(&floats(&z, "z")?, &mu)?;
        let mut matrix = NewtonSystem::for_network(&self.inner);
        self.inner
            .newton_matrix(&point, &mu, &floats(&sigma, "sigma")?, &mut matrix);
        Ok(PyArray1::from_vec(py, matrix.to_dense()))
    }

    /// What the iterations on this network spent: counts (interior-point steps, polish steps,
    /// evaluations, factorizations) and seconds (evaluation, the Newton systems, the polish's KKT
    /// systems, the iteration altogether).
    #[getter]
    fn statistics(&self) -> std::collections::HashMap<&'static str, f64> {
        statistics(&self.inner.statistics)
    }

    /// Free nodes, links, constraint rows.
    #[getter]
    fn n_constraints(&self) -> usize {
        self.inner.n_constraints()
    }
}

/// Link contact evaluated in Python, in the problem's units: `function(positions, links)` returns
/// psi (J, L), t (J, L), the gradient of phi (J, L, d) and the Hessian of psi (J, L, 2d, 2d) for the
/// links given by their first nodes.
struct PythonLinks {
    dim: usize,
    function: Py<PyAny>,
    pending: Pending,
}

impl Segments for PythonLinks {
    fn evaluate(
        &mut self,
        positions: &[f64],
        links: &[usize],
        psi: &mut [f64],
        t: &mut [f64],
        gradient: &mut [f64],
        hessian: &mut [f64],
    ) -> Result<(), Interrupted> {
        Python::attach(|py| -> PyResult<()> {
            let array =
                PyArray1::from_slice(py, positions).reshape([positions.len() / self.dim, self.dim])?;
            let result = self.function.bind(py).call1((array, index_array(py, links)))?;
            fill(&result.get_item(0)?, psi, "psi")?;
            fill(&result.get_item(1)?, t, "t")?;
            fill(&result.get_item(2)?, gradient, "the gradient of phi")?;
            fill(&result.get_item(3)?, hessian, "the Hessian of psi")
        })
        .map_err(|error| {
            *self.pending.borrow_mut() = Some(error);
            Interrupted
        })
    }
}

/// The built-in shapes given as `(kind, parameters)`: `("quadratic", [centre (d), value, gradient
/// (d), Hessian (d x d, row by row)])` or `("box", [centre (d), half sizes (d), radius, rotation
/// (d x d, row by row)])`; as the core's quadratics and shapes.
fn native_shapes(shapes: Vec<(String, Vec<f64>)>, d: usize) -> PyResult<(Quadratics, Vec<Shape>)> {
    let mut quadratics = Quadratics::default();
    let mut list = Vec::with_capacity(shapes.len());
    let quadratic = 2 * d + 1 + d * d;
    for (kind, p) in shapes {
        match (kind.as_str(), p.len()) {
            ("quadratic", size) if size == quadratic => {
                list.push(Shape::Quadratic(quadratics.values.len()));
                quadratics.centres.extend_from_slice(&p[0..d]);
                quadratics.values.push(p[d]);
                quadratics.gradients.extend_from_slice(&p[d + 1..2 * d + 1]);
                quadratics.hessians.extend_from_slice(&p[2 * d + 1..]);
            }
            ("box", size) if size == quadratic => {
                let (mut centre, mut half_size, mut rotation) = ([0.0; 3], [0.0; 3], [0.0; 9]);
                centre[..d].copy_from_slice(&p[0..d]);
                half_size[..d].copy_from_slice(&p[d..2 * d]);
                rotation[..d * d].copy_from_slice(&p[2 * d + 1..]);
                list.push(Shape::Box {
                    centre,
                    half_size,
                    radius: p[2 * d],
                    rotation,
                })
            }
            _ => {
                return Err(PyValueError::new_err(format!(
                    "a built-in shape in {d}-D is ('quadratic' or 'box', {quadratic} numbers), not ({kind:?}, {} numbers)",
                    p.len()
                )))
            }
        }
    }
    Ok((quadratics, list))
}

/// phi (J, n), its gradient (J, n, d) and Hessian (J, n, d, d) of the built-in `shapes` (see
/// `native_shapes`) at points (n, d): the one evaluation of these shapes, in Python too.
#[pyfunction]
#[pyo3(signature = (shapes, points, dim=2))]
fn evaluate_shapes<'py>(
    py: Python<'py>,
    shapes: Vec<(String, Vec<f64>)>,
    points: Floats<'_>,
    dim: usize,
) -> PyResult<(Vector<'py>, Vector<'py>, Vector<'py>)> {
    let points = floats(&points, "points")?;
    if !(2..=3).contains(&dim) || points.len() % dim != 0 {
        return Err(PyValueError::new_err(
            "points must be an (n, d) array with d = 2 or 3",
        ));
    }
    let (quadratics, shapes) = native_shapes(shapes, dim)?;
    let (k, n, d) = (shapes.len(), points.len() / dim, dim);
    let (mut phi, mut gradient, mut hessian) =
        (vec![0.0; k * n], vec![0.0; k * n * d], vec![0.0; k * n * d * d]);
    NativeField {
        dim,
        shapes,
        quadratics,
    }
    .evaluate(&points, &mut phi, &mut gradient, &mut hessian)
    .expect("the built-in shapes are evaluated here");
    Ok((
        PyArray1::from_vec(py, phi),
        PyArray1::from_vec(py, gradient),
        PyArray1::from_vec(py, hessian),
    ))
}

/// `Chain.presolve`'s answer: positions (N d), movable nodes, the fixed links' tensions, detached
/// ends and the nodes they rest on, and the obstacles' gradients at the movable nodes (or None).
type PresolveAnswer<'py> = (
    Vector<'py>,
    Indices<'py>,
    Vector<'py>,
    Indices<'py>,
    Indices<'py>,
    Option<Vector<'py>>,
);
type Indices<'py> = Bound<'py, PyArray1<i64>>;
/// `Chain.solve`'s answer: status, positions (N d), link multipliers (N - 1), obstacle multipliers
/// (J columns), Newton steps, the core's statistics, and the second-order test at the result if
/// asked for: `("minimum" | "undecided", nan, [])` or `("direction", curvature, moves (N d))`.
type SolveAnswer<'py> = (
    &'static str,
    Vector<'py>,
    Vector<'py>,
    Vector<'py>,
    usize,
    std::collections::HashMap<&'static str, f64>,
    Option<(&'static str, f64, Vector<'py>)>,
);

/// Node indices as a numpy array.
fn index_array<'py>(py: Python<'py>, values: &[usize]) -> Indices<'py> {
    PyArray1::from_iter(py, values.iter().map(|&v| v as i64))
}

fn statistics(s: &Statistics) -> std::collections::HashMap<&'static str, f64> {
    std::collections::HashMap::from([
        ("interior_point_steps", s.interior_point_steps as f64),
        ("polish_steps", s.polish_steps as f64),
        ("evaluations", s.evaluations as f64),
        ("factorizations", s.factorizations as f64),
        ("evaluation_seconds", s.evaluation_seconds),
        ("newton_seconds", s.newton_seconds),
        ("polish_seconds", s.polish_seconds),
        ("core_seconds", s.total_seconds),
    ])
}

/// The error a Python function left, or a `ValueError` whose args say what is wrong:
/// `("too_far", a, b, distance, length)`, `("taut_not_vertical", a, b)`, `("not_factored",)` or
/// `("obstacle_not_finite", obstacle, node or link, at_start)`.
fn core_error(pending: &Pending, error: SolveError) -> PyErr {
    match error {
        SolveError::Interrupted | SolveError::Infeasible(Infeasible::Interrupted) => pending
            .borrow_mut()
            .take()
            .unwrap_or_else(|| PyValueError::new_err("the solver core was stopped without a reason")),
        SolveError::Infeasible(Infeasible::TooFar {
            a,
            b,
            distance,
            length,
        }) => PyValueError::new_err(("too_far", a, b, distance, length)),
        SolveError::Infeasible(Infeasible::TautNotVertical { a, b }) => {
            PyValueError::new_err(("taut_not_vertical", a, b))
        }
        SolveError::NotFactored => PyValueError::new_err(("not_factored",)),
        SolveError::ObstacleNotFinite {
            obstacle,
            index,
            at_start,
        } => PyValueError::new_err(("obstacle_not_finite", obstacle, index, at_start)),
    }
}

/// `solve()`, or a `ValueError` `("internal", message)` if the core panics (a bug): the caller
/// turns it into the package's error instead of the interpreter's panic.
fn guarded<T>(solve: impl FnOnce() -> T) -> PyResult<T> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(solve)).map_err(|panic| {
        let message = panic
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| panic.downcast_ref::<&str>().copied())
            .unwrap_or("no message");
        PyValueError::new_err(("internal", message.trim().to_string()))
    })
}

/// A whole solve as Python runs it: freed work arrays reused until it returns, Ctrl-C asked about
/// between steps, a panic and the core's errors turned into Python's, the answer converted.
fn run<'py>(
    py: Python<'py>,
    pending: &Pending,
    solve: impl FnOnce(&mut dyn FnMut() -> bool) -> Result<Solved, SolveError>,
) -> PyResult<SolveAnswer<'py>> {
    let _reuse = memory::Reuse::begin();
    let mut check = signals(py, pending);
    let solved = guarded(|| solve(&mut check))?.map_err(|error| core_error(pending, error))?;
    Ok(answer(py, solved))
}

/// A solve's answer as Python takes it (`SolveAnswer`).
fn answer(py: Python<'_>, solved: Solved) -> SolveAnswer<'_> {
    let judged = solved.judged.map(|judged| match judged {
        Judged::Minimum => ("minimum", f64::NAN, PyArray1::from_vec(py, Vec::new())),
        Judged::Undecided => ("undecided", f64::NAN, PyArray1::from_vec(py, Vec::new())),
        Judged::Direction(value, moves) => ("direction", value, PyArray1::from_vec(py, moves)),
    });
    (
        solved.status.name(),
        PyArray1::from_vec(py, solved.positions),
        PyArray1::from_vec(py, solved.link_multipliers),
        PyArray1::from_vec(py, solved.obstacle_multipliers),
        solved.iterations,
        statistics(&solved.statistics),
        judged,
    )
}

/// At least one support, ascending node indices below `n`, with `dim` coordinates each.
fn supports_valid(supports: &[usize], positions: &[f64], n: usize, dim: usize) -> bool {
    !supports.is_empty()
        && supports.windows(2).all(|p| p[0] < p[1])
        && supports[supports.len() - 1] < n
        && positions.len() == supports.len() * dim
}

/// A problem's formulation and obstacles as the core takes them (see `Chain`).
fn setup(
    dim: usize,
    squared: bool,
    shapes: Option<Vec<(String, Vec<f64>)>>,
    field: Option<Py<PyAny>>,
    links: Option<Py<PyAny>>,
    n_obstacles: usize,
    pending: &Pending,
) -> PyResult<Setup> {
    // Built-in shapes are evaluated here: quadratics alone by the iteration's own fast path,
    // with a box among them as a node field; any other obstacle by the caller's field.
    let (mut quadratics, mut nodes) = (None, None::<Rc<RefCell<dyn NodeField>>>);
    match (shapes, field) {
        (Some(shapes), None) if shapes.len() == n_obstacles => {
            let (stacked, list) = native_shapes(shapes, dim)?;
            if list.iter().all(|s| matches!(s, Shape::Quadratic(_))) {
                quadratics = Some(stacked);
            } else {
                nodes = Some(Rc::new(RefCell::new(NativeField {
                    dim,
                    shapes: list,
                    quadratics: stacked,
                })));
            }
        }
        (None, Some(function)) => {
            nodes = Some(Rc::new(RefCell::new(PythonNodes {
                count: n_obstacles,
                dim,
                function,
                pending: pending.clone(),
            })));
        }
        (None, None) if n_obstacles == 0 => {}
        _ => {
            return Err(PyValueError::new_err(
                "obstacles need their built-in shapes (one per obstacle) or a field, not both",
            ))
        }
    }
    let links_contact = links.is_some();
    let segments = links.map(|function| -> Rc<RefCell<dyn Segments>> {
        Rc::new(RefCell::new(PythonLinks {
            dim,
            function,
            pending: pending.clone(),
        }))
    });
    Ok(Setup {
        formulation: if squared {
            Formulation::Squared
        } else {
            Formulation::Norm
        },
        obstacles: CoreObstacles {
            count: n_obstacles,
            quadratics,
            nodes,
            segments,
        },
        links_contact,
    })
}

/// A chain in the problem's units: masses (N), link lengths (N - 1), gravity, supports ascending
/// with their positions (S, d), the formulation; obstacles as the built-in shapes the core
/// evaluates (`native_shapes`) or a function `field(points) -> (phi, gradient, Hessian)` of all
/// obstacles at points (n, d); with link contact also `links(positions, links) -> (psi, t,
/// gradient, Hessian)`.
#[pyclass(unsendable, module = "funicular._core")]
struct Chain {
    inner: CoreChain,
    setup: Setup,
    pending: Pending,
}

impl Chain {
    fn answer<'py>(&self, py: Python<'py>, presolved: Presolved) -> PresolveAnswer<'py> {
        (
            PyArray1::from_vec(py, presolved.positions),
            index_array(py, &presolved.movable),
            PyArray1::from_vec(py, presolved.fixed_tension),
            index_array(py, &presolved.detached),
            index_array(py, &presolved.attach),
            presolved.gradients.map(|g| PyArray1::from_vec(py, g)),
        )
    }

    fn error(&self, error: SolveError) -> PyErr {
        core_error(&self.pending, error)
    }

    fn shapes(&self) -> OneByOne<'_> {
        OneByOne {
            dim: self.inner.dim,
            obstacles: &self.setup.obstacles,
        }
    }

    fn size(&self) -> usize {
        self.inner.n_nodes() * self.inner.dim
    }
}

#[pymethods]
impl Chain {
    #[new]
    #[pyo3(signature = (dim, masses, lengths, gravity, supports, support_positions, squared=false, shapes=None, field=None, links=None, n_obstacles=0))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        dim: usize,
        masses: Floats<'_>,
        lengths: Floats<'_>,
        gravity: f64,
        supports: PyReadonlyArrayDyn<'_, i64>,
        support_positions: Floats<'_>,
        squared: bool,
        shapes: Option<Vec<(String, Vec<f64>)>>,
        field: Option<Py<PyAny>>,
        links: Option<Py<PyAny>>,
        n_obstacles: usize,
    ) -> PyResult<Self> {
        let inner = CoreChain {
            dim,
            masses: floats(&masses, "masses")?,
            lengths: floats(&lengths, "lengths")?,
            gravity,
            supports: indices(&supports, "supports")?,
            support_positions: floats(&support_positions, "support_positions")?,
        };
        let n = inner.masses.len();
        if !(1..=3).contains(&dim)
            || n < 2
            || inner.lengths.len() != n - 1
            || !supports_valid(&inner.supports, &inner.support_positions, n, dim)
        {
            return Err(PyValueError::new_err(
                "a chain needs N >= 2 masses, N - 1 lengths and ascending supports with (S, d) positions",
            ));
        }
        let pending: Pending = Rc::new(RefCell::new(None));
        let setup = setup(dim, squared, shapes, field, links, n_obstacles, &pending)?;
        Ok(Chain {
            inner,
            setup,
            pending,
        })
    }

    /// The presolve (see the core's `presolve`): from the built-in guess, or from `guess` (N d)
    /// (`settled`: a solved chain's).
    #[pyo3(signature = (guess=None, settled=false))]
    fn presolve<'py>(
        &self,
        py: Python<'py>,
        guess: Option<Floats<'_>>,
        settled: bool,
    ) -> PyResult<PresolveAnswer<'py>> {
        let guess = guess.map(|g| floats(&g, "guess")).transpose()?;
        if guess.as_ref().is_some_and(|g| g.len() != self.size()) {
            return Err(PyValueError::new_err(
                "presolve: the guess must hold N d coordinates",
            ));
        }
        match presolve(&self.inner, &mut self.shapes(), guess.as_deref(), settled) {
            Ok(presolved) => Ok(self.answer(py, presolved)),
            Err(infeasible) => Err(self.error(SolveError::Infeasible(infeasible))),
        }
    }

    /// The chain's equilibrium and link tensions, `(positions (N d), tensions (N - 1))`, if it
    /// touches no obstacle and every span is a discrete catenary (the core's `exact_start`), else
    /// None.
    fn exact_start<'py>(&self, py: Python<'py>) -> PyResult<Option<(Vector<'py>, Vector<'py>)>> {
        match exact_start(&self.inner, &mut self.shapes()) {
            Ok(start) => Ok(start.map(|(p, t)| (PyArray1::from_vec(py, p), PyArray1::from_vec(py, t)))),
            Err(_) => Err(self.error(SolveError::Interrupted)),
        }
    }

    /// The equilibrium with its forces (the core's `solve::solve`), from the built-in start or from
    /// `guess` (N d) with, if given, the multipliers (every link's, and every obstacle's contact
    /// columns); `settled`: the guess is a solved chain's; `judge`: the second-order test at the
    /// result too.
    #[pyo3(signature = (tol, max_iterations, escape_saddles=true, exact_start=true, guess=None, link_multipliers=None, obstacle_multipliers=None, settled=false, judge=false))]
    #[allow(clippy::too_many_arguments)]
    fn solve<'py>(
        &self,
        py: Python<'py>,
        tol: f64,
        max_iterations: usize,
        escape_saddles: bool,
        exact_start: bool,
        guess: Option<Floats<'_>>,
        link_multipliers: Option<Floats<'_>>,
        obstacle_multipliers: Option<Floats<'_>>,
        settled: bool,
        judge: bool,
    ) -> PyResult<SolveAnswer<'py>> {
        let initial = match guess {
            Some(positions) => Some(Guess {
                positions: floats(&positions, "guess")?,
                link_multipliers: link_multipliers
                    .map(|m| floats(&m, "link_multipliers"))
                    .transpose()?,
                obstacle_multipliers: obstacle_multipliers
                    .map(|m| floats(&m, "obstacle_multipliers"))
                    .transpose()?,
                settled,
                statistics: Statistics::default(),
            }),
            None => None,
        };
        let n = self.inner.n_nodes();
        let columns = if self.setup.links_contact { n - 1 } else { n };
        if let Some(guess) = &initial {
            let sizes_match = guess.positions.len() == self.size()
                && guess.link_multipliers.as_ref().is_none_or(|m| m.len() == n - 1)
                && guess
                    .obstacle_multipliers
                    .as_ref()
                    .is_none_or(|m| m.len() == self.setup.obstacles.count * columns);
            if !sizes_match {
                return Err(PyValueError::new_err(
                    "solve: the guess's arrays do not match the chain",
                ));
            }
        }
        let options = Options {
            tol,
            max_iterations,
            escape_saddles,
            exact_start,
        };
        run(py, &self.pending, |check| {
            solve(&self.inner, &self.setup, &options, initial.as_ref(), judge, check)
        })
    }

    /// The network the iteration would start from at `guess` (N d), in the solver's units, and its
    /// free coordinates (for tests of the iteration's derivatives).
    fn network<'py>(&self, py: Python<'py>, guess: Floats<'_>) -> PyResult<(Network, Vector<'py>)> {
        let guess = floats(&guess, "guess")?;
        if guess.len() != self.size() {
            return Err(PyValueError::new_err(
                "network: the guess must hold N d coordinates",
            ));
        }
        let inner = network_at(&self.inner, &self.setup, &guess).map_err(|error| self.error(error))?;
        let z = inner.free_coordinates();
        Ok((
            Network {
                inner,
                pending: self.pending.clone(),
            },
            PyArray1::from_vec(py, z),
        ))
    }
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

/// A cable net in the problem's units: masses (N), links (L, 2) node pairs with their lengths (L),
/// gravity, supports ascending with their positions (S, d), the formulation; obstacles (node
/// contact) as for `Chain`.
#[pyclass(unsendable, module = "funicular._core")]
struct Net {
    inner: CoreNet,
    setup: Setup,
    pending: Pending,
}

#[pymethods]
impl Net {
    #[new]
    #[pyo3(signature = (dim, masses, links, lengths, gravity, supports, support_positions, squared=false, shapes=None, field=None, n_obstacles=0, loads=None, stiffness=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        dim: usize,
        masses: Floats<'_>,
        links: PyReadonlyArrayDyn<'_, i64>,
        lengths: Floats<'_>,
        gravity: f64,
        supports: PyReadonlyArrayDyn<'_, i64>,
        support_positions: Floats<'_>,
        squared: bool,
        shapes: Option<Vec<(String, Vec<f64>)>>,
        field: Option<Py<PyAny>>,
        n_obstacles: usize,
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
            loads: match &loads {
                Some(loads) => floats(loads, "loads")?,
                None => Vec::new(),
            },
            stiffness: match &stiffness {
                Some(stiffness) => floats(stiffness, "stiffness")?,
                None => Vec::new(),
            },
        };
        let n = inner.n_nodes();
        let valid = (2..=3).contains(&dim)
            && (inner.loads.is_empty() || inner.loads.len() == n * dim)
            && ends.len() % 2 == 0
            && inner.lengths.len() == inner.links.len()
            && (inner.stiffness.is_empty() || inner.stiffness.len() == inner.links.len())
            && inner.links.iter().all(|&[a, b]| a < n && b < n && a != b)
            && supports_valid(&inner.supports, &inner.support_positions, n, dim);
        if !valid {
            return Err(PyValueError::new_err(
                "a net needs (L, 2) links between distinct nodes with L lengths, ascending supports with (S, d) positions, and (N, d) loads if any",
            ));
        }
        let pending: Pending = Rc::new(RefCell::new(None));
        let setup = setup(dim, squared, shapes, field, None, n_obstacles, &pending)?;
        Ok(Net {
            inner,
            setup,
            pending,
        })
    }

    /// The force-density start (the core's `net::hanging_start`): positions (N d), or None where a
    /// node reaches no support.
    fn hanging_start<'py>(&self, py: Python<'py>) -> PyResult<Option<Vector<'py>>> {
        match hanging_start(&self.inner, &self.setup) {
            Ok(start) => Ok(start.map(|p| PyArray1::from_vec(py, p))),
            Err(_) => Err(core_error(&self.pending, SolveError::Interrupted)),
        }
    }

    /// The equilibrium with its forces (the core's `net::solve_net`), from the force-density start
    /// or from `guess` (N d); `judge`: the second-order test at the result too.
    #[pyo3(signature = (tol, max_iterations, escape_saddles=true, guess=None, judge=false))]
    fn solve<'py>(
        &self,
        py: Python<'py>,
        tol: f64,
        max_iterations: usize,
        escape_saddles: bool,
        guess: Option<Floats<'_>>,
        judge: bool,
    ) -> PyResult<SolveAnswer<'py>> {
        let initial = match guess {
            Some(positions) => Some(Guess {
                positions: floats(&positions, "guess")?,
                ..Guess::default()
            }),
            None => None,
        };
        if initial
            .as_ref()
            .is_some_and(|g| g.positions.len() != self.inner.n_nodes() * self.inner.dim)
        {
            return Err(PyValueError::new_err(
                "solve: the guess must hold N d coordinates",
            ));
        }
        let options = Options {
            tol,
            max_iterations,
            escape_saddles,
            exact_start: false,
        };
        run(py, &self.pending, |check| {
            solve_net(&self.inner, &self.setup, &options, initial.as_ref(), judge, check)
        })
    }
}

/// Interior node positions ((n - 1) d) and link tensions (n) of n links hanging between `left`
/// and `right` (d coordinates each) with every link taut (the core's `catenary::hanging_span`), or
/// None; obstacles as for `Chain` (quadratics or a field).
#[pyfunction]
#[pyo3(signature = (interior_masses, lengths, gravity, left, right, field=None, n_obstacles=0))]
#[allow(clippy::too_many_arguments)]
fn hanging_span<'py>(
    py: Python<'py>,
    interior_masses: Floats<'_>,
    lengths: Floats<'_>,
    gravity: f64,
    left: Floats<'_>,
    right: Floats<'_>,
    field: Option<Py<PyAny>>,
    n_obstacles: usize,
) -> PyResult<Option<(Vector<'py>, Vector<'py>)>> {
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
        Ok(span) => Ok(span.map(|(p, t)| (PyArray1::from_vec(py, p), PyArray1::from_vec(py, t)))),
        Err(_) => Err(pending
            .borrow_mut()
            .take()
            .unwrap_or_else(|| PyValueError::new_err("an obstacle's evaluation was stopped"))),
    }
}

/// rho and the shift s of the second-order test's sufficient condition `W + rho A^T A - s I`
/// positive definite (the core's `curvature::penalty_and_shift`): `stiffest` the largest entry of
/// W's diagonal blocks, `stiffness` the weight per chain length, `degree` the most links at a node,
/// `penalty` rho in units of the larger of the two (`CURVATURE_PENALTY`).
#[pyfunction]
#[pyo3(signature = (stiffest, stiffness, degree, n_obstacles, threshold, penalty=funicular_core::curvature::PENALTY))]
fn penalty_and_shift(
    stiffest: f64,
    stiffness: f64,
    degree: usize,
    n_obstacles: usize,
    threshold: f64,
    penalty: f64,
) -> (f64, f64) {
    funicular_core::curvature::penalty_and_shift(stiffest, stiffness, degree, n_obstacles, threshold, penalty)
}

/// The curvature below which an eigenvalue counts as zero: one that changes the energy by less than
/// `tol * weight * total_length` when every node moves by the chain's length.
#[pyfunction]
fn zero_curvature(tol: f64, weight: f64, n_nodes: usize, total_length: f64) -> f64 {
    funicular_core::curvature::zero_curvature(tol, weight, n_nodes, total_length)
}

#[pymodule]
fn _core(module: &Bound<'_, PyModule>) -> PyResult<()> {
    module.add_class::<Network>()?;
    module.add_class::<Chain>()?;
    module.add_class::<Net>()?;
    module.add_function(wrap_pyfunction!(penalty_and_shift, module)?)?;
    module.add_function(wrap_pyfunction!(hanging_span, module)?)?;
    module.add_function(wrap_pyfunction!(evaluate_shapes, module)?)?;
    module.add_function(wrap_pyfunction!(zero_curvature, module)?)?;
    module.add_function(wrap_pyfunction!(gram_positive_definite, module)?)?;
    module.add_function(wrap_pyfunction!(blocks_positive_definite, module)?)?;
    module.add_function(wrap_pyfunction!(json::read_json, module)?)?;
    module.add("SMOOTH_RATIO", SMOOTH_RATIO)?;
    module.add("PROXIMAL", funicular_core::polish::PROXIMAL)?;
    module.add("CURVATURE_PENALTY", funicular_core::curvature::PENALTY)?;
    Ok(())
}

/// Whether `A A^T + shift I` is positive definite for rows of `+vectors[r]` (m, d) at node
/// `nodes[r, 0]` and `-vectors[r]` at `nodes[r, 1]` (-1: none): banded up to `max_band`, sparse
/// beyond (the core's `gram::gram_positive_definite`).
#[pyfunction]
fn gram_positive_definite(
    py: Python<'_>,
    nodes: PyReadonlyArrayDyn<'_, i64>,
    vectors: Floats<'_>,
    shift: f64,
    max_band: usize,
) -> PyResult<bool> {
    let (shape, dims) = (nodes.shape().to_vec(), vectors.shape().to_vec());
    if shape.len() != 2 || shape[1] != 2 || dims.len() != 2 || dims[0] != shape[0] {
        return Err(PyValueError::new_err("nodes must be (m, 2) and vectors (m, d)"));
    }
    let nodes = nodes
        .as_slice()
        .map_err(|_| PyValueError::new_err("nodes must be contiguous"))?;
    let vectors = vectors
        .as_slice()
        .map_err(|_| PyValueError::new_err("vectors must be contiguous"))?;
    let rows = funicular_core::gram::SparseRows {
        nodes,
        vectors,
        dim: dims[1],
    };
    Ok(py.detach(|| funicular_core::gram::gram_positive_definite(&rows, shift, max_band)))
}

/// Whether the symmetric matrix with d x d blocks `node_blocks` (n, d, d) on its diagonal and
/// `pair_blocks` (p, d, d) at node pairs `pairs` (p, 2) (their transposes mirrored), plus `shift`
/// I, is positive definite (the core's `sparse::blocks_positive_definite`).
#[pyfunction]
fn blocks_positive_definite(
    py: Python<'_>,
    node_blocks: Floats<'_>,
    pairs: PyReadonlyArrayDyn<'_, i64>,
    pair_blocks: Floats<'_>,
    shift: f64,
) -> PyResult<bool> {
    let (nodes, shape, blocks) = (
        node_blocks.shape().to_vec(),
        pairs.shape().to_vec(),
        pair_blocks.shape().to_vec(),
    );
    let d = nodes.get(1).copied().unwrap_or(0);
    let square = |s: &[usize]| s.len() == 3 && s[1] == d && s[2] == d;
    if !(1..=3).contains(&d)
        || !square(&nodes)
        || !square(&blocks)
        || shape.len() != 2
        || shape[1] != 2
        || blocks[0] != shape[0]
    {
        return Err(PyValueError::new_err(
            "node_blocks must be (n, d, d), pairs (p, 2) and pair_blocks (p, d, d), d = 1, 2 or 3",
        ));
    }
    let n = nodes[0];
    let pairs = pairs
        .as_slice()
        .map_err(|_| PyValueError::new_err("pairs must be contiguous"))?;
    if pairs.iter().any(|&f| f < 0 || f as usize >= n) || pairs.chunks_exact(2).any(|p| p[0] == p[1]) {
        return Err(PyValueError::new_err(
            "pairs must hold two different node indices below n (a node's own block is in node_blocks)",
        ));
    }
    let pairs: Vec<[usize; 2]> = pairs
        .chunks_exact(2)
        .map(|p| [p[0] as usize, p[1] as usize])
        .collect();
    let (node_blocks, pair_blocks) = (
        node_blocks
            .as_slice()
            .map_err(|_| PyValueError::new_err("node_blocks must be contiguous"))?,
        pair_blocks
            .as_slice()
            .map_err(|_| PyValueError::new_err("pair_blocks must be contiguous"))?,
    );
    Ok(py.detach(|| {
        funicular_core::sparse::blocks_positive_definite(d, node_blocks, &pairs, pair_blocks, shift)
    }))
}
