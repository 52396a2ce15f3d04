//! The time step, generic over its parts: contact law (form `F`, friction `T`), domain `D`,
//! walls `W` and body force `G`. A scene without walls or gravity has none of their code in its
//! step (`W::ON`, `G::ON` are constants, so the branches compile away).
//!
//! One step (velocity Verlet, as LAMMPS `nve/sphere`):
//! 1. half-kick and drift (the domain integrates: a deforming cell moves particles too);
//! 2. wrap into the cell; rebuild the pair list if a particle moved more than half the skin;
//! 3. pair forces into a per-pair buffer (parallel over fixed chunks of pairs), then each particle
//!    gathers its pairs in list order plus walls and gravity (parallel over fixed chunks of
//!    particles). Every floating-point sum has an order that does not depend on the thread count,
//!    so 1 and 2 threads give the same bits;
//! 4. second half-kick (and the cell's momentum update).

use crate::contact::{Form, Friction, Law, LawParams};
use crate::domain::Domain;
use crate::error::{Error, Result};
use crate::neighbor::{image_shifts, NeighborList, CHUNK};
use crate::particles::Particles;
use crate::{M3, V3};
use rayon::prelude::*;
use std::time::Instant;

/// Most planar walls a scene can have (two side walls and a temporary floor).
pub const MAX_WALLS: usize = 3;

/// A planar wall: the plane x[axis] = pos, particles on the side `sign` (+1: x > pos).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    pub axis: usize,
    pub pos: f64,
    pub sign: f64,
}

/// Walls as a component. `NoWalls` compiles to nothing.
pub trait Walls<F: Form, T: Friction>: Clone + Send + Sync + 'static {
    const ON: bool;
    fn planes(&self) -> &[Plane];
    fn law(&self) -> Option<&Law<F, T>>;
}

#[derive(Clone, Copy, Debug, Default)]
pub struct NoWalls;
impl<F: Form, T: Friction> Walls<F, T> for NoWalls {
    const ON: bool = false;
    fn planes(&self) -> &[Plane] {
        &[]
    }
    fn law(&self) -> Option<&Law<F, T>> {
        None
    }
}

/// Flat frictional walls (planes of infinite mass) with their own law and per-particle history.
#[derive(Clone, Debug)]
pub struct PlaneWalls<F: Form, T: Friction> {
    pub planes: Vec<Plane>,
    pub law: Law<F, T>,
}

impl<F: Form, T: Friction> PlaneWalls<F, T> {
    pub fn new(planes: Vec<Plane>, params: LawParams) -> Result<Self> {
        if planes.len() > MAX_WALLS {
            return Err(Error::param(
                "walls",
                planes.len(),
                format!("at most {MAX_WALLS}"),
            ));
        }
        params.validate("wall_")?;
        Ok(PlaneWalls {
            planes,
            law: Law::new(params)?,
        })
    }
}

impl<F: Form, T: Friction> Walls<F, T> for PlaneWalls<F, T> {
    const ON: bool = true;
    fn planes(&self) -> &[Plane] {
        &self.planes
    }
    fn law(&self) -> Option<&Law<F, T>> {
        Some(&self.law)
    }
}

/// Uniform body force per unit mass (gravity) as a component.
pub trait Body: Clone + Send + Sync + 'static {
    const ON: bool;
    fn g(&self) -> V3;
}
#[derive(Clone, Copy, Debug, Default)]
pub struct NoBody;
impl Body for NoBody {
    const ON: bool = false;
    fn g(&self) -> V3 {
        V3::zeros()
    }
}
#[derive(Clone, Copy, Debug)]
pub struct Gravity(pub V3);
impl Body for Gravity {
    const ON: bool = true;
    fn g(&self) -> V3 {
        self.0
    }
}

/// A raw pointer that work units share; each writes only the entries it owns.
#[derive(Clone, Copy)]
struct SyncPtr<T>(*mut T);
unsafe impl<T> Sync for SyncPtr<T> {}
unsafe impl<T> Send for SyncPtr<T> {}
impl<T> SyncPtr<T> {
    fn get(self) -> *mut T {
        self.0
    }
}

/// Result of a cross pair: force on i, and q = -(r/(R_i+R_j)) n x F_t so that the torques are
/// R_i q on i and R_j q on j.
#[derive(Clone, Copy, Debug, Default)]
pub struct PairOut {
    pub f: V3,
    pub q: V3,
}

