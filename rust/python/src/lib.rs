//! The Python module `funicular._core`: a thin front end to the solver core.
//!
//! `Network` holds a problem in the solver's units (built by `funicular.solver.ipm` from a
//! `Problem`); `iterate` runs the interior-point method with its polish, `escape` the second-order
//! test. Obstacles that are not quadratics are evaluated by a Python function called once per
//! evaluation with every point at once.

mod memory;

use std::cell::RefCell;
use std::rc::Rc;

use funicular_core::curvature::{escape_test, Verdict};
use funicular_core::evaluate::Point;
use funicular_core::ipm::{iterate, Failure, Settings};
use funicular_core::linalg::BlockTridiagonal;
use funicular_core::network::{
    Formulation, Interrupted, Network as CoreNetwork, NodeField, Obstacles, Quadratics, SegmentField,
    SMOOTH_RATIO,
};
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArrayDyn};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

#[global_allocator]
static ALLOCATOR: memory::HugePages = memory::HugePages;

/// Where a Python function's exception waits while the core unwinds.
type Pending = Rc<RefCell<Option<PyErr>>>;
/// A float array from Python, and one handed back.
type Floats<'a> = PyReadonlyArrayDyn<'a, f64>;
type Vector<'py> = Bound<'py, PyArray1<f64>>;
/// `Network.iterate`'s answer: status, z, mu, Newton steps, and where an obstacle was not finite.
type Iterated<'py> = (
    String,
    Vector<'py>,
    Vector<'py>,
    usize,
    Option<(usize, usize, bool)>,
);

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

struct PythonSegments {
    count: usize,
    dim: usize,
    function: Py<PyAny>,
    pending: Pending,
}

impl SegmentField for PythonSegments {
    fn count(&self) -> usize {
        self.count
    }

