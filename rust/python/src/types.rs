//! The values that cross the boundary, each a class with named fields: what a solve is asked
//! ([`Settings`], [`Start`]), the obstacles ([`Obstacles`], [`Shape`], [`Quadratics`]) and what their
//! evaluations in Python return ([`NodeFields`], [`SegmentFields`]), and the answers ([`Solved`],
//! [`Curvature`], [`Presolved`], [`Hanging`], [`Evaluated`], [`SecondOrderBound`]). Arguments are
//! keyword-only and none has a default: the package's front end (`funicular._solver`) holds them.

use std::collections::HashMap;

use funicular_core::driver::{Judged, Options, Solved as CoreSolved};
use funicular_core::problem::Statistics;
use numpy::{PyArray1, PyArrayDyn, PyReadonlyArrayDyn};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// A float array from Python.
pub type Floats<'a> = PyReadonlyArrayDyn<'a, f64>;
/// Node indices from Python.
pub type Indices<'a> = PyReadonlyArrayDyn<'a, i64>;

/// A contiguous float array's numbers.
pub fn floats(array: &Floats<'_>, name: &str) -> PyResult<Vec<f64>> {
    array
        .as_slice()
        .map(<[f64]>::to_vec)
        .map_err(|_| PyValueError::new_err(format!("{name} must be contiguous")))
}

/// An optional contiguous float array's numbers, none (empty) where it is not given.
pub fn optional_floats(array: Option<Floats<'_>>, name: &str) -> PyResult<Vec<f64>> {
    array.map_or(Ok(Vec::new()), |array| floats(&array, name))
}

/// A contiguous array of non-negative integers as indices.
pub fn indices(array: &Indices<'_>, name: &str) -> PyResult<Vec<usize>> {
    let values = array
        .as_slice()
        .map_err(|_| PyValueError::new_err(format!("{name} must be contiguous")))?;
    values
        .iter()
        .map(|&v| usize::try_from(v).map_err(|_| PyValueError::new_err(format!("{name} holds {v}"))))
        .collect()
}

/// A float array as numpy's.
pub fn array(py: Python<'_>, values: Vec<f64>) -> Py<PyArray1<f64>> {
    PyArray1::from_vec(py, values).unbind()
}

/// Indices as numpy's int64 array.
pub fn index_array(py: Python<'_>, values: &[usize]) -> Py<PyArray1<i64>> {
    PyArray1::from_iter(py, values.iter().map(|&v| v as i64)).unbind()
}

/// What a solve may be asked: the stopping test's tolerance, the iteration limit, whether to leave
/// a saddle and up to how many nodes (None: the core's cap for chains or nets), and (a chain)
/// whether to start from the exact catenary where it applies.
#[pyclass(frozen, get_all, module = "funicular._core")]
pub struct Settings {
    pub tol: f64,
    pub max_iterations: usize,
    pub escape_saddles: bool,
    pub escape_up_to: Option<usize>,
    pub exact_start: bool,
}

#[pymethods]
impl Settings {
    #[new]
    #[pyo3(signature = (*, tol, max_iterations, escape_saddles, exact_start, escape_up_to=None))]
    fn new(
        tol: f64,
        max_iterations: usize,
        escape_saddles: bool,
        exact_start: bool,
        escape_up_to: Option<usize>,
    ) -> Self {
        Settings {
            tol,
            max_iterations,
            escape_saddles,
            escape_up_to,
            exact_start,
        }
    }
}

impl Settings {
    pub fn options(&self) -> Options {
        Options {
            tol: self.tol,
            max_iterations: self.max_iterations,
            escape_saddles: self.escape_saddles,
            escape_up_to: self.escape_up_to,
            exact_start: self.exact_start,
        }
    }
}

/// Where a solve starts: positions (N d) and, when known, the multipliers in the problem's units
/// (every link's, and every obstacle's contact columns); `settled`: the positions are a solved
/// chain's (nodes on a surface stay there).
#[pyclass(frozen, module = "funicular._core")]
pub struct Start {
    pub positions: Vec<f64>,
    pub link_multipliers: Option<Vec<f64>>,
    pub obstacle_multipliers: Option<Vec<f64>>,
    pub settled: bool,
}

#[pymethods]
impl Start {
    #[new]
    #[pyo3(signature = (*, positions, link_multipliers, obstacle_multipliers, settled))]
    fn new(
        positions: Floats<'_>,
        link_multipliers: Option<Floats<'_>>,
        obstacle_multipliers: Option<Floats<'_>>,
        settled: bool,
    ) -> PyResult<Self> {
        Ok(Start {
            positions: floats(&positions, "positions")?,
            link_multipliers: link_multipliers
                .map(|m| floats(&m, "link_multipliers"))
                .transpose()?,
            obstacle_multipliers: obstacle_multipliers
                .map(|m| floats(&m, "obstacle_multipliers"))
                .transpose()?,
            settled,
        })
    }
}