/// What the last force evaluation saw (for guards, diagnostics and samplers).
#[derive(Clone, Debug, Default)]
pub struct StepDiag {
    /// Largest overlap / (pair mean diameter) among pair and wall contacts.
    pub max_overlap: f64,
    /// Particle indices (current order) of that contact (wall: second is usize::MAX).
    pub max_overlap_at: (usize, usize),
    /// Total force exerted by the particles on each wall (minus the force on the particles).
    pub wall_force: [V3; MAX_WALLS],
    /// sum over pairs of r_ij (x) f_ij (computed when the domain needs it or `want_virial`).
    pub virial: M3,
    pub contacts: usize,
}

/// Wall-clock seconds spent in each part of the step (cheap: a few clock reads per step).
#[derive(Clone, Debug, Default)]
pub struct Timers {
    pub integrate: f64,
    pub neighbor: f64,
    pub forces: f64,
    pub pair_phase: f64,
    pub gather_phase: f64,
}

/// Run-time guards: stop with a clear error instead of writing NaN.
#[derive(Clone, Debug)]
pub struct Guards {
    /// Largest overlap allowed, as a fraction of the pair mean diameter.
    pub max_overlap: f64,
    /// Check positions and velocities for NaN/inf every this many steps.
    pub check_every: u64,
}
impl Default for Guards {
    fn default() -> Self {
        Guards {
            max_overlap: 0.25,
            check_every: 50,
        }
    }
}

pub struct Engine<F: Form, T: Friction, D: Domain, W: Walls<F, T>, G: Body> {
    pub p: Particles,
    pub law: Law<F, T>,
    pub domain: D,
    pub walls: W,
    pub body: G,
    pub nl: NeighborList<T>,
    /// Per-particle wall histories (empty without walls; zero-sized without friction).
    pub wall_hist: Vec<[T::History; MAX_WALLS]>,
    pub dt: f64,
    pub step: u64,
    pub time: f64,
    pub guards: Guards,
    pub diag: StepDiag,
    pub timers: Timers,
    /// Per-step packed copies for the pair loop: (x, R) in one 32-byte record for the distance
    /// test, and (predicted v, m, predicted w) in one 64-byte line for contacts, so a
    /// neighbour costs one or two cache lines instead of one per array.
    pub(crate) xr: Vec<[f64; 4]>,
    pub(crate) kin: Vec<[f64; 8]>,
    /// Ask the next force evaluation for the virial (samplers set this).
    pub want_virial: bool,
    /// Ask the next force evaluation for per-particle contact sums (samplers set this).
    pub want_stats: bool,
    /// Time integral of the force the particles exert on each wall (trapezoid rule, which is
    /// exactly what velocity Verlet applies to the particles): momentum balances close to
    /// round-off.
    pub wall_impulse: [V3; MAX_WALLS],
    /// Per particle (internal order), from the last evaluation with `want_stats`: the contact
    /// stress sum S_i = sum_j r_ij (x) f_ij / 2 (+ r (x) f in full for wall contacts; r from the
    /// contact point to the centre), row-major, then the power P_i = sum_j f_ij . v_ij / 2
    /// (+ wall contacts in full; negative when dissipating).
    pub pstats: Vec<[f64; 10]>,
    /// Forces of the cross pairs (see [`crate::neighbor::CHUNK`]) of the last evaluation.
    pub(crate) cross: Vec<PairOut>,
    /// Their stress/power records when `want_stats`.
    cross_stats: Vec<[f64; 10]>,
    /// 1 where the pair was in contact at the last evaluation (list order). Lets the force loop
    /// touch a pair's output and history only when it is or just was in contact; `pair_out` is
    /// zero for every pair not in contact.
    pub in_contact: Vec<u8>,
    /// Total energy at the first guard check (closed systems only).
    energy_ref: Option<f64>,
    forces_valid: bool,
}

/// Contact duration of the stiffest, lightest pair for a law and a particle set.
pub fn min_contact_time(params: &LawParams, p: &Particles) -> Result<f64> {
    let m = p.min_mass();
    params.contact_time(0.5 * m)
}

