//! `Sim`: a Python handle on any composed engine.

use crate::arrow::ArrowBatch;
use crate::errors::{param_err, IntoPy};
use granflow::sim::Simulation;
use granflow::V3;
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;

#[pyclass(module = "granflow._core")]
pub struct Sim {
    pub inner: Box<dyn Simulation>,
    pool: rayon::ThreadPool,
    threads: usize,
    pub scene: String,
}

fn make_pool(n: usize) -> PyResult<rayon::ThreadPool> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .build()
        .map_err(|e| param_err("threads", n, &format!("a buildable thread count ({e})")))
}

pub fn default_threads() -> usize {
    std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
}

impl Sim {
    pub fn new(inner: Box<dyn Simulation>, scene: &str) -> PyResult<Self> {
        let threads = default_threads();
        Ok(Sim {
            inner,
            pool: make_pool(threads)?,
            threads,
            scene: scene.to_string(),
        })
    }

    /// Per-particle vectors in id order (the kernel re-orders particles for locality).
    fn by_id<'py>(&self, py: Python<'py>, f: impl Fn(usize) -> V3) -> Bound<'py, PyArray2<f64>> {
        let p = self.inner.particles();
        let n = p.len();
        let mut out = vec![0.0; 3 * n];
        for i in 0..n {
            let k = p.id[i] as usize;
            let v = f(i);
            out[3 * k] = v.x;
            out[3 * k + 1] = v.y;
            out[3 * k + 2] = v.z;
        }
        PyArray1::from_vec(py, out).reshape([n, 3]).unwrap()
    }

    fn set_by_id(
        &mut self,
        name: &str,
        arr: PyReadonlyArray2<'_, f64>,
        set: impl Fn(&mut granflow::particles::Particles, usize, V3),
    ) -> PyResult<()> {
        let a = arr.as_array();
        let n = self.inner.particles().len();
        if a.shape() != [n, 3] {
            return Err(param_err(
                name,
                format!("shape {:?}", a.shape()),
                &format!("an array of shape ({n}, 3)"),
            ));
        }
        if a.iter().any(|x| !x.is_finite()) {
            return Err(param_err(name, "non-finite values", "finite numbers"));
        }
        let p = self.inner.particles_mut();
        for i in 0..n {
            let k = p.id[i] as usize;
            set(p, i, V3::new(a[[k, 0]], a[[k, 1]], a[[k, 2]]));
        }
        self.inner.invalidate();
        Ok(())
    }
}

/// Read what is needed to rebuild the simulation a checkpoint came from:
/// (scene, params JSON, positions by id, diameters by id).
type Header<'py> = (
    String,
    String,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
);

#[pyfunction]
pub fn read_checkpoint_header<'py>(
    py: Python<'py>,
    path: std::path::PathBuf,
) -> PyResult<Header<'py>> {
    let r = granflow::checkpoint::Reader::read(&path).py_err()?;
    let id = r.u32s("p.id").py_err()?;
    let x = r.f64s("p.x").py_err()?;
    let rad = r.f64s("p.radius").py_err()?;
    let n = id.len();
    let mut xo = vec![0.0; 3 * n];
    let mut d = vec![0.0; n];
    for (k, &i) in id.iter().enumerate() {
        let i = i as usize;
        if i >= n {
            return Err(param_err(
                "checkpoint",
                "bad particle ids",
                "a granflow checkpoint",
            ));
        }
        xo[3 * i..3 * i + 3].copy_from_slice(&x[3 * k..3 * k + 3]);
        d[i] = 2.0 * rad[k];
    }
    Ok((
        r.text("scene").py_err()?,
        r.text("params").py_err()?,
        PyArray1::from_vec(py, xo).reshape([n, 3])?,
        PyArray1::from_vec(py, d),
    ))
}

#[pymethods]
impl Sim {
    /// Advance `steps` steps with the GIL released. Python drives long runs in chunks
    /// (progress, Ctrl-C between chunks).
    fn run(&mut self, py: Python<'_>, steps: u64) -> PyResult<()> {
        let inner = &mut self.inner;
        let pool = &self.pool;
        let r = py.detach(|| pool.install(|| inner.run(steps)));
        r.py_err()
    }

