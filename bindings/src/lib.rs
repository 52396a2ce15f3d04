//! Python bindings of granflow: the only crate that knows Python.
//!
//! - `errors`: every `granflow::Error` variant maps onto one Python exception, in one place.
//! - `convert`: Python arguments into kernel values and back (a leaf: `build` and `sim` use it).
//! - `arrow`: sample tables leave as Arrow C data (PyCapsule interface), no per-row copies.
//! - `sim`: `Sim`, a handle on any composed engine; runs release the GIL.
//! - `build`: the constructors (`box_sim`, `cell_sim`, ...), Python arguments into a
//!   `granflow::scene::SceneSpec`.

use pyo3::prelude::*;

mod arrow;
mod build;
mod convert;
mod errors;
mod sim;

/// Mean round trip in nanoseconds of a value bounced `iters` times between two threads
/// through one cache line (`granflow::probe`), with the GIL released: benchmarks record it to
/// tell a VM's near and far placements of its cores apart.
#[pyfunction]
#[pyo3(signature = (iters = 200_000))]
fn core_round_trip_ns(py: Python<'_>, iters: i64) -> PyResult<f64> {
    if !(2..=1_000_000_000).contains(&iters) {
        return Err(errors::param_err("iters", iters, "2 <= iters <= 1e9"));
    }
    Ok(py.detach(|| granflow::probe::core_round_trip_ns(iters as u64)))
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    errors::register(m)?;
    m.add_class::<sim::Sim>()?;
    m.add_class::<arrow::ArrowBatch>()?;
    build::register(m)?;
    m.add_function(wrap_pyfunction!(sim::read_checkpoint_header, m)?)?;
    m.add_function(wrap_pyfunction!(core_round_trip_ns, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    // the kernel's default neighbour-list skin (what `skin=None` gives), for Python to read
    m.add("DEFAULT_SKIN", granflow::scene::DEFAULT_SKIN)?;
    Ok(())
}
