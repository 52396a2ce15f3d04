//! Constructors: parse Python parameters, then pick the compile-time composition
//! (form x friction x walls x gravity) once. Validation errors name the parameter.

use crate::errors::{param_err, IntoPy};
use crate::sim::Sim;
use granflow::components::{Body, Gravity, NoBody, NoWalls, Plane, PlaneWalls, Walls};
use granflow::contact::{Coulomb, Damping, Form, Friction, Frictionless, Hertz, Hooke, LawParams};
use granflow::domain::OrthoBox;
use granflow::engine::Engine;
use granflow::particles::Particles;
use granflow::sim::Simulation;
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
    Ok(())
}

fn get_f64(d: &Bound<'_, PyDict>, key: &str) -> PyResult<Option<f64>> {
    match d.get_item(key)? {
        None => Ok(None),
        Some(v) if v.is_none() => Ok(None),
        Some(v) => v
            .extract::<f64>()
            .map(Some)
            .map_err(|_| param_err(key, v.to_string(), "a number")),
    }
}

/// Parse a contact-law dict: kn, kt (default 2/7 kn), e_n or xi_n, xi_t_ratio (default 1/2), mu.
pub fn parse_law(d: &Bound<'_, PyDict>, prefix: &str) -> PyResult<LawParams> {
    let allowed = ["kn", "kt", "e_n", "xi_n", "xi_t_ratio", "mu"];
    for k in d.keys() {
        let k: String = k.extract()?;
        if !allowed.contains(&k.as_str()) {
            return Err(param_err(
                &format!("{prefix}{k}"),
                "(unknown key)",
                &format!("one of {allowed:?}"),
            ));
        }
    }
    let kn =
        get_f64(d, "kn")?.ok_or_else(|| param_err(&format!("{prefix}kn"), "missing", "> 0"))?;
    let mu = get_f64(d, "mu")?.unwrap_or(0.0);
    let damping = match (get_f64(d, "e_n")?, get_f64(d, "xi_n")?) {
        (Some(e), None) => Damping::Restitution(e),
        (None, Some(x)) => Damping::Rate(x),
        (None, None) => Damping::Restitution(1.0),
        (Some(_), Some(_)) => {
            return Err(param_err(
                &format!("{prefix}e_n/xi_n"),
                "both given",
                "exactly one of e_n (restitution) or xi_n (damping rate)",
            ))
        }
    };
    let p = LawParams {
        kn,
        kt: get_f64(d, "kt")?.unwrap_or(2.0 / 7.0 * kn),
        damping,
        xi_t_ratio: get_f64(d, "xi_t_ratio")?.unwrap_or(0.5),
        mu,
    };
    p.validate(prefix).py_err()?;
    Ok(p)
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

#[allow(clippy::too_many_arguments)]
fn finish<F: Form, T: Friction, W: Walls<F, T>, G: Body>(
    p: Particles,
    law: LawParams,
    dom: OrthoBox,
    walls: W,
    g: G,
    dt: Option<f64>,
    skin: f64,
) -> PyResult<Box<dyn Simulation>> {
    let e: Engine<F, T, OrthoBox, W, G> = Engine::new(p, law, dom, walls, g, dt, skin).py_err()?;
    Ok(Box::new(e))
}

#[allow(clippy::too_many_arguments)]
fn with_walls<F: Form, T: Friction>(
    p: Particles,
    law: LawParams,
    dom: OrthoBox,
    planes: Vec<Plane>,
    wall_law: LawParams,
    gravity: Option<V3>,
    dt: Option<f64>,
    skin: f64,
) -> PyResult<Box<dyn Simulation>> {
    match (planes.is_empty(), gravity) {
        (true, None) => finish::<F, T, NoWalls, NoBody>(p, law, dom, NoWalls, NoBody, dt, skin),
        (true, Some(g)) => {
            finish::<F, T, NoWalls, Gravity>(p, law, dom, NoWalls, Gravity(g), dt, skin)
        }
        (false, g) => {
            let w = PlaneWalls::<F, T>::new(planes, wall_law).py_err()?;
            match g {
                None => finish::<F, T, _, NoBody>(p, law, dom, w, NoBody, dt, skin),
                Some(g) => finish::<F, T, _, Gravity>(p, law, dom, w, Gravity(g), dt, skin),
            }
        }
    }
}

/// Build a simulation in an orthogonal box (periodic flag per axis), with optional planar walls
/// and gravity. `form`: "hooke" or "hertz". Friction (tangential history) is compiled in only
/// when mu > 0 for the particles or the walls.
#[pyfunction]
#[pyo3(signature = (x, diameter, density, lo, length, periodic, form, law, walls=None, wall_law=None, gravity=None, dt=None, skin=0.3, v=None, omega=None))]
#[allow(clippy::too_many_arguments)]
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
    skin: f64,
    v: Option<PyReadonlyArray2<'_, f64>>,
    omega: Option<PyReadonlyArray2<'_, f64>>,
) -> PyResult<Sim> {
    let xs = vec3_rows(&x, "positions", None)?;
    let n = xs.len();
    let d = diameter.as_array().to_vec();
    let mut p = Particles::new(xs, &d, density).py_err()?;
    if let Some(v) = v {
        p.v = vec3_rows(&v, "velocities", Some(n))?;
    }
    if let Some(w) = omega {
        p.omega = vec3_rows(&w, "angular_velocities", Some(n))?;
    }
    let law = parse_law(law, "")?;
    let wall_law = match wall_law {
        Some(w) => parse_law(w, "wall_")?,
        None => law,
    };
    let dom = OrthoBox::new(V3::from(lo), V3::from(length), periodic).py_err()?;
    let mut planes = Vec::new();
    for (axis, pos, sign) in walls.unwrap_or_default() {
        if axis > 2 || !(sign == 1.0 || sign == -1.0) || !pos.is_finite() {
            return Err(param_err(
                "walls",
                format!("({axis}, {pos}, {sign})"),
                "(axis 0..2, position, sign +1 or -1)",
            ));
        }
        if periodic[axis] {
            return Err(param_err(
                "walls",
                format!("a wall on periodic axis {axis}"),
                "walls only on non-periodic axes",
            ));
        }
        planes.push(Plane { axis, pos, sign });
    }
    let g = gravity.map(V3::from);
    let frictional = law.mu > 0.0 || (!planes.is_empty() && wall_law.mu > 0.0);
    let inner = match (form, frictional) {
        ("hooke", true) => {
            with_walls::<Hooke, Coulomb>(p, law, dom, planes, wall_law, g, dt, skin)?
        }
        ("hooke", false) => {
            with_walls::<Hooke, Frictionless>(p, law, dom, planes, wall_law, g, dt, skin)?
        }
        ("hertz", true) => {
            with_walls::<Hertz, Coulomb>(p, law, dom, planes, wall_law, g, dt, skin)?
        }
        ("hertz", false) => {
            with_walls::<Hertz, Frictionless>(p, law, dom, planes, wall_law, g, dt, skin)?
        }
        _ => return Err(param_err("form", form, "'hooke' or 'hertz'")),
    };
    Sim::new(inner, "box")
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
    if !(e_n > 0.0 && e_n <= 1.0) {
        return Err(param_err("e_n", e_n, "0 < e_n <= 1"));
    }
    Ok(<Hertz as Form>::zeta(e_n))
}

