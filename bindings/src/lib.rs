//! Python bindings of granflow: the only crate that knows Python.
//!
//! - `errors`: every `granflow::Error` variant maps onto one Python exception, in one place.
//! - `arrow`: sample tables leave as Arrow C data (PyCapsule interface), no per-row copies.
//! - `sim`: `Sim`, a handle on any composed engine; runs release the GIL.

use pyo3::prelude::*;

mod arrow;
mod build;
mod errors;
mod sim;

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    errors::register(m)?;
    m.add_class::<sim::Sim>()?;
    m.add_class::<arrow::ArrowBatch>()?;
    build::register(m)?;
    m.add_function(wrap_pyfunction!(sim::read_checkpoint_header, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
