//! Obstacles as the core takes them: the built-in shapes evaluated in the core, or fields evaluated
//! by a Python function called once per evaluation with every point at once.

use std::cell::RefCell;
use std::rc::Rc;

use funicular_core::problem::{
    Formulation, Interrupted, NodeField, Obstacles as CoreObstacles, Quadratics, Segments, Setup,
};
use funicular_core::shapes::{NativeField, Shape as CoreShape};
use numpy::{PyArray1, PyArrayDyn, PyArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::errors::Pending;
use crate::types::{floats, index_array, Floats, NodeFields, Obstacles, SegmentFields, Shape};

/// Copies an array a Python function returned into the core's buffer.
fn fill(array: &Py<PyArrayDyn<f64>>, py: Python<'_>, out: &mut [f64], name: &str) -> PyResult<()> {
    let array = array.bind(py).readonly();
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

/// Node contact evaluated by a Python function `function(points) -> NodeFields`.
pub struct PythonNodes {
    pub count: usize,
    pub dim: usize,
    pub function: Py<PyAny>,
    pub pending: Pending,
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
            let fields = result.cast::<NodeFields>()?.get();
            fill(&fields.phi, py, phi, "phi")?;
            fill(&fields.gradient, py, gradient, "the gradient of phi")?;
            fill(&fields.hessian, py, hessian, "the Hessian of phi")
        })
        .map_err(|error| {
            *self.pending.borrow_mut() = Some(error);
            Interrupted
        })
    }
}

/// Link contact evaluated by a Python function `function(positions, links) -> SegmentFields`, in
/// the problem's units, for the links given by their first nodes.
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
            let fields = result.cast::<SegmentFields>()?.get();
            fill(&fields.psi, py, psi, "psi")?;
            fill(&fields.t, py, t, "t")?;
            fill(&fields.gradient, py, gradient, "the gradient of phi")?;
            fill(&fields.hessian, py, hessian, "the Hessian of psi")
        })
        .map_err(|error| {
            *self.pending.borrow_mut() = Some(error);
            Interrupted
        })
    }
}

/// The built-in shapes as the core's quadratics and shapes (see [`Shape`]).
fn native_shapes(shapes: &[Shape], d: usize) -> PyResult<(Quadratics, Vec<CoreShape>)> {
    let mut quadratics = Quadratics::default();
    let mut list = Vec::with_capacity(shapes.len());
    let quadratic = 2 * d + 1 + d * d;
    for Shape { kind, parameters: p } in shapes {
        match (kind.as_str(), p.len()) {
            ("quadratic", size) if size == quadratic => {
                list.push(CoreShape::Quadratic(quadratics.values.len()));
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
                list.push(CoreShape::Box {
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

/// phi (J, n), its gradient (J, n, d) and Hessian (J, n, d, d) of the built-in `shapes` at points
/// (n, d): the one evaluation of these shapes, in Python too.
#[pyfunction]
#[pyo3(signature = (*, shapes, points, dim))]
pub fn evaluate_shapes(
    py: Python<'_>,
    shapes: Vec<Shape>,
    points: Floats<'_>,
    dim: usize,
) -> PyResult<NodeFields> {
    let points = floats(&points, "points")?;
    if !(2..=3).contains(&dim) || points.len() % dim != 0 {
        return Err(PyValueError::new_err(
            "points must be an (n, d) array with d = 2 or 3",
        ));
    }
    let (quadratics, shapes) = native_shapes(&shapes, dim)?;
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
    let dynamic = |values: Vec<f64>| PyArray1::from_vec(py, values).to_dyn().clone().unbind();
    Ok(NodeFields {
        phi: dynamic(phi),
        gradient: dynamic(gradient),
        hessian: dynamic(hessian),
    })
}

/// A problem's formulation and obstacles as the core takes them (see [`Obstacles`]).
pub fn setup(
    py: Python<'_>,
    dim: usize,
    squared: bool,
    obstacles: &Obstacles,
    pending: &Pending,
) -> PyResult<Setup> {
    // Built-in shapes are evaluated here: quadratics alone by the iteration's own fast path,
    // with a box among them as a node field; any other obstacle by the caller's field.
    let (mut quadratics, mut nodes) = (None, None::<Rc<RefCell<dyn NodeField>>>);
    let count = obstacles.count;
    match (&obstacles.shapes, &obstacles.field) {
        (Some(shapes), None) if shapes.len() == count => {
            let (stacked, list) = native_shapes(shapes, dim)?;
            if list.iter().all(|s| matches!(s, CoreShape::Quadratic(_))) {
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
                count,
                dim,
                function: function.clone_ref(py),
                pending: pending.clone(),
            })));
        }
        (None, None) if count == 0 => {}
        _ => {
            return Err(PyValueError::new_err(
                "obstacles need their built-in shapes (one per obstacle) or a field, not both",
            ))
        }
    }
    let segments = obstacles
        .links
        .as_ref()
        .map(|function| -> Rc<RefCell<dyn Segments>> {
            Rc::new(RefCell::new(PythonLinks {
                dim,
                function: function.clone_ref(py),
                pending: pending.clone(),
            }))
        });
    Ok(Setup {
        formulation: if squared {
            Formulation::Squared
        } else {
            Formulation::Norm
        },
        links_contact: segments.is_some(),
        obstacles: CoreObstacles {
            count,
            quadratics,
            nodes,
            segments,
        },
    })
}
