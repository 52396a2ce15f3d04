//! The stress-controlled triclinic cell of 002_89269f1b918188b3 (Srivastava et al.) §2.2–2.3:
//! a fully periodic cell H (upper-triangular, columns = cell vectors) driven by an imposed
//! mean normal stress p_ext and shear stress tau_ext on xy, with the modularly-invariant
//! Parrinello–Rahman equations of motion (2.10a–d; Shinoda et al. 2004).
//!
//! Conventions. Stresses are compressive-positive (2.11: sigma = (1/V)[sum r_ij (x) f_ij +
//! sum m v' (x) v']). Particle velocities are stored as the peculiar velocities p_i/m_i of 2.10a
//! (`STREAMING`): contacts add L r_ij, L = P_g/W_g = dH/dt H^-1 (2.16). The imposed stress in
//! the compressive-positive convention is sigma_ext = p_ext I - tau_ext (e_x e_y + e_y e_x), so
//! that tau_ext > 0 drives dH_xy/dt > 0 (v_x = L_xy y).
//!
//! Driving (2.10d with the reference cell updated every step, as the paper does, so that
//! H Sigma H^T reduces to the imposed deviatoric stress): dP_g/dt = V (sigma_int - sigma_ext),
//! keeping only the upper-triangular part (with the symmetrised internal stress this prevents
//! cell rotation), and with the three diagonal entries all driven by the pressure difference
//! (tr sigma_int/3 - p_ext): the diagonal dilates or compacts isotropically (F_xx = F_yy = F_zz)
//! — 002 reports that balancing each sigma_ii separately is unstable.
//!
//! Integration (velocity-Verlet-like, time-reversible for the conservative part): half-kick of
//! P_g with the stress of the previous step, half-kick of the peculiar momenta with
//! f - L p - (tr L / 3N) p (2.10b), drift r += dt (v' + L r) and H += dt L H (so reduced
//! coordinates only change through v'), forces, half-kick of the momenta, new internal stress,
//! half-kick of P_g.
//!
//! Rate control (`drive_at_rate`, the protocol LAMMPS can run): the
//! xy entry of P_g is held at W_g rate (L_xy = rate, so dH_xy/dt = rate H_yy plus the breathing
//! L_xx H_xy), xz and yz at zero, and only the normal stress is driven as above: the pressure
//! (`Normal::Pressure`, the isotropic diagonal) or sigma_yy alone (`Normal::Gradient`, with
//! L_xx = L_zz = 0: LAMMPS's `fix deform/pressure` on y). The barostat's W_g sets how fast the
//! normal stress is followed, not its mean: the time integral of the drive is the change of
//! P_g, so the mean internal stress equals the target in any steady state.
//!
//! Flips: when |H_xy| > L_x/2 (or |H_xz| > L_x/2, |H_yz| > L_y/2) the cell is replaced by the
//! equivalent lattice (LAMMPS's flip): Cartesian positions, velocities and contact histories are
//! unchanged, image counters are remapped, the pair list is rebuilt. Contact forces do not
//! change (checked by a test).

use super::{Domain, StepMaps};
use crate::error::{Error, Result};
use crate::particles::Particles;
use crate::{M3, V3};

const MAGIC: f64 = 6_755_399_441_055_744.0;

/// Which normal stress a rate-controlled cell holds at p_ext.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Normal {
    /// The mean pressure tr(sigma)/3, with an isotropic dilation (as the stress-controlled cell).
    Pressure,
    /// sigma_yy, the gradient direction's, with the flow and vorticity lengths fixed.
    Gradient,
}

/// How the cell is driven: an imposed stress (002) or an imposed xy shear rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Control {
    Stress,
    Rate { rate: f64, normal: Normal },
}

#[derive(Clone, Debug)]
pub struct PrCell {
    pub h: M3,
    h_inv: M3,
    /// Cell momentum (upper-triangular).
    pub pg: M3,
    /// Cell mass W_g = N kn a^2 / omega_g^2.
    pub wg: f64,
    pub p_ext: f64,
    pub tau_ext: f64,
    pub control: Control,
    /// Driving of the last completed step, V (sigma_int - sigma_ext) (projected).
    drive: M3,
    /// Internal stress of the last completed step (contact part, kinetic part).
    pub sigma_c: M3,
    pub sigma_k: M3,
    pub flips: u64,
    /// `flips` at the last neighbour build.
    flips_build: u64,
    n: usize,
    /// Smallest volume seen (for the runaway-dilation guard) and the largest diameter.
    v_ref: f64,
    pub d_max: f64,
}