impl<F: Form, T: Friction, D: Domain, W: Walls<F, T>, G: Body> Engine<F, T, D, W, G> {
    /// Build an engine. `dt = None` picks t_c/50 of the stiffest, lightest pair.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        p: Particles,
        law: LawParams,
        domain: D,
        walls: W,
        body: G,
        dt: Option<f64>,
        skin: f64,
    ) -> Result<Self> {
        if p.is_empty() {
            return Err(Error::param("particles", 0, "at least 1 particle"));
        }
        let law = Law::<F, T>::new(law)?;
        let tc = min_contact_time(&law.params, &p)?;
        if let Some(wl) = walls.law() {
            // wall contacts: m_eff = m (infinite wall mass); check they are not over-damped
            wl.params.contact_time(p.min_mass())?;
        }
        let dt = match dt {
            None => tc / 50.0,
            Some(dt) => {
                if !(dt.is_finite() && dt > 0.0) {
                    return Err(Error::param("dt", dt, "a finite number > 0"));
                }
                if dt > tc / 10.0 {
                    return Err(
                        Error::param("dt", dt, format!("<= t_c/10 = {:.4e}", tc / 10.0)).with_hint(
                            format!(
                            "t_c = {tc:.4e} is the contact time of the stiffest, lightest pair; \
                             the default dt is t_c/50"
                        ),
                        ),
                    );
                }
                dt
            }
        };
        if !(skin.is_finite() && skin >= 0.0) {
            return Err(Error::param("skin", skin, "a finite number >= 0"));
        }
        let rmax = p.max_radius();
        let w = domain.widths();
        for k in 0..3 {
            if domain.periodic()[k] && w[k] < 2.0 * (2.0 * rmax + skin) {
                return Err(Error::param(
                    format!("box width along axis {k}"),
                    w[k],
                    format!(
                        ">= 2 (d_max + skin) = {:.4} for a periodic axis",
                        2.0 * (2.0 * rmax + skin)
                    ),
                )
                .with_hint("the box is too small for the largest particle"));
            }
            if !domain.periodic()[k] && w[k] < 2.0 * rmax {
                return Err(Error::param(
                    format!("box width along axis {k}"),
                    w[k],
                    format!(">= d_max = {:.4}", 2.0 * rmax),
                ));
            }
        }
        let n = p.len();
        let wall_hist = if W::ON {
            vec![[T::History::default(); MAX_WALLS]; n]
        } else {
            Vec::new()
        };
        let mut e = Engine {
            p,
            law,
            domain,
            walls,
            body,
            nl: NeighborList::new(skin),
            wall_hist,
            dt,
            step: 0,
            time: 0.0,
            guards: Guards::default(),
            diag: StepDiag::default(),
            timers: Timers::default(),
            xr: Vec::new(),
            kin: Vec::new(),
            want_virial: false,
            want_stats: false,
            wall_impulse: [V3::zeros(); MAX_WALLS],
            pstats: Vec::new(),
            cross: Vec::new(),
            cross_stats: Vec::new(),
            in_contact: Vec::new(),
            energy_ref: None,
            forces_valid: false,
        };
        e.wrap_all();
        e.rebuild();
        e.compute_forces_setup();
        if e.diag.max_overlap > e.guards.max_overlap {
            let (i, j) = e.diag.max_overlap_at;
            let who = if j == usize::MAX {
                format!("particle {} and a wall", e.p.id[i])
            } else {
                format!("particles {} and {}", e.p.id[i], e.p.id[j])
            };
            return Err(Error::Configuration {
                message: format!(
                    "initial configuration: {who} overlap by {:.3} of their mean diameter, above \
                     the allowed {:.3} (max_overlap); relax or re-generate the packing",
                    e.diag.max_overlap, e.guards.max_overlap
                ),
            });
        }
        Ok(e)
    }

    /// Contact time of the stiffest, lightest pair.
    pub fn contact_time(&self) -> f64 {
        min_contact_time(&self.law.params, &self.p).unwrap_or(f64::NAN)
    }

    pub fn wrap_all(&mut self) {
        let dom = &self.domain;
        self.p
            .x
            .par_iter_mut()
            .zip(self.p.image.par_iter_mut())
            .with_min_len(4096)
            .for_each(|(x, im)| dom.wrap(x, im));
    }

    /// Wrap into the cell and rebuild the pair list (positions are wrapped only here, so
    /// each pair's periodic image stays fixed between builds).
    pub fn rebuild(&mut self) {
        self.wrap_all();
        let perm = self.nl.build(&mut self.p, &self.domain);
        if !perm.is_empty() && W::ON {
            let old = std::mem::take(&mut self.wall_hist);
            self.wall_hist = perm.iter().map(|&k| old[k]).collect();
        }
        self.domain.on_rebuild();
        let np = self.nl.len();
        self.cross.clear();
        self.cross.resize(self.nl.n_cross(), PairOut::default());
        // carried histories belong to open contacts: mark them so they are reset if the
        // contact turns out to be open at the next evaluation
        self.in_contact.clear();
        if T::FRICTIONAL {
            let zero = T::History::default();
            self.in_contact
                .extend(self.nl.hist.iter().map(|h| (*h != zero) as u8));
        } else {
            self.in_contact.resize(np, 0);
        }
    }

    /// Forces in `p` correspond to the state (after loading a checkpoint).
    pub fn mark_forces_valid(&mut self) {
        self.forces_valid = true;
    }

    /// Mark the state as changed from outside (positions or velocities set by the user).
    pub fn invalidate(&mut self) {
        self.energy_ref = None;
        self.nl.valid = false;
        self.forces_valid = false;
    }

    /// Make sure forces correspond to the current state (needed before the first step).
    pub fn ensure_forces(&mut self) -> Result<()> {
        if !self.forces_valid {
            // velocities are full-step here: the dashpot's prediction must add nothing
            self.p.force.iter_mut().for_each(|f| *f = V3::zeros());
            self.p.torque.iter_mut().for_each(|t| *t = V3::zeros());
            self.wrap_all();
            if self.nl.needs_rebuild(&self.p, &self.domain) {
                self.rebuild();
            }
            self.compute_forces_setup();
            self.check_overlap()?;
        }
        Ok(())
    }

    /// Advance `n` steps.
    pub fn run(&mut self, n: u64) -> Result<()> {
        self.ensure_forces()?;
        for _ in 0..n {
            self.step_once()?;
        }
        Ok(())
    }

    fn step_once(&mut self) -> Result<()> {
        let dt = self.dt;
        let t0 = Instant::now();
        self.domain.integrate_initial(&mut self.p, dt);
        self.domain.check(self.step)?;
        // one pass: displacement since the last build, packed records for the pair loop
        let moved = self.check_and_pack();
        let t1 = Instant::now();
        if moved || !self.nl.valid || self.domain.rebuild_due(self.nl.skin) {
            self.rebuild();
            self.pack();
        }
        let t2 = Instant::now();
        let wf_old = self.diag.wall_force;
        self.evaluate(dt);
        if W::ON {
            for (w, imp) in self.wall_impulse.iter_mut().enumerate() {
                *imp += 0.5 * dt * (wf_old[w] + self.diag.wall_force[w]);
            }
        }
        let t3 = Instant::now();
        let vir = self.diag.virial;
        self.domain.integrate_final(&mut self.p, dt, &vir);
        let t4 = Instant::now();
        let tm = &mut self.timers;
        tm.integrate += (t1 - t0).as_secs_f64() + (t4 - t3).as_secs_f64();
        tm.neighbor += (t2 - t1).as_secs_f64();
        tm.forces += (t3 - t2).as_secs_f64();
        self.step += 1;
        self.time += dt;
        self.check_overlap()?;
        if self.step.is_multiple_of(self.guards.check_every) {
            self.check_finite()?;
            if D::CLOSED && !G::ON {
                self.check_energy()?;
            }
        }
        Ok(())
    }

    /// Pair contacts of the last evaluation in internal indices: (i, j, r_ij, force on i),
    /// recomputed from the positions, the velocities the evaluation used and the stored
    /// histories (without advancing them), so no per-pair force needs to be kept between steps.
    pub fn contact_list(&self) -> Vec<(usize, usize, V3, V3)> {
        let n = self.p.len();
        let p = &self.p;
        let kin_ok = self.kin.len() == n;
        let vel = |i: usize| -> (V3, V3) {
            if kin_ok {
                let k = &self.kin[i];
                (V3::new(k[0], k[1], k[2]), V3::new(k[4], k[5], k[6]))
            } else {
                (p.v[i], p.omega[i])
            }
        };
        let nl = &self.nl;
        let mut out = Vec::with_capacity(self.diag.contacts);
        for i in 0..n {
            for k in nl.own_start[i] as usize..nl.own_start[i + 1] as usize {
                let j = nl.pair_j[k] as usize;
                let d = self.domain.delta(&p.x[i], &p.x[j]);
                let (ri, rj) = (p.radius[i], p.radius[j]);
                let rs = ri + rj;
                let r = d.norm();
                if r >= rs {
                    continue;
                }
                let nrm = d / r;
                let meff = 1.0 / (p.inv_mass[i] + p.inv_mass[j]);
                let arm = r / rs;
                let ((vi, wi), (vj, wj)) = (vel(i), vel(j));
                let mut vrel = vi - vj - (arm * (ri * wi + rj * wj)).cross(&nrm);
                if D::STREAMING {
                    vrel += self.domain.streaming_velocity(&d);
                }
                let mut h = nl.hist[k];
                let pf = self.law.eval(&nrm, rs - r, rs, meff, &vrel, &mut h, 0.0);
                out.push((i, j, d, pf.f));
            }
        }
        out
    }

    /// Packed per-step records: (x, R) and the velocities predicted to the end of the step,
    /// v(n+1/2) + dt/2 a(n) (and the same for w), with 1/m.
    fn pack(&mut self) {
        let n = self.p.len();
        let hdt = 0.5 * self.dt;
        let p = &self.p;
        self.xr.resize(n, [0.0; 4]);
        self.kin.resize(n, [0.0; 8]);
        self.xr
            .par_chunks_mut(CHUNK)
            .zip(self.kin.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, (a, b))| {
                for l in 0..a.len() {
                    let i = c * CHUNK + l;
                    let x = p.x[i];
                    a[l] = [x.x, x.y, x.z, p.radius[i]];
                    let v = p.v[i] + (hdt * p.inv_mass[i]) * p.force[i];
                    let w = p.omega[i] + (hdt * p.inv_inertia[i]) * p.torque[i];
                    b[l] = [v.x, v.y, v.z, p.inv_mass[i], w.x, w.y, w.z, 0.0];
                }
            });
    }

    /// Pack the step records; true if some particle moved more than half the skin since the
    /// last build (the list must be rebuilt).
    fn check_and_pack(&mut self) -> bool {
        let n = self.p.len();
        if self.nl.x_build.len() != n {
            return true;
        }
        let hdt = 0.5 * self.dt;
        let lim = 0.25 * self.nl.skin * self.nl.skin;
        let dom = &self.domain;
        let xb = &self.nl.x_build;
        self.xr.resize(n, [0.0; 4]);
        self.kin.resize(n, [0.0; 8]);
        let p = &self.p;
        let (v, om, f, t) = (&p.v, &p.omega, &p.force, &p.torque);
        let (rad, im, ii) = (&p.radius, &p.inv_mass, &p.inv_inertia);
        let x = &p.x;
        self.xr
            .par_chunks_mut(CHUNK)
            .zip(self.kin.par_chunks_mut(CHUNK))
            .enumerate()
            .map(|(c, (a, b))| {
                let mut moved = false;
                for l in 0..a.len() {
                    let i = c * CHUNK + l;
                    let xi = x[i];
                    moved |= dom.delta(&xi, &xb[i]).norm_squared() > lim;
                    a[l] = [xi.x, xi.y, xi.z, rad[i]];
                    let vp = v[i] + (hdt * im[i]) * f[i];
                    let wp = om[i] + (hdt * ii[i]) * t[i];
                    b[l] = [vp.x, vp.y, vp.z, im[i], wp.x, wp.y, wp.z, 0.0];
                }
                moved
            })
            .reduce(|| false, |a, b| a || b)
    }

    fn check_overlap(&self) -> Result<()> {
        let d = &self.diag;
        if d.max_overlap.is_nan() || d.max_overlap > self.guards.max_overlap {
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
    fn check_energy(&mut self) -> Result<()> {
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
        let bad = self
            .p
            .x
            .par_iter()
            .zip(self.p.v.par_iter())
            .zip(self.p.omega.par_iter())
            .position_first(|((x, v), w)| {
                !(x.iter().all(|c| c.is_finite())
                    && v.iter().all(|c| c.is_finite())
                    && w.iter().all(|c| c.is_finite()))
            });
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

    /// Evaluate all forces and torques for the current positions and velocities, advancing
    /// the tangential histories by one step (the evaluation inside a time step).
    pub fn compute_forces(&mut self) {
        self.pack();
        self.evaluate(self.dt);
    }

    /// Evaluate forces without advancing any tangential history: no time has passed (the first
    /// evaluation, or after the state was set from outside). As LAMMPS's setup, which skips
    /// the history update.
    pub fn compute_forces_setup(&mut self) {
        self.pack();
        self.evaluate(0.0);
    }

    /// Forces from the packed records (`pack` or `wrap_and_pack` must have run). `hist_dt`: the
    /// time over which the histories are advanced (dt in a step, 0 at set-up).
    ///
    /// Phase 1, parallel over fixed chunks of particles: each chunk sweeps its particles in
    /// order; a pair inside the chunk is added to both particles at once (j > i, so j has all
    /// its in-chunk contributions from earlier particles before its own pairs are added); a
    /// pair reaching into a later chunk adds to i and writes its force to its cross slot. Walls
    /// and gravity are added by the owner. Phase 2 adds the cross slots to their second
    /// particles in list order. Every sum has one order fixed by the list.
    fn evaluate(&mut self, hist_dt: f64) {
        // the statistics and virial paths are compiled separately, so the plain step carries
        // none of their code (nor its register pressure)
        match (self.want_stats, D::NEEDS_VIRIAL || self.want_virial) {
            (false, false) => self.evaluate_with::<false, false>(hist_dt),
            (false, true) => self.evaluate_with::<false, true>(hist_dt),
            (true, false) => self.evaluate_with::<true, false>(hist_dt),
            (true, true) => self.evaluate_with::<true, true>(hist_dt),
        }
    }

    fn evaluate_with<const STATS: bool, const VIR: bool>(&mut self, hist_dt: f64) {
        let tstart = Instant::now();
        let dt = hist_dt;
        let want_vir = VIR;
        let want_stats = STATS;
        let n = self.p.len();
        let ncross = self.nl.n_cross();
        if self.cross.len() != ncross {
            self.cross.resize(ncross, PairOut::default());
        }
        if want_stats {
            self.pstats.clear();
            self.pstats.resize(n, [0.0; 10]);
            self.cross_stats.clear();
            self.cross_stats.resize(ncross, [0.0; 10]);
        }
        let law = &self.law;
        let dom = &self.domain;
        let g = self.body.g();
        let planes = self.walls.planes();
        let wlaw = self.walls.law();
        let nl = &mut self.nl;
        let own_start = &nl.own_start;
        let pair_j = &nl.pair_j;
        let pair_img = &nl.pair_img;
        let shifts = image_shifts(&dom.h());
        let xr = &self.xr;
        let kin = &self.kin;
        let mass = &self.p.mass;
        let nchunks = n.div_ceil(CHUNK);

        // split the per-pair and per-chunk arrays into the pieces each chunk owns
        struct Piece<'a, H, WH> {
            c: usize,
            hist: &'a mut [H],
            flag: &'a mut [u8],
            cross: &'a mut [PairOut],
            cstat: &'a mut [[f64; 10]],
            ps: &'a mut [[f64; 10]],
            wh: &'a mut [WH],
        }
        let mut pieces = Vec::with_capacity(nchunks);
        {
            let mut h: &mut [T::History] = &mut nl.hist;
            let mut fl: &mut [u8] = &mut self.in_contact;
            let mut cr: &mut [PairOut] = &mut self.cross;
            let mut cs: &mut [[f64; 10]] = &mut self.cross_stats;
            let mut ps: &mut [[f64; 10]] = &mut self.pstats;
            let mut wh: &mut [[T::History; MAX_WALLS]] = &mut self.wall_hist;
            for c in 0..nchunks {
                let i0 = c * CHUNK;
                let i1 = ((c + 1) * CHUNK).min(n);
                let np = (own_start[i1] - own_start[i0]) as usize;
                let nx = (nl.cross_off[c + 1] - nl.cross_off[c]) as usize;
                let (a, rest) = std::mem::take(&mut h).split_at_mut(np);
                h = rest;
                let (b, rest) = std::mem::take(&mut fl).split_at_mut(np);
                fl = rest;
                let (x, rest) = std::mem::take(&mut cr).split_at_mut(nx);
                cr = rest;
                let (cst, pst) = if want_stats {
                    let (u, rest) = std::mem::take(&mut cs).split_at_mut(nx);
                    cs = rest;
                    let (v, rest) = std::mem::take(&mut ps).split_at_mut(i1 - i0);
                    ps = rest;
                    (u, v)
                } else {
                    (&mut [][..], &mut [][..])
                };
                let w = if W::ON {
                    let (u, rest) = std::mem::take(&mut wh).split_at_mut(i1 - i0);
                    wh = rest;
                    u
                } else {
                    &mut [][..]
                };
                pieces.push(Piece {
                    c,
                    hist: a,
                    flag: b,
                    cross: x,
                    cstat: cst,
                    ps: pst,
                    wh: w,
                });
            }
        }

        let results: Vec<ChunkOut> = pieces
            .into_par_iter()
            .zip(self.p.force.par_chunks_mut(CHUNK))
            .zip(self.p.torque.par_chunks_mut(CHUNK))
            .map(|((pc, fo), to)| {
                let Piece {
                    c,
                    hist,
                    flag,
                    cross,
                    cstat,
                    ps,
                    wh,
                } = pc;
                let mut out = ChunkOut::default();
                let i0 = c * CHUNK;
                let i1 = i0 + fo.len();
                let base = own_start[i0] as usize;
                let mut xs = 0usize;
                fo.iter_mut().for_each(|f| *f = V3::zeros());
                to.iter_mut().for_each(|t| *t = V3::zeros());
                for i in i0..i1 {
                    let li = i - i0;
                    let (k0, k1) = (own_start[i] as usize, own_start[i + 1] as usize);
                    // in-chunk contributions of earlier particles are already in fo/to
                    let mut fsum = fo[li];
                    let mut tsum = to[li];
                    let [xi0, xi1, xi2, ri] = xr[i];
                    let xi = V3::new(xi0, xi1, xi2);
                    let ki = &kin[i];
                    let vi = V3::new(ki[0], ki[1], ki[2]);
                    let wi = V3::new(ki[4], ki[5], ki[6]);
                    let imi = ki[3];
                    for k in k0..k1 {
                        let kk = k - base;
                        // SAFETY: list indices are < n by construction (built from 0..n).
                        let j = unsafe { *pair_j.get_unchecked(k) } as usize;
                        let is_cross = j >= i1;
                        let [xj0, xj1, xj2, rj] = unsafe { *xr.get_unchecked(j) };
                        let sh =
                            unsafe { shifts.get_unchecked(*pair_img.get_unchecked(k) as usize) };
                        let d = V3::new(xi0 - xj0 - sh.x, xi1 - xj1 - sh.y, xi2 - xj2 - sh.z);
                        let r2 = d.norm_squared();
                        let rs = ri + rj;
                        if r2 >= rs * rs {
                            if unsafe { *flag.get_unchecked(kk) } != 0 {
                                // the contact just opened: drop its history
                                if T::FRICTIONAL {
                                    hist[kk] = T::History::default();
                                }
                                flag[kk] = 0;
                            }
                            // an open cross pair's slot is skipped by its flag in phase 2
                            xs += is_cross as usize;
                            continue;
                        }
                        unsafe { *flag.get_unchecked_mut(kk) = 1 };
                        out.contacts += 1;
                        let r = r2.sqrt();
                        let kj = unsafe { kin.get_unchecked(j) };
                        // one division for 1/r, 1/(R_i+R_j) and m_eff = 1/(1/m_i + 1/m_j)
                        let imj = kj[3];
                        let ims = imi + imj;
                        let q = 1.0 / (r * rs * ims);
                        let inv_r = rs * ims * q;
                        let inv_rs = r * ims * q;
                        let meff = r * rs * q;
                        let nrm = d * inv_r;
                        let delta = rs - r;
                        // Lever arms l_i = r R_i/(R_i+R_j), l_j = r R_j/(R_i+R_j): the contact
                        // point lies on the branch vector and l_i + l_j = r, which makes the
                        // pair torques conserve total angular momentum; for equal spheres this
                        // is exactly 002 (2.18b), (w_i + w_j) x r_ij / 2.
                        let arm = r * inv_rs;
                        // kin holds velocities predicted to the end of the step,
                        // v(n+1/2) + dt/2 a(n): the dashpot sees v(n+1) to O(dt^2) instead of
                        // the half-step velocity (plain velocity Verlet: O(dt) error in e_n).
                        let vj = V3::new(kj[0], kj[1], kj[2]);
                        let wj = V3::new(kj[4], kj[5], kj[6]);
                        let mut vrel = vi - vj - (arm * (ri * wi + rj * wj)).cross(&nrm);
                        if D::STREAMING {
                            vrel += dom.streaming_velocity(&d);
                        }
                        let pf = law.eval(
                            &nrm,
                            delta,
                            rs,
                            meff,
                            &vrel,
                            unsafe { hist.get_unchecked_mut(kk) },
                            dt,
                        );
                        let qv = -arm * nrm.cross(&pf.ft);
                        fsum += pf.f;
                        tsum += ri * qv;
                        if is_cross {
                            cross[xs] = PairOut { f: pf.f, q: qv };
                        } else {
                            let lj = j - i0;
                            fo[lj] -= pf.f;
                            to[lj] += rj * qv;
                        }
                        let ov = delta * inv_rs;
                        if ov > out.max_ov {
                            out.max_ov = ov;
                            out.at = (i, j);
                        }
                        if want_vir {
                            out.vir += d * pf.f.transpose();
                        }
                        if want_stats {
                            let half = 0.5 * d * pf.f.transpose();
                            let mut rec = [0.0; 10];
                            for (a, b) in rec.iter_mut().zip(half.transpose().iter()) {
                                *a = *b;
                            }
                            rec[9] = 0.5 * pf.f.dot(&vrel);
                            add10(&mut ps[li], &rec);
                            if is_cross {
                                cstat[xs] = rec;
                            } else {
                                add10(&mut ps[j - i0], &rec);
                            }
                        }
                        if is_cross {
                            xs += 1;
                        }
                    }
                    if W::ON {
                        let wl = wlaw.unwrap();
                        let hs = &mut wh[li];
                        for (w, pl) in planes.iter().enumerate() {
                            let gap = pl.sign * (xi[pl.axis] - pl.pos);
                            if gap >= ri {
                                // read before write: most particles never touch a wall
                                if T::FRICTIONAL && hs[w] != T::History::default() {
                                    hs[w] = T::History::default();
                                }
                                continue;
                            }
                            let mut nrm = V3::zeros();
                            nrm[pl.axis] = pl.sign;
                            let delta = ri - gap;
                            // contact point on the plane: lever arm = gap; predicted
                            // end-of-step velocities, as for pairs
                            let vrel = vi - (gap * wi).cross(&nrm);
                            let pf = wl.eval(&nrm, delta, 2.0 * ri, mass[i], &vrel, &mut hs[w], dt);
                            fsum += pf.f;
                            tsum -= gap * nrm.cross(&pf.ft);
                            out.wall_force[w] -= pf.f;
                            if want_stats {
                                // branch vector from the contact point on the wall to the centre
                                let full = (gap * nrm) * pf.f.transpose();
                                let acc = &mut ps[li];
                                for (a, b) in acc.iter_mut().zip(full.transpose().iter()) {
                                    *a += b;
                                }
                                acc[9] += pf.f.dot(&vrel);
                            }
                            let ov = delta / (2.0 * ri);
                            if ov > out.max_ov {
                                out.max_ov = ov;
                                out.at = (i, usize::MAX);
                            }
                        }
                    }
                    if G::ON {
                        fsum += mass[i] * g;
                    }
                    fo[li] = fsum;
                    to[li] = tsum;
                }
                debug_assert_eq!(xs, cross.len());
                let _ = &cross;
                out
            })
            .collect();

        let tp = Instant::now();
        let mut diag = StepDiag::default();
        for o in &results {
            if o.max_ov > diag.max_overlap {
                diag.max_overlap = o.max_ov;
                diag.max_overlap_at = o.at;
            }
            diag.virial += o.vir;
            diag.contacts += o.contacts;
            for (acc, w) in diag.wall_force.iter_mut().zip(&o.wall_force) {
                *acc += *w;
            }
        }

        // Phase 2: cross pairs onto their second particles, in list order.
        if ncross > 0 {
            let cross = &self.cross;
            let cstat = &self.cross_stats;
            let cs = &nl.cross_start;
            let slot = &nl.cross_slot;
            let cross_k = &nl.cross_k;
            let flags = &self.in_contact;
            let rad = &self.p.radius;
            let pstats_ptr = SyncPtr(self.pstats.as_mut_ptr());
            self.p
                .force
                .par_chunks_mut(CHUNK)
                .zip(self.p.torque.par_chunks_mut(CHUNK))
                .enumerate()
                .for_each(|(c, (fo, to))| {
                    let i0 = c * CHUNK;
                    for l in 0..fo.len() {
                        let i = i0 + l;
                        let (a, b) = (cs[i] as usize, cs[i + 1] as usize);
                        if a == b {
                            continue;
                        }
                        let mut f = fo[l];
                        let mut t = to[l];
                        for &s in &slot[a..b] {
                            if flags[cross_k[s as usize] as usize] != 0 {
                                let o = &cross[s as usize];
                                f -= o.f;
                                t += rad[i] * o.q;
                            }
                        }
                        fo[l] = f;
                        to[l] = t;
                        if want_stats {
                            // SAFETY: pstats has n entries when want_stats; i is owned here.
                            let acc = unsafe { &mut *pstats_ptr.get().add(i) };
                            for &s in &slot[a..b] {
                                if flags[cross_k[s as usize] as usize] != 0 {
                                    add10(acc, &cstat[s as usize]);
                                }
                            }
                        }
                    }
                });
        }
        self.diag = diag;
        self.forces_valid = true;
        self.want_stats = false;
        let te = Instant::now();
        self.timers.pair_phase += (tp - tstart).as_secs_f64();
        self.timers.gather_phase += (te - tp).as_secs_f64();
    }
}

/// What one chunk of the force loop reports.
#[derive(Default)]
struct ChunkOut {
    max_ov: f64,
    at: (usize, usize),
    vir: M3,
    contacts: usize,
    wall_force: [V3; MAX_WALLS],
}

#[inline(always)]
fn add10(acc: &mut [f64; 10], rec: &[f64; 10]) {
    for (a, b) in acc.iter_mut().zip(rec) {
        *a += b;
    }
}