/// A built-in shape the core evaluates: `kind` "quadratic" (centre (d), value, gradient (d),
/// Hessian (d x d, row by row)) or "box" (centre (d), half sizes (d), radius, rotation (d x d)).
#[pyclass(frozen, get_all, from_py_object, module = "funicular._core")]
#[derive(Clone)]
pub struct Shape {
    pub kind: String,
    pub parameters: Vec<f64>,
}

#[pymethods]
impl Shape {
    #[new]
    #[pyo3(signature = (*, kind, parameters))]
    fn new(kind: String, parameters: Vec<f64>) -> Self {
        Shape { kind, parameters }
    }
}

/// A problem's obstacles, `count` of them: the built-in `shapes` the core evaluates, or `field`,
/// every obstacle's phi, gradient and Hessian at points (n, d) evaluated in Python
/// (`field(points) -> NodeFields`); with link contact also `links(positions, links) ->
/// SegmentFields` for the links given by their first nodes.
#[pyclass(frozen, module = "funicular._core")]
pub struct Obstacles {
    pub count: usize,
    pub shapes: Option<Vec<Shape>>,
    pub field: Option<Py<PyAny>>,
    pub links: Option<Py<PyAny>>,
}

#[pymethods]
impl Obstacles {
    #[new]
    #[pyo3(signature = (*, count, shapes, field, links))]
    fn new(
        count: usize,
        shapes: Option<Vec<Shape>>,
        field: Option<Py<PyAny>>,
        links: Option<Py<PyAny>>,
    ) -> Self {
        Obstacles {
            count,
            shapes,
            field,
            links,
        }
    }
}

/// Quadratic obstacles stacked, in the solver's units: centres (J d), values (J), gradients (J d)
/// and Hessians (J d d).
#[pyclass(frozen, module = "funicular._core")]
pub struct Quadratics {
    pub centres: Vec<f64>,
    pub values: Vec<f64>,
    pub gradients: Vec<f64>,
    pub hessians: Vec<f64>,
}

#[pymethods]
impl Quadratics {
    #[new]
    #[pyo3(signature = (*, centres, values, gradients, hessians))]
    fn new(
        centres: Floats<'_>,
        values: Floats<'_>,
        gradients: Floats<'_>,
        hessians: Floats<'_>,
    ) -> PyResult<Self> {
        Ok(Quadratics {
            centres: floats(&centres, "centres")?,
            values: floats(&values, "values")?,
            gradients: floats(&gradients, "gradients")?,
            hessians: floats(&hessians, "hessians")?,
        })
    }
}

/// Obstacles evaluated at n points: phi (J, n), its gradient (J, n, d) and Hessian (J, n, d, d).
#[pyclass(frozen, get_all, module = "funicular._core")]
pub struct NodeFields {
    pub phi: Py<PyArrayDyn<f64>>,
    pub gradient: Py<PyArrayDyn<f64>>,
    pub hessian: Py<PyArrayDyn<f64>>,
}

#[pymethods]
impl NodeFields {
    #[new]
    #[pyo3(signature = (*, phi, gradient, hessian))]
    fn new(phi: Py<PyArrayDyn<f64>>, gradient: Py<PyArrayDyn<f64>>, hessian: Py<PyArrayDyn<f64>>) -> Self {
        NodeFields {
            phi,
            gradient,
            hessian,
        }
    }
}

/// Obstacles evaluated along L links: phi's largest value psi (J, L) along each, where it is
/// (`t` in [0, 1] from the link's first node, (J, L)), the gradient of phi there (J, L, d) and the
/// Hessian of psi over both nodes' coordinates (J, L, 2d, 2d).
#[pyclass(frozen, get_all, module = "funicular._core")]
pub struct SegmentFields {
    pub psi: Py<PyArrayDyn<f64>>,
    pub t: Py<PyArrayDyn<f64>>,
    pub gradient: Py<PyArrayDyn<f64>>,
    pub hessian: Py<PyArrayDyn<f64>>,
}

#[pymethods]
impl SegmentFields {
    #[new]
    #[pyo3(signature = (*, psi, t, gradient, hessian))]
    fn new(
        psi: Py<PyArrayDyn<f64>>,
        t: Py<PyArrayDyn<f64>>,
        gradient: Py<PyArrayDyn<f64>>,
        hessian: Py<PyArrayDyn<f64>>,
    ) -> Self {
        SegmentFields {
            psi,
            t,
            gradient,
            hessian,
        }
    }
}