    #[getter]
    fn threads(&self) -> usize {
        self.threads
    }
    #[setter]
    fn set_threads(&mut self, n: usize) -> PyResult<()> {
        if n == 0 || n > 1024 {
            return Err(param_err("threads", n, "1 <= threads <= 1024"));
        }
        self.pool = make_pool(n)?;
        self.threads = n;
        Ok(())
    }
    #[getter]
    fn scene(&self) -> String {
        self.scene.clone()
    }
    #[getter]
    fn n(&self) -> usize {
        self.inner.particles().len()
    }
    #[getter]
    fn step(&self) -> u64 {
        self.inner.step()
    }
    #[getter]
    fn time(&self) -> f64 {
        self.inner.time()
    }
    #[getter]
    fn dt(&self) -> f64 {
        self.inner.dt()
    }
    #[getter]
    fn contact_time(&self) -> f64 {
        self.inner.contact_time()
    }
    #[getter]
    fn volume(&self) -> f64 {
        self.inner.volume()
    }
    fn positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let p = self.inner.particles();
        self.by_id(py, |i| self.inner.wrapped(p.x[i]))
    }
    /// Unwrapped positions (periodic images added back).
    fn unwrapped_positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let p = self.inner.particles();
        let (h, _) = self.inner.cell();
        self.by_id(py, |i| {
            let im = p.image[i];
            p.x[i] + h * V3::new(im[0] as f64, im[1] as f64, im[2] as f64)
        })
    }
    fn velocities<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let p = self.inner.particles();
        self.by_id(py, |i| p.v[i])
    }
    fn angular_velocities<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let p = self.inner.particles();
        self.by_id(py, |i| p.omega[i])
    }
    fn forces<'py>(&mut self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let p = self.inner.particles();
        self.by_id(py, |i| p.force[i])
    }
    fn torques<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let p = self.inner.particles();
        self.by_id(py, |i| p.torque[i])
    }
    fn diameters<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let p = self.inner.particles();
        let mut out = vec![0.0; p.len()];
        for i in 0..p.len() {
            out[p.id[i] as usize] = 2.0 * p.radius[i];
        }
        PyArray1::from_vec(py, out)
    }
    fn masses<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let p = self.inner.particles();
        let mut out = vec![0.0; p.len()];
        for i in 0..p.len() {
            out[p.id[i] as usize] = p.mass[i];
        }
        PyArray1::from_vec(py, out)
    }
    fn set_velocities(&mut self, v: PyReadonlyArray2<'_, f64>) -> PyResult<()> {
        self.set_by_id("velocities", v, |p, i, x| p.v[i] = x)
    }
    fn set_angular_velocities(&mut self, w: PyReadonlyArray2<'_, f64>) -> PyResult<()> {
        self.set_by_id("angular_velocities", w, |p, i, x| p.omega[i] = x)
    }
    fn set_positions(&mut self, x: PyReadonlyArray2<'_, f64>) -> PyResult<()> {
        self.set_by_id("positions", x, |p, i, v| p.x[i] = v)
    }
    /// Compute forces for the current state without stepping (e.g. step-0 forces).
    fn compute_forces(&mut self) -> PyResult<()> {
        self.inner.run(0).py_err()
    }
    /// Kinetic energies (translational, rotational) and the elastic energy in the contacts.
    fn energies(&self) -> (f64, f64, f64) {
        let (a, b) = self.inner.particles().kinetic_energy();
        (a, b, self.inner.elastic_energy())
    }
    /// What the last force evaluation saw.
    fn diagnostics<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = self.inner.diag();
        let out = PyDict::new(py);
        out.set_item("max_overlap", d.max_overlap)?;
        out.set_item("contacts", d.contacts)?;
        let wf: Vec<[f64; 3]> = d.wall_force.iter().map(|v| [v.x, v.y, v.z]).collect();
        out.set_item("wall_force", wf)?;
        let vir: Vec<f64> = d.virial.iter().cloned().collect();
        out.set_item("virial_colmajor", vir)?;
        let (builds, prunes) = self.inner.list_counts();
        out.set_item("list_builds", builds)?;
        out.set_item("list_prunes", prunes)?;
        Ok(out)
    }
    /// The parts this simulation is composed of.
    /// The particle–particle law in use, resolved by the kernel (every field filled):
    /// kn, kt, e_n or xi_n, xi_t_ratio, mu.
    fn law<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        crate::convert::law_dict(py, &self.inner.law())
    }

    /// The particle–wall law in use (None without walls).
    fn wall_law<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        self.inner
            .wall_law()
            .map(|l| crate::convert::law_dict(py, &l))
            .transpose()
    }

    fn components(&self) -> Vec<String> {
        self.inner.components()
    }
    /// Bytes held by each part.
    fn memory(&self) -> Vec<(String, usize)> {
        self.inner.memory()
    }
    /// Cell matrix (rows x, y, z; columns = cell vectors) and origin.
    fn cell(&self) -> ([[f64; 3]; 3], [f64; 3]) {
        let (h, o) = self.inner.cell();
        let mut m = [[0.0; 3]; 3];
        for (r, row) in m.iter_mut().enumerate() {
            for (c, v) in row.iter_mut().enumerate() {
                *v = h[(r, c)];
            }
        }
        (m, [o.x, o.y, o.z])
    }
    /// Write a checkpoint atomically (tmp file, fsync, rename). `params` is the front end's
    /// description of how to rebuild this simulation (JSON), stored alongside the state.
    fn save_checkpoint(
        &self,
        py: Python<'_>,
        path: std::path::PathBuf,
        params: &str,
    ) -> PyResult<()> {
        let mut w = granflow::checkpoint::Writer::new();
        w.text("params", params);
        w.text("scene", &self.scene);
        self.inner.save_checkpoint(&mut w);
        py.detach(|| w.write_atomic(&path)).py_err()
    }
    /// Restore the state from a checkpoint written by a simulation with the same parameters.
    fn load_checkpoint(&mut self, path: std::path::PathBuf) -> PyResult<()> {
        let r = granflow::checkpoint::Reader::read(&path).py_err()?;
        self.inner.load_checkpoint(&r).py_err()
    }
    /// Ask the next step's force evaluation for per-particle contact sums.
    fn request_stats(&mut self) {
        self.inner.request_stats();
    }
    /// Per-particle contact stress sums S_i = sum_j r_ij (x) f_ij / 2 (walls in full; (N, 9),
    /// row-major xx xy xz yx ...) and contact power P_i = sum_j f_ij . v_ij / 2 ((N,), < 0 when
    /// dissipating), in id order, from the last evaluation that was asked for them.
    #[allow(
        clippy::type_complexity,
        clippy::needless_range_loop,
        reason = "a (stress, power) pair of numpy arrays; rows filled by index in id order"
    )]
    fn particle_stats<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<f64>>)> {
        let p = self.inner.particles();
        let st = self.inner.particle_stats();
        let n = p.len();
        if st.len() != n {
            return Err(param_err(
                "particle_stats",
                "not available",
                "call request_stats() before a step",
            ));
        }
        let mut s = vec![0.0; 9 * n];
        let mut pw = vec![0.0; n];
        for i in 0..n {
            let k = p.id[i] as usize;
            s[9 * k..9 * k + 9].copy_from_slice(&st[i][..9]);
            pw[k] = st[i][9];
        }
        Ok((
            PyArray1::from_vec(py, s).reshape([n, 9])?,
            PyArray1::from_vec(py, pw),
        ))
    }
    /// Force exerted by the particles on each wall at the last evaluation ((n_walls, 3)).
    fn wall_forces(&self) -> Vec<[f64; 3]> {
        self.inner
            .wall_forces()
            .iter()
            .map(|v| [v.x, v.y, v.z])
            .collect()
    }
    /// Pair contacts of the last force evaluation: ids (M, 2), r_ij = x_i - x_j (M, 3) and the
    /// force on i (M, 3).
    #[allow(
        clippy::type_complexity,
        reason = "(ids, branch vectors, forces) as three numpy arrays"
    )]
    fn contacts<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(
        Bound<'py, numpy::PyArray2<i64>>,
        Bound<'py, PyArray2<f64>>,
        Bound<'py, PyArray2<f64>>,
    )> {
        let c = self.inner.contacts();
        let m = c.len();
        let ids: Vec<i64> = c.iter().flat_map(|t| [t.0 as i64, t.1 as i64]).collect();
        let d: Vec<f64> = c.iter().flat_map(|t| [t.2.x, t.2.y, t.2.z]).collect();
        let f: Vec<f64> = c.iter().flat_map(|t| [t.3.x, t.3.y, t.3.z]).collect();
        Ok((
            PyArray1::from_vec(py, ids).reshape([m, 2])?,
            PyArray1::from_vec(py, d).reshape([m, 3])?,
            PyArray1::from_vec(py, f).reshape([m, 3])?,
        ))
    }
    /// Named observables of the domain (the cell's L, contact and kinetic stress, flips).
    fn domain_observables(&self) -> Vec<(String, f64)> {
        self.inner.domain_observables()
    }
    /// Change a stress-controlled cell's imposed pressure and xy shear stress from the next
    /// step on (ParameterError outside p_ext > 0, |tau_ext/p_ext| <= 2, or for another domain).
    fn set_stress(&mut self, p_ext: f64, tau_ext: f64) -> PyResult<()> {
        self.inner.set_stress(p_ext, tau_ext).py_err()
    }
    /// Drive a cell at the xy shear rate `rate` (L_xy = dv_x/dy >= 0) from the next step on,
    /// holding sigma_yy (`gradient`, the x and z lengths fixed) or the pressure at `p_ext`
    /// (ParameterError for a rate < 0 or not finite, p_ext <= 0, or another domain).
    #[pyo3(signature = (rate, p_ext, gradient = false))]
    fn set_rate(&mut self, rate: f64, p_ext: f64, gradient: bool) -> PyResult<()> {
        self.inner.set_rate(rate, gradient, p_ext).py_err()
    }
    /// Time integral of the wall forces since the start ((n_walls, 3)).
    fn wall_impulse(&self) -> Vec<[f64; 3]> {
        self.inner
            .wall_impulse()
            .iter()
            .map(|v| [v.x, v.y, v.z])
            .collect()
    }
    /// Add a sampler that runs inside the step loop every `every` steps (at multiples of it in
    /// the step count): `kind` one of "channel_bins" (needs `window` and the bin `edges`
    /// from x = 0 to x = W), "channel_series", "cell_series", "series" (energies, contacts
    /// and the largest overlap, for any simulation); `columns` keeps only those.
    /// Its tables come out of `take_tables` as Arrow batches.
    #[pyo3(signature = (kind, every, window=1, edges=None, columns=None))]
    fn add_sampler(
        &mut self,
        kind: &str,
        every: i64,
        window: i64,
        edges: Option<Vec<f64>>,
        columns: Option<Vec<String>>,
    ) -> PyResult<()> {
        let count = |name: &str, v: i64, what: &str| -> PyResult<u64> {
            u64::try_from(v)
                .ok()
                .filter(|&v| v >= 1)
                .ok_or_else(|| param_err(&format!("{kind}.{name}"), v, what))
        };
        let spec = granflow::sampling::SamplerSpec {
            every: count("every", every, "an integer >= 1 (steps between samples)")?,
            window: count("window", window, "an integer >= 1 (samples per window)")?,
            edges: edges.unwrap_or_default(),
            columns,
        };
        self.inner.add_sampler(kind, spec).py_err()
    }
    /// The configured samplers as (kind, table) pairs.
    fn samplers(&self) -> Vec<(String, String)> {
        self.inner.samplers()
    }
    /// Sample tables closed since the last call, as Arrow batches (oldest first).
    fn take_tables(&mut self) -> Vec<ArrowBatch> {
        self.inner
            .take_tables()
            .into_iter()
            .map(|(name, t)| ArrowBatch::from_table(&name, t))
            .collect()
    }
}