/// The imposed stress a cell accepts: p_ext > 0, |tau_ext/p_ext| <= 2.
fn check_stress(p_ext: f64, tau_ext: f64) -> Result<()> {
    crate::error::check_positive("p_ext", p_ext)?;
    if !(tau_ext.is_finite() && tau_ext.abs() <= 2.0 * p_ext) {
        return Err(Error::param(
            "tau_ext/p_ext",
            tau_ext / p_ext,
            "|tau_ext/p_ext| <= 2 (beyond, no dense steady flow: the cell accelerates)",
        ));
    }
    Ok(())
}

/// Whether a rate-controlled cell with `normal` drives the cell momentum's entry (a, b).
fn drives(normal: Normal, a: usize, b: usize) -> bool {
    match normal {
        Normal::Pressure => a == b,
        Normal::Gradient => a == 1 && b == 1,
    }
}

fn upper(m: &M3) -> M3 {
    let mut u = *m;
    u[(1, 0)] = 0.0;
    u[(2, 0)] = 0.0;
    u[(2, 1)] = 0.0;
    u
}

impl PrCell {
    /// A cubic cell of side `l` around the particles, at rest.
    pub fn new(l: f64, n: usize, wg: f64, p_ext: f64, tau_ext: f64) -> Result<Self> {
        crate::error::check_positive("cell length", l)?;
        check_stress(p_ext, tau_ext)?;
        crate::error::check_positive("W_g (cell mass)", wg)?;
        if n < 50 {
            return Err(Error::param(
                "N",
                n,
                ">= 50 particles for the periodic cell",
            ));
        }
        let h = M3::from_diagonal(&V3::new(l, l, l));
        Ok(PrCell {
            h,
            h_inv: h.try_inverse().unwrap(),
            pg: M3::zeros(),
            wg,
            p_ext,
            tau_ext,
            control: Control::Stress,
            drive: M3::zeros(),
            sigma_c: M3::zeros(),
            sigma_k: M3::zeros(),
            flips: 0,
            flips_build: 0,
            n,
            v_ref: l * l * l,
            d_max: 0.0,
        })
    }

    pub fn l_grad(&self) -> M3 {
        self.pg / self.wg
    }

    /// Replace the cell matrix (upper-triangular).
    pub fn set_h(&mut self, h: M3) {
        self.h = h;
        self.h_inv = h.try_inverse().expect("cell matrix became singular");
    }

    pub fn sigma_ext(&self) -> M3 {
        let mut s = M3::from_diagonal(&V3::new(self.p_ext, self.p_ext, self.p_ext));
        s[(0, 1)] = -self.tau_ext;
        s[(1, 0)] = -self.tau_ext;
        s
    }

    /// The particles' maps at the current cell momentum: the half-kick's drag l = p_g / W_g
    /// with its trace term, and a drift over `dt` (r += dt (v' + L r); H += dt L H: reduced
    /// coordinates move only with v').
    fn maps(&self, dt: f64) -> StepMaps {
        let l = self.l_grad();
        StepMaps {
            l,
            tr: l.trace() / (3.0 * self.n as f64),
            a: M3::identity() + dt * l,
        }
    }

    fn update_drive(&mut self, virial: &M3, kin: &M3) {
        let v = self.volume();
        self.sigma_c = virial / v;
        self.sigma_k = kin / v;
        let sig = self.sigma_c + self.sigma_k;
        let sym = 0.5 * (sig + sig.transpose());
        self.drive = match self.control {
            Control::Stress => {
                let mut g = v * (sym - self.sigma_ext());
                let piso = v * (sym.trace() / 3.0 - self.p_ext);
                for k in 0..3 {
                    g[(k, k)] = piso;
                }
                upper(&g)
            }
            // (once a step on a 3x3 matrix: the particle passes are the same for both)
            Control::Rate { normal, .. } => {
                let mut g = M3::zeros();
                match normal {
                    Normal::Pressure => {
                        let piso = v * (sym.trace() / 3.0 - self.p_ext);
                        for k in 0..3 {
                            g[(k, k)] = piso;
                        }
                    }
                    Normal::Gradient => g[(1, 1)] = v * (sym[(1, 1)] - self.p_ext),
                }
                g
            }
        };
    }