/// Contact duration t_c of the linear law (as dict) for a pair of effective mass `m_eff`, the
/// time the default dt is derived from; an over-damped law raises ParameterError.
#[pyfunction]
fn contact_time(law: &Bound<'_, PyDict>, m_eff: f64) -> PyResult<f64> {
    let p = parse_law(law, "")?;
    p.validate("").py_err()?;
    granflow::error::check_positive("m_eff", m_eff).py_err()?;
    p.contact_time(m_eff).py_err()
}

fn cell_engine<F: Form, T: Friction>(
    p: Particles,
    law: LawParams,
    cell: granflow::domain::PrCell,
    dt: Option<f64>,
    skin: f64,
) -> PyResult<Box<dyn Simulation>> {
    let e: Engine<F, T, granflow::domain::PrCell, NoWalls, NoBody> =
        Engine::new(p, law, cell, NoWalls, NoBody, dt, skin).py_err()?;
    Ok(Box::new(e))
}

/// The stress-controlled triclinic cell of 002: particles in a cubic periodic cell of side
/// `length`, imposed p_ext and tau_ext (xy), cell mass `wg`. No walls, no gravity.
#[pyfunction]
#[pyo3(signature = (x, diameter, density, length, form, law, p_ext, tau_ext, wg, dt=None, skin=0.3))]
#[allow(clippy::too_many_arguments)]
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
    skin: f64,
) -> PyResult<Sim> {
    let xs = vec3_rows(&x, "positions", None)?;
    let d = diameter.as_array().to_vec();
    let p = Particles::new(xs, &d, density).py_err()?;
    let law = parse_law(law, "")?;
    let mut cell = granflow::domain::PrCell::new(length, p.len(), wg, p_ext, tau_ext).py_err()?;
    cell.d_max = 2.0 * p.max_radius();
    let inner = match (form, law.mu > 0.0) {
        ("hooke", true) => cell_engine::<Hooke, Coulomb>(p, law, cell, dt, skin)?,
        ("hooke", false) => cell_engine::<Hooke, Frictionless>(p, law, cell, dt, skin)?,
        ("hertz", true) => cell_engine::<Hertz, Coulomb>(p, law, cell, dt, skin)?,
        ("hertz", false) => cell_engine::<Hertz, Frictionless>(p, law, cell, dt, skin)?,
        _ => return Err(param_err("form", form, "'hooke' or 'hertz'")),
    };
    Sim::new(inner, "cell")
}
