//! The one place where kernel errors become Python exceptions.

use granflow::Error;
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyKeyboardInterrupt};
use pyo3::prelude::*;

create_exception!(
    granflow,
    GranflowError,
    PyException,
    "Base class of granflow errors."
);
create_exception!(
    granflow,
    ParameterError,
    GranflowError,
    "A parameter is outside its allowed range; the message names it and the range."
);
create_exception!(
    granflow,
    ConfigurationError,
    GranflowError,
    "The particle configuration cannot be used (e.g. overlaps beyond the allowed fraction)."
);
create_exception!(
    granflow,
    InstabilityError,
    GranflowError,
    "The integration became unstable; the message gives the step, particles and likely cause."
);
create_exception!(
    granflow,
    GranflowIOError,
    GranflowError,
    "Reading or writing failed."
);

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("GranflowError", py.get_type::<GranflowError>())?;
    m.add("ParameterError", py.get_type::<ParameterError>())?;
    m.add("ConfigurationError", py.get_type::<ConfigurationError>())?;
    m.add("InstabilityError", py.get_type::<InstabilityError>())?;
    m.add("GranflowIOError", py.get_type::<GranflowIOError>())?;
    Ok(())
}

/// Map a kernel error onto its Python exception.
pub fn to_py(e: Error) -> PyErr {
    let msg = e.to_string();
    match e {
        Error::Parameter { .. } => ParameterError::new_err(msg),
        Error::Configuration { .. } => ConfigurationError::new_err(msg),
        Error::Instability { .. } => InstabilityError::new_err(msg),
        Error::Interrupted { .. } => PyKeyboardInterrupt::new_err(msg),
        Error::Io { .. } => GranflowIOError::new_err(msg),
    }
}

pub trait IntoPy<T> {
    fn py_err(self) -> PyResult<T>;
}
impl<T> IntoPy<T> for Result<T, Error> {
    fn py_err(self) -> PyResult<T> {
        self.map_err(to_py)
    }
}

pub fn param_err(name: &str, value: impl std::fmt::Display, allowed: &str) -> PyErr {
    to_py(Error::param(name, value, allowed))
}
