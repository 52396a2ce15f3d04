//! The channel's `series` sampler: one row per sample of whole-channel quantities (centre of
//! mass velocity, kinetic energies, wall stresses, contacts, momentum, wall impulses; columns
//! in docs/columns.md).

use crate::error::{Error, Result};
use crate::particles::Motion;
use crate::sampling::{chunk_parts, ChunkView, Rows, SampleView, Sampler, SamplerSpec, Setup};
use crate::table::Table;

/// The `series` sampler: one row per sample.
pub struct Series {
    every: u64,
    /// H B: the walls' area.
    area: f64,
    rows: Rows,
    /// The coming sample's chunk sums (`Motion` rows), when the team made them (else empty).
    parts: Vec<Vec<f64>>,
}

const SERIES: [&str; 21] = [
    "step",
    "t",
    "vcm_x",
    "vcm_y",
    "vcm_z",
    "ke_trans",
    "ke_rot",
    "wall0_sigma_xx",
    "wall0_sigma_xy",
    "wall0_sigma_xz",
    "wall1_sigma_xx",
    "wall1_sigma_xy",
    "wall1_sigma_xz",
    "n_contacts",
    "max_overlap",
    "px",
    "py",
    "pz",
    "wall_impulse_x",
    "wall_impulse_y",
    "wall_impulse_z",
];

fn series_names() -> Vec<&'static str> {
    SERIES.to_vec()
}

fn series_unit(name: &str) -> &'static str {
    match name {
        "step" | "n_contacts" | "max_overlap" => "",
        "t" => "sqrt(d/g)",
        "ke_trans" | "ke_rot" => "rho_p g d^4",
        "px" | "py" | "pz" => "rho_p d^3 sqrt(g d)",
        n if n.starts_with("wall_impulse") => "rho_p d^3 sqrt(g d)",
        n if n.starts_with("wall") => "rho_p g d",
        _ => "sqrt(g d)",
    }
}

impl Series {
    pub fn new(spec: &SamplerSpec, setup: &Setup) -> Result<Self> {
        if setup.walls < 2 {
            return Err(Error::param(
                "channel_series",
                "this simulation",
                "a channel with its two walls",
            ));
        }
        let names = series_names();
        let units = names.iter().map(|n| series_unit(n)).collect();
        Ok(Series {
            every: spec.every,
            area: setup.widths[1] * setup.widths[2],
            rows: Rows::new(names, units, &["step"]),
            parts: Vec::new(),
        })
    }

    /// The particles' motion: each force-loop chunk summed apart (`chunk_parts`: by the team
    /// as it completes the chunks, or here), then added in chunk order.
    fn motion(&mut self, v: &SampleView) -> Motion {
        let given = std::mem::take(&mut self.parts);
        let mut m = Motion::default();
        for part in chunk_parts(given, v, chunk_motion) {
            m.add_row(&part);
        }
        m
    }
}

/// One chunk's motion sums, as a `Motion` row.
fn chunk_motion(c: &ChunkView) -> Vec<f64> {
    let r = c.r.clone();
    Motion::of(&c.mass[r.clone()], c.v, c.omega, &c.inv_inertia[r])
        .to_row()
        .to_vec()
}

impl Sampler for Series {
    fn kind(&self) -> &'static str {
        "channel_series"
    }
    fn needs_contacts(&self) -> bool {
        // (its contact count and largest overlap are the evaluation's own)
        false
    }
    fn table(&self) -> &'static str {
        "series"
    }
    fn every(&self) -> u64 {
        self.every
    }
    fn columns(&self) -> Vec<&'static str> {
        series_names()
    }
    fn chunk_part(&self, c: &ChunkView) -> Option<Vec<f64>> {
        Some(chunk_motion(c))
    }
    fn set_parts(&mut self, parts: Vec<Vec<f64>>) {
        self.parts = parts;
    }
    fn sample(&mut self, v: &SampleView) -> Result<()> {
        let m = self.motion(v);
        let (mv, ket, ker) = (m.momentum, m.translational, m.rotational);
        let vcm = mv / m.mass;
        let wf = v.wall_force;
        let imp = v.wall_impulse[0] + v.wall_impulse[1];
        let a = self.area;
        let row = [
            v.step as f64,
            v.time,
            vcm.x,
            vcm.y,
            vcm.z,
            ket,
            ker,
            wf[0].x / a,
            wf[0].y / a,
            wf[0].z / a,
            wf[1].x / a,
            wf[1].y / a,
            wf[1].z / a,
            v.n_contacts as f64,
            v.max_overlap,
            mv.x,
            mv.y,
            mv.z,
            imp.x,
            imp.y,
            imp.z,
        ];
        self.rows.push_finite("channel series", v.step, &row)
    }
    fn take(&mut self) -> Vec<Table> {
        self.rows.take("channel_series")
    }
    fn save(&self) -> Vec<f64> {
        self.rows.flat()
    }
    fn load(&mut self, s: &[f64]) -> Result<()> {
        self.rows.set_flat(s)
    }
    fn bytes(&self) -> usize {
        self.rows.bytes()
    }
}
