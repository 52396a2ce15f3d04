//! Constructors: typed extraction of Python arguments into a `granflow::scene::SceneSpec`,
//! then `granflow::scene::build` (the one place engines are composed). Defaults and
//! validation of contact laws live in `granflow::contact::LawSpec`; errors map to Python in
//! `errors`.

use crate::convert::{law_dict, parse_law, particles, vec3_rows};
use crate::errors::{param_err, IntoPy};
use crate::sim::Sim;
use granflow::components::Plane;
use granflow::contact::{Form, Hertz, LawInput, LawSpec};
use granflow::scene::{build, DomainSpec, FormKind, SceneSpec};
use granflow::V3;
use numpy::{PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(box_sim, m)?)?;
    m.add_function(wrap_pyfunction!(insert_spheres, m)?)?;
    m.add_function(wrap_pyfunction!(diameters_for_volume, m)?)?;
    m.add_function(wrap_pyfunction!(hertz_zeta, m)?)?;
    m.add_function(wrap_pyfunction!(contact_time, m)?)?;
    m.add_function(wrap_pyfunction!(cell_sim, m)?)?;
    m.add_function(wrap_pyfunction!(resolve_law, m)?)?;
    Ok(())
}

/// The kernel's resolution of a contact-law dict: every field filled with its default
/// (kn 1e6, kt 2/7 kn, e_n 0.82 unless xi_n is given, xi_t_ratio 1/2, mu 0.5) and validated;
/// an invalid law raises ParameterError.
#[pyfunction]
fn resolve_law<'py>(py: Python<'py>, law: &Bound<'py, PyDict>) -> PyResult<Bound<'py, PyDict>> {
    law_dict(py, &parse_law(law, "")?)
}

/// Build a simulation in an orthogonal box (periodic flag per axis), with optional planar walls
/// and gravity. `form`: "hooke" or "hertz". Friction (tangential history) is compiled in only
/// when mu > 0 for the particles or the walls. `dt`, `skin`: None gives the kernel's default
/// (dt from the contact time, skin `DEFAULT_SKIN`).
#[pyfunction]
#[pyo3(signature = (x, diameter, density, lo, length, periodic, form, law, walls=None, wall_law=None, gravity=None, dt=None, skin=None, v=None, omega=None))]
#[allow(
    clippy::too_many_arguments,
    reason = "the Python signature of box_sim, keyword arguments with defaults"
)]
fn box_sim(
    x: PyReadonlyArray2<'_, f64>,
    diameter: PyReadonlyArray1<'_, f64>,
    density: f64,
    lo: [f64; 3],
    length: [f64; 3],
    periodic: [bool; 3],
    form: &str,
    law: &Bound<'_, PyDict>,
    walls: Option<Vec<(usize, f64, f64)>>,
    wall_law: Option<&Bound<'_, PyDict>>,
    gravity: Option<[f64; 3]>,
    dt: Option<f64>,
    skin: Option<f64>,
    v: Option<PyReadonlyArray2<'_, f64>>,
    omega: Option<PyReadonlyArray2<'_, f64>>,
) -> PyResult<Sim> {
    let mut p = particles(&x, &diameter, density)?;
    let n = p.len();
    if let Some(v) = v {
        p.v = vec3_rows(&v, "velocities", Some(n))?;
    }
    if let Some(w) = omega {
        p.omega = vec3_rows(&w, "angular_velocities", Some(n))?;
    }
    let domain = DomainSpec::Box {
        lo: V3::from(lo),
        length: V3::from(length),
        periodic,
    };
    let mut spec = SceneSpec::new(p, parse_law(law, "")?, domain);
    spec.wall_law = wall_law.map(|w| parse_law(w, "wall_")).transpose()?;
    spec.walls = walls
        .unwrap_or_default()
        .into_iter()
        .map(|(axis, pos, sign)| Plane { axis, pos, sign })
        .collect();
    spec.form = FormKind::parse(form).py_err()?;
    spec.gravity = gravity.map(V3::from);
    spec.dt = dt;
    if let Some(skin) = skin {
        spec.skin = skin;
    }
    Sim::new(build(spec).py_err()?, "box")
}

