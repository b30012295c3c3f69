//! The Python module `funicular._core`: a thin front end to the solver core, with a typed
//! boundary: classes with named fields for what crosses it ([`types`]), exception classes for the
//! core's errors ([`errors`]), keyword-only arguments without defaults (the package's front end,
//! `funicular._solver`, holds them).
//!
//! `Chain` and `Net` hold a problem in the problem's units (built by `funicular._solver.core_problem` from
//! a `Problem`); `solve` runs the whole solve, `presolve`, `exact_start` and `hanging_start` its
//! first parts. `Network` is a problem in the solver's units, for tests of the iteration's
//! derivatives. Obstacles that are not built-in shapes are evaluated by a Python function called
//! once per evaluation with every point at once ([`fields`]).

mod errors;
mod fields;
mod json;
mod problems;
mod types;

use numpy::{PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::types::{Floats, SecondOrderBound};

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
) -> SecondOrderBound {
    let (rho, shift) = funicular_core::curvature::penalty_and_shift(
        stiffest,
        stiffness,
        degree,
        n_obstacles,
        threshold,
        penalty,
    );
    SecondOrderBound { rho, shift }
}

/// The curvature below which an eigenvalue counts as zero: one that changes the energy by less than
/// `tol * weight * total_length` when every node moves by the chain's length.
#[pyfunction]
fn zero_curvature(tol: f64, weight: f64, n_nodes: usize, total_length: f64) -> f64 {
    funicular_core::curvature::zero_curvature(tol, weight, n_nodes, total_length)
}

/// Keeps the memory a solve frees for the next one: blocks up to MALLOC_KEPT_BLOCK bytes come from
/// the heap (not fresh pages of their own), which is trimmed only once MALLOC_TRIM bytes at its top
/// are free. A large solve frees several hundred MB of work arrays at its end; faulted in afresh,
/// they would cost the next solve of a sweep a third of its time (10^6 nodes: 0.57 s instead of
/// 0.40 s), and huge pages (which make faults cheap) cost the first solve a compaction of memory.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn keep_freed_memory() {
    const MALLOC_KEPT_BLOCK: libc::c_int = 32 << 20; // (glibc's largest)
    const MALLOC_TRIM: libc::c_int = 1 << 30;
    // SAFETY: mallopt only sets two of glibc's malloc parameters (it takes malloc's own lock); no
    // memory is touched, and an unaccepted value leaves the parameter as it was.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, MALLOC_KEPT_BLOCK);
        libc::mallopt(libc::M_TRIM_THRESHOLD, MALLOC_TRIM);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn keep_freed_memory() {}

#[pymodule]
fn _core(module: &Bound<'_, PyModule>) -> PyResult<()> {
    keep_freed_memory();
    module.add_class::<types::Settings>()?;
    module.add_class::<types::Start>()?;
    module.add_class::<types::Shape>()?;
    module.add_class::<types::Obstacles>()?;
    module.add_class::<types::Quadratics>()?;
    module.add_class::<types::NodeFields>()?;
    module.add_class::<types::SegmentFields>()?;
    module.add_class::<types::Presolved>()?;
    module.add_class::<types::Hanging>()?;
    module.add_class::<types::Curvature>()?;
    module.add_class::<types::Solved>()?;
    module.add_class::<types::Evaluated>()?;
    module.add_class::<types::SecondOrderBound>()?;
    module.add_class::<problems::Chain>()?;
    module.add_class::<problems::Net>()?;
    module.add_class::<problems::Network>()?;
    errors::add_to(module)?;
    module.add_function(wrap_pyfunction!(penalty_and_shift, module)?)?;
    module.add_function(wrap_pyfunction!(problems::hanging_span, module)?)?;
    module.add_function(wrap_pyfunction!(fields::evaluate_shapes, module)?)?;
    module.add_function(wrap_pyfunction!(zero_curvature, module)?)?;
    module.add_function(wrap_pyfunction!(gram_positive_definite, module)?)?;
    module.add_function(wrap_pyfunction!(blocks_positive_definite, module)?)?;
    module.add_function(wrap_pyfunction!(json::read_json, module)?)?;
    module.add("SMOOTH_RATIO", funicular_core::problem::SMOOTH_RATIO)?;
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
        funicular_core::linalg::blocks_positive_definite(d, node_blocks, &pairs, pair_blocks, shift)
    }))
}
