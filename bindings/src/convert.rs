//! Conversions of Python arguments into kernel values (contact-law dicts, (N, 3) arrays,
//! particles) and back (a resolved law as a dict). A leaf of the bindings: `build` and `sim`
//! both use it and it uses neither (only `errors`), so the bindings' modules depend one way:
//! `build` -> `sim` -> {`convert`, `arrow`} -> `errors`.

use crate::errors::{param_err, IntoPy};
use granflow::contact::{LawInput, LawSpec};
use granflow::particles::Particles;
use granflow::V3;
use numpy::{PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;

fn get_f64(d: &Bound<'_, PyDict>, key: &str, prefix: &str) -> PyResult<Option<f64>> {
    match d.get_item(key)? {
        None => Ok(None),
        Some(v) if v.is_none() => Ok(None),
        Some(v) => v
            .extract::<f64>()
            .map(Some)
            .map_err(|_| param_err(&format!("{prefix}{key}"), v.to_string(), "a number")),
    }
}

/// The fields of a contact-law dict (kn, kt, e_n, xi_n, xi_t_ratio, mu; missing or None: the
/// kernel's default), unknown keys refused.
fn law_input(d: &Bound<'_, PyDict>, prefix: &str) -> PyResult<LawInput> {
    const ALLOWED: [&str; 6] = ["kn", "kt", "e_n", "xi_n", "xi_t_ratio", "mu"];
    for k in d.keys() {
        let k: String = k.extract()?;
        if !ALLOWED.contains(&k.as_str()) {
            return Err(param_err(
                &format!("{prefix}{k}"),
                "(unknown key)",
                &format!("one of {ALLOWED:?}"),
            ));
        }
    }
    let f = |k: &str| get_f64(d, k, prefix);
    Ok(LawInput {
        kn: f("kn")?,
        kt: f("kt")?,
        e_n: f("e_n")?,
        xi_n: f("xi_n")?,
        xi_t_ratio: f("xi_t_ratio")?,
        mu: f("mu")?,
    })
}

/// Parse a contact-law dict into a resolved, validated law (`LawSpec::resolve`).
pub fn parse_law(d: &Bound<'_, PyDict>, prefix: &str) -> PyResult<LawSpec> {
    LawSpec::resolve(&law_input(d, prefix)?, prefix).py_err()
}

/// A resolved law as a dict: kn, kt, e_n or xi_n, xi_t_ratio, mu.
pub fn law_dict<'py>(py: Python<'py>, law: &LawSpec) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (k, v) in law.entries() {
        d.set_item(k, v)?;
    }
    Ok(d)
}

pub fn vec3_rows(a: &PyReadonlyArray2<'_, f64>, name: &str, n: Option<usize>) -> PyResult<Vec<V3>> {
    let a = a.as_array();
    if a.ncols() != 3 || n.is_some_and(|n| a.nrows() != n) {
        return Err(param_err(
            name,
            format!("shape {:?}", a.shape()),
            "an (N, 3) array with one row per particle",
        ));
    }
    Ok(a.rows()
        .into_iter()
        .map(|r| V3::new(r[0], r[1], r[2]))
        .collect())
}

pub fn particles(
    x: &PyReadonlyArray2<'_, f64>,
    diameter: &PyReadonlyArray1<'_, f64>,
    density: f64,
) -> PyResult<Particles> {
    let xs = vec3_rows(x, "positions", None)?;
    let d = diameter.as_array().to_vec();
    Particles::new(xs, &d, density).py_err()
}
