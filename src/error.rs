//! One error type for the crate. Every variant carries what a user needs to act: the parameter,
//! the value, the allowed range; or the step, the particles and the likely cause.

use std::fmt;

#[derive(Debug, Clone, PartialEq)]
pub enum Error {
    /// A user-supplied value is outside its allowed range.
    Parameter {
        name: String,
        value: String,
        allowed: String,
        hint: String,
    },
    /// The initial or current configuration is unusable (e.g. overlaps beyond the allowed fraction).
    Configuration { message: String },
    /// The integration became unstable: NaN/inf, runaway overlap, energy growth without a source.
    Instability {
        step: u64,
        particles: Vec<usize>,
        message: String,
        cause: String,
    },
    /// The run was interrupted (Ctrl-C) between steps; the state is consistent.
    Interrupted { step: u64 },
    /// Reading or writing a file failed.
    Io { message: String },
}

pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    pub fn param(
        name: impl Into<String>,
        value: impl fmt::Display,
        allowed: impl Into<String>,
    ) -> Self {
        Error::Parameter {
            name: name.into(),
            value: value.to_string(),
            allowed: allowed.into(),
            hint: String::new(),
        }
    }
    pub fn with_hint(self, h: impl Into<String>) -> Self {
        match self {
            Error::Parameter {
                name,
                value,
                allowed,
                ..
            } => Error::Parameter {
                name,
                value,
                allowed,
                hint: h.into(),
            },
            other => other,
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Parameter {
                name,
                value,
                allowed,
                hint,
            } => {
                write!(f, "invalid {name} = {value}: allowed {allowed}")?;
                if !hint.is_empty() {
                    write!(f, " ({hint})")?;
                }
                Ok(())
            }
            Error::Configuration { message } => write!(f, "{message}"),
            Error::Instability {
                step,
                particles,
                message,
                cause,
            } => {
                let shown: Vec<String> = particles.iter().take(8).map(|p| p.to_string()).collect();
                write!(
                    f,
                    "instability at step {step}: {message}; particles [{}]; likely cause: {cause}",
                    shown.join(", ")
                )
            }
            Error::Interrupted { step } => write!(f, "interrupted at step {step}"),
            Error::Io { message } => write!(f, "{message}"),
        }
    }
}

impl std::error::Error for Error {}

impl From<std::io::Error> for Error {
    fn from(e: std::io::Error) -> Self {
        Error::Io {
            message: e.to_string(),
        }
    }
}

/// Check `lo < value` (or `<=`) and finiteness, naming the parameter.
pub fn check_positive(name: &str, v: f64) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(Error::param(name, v, "a finite number > 0"))
    }
}

pub fn check_range(name: &str, v: f64, lo: f64, hi: f64, allowed: &str) -> Result<()> {
    if v.is_finite() && v >= lo && v <= hi {
        Ok(())
    } else {
        Err(Error::param(name, v, allowed))
    }
}