    fn evaluate(
        &mut self,
        positions: &[f64],
        psi: &mut [f64],
        t: &mut [f64],
        gradient: &mut [f64],
        hessian: &mut [f64],
    ) -> Result<(), Interrupted> {
        Python::attach(|py| -> PyResult<()> {
            let array =
                PyArray1::from_slice(py, positions).reshape([positions.len() / self.dim, self.dim])?;
            let result = self.function.bind(py).call1((array,))?;
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

/// A problem in the solver's units. Positions (N, d), free nodes ascending, links (L, 2) node
/// pairs with their lengths, each node's weight, the physical origin in solver units; obstacles as
/// stacked quadratics `(centres, values, gradients, Hessians)`, or a function of the free nodes'
/// positions (node contact) or of every node's (link contact, `links_contact=True`) returning
/// phi's values and derivatives stacked obstacle by obstacle.
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
    #[pyo3(signature = (dim, squared, positions, free, links, lengths, load, origin, quadratics=None, field=None, n_obstacles=0, links_contact=false))]
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
        field: Option<Py<PyAny>>,
        n_obstacles: usize,
        links_contact: bool,
    ) -> PyResult<Self> {
        let pending: Pending = Rc::new(RefCell::new(None));
        let obstacles = match (quadratics, field) {
            (Some((centres, values, gradients, hessians)), None) => Obstacles::Quadratic(Quadratics {
                centres: floats(&centres, "centres")?,
                values: floats(&values, "values")?,
                gradients: floats(&gradients, "gradients")?,
                hessians: floats(&hessians, "hessians")?,
            }),
            (None, Some(function)) if links_contact => Obstacles::Links(Box::new(PythonSegments {
                count: n_obstacles,
                dim,
                function,
                pending: pending.clone(),
            })),
            (None, Some(function)) => Obstacles::Nodes(Box::new(PythonNodes {
                count: n_obstacles,
                dim,
                function,
                pending: pending.clone(),
            })),
            (None, None) => Obstacles::none(),
            (Some(_), Some(_)) => return Err(PyValueError::new_err("give quadratics or a field, not both")),
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
        Ok(Network { inner, pending })
    }

    /// The interior-point method with its polish from the free coordinates `z` (flat) and, if
    /// given, a guess of the multipliers (solver units). Returns `(status, z, mu, iterations,
    /// detail)`: status "optimal", "max_iterations", "stalled" or "nonfinite" with the iterate;
    /// "not_factored" (the Newton matrix stayed indefinite under every inertia correction); or
    /// "obstacle_not_finite" with detail `(obstacle, contact row, at_start)`.
    #[pyo3(signature = (z, guess, tol, max_iterations))]
    fn iterate<'py>(
        &mut self,
        py: Python<'py>,
        z: Floats<'_>,
        guess: Option<Floats<'_>>,
        tol: f64,
        max_iterations: usize,
    ) -> PyResult<Iterated<'py>> {
        let z = floats(&z, "z")?;
        let guess = guess.map(|g| floats(&g, "guess")).transpose()?;
        let pending = self.pending.clone();
        let mut check = || match py.check_signals() {
            Ok(()) => true,
            Err(error) => {
                *pending.borrow_mut() = Some(error);
                false
            }
        };
        let settings = Settings { tol, max_iterations };
        let result = iterate(&mut self.inner, settings, z, guess.as_deref(), &mut check);
        let empty = || PyArray1::from_vec(py, Vec::new());
        match result {
            Ok(outcome) => Ok((
                outcome.status.name().into(),
                PyArray1::from_vec(py, outcome.z),
                PyArray1::from_vec(py, outcome.mu),
                outcome.iterations,
                None,
            )),
            Err(Failure::Interrupted) => Err(self
                .pending
                .borrow_mut()
                .take()
                .unwrap_or_else(|| PyValueError::new_err("the solver core was stopped without a reason"))),
            Err(Failure::NotFactored) => Ok(("not_factored".into(), empty(), empty(), 0, None)),
            Err(Failure::ObstacleNotFinite {
                obstacle,
                row,
                at_start,
            }) => Ok((
                "obstacle_not_finite".into(),
                empty(),
                empty(),
                0,
                Some((obstacle, row, at_start)),
            )),
        }
    }

    /// The second-order test at `(z, mu)` (solver units): `("minimum", nan, [])`, `("direction",
    /// curvature, unit vector over the free coordinates)` or `("undecided", nan, [])`.
    /// `total_length`: the whole chain's length in solver units.
    fn escape<'py>(
        &mut self,
        py: Python<'py>,
        z: Floats<'_>,
        mu: Floats<'_>,
        tol: f64,
        total_length: f64,
    ) -> PyResult<(String, f64, Vector<'py>)> {
        let z = floats(&z, "z")?;
        let mu = floats(&mu, "mu")?;
        let point = self.point(&z, &mu)?;
        Ok(match escape_test(&self.inner, &point, &mu, tol, total_length) {
            Verdict::Minimum => ("minimum".into(), f64::NAN, PyArray1::from_vec(py, Vec::new())),
            Verdict::Undecided => ("undecided".into(), f64::NAN, PyArray1::from_vec(py, Vec::new())),
            Verdict::Direction(value, vector) => ("direction".into(), value, PyArray1::from_vec(py, vector)),
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
        let mut matrix = BlockTridiagonal::new(self.inner.n_free(), self.inner.dim);
        self.inner
            .newton_matrix(&point, &mu, &floats(&sigma, "sigma")?, &mut matrix);
        Ok(PyArray1::from_vec(py, matrix.to_dense()))
    }

    /// What the iterations on this network spent: counts (interior-point steps, polish steps,
    /// evaluations, factorizations) and seconds (evaluation, the Newton systems, the polish's KKT
    /// systems, the iteration altogether).
    #[getter]
    fn statistics(&self) -> std::collections::HashMap<&'static str, f64> {
        let s = &self.inner.statistics;
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

    /// Free nodes, links, constraint rows.
    #[getter]
    fn n_constraints(&self) -> usize {
        self.inner.n_constraints()
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
    module.add_function(wrap_pyfunction!(penalty_and_shift, module)?)?;
    module.add_function(wrap_pyfunction!(zero_curvature, module)?)?;
    module.add("SMOOTH_RATIO", SMOOTH_RATIO)?;
    module.add("PROXIMAL", funicular_core::polish::PROXIMAL)?;
    module.add("CURVATURE_PENALTY", funicular_core::curvature::PENALTY)?;
    Ok(())
}
