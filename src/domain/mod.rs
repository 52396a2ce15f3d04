//! Simulation domains. A domain answers geometric questions (minimum image, wrapping,
//! fractional coordinates for binning) and owns the integration of the equations of motion,
//! because a deforming cell (Parrinello–Rahman) changes how particles move.
//!
//! [`OrthoBox`] is an orthogonal box with a periodic flag per axis: fully periodic for a bulk
//! packing, periodic in y and z only for the channel (walls at x = lo and x = hi are a separate
//! component, see `crate::components::Walls`). The triclinic stress-controlled cell (Parrinello–Rahman) is [`PrCell`].

use crate::error::{Error, Result};
use crate::particles::Particles;
use crate::{M3, V3};

mod ortho;
mod prcell;

pub use ortho::OrthoBox;
pub use prcell::PrCell;

/// The affine maps of a domain's particle updates (see `Domain::begin_step`): a half-kick
/// v <- v + (dt/2) (f/m - l v - tr v) and a drift x <- a x + dt v (identity maps for a box).
#[derive(Clone, Copy, Debug)]
pub struct StepMaps {
    pub l: M3,
    pub tr: f64,
    pub a: M3,
}

impl Default for StepMaps {
    fn default() -> Self {
        StepMaps {
            l: M3::zeros(),
            tr: 0.0,
            a: M3::identity(),
        }
    }
}

impl StepMaps {
    /// The half-kick of one particle (002 2.10b with the cell's drag; the arithmetic of the
    /// earlier per-domain loops, so the same bits).
    #[inline(always)]
    pub fn kick(&self, v: &V3, f: &V3, im: f64, h2: f64) -> V3 {
        v + h2 * (f * im - self.l * v - self.tr * v)
    }
}

