//! Run-time guards: a run that goes unstable stops with a clear error (the step, the particles
//! involved, the likely cause) instead of writing NaN.

use super::{Body, Engine, Walls};
use crate::contact::{Form, Friction};
use crate::domain::Domain;
use crate::error::{Error, Result};

impl<F: Form, T: Friction, D: Domain, W: Walls<F, T>, G: Body> Engine<F, T, D, W, G> {
    pub(super) fn check_overlap(&self) -> Result<()> {
        let d = &self.diag;
        if self.guards.overlap_exceeded(d) {
            let (i, j) = d.max_overlap_at;
            let mut ids = vec![self.p.id[i] as usize];
            if j != usize::MAX {
                ids.push(self.p.id[j] as usize);
            }
            return Err(Error::Instability {
                step: self.step,
                particles: ids,
                message: format!(
                    "overlap {:.3} of the pair's diameter exceeds the limit {:.3}",
                    d.max_overlap, self.guards.max_overlap
                ),
                cause: format!(
                    "contacts too soft for the load (raise kn, or lower the pressure/height: \
                     overlap ~ load/kn), or dt = {:.3e} too large against t_c = {:.3e}",
                    self.dt,
                    self.contact_time()
                ),
            });
        }
        Ok(())
    }

    /// A closed system without body force cannot gain energy: contacts are passive. Growth by
    /// half again over the first checked value means the integration is unstable.
    pub(super) fn check_energy(&mut self) -> Result<()> {
        let (et, er) = self.p.kinetic_energy();
        let e = et + er + self.elastic_energy_sum();
        let n = self.p.len() as f64;
        let d = 2.0 * self.p.max_radius();
        let floor = 1e-12 * self.law.params.kn * d * d * n;
        match self.energy_ref {
            None => self.energy_ref = Some(e),
            Some(e0) => {
                if e > 1.5 * e0 + floor {
                    return Err(Error::Instability {
                        step: self.step,
                        particles: vec![],
                        message: format!(
                            "total energy grew from {e0:.4e} to {e:.4e} with no energy source"
                        ),
                        cause: format!(
                            "dt = {:.3e} too large against t_c = {:.3e} (keep dt <= t_c/10)",
                            self.dt,
                            self.contact_time()
                        ),
                    });
                }
            }
        }
        Ok(())
    }

    pub fn check_finite(&self) -> Result<()> {
        let p = &self.p;
        // one branch-free pass (vectorised; a parallel search cost ~0.1 ms a check in rayon's
        // splitting at 7k particles), then the first bad particle only if there is one
        let finite = |a: &[crate::V3]| {
            a.iter().fold(true, |ok, c| {
                ok & c.x.is_finite() & c.y.is_finite() & c.z.is_finite()
            })
        };
        let bad = if finite(&p.x) && finite(&p.v) && finite(&p.omega) {
            None
        } else {
            (0..p.len()).find(|&i| {
                let one = |a: &[crate::V3]| finite(&a[i..=i]);
                !(one(&p.x) && one(&p.v) && one(&p.omega))
            })
        };
        if let Some(i) = bad {
            return Err(Error::Instability {
                step: self.step,
                particles: vec![self.p.id[i] as usize],
                message: "a position or velocity became NaN or infinite".into(),
                cause: format!(
                    "dt = {:.3e} too large against the contact time t_c = {:.3e} \
                     (keep dt <= t_c/10), or an extreme overlap",
                    self.dt,
                    self.contact_time()
                ),
            });
        }
        Ok(())
    }
}
