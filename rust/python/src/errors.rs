//! The core's errors as Python exception classes, all under `CoreError`: each names what it is about
//! in attributes (nodes, lengths, an obstacle), which the package turns into its own errors in one
//! place (`funicular._solver.core_problem.package_error`). An exception a Python function raised inside the
//! core (an obstacle's evaluation, Ctrl-C) comes out as it was.

use std::cell::RefCell;
use std::rc::Rc;

use funicular_core::driver::SolveError;
use funicular_core::presolve::Infeasible;
use pyo3::exceptions::{PyBaseException, PyException};
use pyo3::prelude::*;
use pyo3::PyTypeInfo;

pyo3::create_exception!(
    funicular._core,
    CoreError,
    PyException,
    "Why the solver core has no answer."
);
pyo3::create_exception!(
    funicular._core,
    SupportsTooFar,
    CoreError,
    "The supports at nodes `a` and `b` are `distance` apart with only `length` of chain between them."
);
pyo3::create_exception!(
    funicular._core,
    TautNotVertical,
    CoreError,
    "The chain between the supports at nodes `a` and `b` is exactly taut, not vertical, and carries weight."
);
pyo3::create_exception!(
    funicular._core,
    NotFactored,
    CoreError,
    "The Newton matrix stayed indefinite under every inertia correction."
);
pyo3::create_exception!(
    funicular._core,
    ObstacleNotFinite,
    CoreError,
    "Obstacle `obstacle`'s phi or derivatives are not finite at node (or link) `index` of the start (`at_start`) or of the result."
);
pyo3::create_exception!(
    funicular._core,
    InternalError,
    CoreError,
    "The core stopped on an error of its own (a bug): `message` says where."
);

/// Where a Python function's exception waits while the core unwinds.
pub type Pending = Rc<RefCell<Option<PyErr>>>;

/// An exception of type `E` with `message`, its attributes set by `set`.
fn raised<E: PyTypeInfo>(
    py: Python<'_>,
    message: String,
    set: impl FnOnce(&Bound<'_, PyBaseException>) -> PyResult<()>,
) -> PyErr {
    let error = PyErr::new::<E, _>(message);
    match set(error.value(py)) {
        Ok(()) => error,
        Err(failed) => failed,
    }
}

/// An `InternalError` with `message`.
fn internal(py: Python<'_>, message: String) -> PyErr {
    raised::<InternalError>(py, message.clone(), |error| error.setattr("message", message))
}

/// The exception a Python function left in `pending`, or the core's error as its exception class.
pub fn core_error(py: Python<'_>, pending: &Pending, error: SolveError) -> PyErr {
    match error {
        SolveError::Interrupted | SolveError::Infeasible(Infeasible::Interrupted) => pending
            .borrow_mut()
            .take()
            .unwrap_or_else(|| internal(py, "the solver core was stopped without a reason".into())),
        SolveError::Infeasible(Infeasible::TooFar {
            a,
            b,
            distance,
            length,
        }) => raised::<SupportsTooFar>(
            py,
            format!("supports at nodes {a} and {b} are {distance} apart with {length} of chain between them"),
            |error| {
                error.setattr("a", a)?;
                error.setattr("b", b)?;
                error.setattr("distance", distance)?;
                error.setattr("length", length)
            },
        ),
        SolveError::Infeasible(Infeasible::TautNotVertical { a, b }) => raised::<TautNotVertical>(
            py,
            format!("the chain between the supports at nodes {a} and {b} is taut, not vertical, and carries weight"),
            |error| {
                error.setattr("a", a)?;
                error.setattr("b", b)
            },
        ),
        SolveError::NotFactored => NotFactored::new_err("the Newton matrix stayed indefinite under every inertia correction"),
        SolveError::ObstacleNotFinite {
            obstacle,
            index,
            at_start,
        } => raised::<ObstacleNotFinite>(
            py,
            format!("obstacle {obstacle}'s phi is not finite at row {index}"),
            |error| {
                error.setattr("obstacle", obstacle)?;
                error.setattr("index", index)?;
                error.setattr("at_start", at_start)
            },
        ),
    }
}

/// `solve()`, or an `InternalError` naming the panic if the core panics (a bug): the caller turns
/// it into the package's error instead of the interpreter's panic.
pub fn guarded<T>(py: Python<'_>, solve: impl FnOnce() -> T) -> PyResult<T> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(solve)).map_err(|panic| {
        let message = panic
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| panic.downcast_ref::<&str>().copied())
            .unwrap_or("no message")
            .trim()
            .to_string();
        internal(py, message)
    })
}

/// The exception classes, added to the module.
pub fn add_to(module: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = module.py();
    module.add("CoreError", py.get_type::<CoreError>())?;
    module.add("SupportsTooFar", py.get_type::<SupportsTooFar>())?;
    module.add("TautNotVertical", py.get_type::<TautNotVertical>())?;
    module.add("NotFactored", py.get_type::<NotFactored>())?;
    module.add("ObstacleNotFinite", py.get_type::<ObstacleNotFinite>())?;
    module.add("InternalError", py.get_type::<InternalError>())?;
    Ok(())
}