/// Random non-overlapping insertion; returns an (N, 3) array.
#[pyfunction]
#[pyo3(signature = (diameter, lo, hi, periodic, seed, max_attempts=10000))]
fn insert_spheres<'py>(
    py: Python<'py>,
    diameter: PyReadonlyArray1<'_, f64>,
    lo: [f64; 3],
    hi: [f64; 3],
    periodic: [bool; 3],
    seed: u64,
    max_attempts: usize,
) -> PyResult<Bound<'py, numpy::PyArray2<f64>>> {
    let d = diameter.as_array().to_vec();
    if d.is_empty() {
        return Err(param_err("diameter", "[]", "at least one particle"));
    }
    for (i, x) in d.iter().enumerate() {
        if !(x.is_finite() && *x > 0.0) {
            return Err(param_err(
                &format!("diameter[{i}]"),
                x,
                "a finite number > 0",
            ));
        }
    }
    let pos = py
        .detach(|| {
            granflow::insert::insert(&d, V3::from(lo), V3::from(hi), periodic, seed, max_attempts)
        })
        .py_err()?;
    let flat: Vec<f64> = pos.iter().flat_map(|v| [v.x, v.y, v.z]).collect();
    numpy::PyArray1::from_vec(py, flat).reshape([pos.len(), 3])
}

/// Diameters for a solid volume from a size distribution:
/// kind "mono" (params [d]), "discrete" (params [d1, f1, d2, f2, ...]), "uniform" ([lo, hi]).
#[pyfunction]
fn diameters_for_volume(
    kind: &str,
    params: Vec<f64>,
    volume: f64,
    seed: u64,
) -> PyResult<Vec<f64>> {
    use granflow::insert::SizeDist;
    let dist = match kind {
        "mono" if params.len() == 1 => SizeDist::Mono(params[0]),
        "discrete" if params.len() >= 2 && params.len().is_multiple_of(2) => {
            SizeDist::Discrete(params.chunks(2).map(|c| (c[0], c[1])).collect())
        }
        "uniform" if params.len() == 2 => SizeDist::Uniform(params[0], params[1]),
        _ => {
            return Err(param_err(
                "sizes",
                format!("{kind} {params:?}"),
                "mono [d] | discrete [d1, f1, ...] | uniform [lo, hi]",
            ))
        }
    };
    dist.validate().py_err()?;
    granflow::error::check_positive("volume", volume).py_err()?;
    let mut rng = granflow::rng::Rng::new(seed);
    Ok(dist.diameters_for_volume(volume, &mut rng))
}

/// Dimensionless damping of the Hertz–Tsuji law for a restitution e_n (for documentation/tests).
#[pyfunction]
fn hertz_zeta(e_n: f64) -> PyResult<f64> {
    // e_n checked as the law checks it
    let input = LawInput {
        e_n: Some(e_n),
        ..LawInput::default()
    };
    LawSpec::resolve(&input, "").py_err()?;
    Ok(<Hertz as Form>::zeta(e_n))
}

/// Contact duration t_c of the linear law (as dict) for a pair of effective mass `m_eff`, the
/// time the default dt is derived from; an over-damped law raises ParameterError.
#[pyfunction]
fn contact_time(law: &Bound<'_, PyDict>, m_eff: f64) -> PyResult<f64> {
    let p = parse_law(law, "")?;
    granflow::error::check_positive("m_eff", m_eff).py_err()?;
    p.contact_time(m_eff).py_err()
}

/// The stress-controlled triclinic cell of 002: particles in a cubic periodic cell of side
/// `length`, imposed p_ext and tau_ext (xy), cell mass `wg`. No walls, no gravity. `dt`,
/// `skin`: None gives the kernel's default (as `box_sim`).
#[pyfunction]
#[pyo3(signature = (x, diameter, density, length, form, law, p_ext, tau_ext, wg, dt=None, skin=None))]
#[allow(
    clippy::too_many_arguments,
    reason = "the Python signature of cell_sim, keyword arguments with defaults"
)]
fn cell_sim(
    x: PyReadonlyArray2<'_, f64>,
    diameter: PyReadonlyArray1<'_, f64>,
    density: f64,
    length: f64,
    form: &str,
    law: &Bound<'_, PyDict>,
    p_ext: f64,
    tau_ext: f64,
    wg: f64,
    dt: Option<f64>,
    skin: Option<f64>,
) -> PyResult<Sim> {
    let p = particles(&x, &diameter, density)?;
    let domain = DomainSpec::Cell {
        length,
        p_ext,
        tau_ext,
        wg,
    };
    let mut spec = SceneSpec::new(p, parse_law(law, "")?, domain);
    spec.form = FormKind::parse(form).py_err()?;
    spec.dt = dt;
    if let Some(skin) = skin {
        spec.skin = skin;
    }
    Sim::new(build(spec).py_err()?, "cell")
}
