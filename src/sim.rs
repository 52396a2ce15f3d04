//! An object-safe view of any composed engine, so front ends (Python bindings, CLI) can hold
//! "a simulation" without naming its type parameters. The hot loop stays monomorphised: dynamic
//! dispatch happens once per `run` call, never per particle or pair.

use crate::contact::{Form, Friction};
use crate::domain::Domain;
use crate::engine::{Body, Engine, StepDiag, Walls};
use crate::error::Result;
use crate::particles::Particles;
use crate::table::Table;

pub trait Simulation: Send + Sync {
    /// Advance `n` steps (samplers, if any, run on their triggers).
    fn run(&mut self, n: u64) -> Result<()>;
    fn particles(&self) -> &Particles;
    /// Mutable access; call [`Simulation::invalidate`] after changing positions or velocities.
    fn particles_mut(&mut self) -> &mut Particles;
    fn invalidate(&mut self);
    fn step(&self) -> u64;
    fn time(&self) -> f64;
    fn dt(&self) -> f64;
    fn contact_time(&self) -> f64;
    fn diag(&self) -> StepDiag;
    /// The parts this simulation is composed of (e.g. "contact: hooke/coulomb", "walls: 2 planes").
    fn components(&self) -> Vec<String>;
    /// Bytes held by each part (capacity of its arrays).
    fn memory(&self) -> Vec<(String, usize)>;
    /// Tables produced by samplers since the last call (name, table). Default: none.
    fn take_tables(&mut self) -> Vec<(String, Table)> {
        Vec::new()
    }
    /// Volume of the domain.
    fn volume(&self) -> f64;
    /// Cell matrix (columns = cell vectors) and origin.
    fn cell(&self) -> (crate::M3, crate::V3);
    /// Total elastic energy stored in the contacts (linear law: kn delta^2/2; Hertz:
    /// 2/5 kn delta^(5/2)/sqrt(d)); used for energy balances.
    fn elastic_energy(&self) -> f64;
}

fn vec_bytes<T>(v: &Vec<T>) -> usize {
    v.capacity() * std::mem::size_of::<T>()
}

/// Bytes held by the particle arrays.
pub fn particle_bytes(p: &Particles) -> usize {
    vec_bytes(&p.x)
        + vec_bytes(&p.v)
        + vec_bytes(&p.omega)
        + vec_bytes(&p.force)
        + vec_bytes(&p.torque)
        + vec_bytes(&p.radius)
        + vec_bytes(&p.mass)
        + vec_bytes(&p.inv_mass)
        + vec_bytes(&p.inv_inertia)
        + vec_bytes(&p.image)
        + vec_bytes(&p.id)
}

impl<F: Form, T: Friction, D: Domain, W: Walls<F, T>, G: Body> Engine<F, T, D, W, G> {
    pub fn component_list(&self) -> Vec<String> {
        let mut c = vec![
            format!("contact: {}", crate::contact::Law::<F, T>::name()),
            format!(
                "tangential history: {}",
                if T::FRICTIONAL {
                    "per contact"
                } else {
                    "none"
                }
            ),
            format!("domain: {}", D::NAME),
            "integrator: velocity Verlet (translation + rotation)".to_string(),
            "neighbours: cell list + Verlet list with skin".to_string(),
        ];
        if W::ON {
            c.push(format!("walls: {} planes", self.walls.planes().len()));
        }
        if G::ON {
            let g = self.body.g();
            c.push(format!("body force: gravity ({}, {}, {})", g.x, g.y, g.z));
        }
        c
    }

    pub fn memory_list(&self) -> Vec<(String, usize)> {
        let nl = &self.nl;
        vec![
            ("particles".to_string(), particle_bytes(&self.p)),
            (
                "pair list".to_string(),
                vec_bytes(&nl.pair_i)
                    + vec_bytes(&nl.pair_j)
                    + vec_bytes(&nl.own_start)
                    + vec_bytes(&nl.rev_start)
                    + vec_bytes(&nl.rev_k)
                    + vec_bytes(&nl.x_build),
            ),
            ("pair forces".to_string(), vec_bytes(&self.pair_out)),
            ("tangential history".to_string(), vec_bytes(&nl.hist)),
            ("wall history".to_string(), vec_bytes(&self.wall_hist)),
        ]
    }

    pub fn elastic_energy_sum(&self) -> f64 {
        let kn = self.law.params.kn;
        let mut u = 0.0;
        for k in 0..self.nl.len() {
            let i = self.nl.pair_i[k] as usize;
            let j = self.nl.pair_j[k] as usize;
            let rs = self.p.radius[i] + self.p.radius[j];
            let r = self.domain.delta(&self.p.x[i], &self.p.x[j]).norm();
            let delta = rs - r;
            if delta > 0.0 {
                u += elastic::<F>(kn, delta, rs);
            }
        }
        if let Some(wl) = self.walls.law() {
            let kw = wl.params.kn;
            for i in 0..self.p.len() {
                let ri = self.p.radius[i];
                for pl in self.walls.planes() {
                    let gap = pl.sign * (self.p.x[i][pl.axis] - pl.pos);
                    if gap < ri {
                        u += elastic::<F>(kw, ri - gap, 2.0 * ri);
                    }
                }
            }
        }
        u
    }
}

fn elastic<F: Form>(kn: f64, delta: f64, d: f64) -> f64 {
    let (s, _) = F::factors(delta, d, false);
    if s == 1.0 {
        0.5 * kn * delta * delta
    } else {
        // integral of kn (x/d)^(1/2) x dx = 2/5 kn x^(5/2) / d^(1/2)
        0.4 * kn * delta * delta * s
    }
}

impl<F: Form, T: Friction, D: Domain, W: Walls<F, T>, G: Body> Simulation
    for Engine<F, T, D, W, G>
{
    fn run(&mut self, n: u64) -> Result<()> {
        Engine::run(self, n)
    }
    fn particles(&self) -> &Particles {
        &self.p
    }
    fn particles_mut(&mut self) -> &mut Particles {
        &mut self.p
    }
    fn invalidate(&mut self) {
        Engine::invalidate(self)
    }
    fn step(&self) -> u64 {
        self.step
    }
    fn time(&self) -> f64 {
        self.time
    }
    fn dt(&self) -> f64 {
        self.dt
    }
    fn contact_time(&self) -> f64 {
        Engine::contact_time(self)
    }
    fn diag(&self) -> StepDiag {
        self.diag.clone()
    }
    fn components(&self) -> Vec<String> {
        self.component_list()
    }
    fn memory(&self) -> Vec<(String, usize)> {
        self.memory_list()
    }
    fn volume(&self) -> f64 {
        self.domain.volume()
    }
    fn cell(&self) -> (crate::M3, crate::V3) {
        (self.domain.h(), self.domain.origin())
    }
    fn elastic_energy(&self) -> f64 {
        self.elastic_energy_sum()
    }
}