    /// Drive the cell at the xy shear rate `rate` (= L_xy = dv_x/dy, >= 0) with the normal
    /// stress `normal` held at `p_ext`, from the next step on (module docs). The cell's
    /// momentum takes the rate at once; for `Normal::Gradient` the x and z lengths stop.
    pub fn drive_at_rate(&mut self, rate: f64, normal: Normal, p_ext: f64) -> Result<()> {
        crate::error::check_positive("p_ext", p_ext)?;
        if !(rate.is_finite() && rate >= 0.0) {
            return Err(Error::param(
                "shear rate",
                rate,
                "a finite rate >= 0 (dv_x/dy; the sign of the flow is +x at +y)",
            ));
        }
        self.control = Control::Rate { rate, normal };
        self.p_ext = p_ext;
        self.tau_ext = 0.0;
        // What this control does not drive stops: the cell momentum's entries (but xy, held at
        // the rate) and the last step's drive, which the next half-kick uses (after a restore
        // that is the drive as saved, so restarts stay bitwise; at the switch from the stress
        // control, sigma_yy's first half-kick is the pressure's).
        for a in 0..3 {
            for b in a..3 {
                if !drives(normal, a, b) {
                    self.drive[(a, b)] = 0.0;
                    self.pg[(a, b)] = 0.0;
                }
            }
        }
        self.pg[(0, 1)] = self.wg * rate;
        Ok(())
    }

    /// Remap the cell to the equivalent lattice with the smallest tilts.
    fn flip(&mut self, p: &mut Particles) -> bool {
        let mut h = self.h;
        let mut flipped = false;
        // yz first (it changes xz by xy), then xz, then xy
        let ly = h[(1, 1)];
        if h[(1, 2)].abs() > 0.5 * ly {
            let s = (h[(1, 2)] / ly).round();
            h[(1, 2)] -= s * ly;
            h[(0, 2)] -= s * h[(0, 1)];
            for im in p.image.iter_mut() {
                im[1] += s as i32 * im[2];
            }
            flipped = true;
        }
        let lx = h[(0, 0)];
        if h[(0, 2)].abs() > 0.5 * lx {
            let s = (h[(0, 2)] / lx).round();
            h[(0, 2)] -= s * lx;
            for im in p.image.iter_mut() {
                im[0] += s as i32 * im[2];
            }
            flipped = true;
        }
        if h[(0, 1)].abs() > 0.5 * lx {
            let s = (h[(0, 1)] / lx).round();
            h[(0, 1)] -= s * lx;
            for im in p.image.iter_mut() {
                im[0] += s as i32 * im[1];
            }
            flipped = true;
        }
        if flipped {
            self.set_h(h);
            self.flips += 1;
        }
        flipped
    }
}

impl Domain for PrCell {
    const NAME: &'static str = "triclinic cell (Parrinello-Rahman, imposed stress)";
    const NEEDS_VIRIAL: bool = true;
    const STREAMING: bool = true;
    const PLAIN_NVE: bool = false;

    fn periodic(&self) -> [bool; 3] {
        [true; 3]
    }
    #[inline(always)]
    fn streaming_map(&self) -> (M3, f64) {
        (self.pg, self.wg)
    }
    #[inline(always)]
    fn delta(&self, xi: &V3, xj: &V3) -> V3 {
        let mut s = self.h_inv * (xi - xj);
        for k in 0..3 {
            s[k] -= (s[k] + MAGIC) - MAGIC;
        }
        self.h * s
    }
    fn wrap(&self, x: &mut V3, image: &mut [i32; 3]) {
        let mut s = self.h_inv * *x;
        let mut moved = false;
        for k in 0..3 {
            let f = s[k].floor();
            if f != 0.0 {
                s[k] -= f;
                image[k] += f as i32;
                moved = true;
            }
        }
        if moved {
            *x = self.h * s;
        }
    }
    fn frac(&self, x: &V3) -> V3 {
        let s = self.h_inv * x;
        s.map(|c| (c - c.floor()).clamp(0.0, 1.0 - 1e-12))
    }
    fn widths(&self) -> V3 {
        let a = self.h.column(0).into_owned();
        let b = self.h.column(1).into_owned();
        let c = self.h.column(2).into_owned();
        let v = self.volume();
        V3::new(
            v / b.cross(&c).norm(),
            v / c.cross(&a).norm(),
            v / a.cross(&b).norm(),
        )
    }
    fn volume(&self) -> f64 {
        self.h.determinant()
    }
    fn h(&self) -> M3 {
        self.h
    }
    fn origin(&self) -> V3 {
        V3::zeros()
    }

    fn begin_step(&mut self, dt: f64) -> StepMaps {
        self.pg += (0.5 * dt) * self.drive;
        self.maps(dt)
    }

    fn after_drift(&mut self, m: &StepMaps, p: &mut Particles) {
        let h = upper(&(m.a * self.h));
        self.set_h(h);
        self.flip(p);
    }

