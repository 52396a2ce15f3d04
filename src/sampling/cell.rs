//! The stress-controlled cell's `series` sampler (002_89269f1b918188b3; columns in
//! docs/columns.md): one row of observables (`super::cell_obs`) per sample.

use super::cell_obs::{cell_columns, cell_row, CellInput};
use super::{Rows, SampleView, Sampler, SamplerSpec, Setup, WALL};
use crate::error::{Error, Result};
use crate::table::Table;
use crate::{M3, V3};
use std::f64::consts::PI;

pub struct Series {
    every: u64,
    /// The cell when the sampler was set up (the deformation gradient's reference).
    h0: M3,
    /// Total particle volume, mean diameter and density.
    vs: f64,
    a: f64,
    density: f64,
    rows: Rows,
    /// Scratch: the step's pair contacts and branch vectors.
    pairs: Vec<[u32; 2]>,
    branch: Vec<V3>,
}

impl Series {
    pub fn new(spec: &SamplerSpec, setup: &Setup) -> Result<Self> {
        if setup.periodic != [true; 3] || setup.walls != 0 {
            return Err(Error::param(
                "cell_series",
                "this simulation",
                "a fully periodic (stress-controlled) cell",
            ));
        }
        let p = setup.p;
        let n = p.len() as f64;
        let d: Vec<f64> = p.radius.iter().map(|r| 2.0 * r).collect();
        let vs: f64 = d.iter().map(|d| PI * d * d * d / 6.0).sum();
        let a = d.iter().sum::<f64>() / n;
        let density = p.mass[0] / (PI * d[0] * d[0] * d[0] / 6.0);
        let names = cell_columns();
        let units = vec![""; names.len()];
        Ok(Series {
            every: spec.every,
            h0: setup.h,
            vs,
            a,
            density,
            rows: Rows::new(names, units, &["step", "tilt_flips"]),
            pairs: Vec::new(),
            branch: Vec::new(),
        })
    }
}

impl Sampler for Series {
    fn kind(&self) -> &'static str {
        "cell_series"
    }
    fn table(&self) -> &'static str {
        "series"
    }
    fn every(&self) -> u64 {
        self.every
    }
    fn columns(&self) -> Vec<&'static str> {
        cell_columns()
    }
    fn sample(&mut self, v: &SampleView) -> Result<()> {
        self.pairs.clear();
        self.branch.clear();
        for c in v.contacts.iter().flatten().filter(|c| c.j != WALL) {
            self.pairs.push([c.i, c.j]);
            self.branch.push(c.d);
        }
        let inp = CellInput {
            step: v.step,
            t: v.time,
            h: v.h,
            h0: self.h0,
            l: v.tensor("L"),
            sigma_c: v.tensor("sigma_c"),
            sigma_k: v.tensor("sigma_k"),
            vs: self.vs,
            a: self.a,
            density: self.density,
            n: v.p.len(),
            pairs: &self.pairs,
            branch: &self.branch,
            max_overlap: v.max_overlap,
            tilt_flips: v.observable("tilt_flips"),
        };
        let row = cell_row(&inp)?;
        let vals: Vec<f64> = row.iter().map(|r| r.1).collect();
        self.rows.push(&vals);
        Ok(())
    }
    fn take(&mut self) -> Vec<Table> {
        self.rows.take("cell_series")
    }
    fn save(&self) -> Vec<f64> {
        let mut s: Vec<f64> = self.h0.iter().copied().collect();
        s.extend(self.rows.flat());
        s
    }
    fn load(&mut self, s: &[f64]) -> Result<()> {
        if s.len() < 9 {
            return Err(Error::Io {
                message: "checkpoint: the cell series' state is too short".into(),
            });
        }
        self.h0 = M3::from_column_slice(&s[..9]);
        self.rows.set_flat(&s[9..])
    }
    fn bytes(&self) -> usize {
        self.rows.bytes() + 8 * self.pairs.capacity() + 24 * self.branch.capacity()
    }
}
