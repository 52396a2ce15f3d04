//! Structure-of-arrays particle state. Spheres: mass = rho pi d^3 / 6, moment of inertia
//! I = m d^2 / 10 (solid sphere, 2/5 m R^2).

use crate::error::{Error, Result};
use crate::V3;

#[derive(Clone, Debug, Default)]
pub struct Particles {
    pub x: Vec<V3>,
    pub v: Vec<V3>,
    pub omega: Vec<V3>,
    pub force: Vec<V3>,
    pub torque: Vec<V3>,
    pub radius: Vec<f64>,
    pub mass: Vec<f64>,
    pub inv_mass: Vec<f64>,
    pub inv_inertia: Vec<f64>,
    /// Periodic image counters (how many times a particle crossed each periodic boundary), so
    /// unwrapped trajectories and restarts stay exact.
    pub image: Vec<[i32; 3]>,
    /// The user's label of each particle (arrays are re-ordered internally for locality).
    pub id: Vec<u32>,
}

/// Sums over the particles' motion (`Particles::motion`).
#[derive(Clone, Copy, Debug, Default)]
pub struct Motion {
    pub momentum: V3,
    pub mass: f64,
    pub translational: f64,
    pub rotational: f64,
}

impl Motion {
    /// The sums over the particles of these slices (masses, velocities, spins, inverse
    /// moments of inertia, all of one length), in their order.
    pub fn of(mass: &[f64], v: &[V3], omega: &[V3], inv_inertia: &[f64]) -> Motion {
        let mut m = Motion::default();
        for (((&mi, vi), wi), &ii) in mass.iter().zip(v).zip(omega).zip(inv_inertia) {
            m.momentum += mi * vi;
            m.mass += mi;
            m.translational += 0.5 * mi * vi.norm_squared();
            m.rotational += 0.5 * wi.norm_squared() / ii;
        }
        m
    }

    /// As a flat row: momentum (3), mass, translational and rotational energy.
    pub fn to_row(self) -> [f64; 6] {
        let p = self.momentum;
        [
            p.x,
            p.y,
            p.z,
            self.mass,
            self.translational,
            self.rotational,
        ]
    }

    /// `self` plus the sums of a `to_row` row.
    pub fn add_row(&mut self, r: &[f64]) {
        self.momentum += V3::new(r[0], r[1], r[2]);
        self.mass += r[3];
        self.translational += r[4];
        self.rotational += r[5];
    }
}

impl Particles {
    /// Build from diameters and a single density; positions given; velocities and spins zero
    /// unless set afterwards.
    pub fn new(x: Vec<V3>, diameter: &[f64], density: f64) -> Result<Self> {
        let n = x.len();
        if n == 0 {
            return Err(Error::param("particles", 0, "at least 1 particle"));
        }
        if diameter.len() != n {
            return Err(Error::param(
                "diameter",
                format!("{} values", diameter.len()),
                format!("one per particle ({n})"),
            ));
        }
        crate::error::check_positive("density", density)?;
        let mut p = Particles {
            x,
            v: vec![V3::zeros(); n],
            omega: vec![V3::zeros(); n],
            force: vec![V3::zeros(); n],
            torque: vec![V3::zeros(); n],
            radius: Vec::with_capacity(n),
            mass: Vec::with_capacity(n),
            inv_mass: Vec::with_capacity(n),
            inv_inertia: Vec::with_capacity(n),
            image: vec![[0; 3]; n],
            id: (0..n as u32).collect(),
        };
        for (i, &d) in diameter.iter().enumerate() {
            if !(d.is_finite() && d > 0.0) {
                return Err(Error::param(
                    format!("diameter[{i}]"),
                    d,
                    "a finite number > 0",
                ));
            }
            let m = density * std::f64::consts::PI * d * d * d / 6.0;
            p.radius.push(0.5 * d);
            p.mass.push(m);
            p.inv_mass.push(1.0 / m);
            p.inv_inertia.push(10.0 / (m * d * d));
        }
        for (i, xi) in p.x.iter().enumerate() {
            if !xi.iter().all(|c| c.is_finite()) {
                return Err(Error::param(
                    format!("position[{i}]"),
                    format!("{:?}", xi.as_slice()),
                    "finite coordinates",
                ));
            }
        }
        Ok(p)
    }

    pub fn len(&self) -> usize {
        self.x.len()
    }
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }
    pub fn inertia(&self, i: usize) -> f64 {
        1.0 / self.inv_inertia[i]
    }
    pub fn max_radius(&self) -> f64 {
        self.radius.iter().cloned().fold(0.0, f64::max)
    }
    pub fn min_mass(&self) -> f64 {
        self.mass.iter().cloned().fold(f64::INFINITY, f64::min)
    }
    pub fn total_volume(&self) -> f64 {
        self.radius
            .iter()
            .map(|r| 4.0 / 3.0 * std::f64::consts::PI * r * r * r)
            .sum()
    }
    /// Translational and rotational kinetic energy.
    pub fn kinetic_energy(&self) -> (f64, f64) {
        let m = self.motion();
        (m.translational, m.rotational)
    }
    pub fn momentum(&self) -> V3 {
        self.motion().momentum
    }

    /// Momentum, total mass and kinetic energies in one pass (each summed in particle order,
    /// as the separate sums would be: the same bits).
    pub fn motion(&self) -> Motion {
        Motion::of(&self.mass, &self.v, &self.omega, &self.inv_inertia)
    }

    /// Apply a permutation: new[k] = old[perm[k]].
    pub fn permute(&mut self, perm: &[usize]) {
        permute_vec(&mut self.x, perm);
        permute_vec(&mut self.v, perm);
        permute_vec(&mut self.omega, perm);
        permute_vec(&mut self.force, perm);
        permute_vec(&mut self.torque, perm);
        permute_vec(&mut self.radius, perm);
        permute_vec(&mut self.mass, perm);
        permute_vec(&mut self.inv_mass, perm);
        permute_vec(&mut self.inv_inertia, perm);
        permute_vec(&mut self.image, perm);
        permute_vec(&mut self.id, perm);
    }
}

/// Apply a permutation to one per-particle array: new[k] = old[perm[k]].
pub fn permute_vec<T: Clone>(v: &mut Vec<T>, perm: &[usize]) {
    let old = std::mem::take(v);
    *v = perm.iter().map(|&k| old[k].clone()).collect();
}