    fn final_kick(&self) -> StepMaps {
        self.maps(0.0)
    }

    fn end_step(&mut self, dt: f64, virial: &M3, kinetic: &M3) {
        self.update_drive(virial, kinetic);
        self.pg += (0.5 * dt) * self.drive;
        self.v_ref = self.v_ref.min(self.volume());
    }

    fn check(&self, step: u64) -> Result<()> {
        // A stress ratio above what the material can sustain makes the cell dilate and shear
        // without bound (a run that keeps accelerating); stop it before the packing dissolves.
        let phi_ratio = self.v_ref / self.volume();
        if phi_ratio < 0.05 {
            let (driving, cause) = match self.control {
                Control::Stress => (
                    format!("tau_ext/p_ext = {:.3}", self.tau_ext / self.p_ext),
                    "the imposed stress ratio is above the largest the material sustains in \
                     steady flow: the flow accelerates and dilutes (not steady, not averaged)",
                ),
                Control::Rate { rate, .. } => (
                    format!("shear rate {rate:.3e} at p_ext = {:.3e}", self.p_ext),
                    "the imposed rate is too fast for the normal stress: the cell dilutes to a \
                     gas (lower the rate or raise p_ext)",
                ),
            };
            return Err(Error::Instability {
                step,
                particles: vec![],
                message: format!(
                    "the cell dilated {:.0}-fold from its densest state ({driving})",
                    1.0 / phi_ratio,
                ),
                cause: cause.into(),
            });
        }
        let w = self.widths();
        let lmin = w.x.min(w.y).min(w.z);
        if lmin < 3.0 * self.d_max {
            return Err(Error::Instability {
                step,
                particles: vec![],
                message: format!("the cell became too thin: smallest width {lmin:.3} < 3 d_max"),
                cause: "a collapse of the cell under the imposed stress (too few particles, or \
                        p_ext too large for kn)"
                    .into(),
            });
        }
        Ok(())
    }

    fn affine_rate(&self) -> f64 {
        // the Frobenius norm bounds the operator norm
        self.l_grad().norm()
    }
    fn rebuild_due(&self, _skin: f64) -> bool {
        // A pair's image shift H n moves with the cell, which the lists' displacement bound
        // counts (`affine_rate`); a flip changes the lattice basis and so every image code.
        self.flips != self.flips_build
    }
    fn on_rebuild(&mut self) {
        self.flips_build = self.flips;
    }
    fn set_stress(&mut self, p_ext: f64, tau_ext: f64) -> Result<()> {
        check_stress(p_ext, tau_ext)?;
        self.p_ext = p_ext;
        self.tau_ext = tau_ext;
        self.control = Control::Stress;
        Ok(())
    }
    fn set_rate(&mut self, rate: f64, gradient: bool, p_ext: f64) -> Result<()> {
        let normal = if gradient {
            Normal::Gradient
        } else {
            Normal::Pressure
        };
        self.drive_at_rate(rate, normal, p_ext)
    }
    fn observables(&self) -> Vec<(String, f64)> {
        let ax = ["x", "y", "z"];
        let mut out = Vec::new();
        let l = self.l_grad();
        for (name, m) in [
            ("L", &l),
            ("sigma_c", &self.sigma_c),
            ("sigma_k", &self.sigma_k),
        ] {
            for a in 0..3 {
                for b in 0..3 {
                    out.push((format!("{name}_{}{}", ax[a], ax[b]), m[(a, b)]));
                }
            }
        }
        out.push(("tilt_flips".into(), self.flips as f64));
        out
    }
    fn save_state(&self) -> Vec<f64> {
        let mut v = Vec::with_capacity(40);
        v.extend(self.h.iter());
        v.extend(self.pg.iter());
        v.extend(self.drive.iter());
        // (the slot of the cell at the last build, which earlier versions kept)
        v.extend(self.h.iter());
        v.push(self.flips as f64);
        v
    }
    fn load_state(&mut self, s: &[f64]) -> Result<()> {
        if s.len() != 37 {
            return Err(Error::Io {
                message: "checkpoint: cell state has the wrong size".into(),
            });
        }
        self.set_h(M3::from_column_slice(&s[0..9]));
        self.pg = M3::from_column_slice(&s[9..18]);
        self.drive = M3::from_column_slice(&s[18..27]);
        self.flips = s[36] as u64;
        // (checkpoints are written between steps, when a flip has had its rebuild)
        self.flips_build = self.flips;
        Ok(())
    }
}