/// The presolve: positions (N d) to start from, the nodes the iteration moves, the fixed links'
/// tensions (N - 1), the massless free ends and the nodes they rest on, and each obstacle's
/// gradient at the movable nodes (J, movable, d) where the push-out evaluated them and moved none.
#[pyclass(frozen, get_all, module = "funicular._core")]
pub struct Presolved {
    pub positions: Py<PyArray1<f64>>,
    pub movable: Py<PyArray1<i64>>,
    pub fixed_tension: Py<PyArray1<f64>>,
    pub detached: Py<PyArray1<i64>>,
    pub attach: Py<PyArray1<i64>>,
    pub obstacle_gradients: Option<Py<PyArray1<f64>>>,
}

/// A hanging chain's positions (N d, or a span's interior nodes) and its links' tensions.
#[pyclass(frozen, get_all, module = "funicular._core")]
pub struct Hanging {
    pub positions: Py<PyArray1<f64>>,
    pub tensions: Py<PyArray1<f64>>,
}

/// The second-order test at a result: `verdict` "minimum" (a proven strict local minimum),
/// "direction" (of negative curvature `value`, in the solver's units: `direction`, moves of every
/// node (N d), zero at the fixed ones) or "undecided".
#[pyclass(frozen, get_all, module = "funicular._core")]
pub struct Curvature {
    pub verdict: &'static str,
    pub value: f64,
    pub direction: Option<Py<PyArray1<f64>>>,
}

/// A solve's answer: how it ended (`status`: "optimal", "max_iterations", "stalled", "nonfinite"
/// or "diverged"), positions (N d), every link's multiplier, every obstacle's contact multipliers
/// (obstacle after obstacle, a column per node or per link), Newton steps, what the core spent
/// (`statistics`: counts and seconds), and the second-order test if it was asked for.
#[pyclass(frozen, get_all, module = "funicular._core")]
pub struct Solved {
    pub status: &'static str,
    pub positions: Py<PyArray1<f64>>,
    pub link_multipliers: Py<PyArray1<f64>>,
    pub obstacle_multipliers: Py<PyArray1<f64>>,
    pub iterations: usize,
    pub statistics: HashMap<&'static str, f64>,
    pub curvature: Option<Py<Curvature>>,
}

impl Solved {
    pub fn new(py: Python<'_>, solved: CoreSolved) -> PyResult<Self> {
        let curvature = match solved.judged {
            None => None,
            Some(judged) => {
                let (verdict, value, direction) = match judged {
                    Judged::Minimum => ("minimum", f64::NAN, None),
                    Judged::Undecided => ("undecided", f64::NAN, None),
                    Judged::Direction(value, moves) => ("direction", value, Some(array(py, moves))),
                };
                let curvature = Curvature {
                    verdict,
                    value,
                    direction,
                };
                Some(Py::new(py, curvature)?)
            }
        };
        Ok(Solved {
            status: solved.status.name(),
            positions: array(py, solved.positions),
            link_multipliers: array(py, solved.link_multipliers),
            obstacle_multipliers: array(py, solved.obstacle_multipliers),
            iterations: solved.iterations,
            statistics: statistics(&solved.statistics),
            curvature,
        })
    }
}

/// What the core spent, by name: counts (interior-point steps, polish steps, evaluations,
/// factorizations) and seconds (evaluation, the Newton systems, the polish's KKT systems, the
/// iteration altogether).
pub fn statistics(s: &Statistics) -> HashMap<&'static str, f64> {
    HashMap::from([
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

/// Constraint values and the residual of stationarity `grad E + J^T mu` (free coordinates, flat)
/// at an iterate.
#[pyclass(frozen, get_all, module = "funicular._core")]
pub struct Evaluated {
    pub c: Py<PyArray1<f64>>,
    pub dual: Py<PyArray1<f64>>,
}

/// rho and the shift s of the second-order test's sufficient condition `W + rho A^T A - s I`
/// positive definite; it unpacks as `(rho, shift)`, as a named tuple does.
#[pyclass(frozen, get_all, module = "funicular._core")]
pub struct SecondOrderBound {
    pub rho: f64,
    pub shift: f64,
}

#[pymethods]
impl SecondOrderBound {
    fn __iter__(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        let pair = (self.rho, self.shift).into_pyobject(py)?;
        Ok(pair.try_iter()?.into_any().unbind())
    }
}