pub trait Domain: Clone + Send + Sync + 'static {
    const NAME: &'static str;
    /// Whether the integrator needs the contact virial sum_pairs r_ij (x) f_ij every step.
    const NEEDS_VIRIAL: bool = false;
    /// Whether particle velocities are stored relative to a streaming (affine) field, as in the
    /// Parrinello–Rahman cell (002 2.10a: dr/dt = p/m + L r). Contacts then add L r_ij to the
    /// relative velocity.
    const STREAMING: bool = false;
    /// No external work is done on the particles by the domain (a static box): with no body
    /// force the total energy can only decrease, which the engine's energy guard checks.
    const CLOSED: bool = false;
    /// Plain velocity Verlet (`nve_initial`/`nve_final`, no domain dynamics): the engine fuses
    /// the kicks with its own passes over the particles. A domain with dynamics of its own
    /// sets this to false and gives its maps (`begin_step` ...).
    const PLAIN_NVE: bool = true;
    /// The streaming velocity gradient as (P, w): L = P / w (only read if `STREAMING`; the
    /// force loop applies it on lanes of contacts, `engine::chunk::streaming_on_lanes`).
    fn streaming_map(&self) -> (crate::M3, f64) {
        (crate::M3::zeros(), 1.0)
    }
    /// The streaming velocity difference L r_ij = (P r_ij) / w for a displacement r_ij (only
    /// if `STREAMING`).
    #[inline(always)]
    fn streaming_velocity(&self, rij: &V3) -> V3 {
        let (pg, wg) = self.streaming_map();
        (pg * rij) / wg
    }
    fn periodic(&self) -> [bool; 3];
    /// Minimum-image displacement x_i - x_j.
    fn delta(&self, xi: &V3, xj: &V3) -> V3;
    /// Wrap a position into the primary cell, updating its image counter.
    fn wrap(&self, x: &mut V3, image: &mut [i32; 3]);
    /// Fractional coordinates in [0, 1) along the three cell vectors (clamped on walled axes).
    fn frac(&self, x: &V3) -> V3;
    /// Distances between opposite faces of the cell (bin counts follow from them).
    fn widths(&self) -> V3;
    fn volume(&self) -> f64;
    /// Cell matrix (columns are the cell vectors).
    fn h(&self) -> M3;
    /// Origin of the cell.
    fn origin(&self) -> V3;

    /// A domain with its own dynamics (`PLAIN_NVE` false) moves particles by affine maps the
    /// engine applies in its own passes (fused with packing, parallel): `begin_step` (the
    /// domain's first half-step) gives the half-kick's and the drift's maps, `after_drift`
    /// finishes the domain's drift, `final_kick` gives the second half-kick's map, `end_step`
    /// takes the contact virial and the kinetic sum sum_i m_i v_i (x) v_i after that kick.
    fn begin_step(&mut self, _dt: f64) -> StepMaps {
        StepMaps::default()
    }
    fn after_drift(&mut self, _maps: &StepMaps, _p: &mut Particles) {}
    fn final_kick(&self) -> StepMaps {
        StepMaps::default()
    }
    fn end_step(&mut self, _dt: f64, _virial: &M3, _kinetic: &M3) {}
    /// A bound on the norm of the velocity gradient L that the last drift applied (zero for a
    /// static box): a pair's separation then changed by dt (v_i - v_j + L r_ij), so its gap
    /// closes at most at 2 max |v| + |L| |r_ij| (the inner list's displacement bound).
    fn affine_rate(&self) -> f64 {
        0.0
    }
    /// Whether the cell changed enough since the last neighbour build to force a rebuild.
    fn rebuild_due(&self, _skin: f64) -> bool {
        false
    }
    /// Called after every neighbour-list rebuild.
    fn on_rebuild(&mut self) {}
    /// Run-time guard, called once per step after the drift: a domain that found its
    /// state unusable (e.g. a deforming cell too thin for the minimum image) reports it here.
    fn check(&self, _step: u64) -> Result<()> {
        Ok(())
    }
    /// Change the imposed stress (pressure, xy shear stress) from the next step on; only a
    /// stress-controlled domain has one.
    fn set_stress(&mut self, _p_ext: f64, _tau_ext: f64) -> Result<()> {
        Err(Error::param(
            "domain",
            Self::NAME,
            "a stress-controlled cell (this domain has no imposed stress)",
        ))
    }
    /// Drive a cell at an imposed xy shear rate with its normal stress (sigma_yy if
    /// `gradient`, else the pressure) held at `p_ext` (the cell; other domains refuse).
    fn set_rate(&mut self, _rate: f64, _gradient: bool, _p_ext: f64) -> Result<()> {
        Err(Error::param(
            "domain",
            Self::NAME,
            "a cell (this domain has no imposed rate)",
        ))
    }
    /// Named scalar observables of the domain itself (e.g. a cell's velocity gradient).
    fn observables(&self) -> Vec<(String, f64)> {
        Vec::new()
    }
    /// Dynamic state for checkpoints (a static box has none).
    fn save_state(&self) -> Vec<f64> {
        Vec::new()
    }
    fn load_state(&mut self, _s: &[f64]) -> Result<()> {
        Ok(())
    }
}

/// Velocity Verlet, first half (translation and rotation of spheres).
pub fn nve_initial(p: &mut Particles, dt: f64) {
    use rayon::prelude::*;
    let h = 0.5 * dt;
    p.x.par_iter_mut()
        .zip(p.v.par_iter_mut())
        .zip(p.omega.par_iter_mut())
        .zip(p.force.par_iter())
        .zip(p.torque.par_iter())
        .zip(p.inv_mass.par_iter())
        .zip(p.inv_inertia.par_iter())
        .with_min_len(1024)
        .for_each(|((((((x, v), w), f), t), im), ii)| {
            let vn = *v + f * (h * im);
            *v = vn;
            *x += vn * dt;
            *w += t * (h * ii);
        });
}

/// Velocity Verlet, second half.
pub fn nve_final(p: &mut Particles, dt: f64) {
    use rayon::prelude::*;
    let h = 0.5 * dt;
    p.v.par_iter_mut()
        .zip(p.omega.par_iter_mut())
        .zip(p.force.par_iter())
        .zip(p.torque.par_iter())
        .zip(p.inv_mass.par_iter())
        .zip(p.inv_inertia.par_iter())
        .with_min_len(1024)
        .for_each(|(((((v, w), f), t), im), ii)| {
            *v += f * (h * im);
            *w += t * (h * ii);
        });
}
