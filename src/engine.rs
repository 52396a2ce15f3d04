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
use crate::neighbor::NeighborList;
use crate::particles::Particles;
use crate::{M3, V3};
use rayon::prelude::*;
use std::time::Instant;

/// Particles per work unit of the gather loop.
const PART_CHUNK: usize = 1024;
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

/// Per-pair result of the force loop: force on i, and q = -(r/(R_i+R_j)) n x F_t so that the
/// torques are R_i q on i and R_j q on j.
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
    pair_power: Vec<f64>,
    /// Per-pair forces of the last evaluation (list order).
    pub pair_out: Vec<PairOut>,
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
            pair_power: Vec::new(),
            pair_out: Vec::new(),
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

    pub fn rebuild(&mut self) {
        let perm = self.nl.build(&mut self.p, &self.domain);
        if !perm.is_empty() && W::ON {
            let old = std::mem::take(&mut self.wall_hist);
            self.wall_hist = perm.iter().map(|&k| old[k]).collect();
        }
        self.domain.on_rebuild();
        let np = self.nl.len();
        self.pair_out = vec![PairOut::default(); np];
        // carried histories belong to open contacts: mark them so they are reset if the
        // contact turns out to be open at the next evaluation
        self.in_contact = vec![0; np];
        if T::FRICTIONAL {
            let zero = T::History::default();
            for (f, h) in self.in_contact.iter_mut().zip(&self.nl.hist) {
                *f = (*h != zero) as u8;
            }
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
        self.wrap_all();
        let t1 = Instant::now();
        if self.nl.needs_rebuild(&self.p, &self.domain) || self.domain.rebuild_due(self.nl.skin) {
            self.rebuild();
        }
        let t2 = Instant::now();
        let wf_old = self.diag.wall_force;
        self.compute_forces();
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
        self.evaluate(self.dt);
    }

    /// Evaluate forces without advancing any tangential history: no time has passed (the first
    /// evaluation, or after the state was set from outside). As LAMMPS's setup, which skips
    /// the history update.
    pub fn compute_forces_setup(&mut self) {
        self.evaluate(0.0);
    }

    /// `hist_dt`: the time over which the histories are advanced (dt in a step, 0 at set-up).
    fn evaluate(&mut self, hist_dt: f64) {
        let tstart = Instant::now();
        let dt = hist_dt;
        let hdt = 0.5 * dt;
        let want_vir = D::NEEDS_VIRIAL || self.want_virial;
        let want_stats = self.want_stats;
        if want_stats {
            self.pstats.clear();
            self.pstats.resize(self.p.len(), [0.0; 10]);
            self.pair_power.clear();
            self.pair_power.resize(self.nl.len(), 0.0);
        }
        let law = &self.law;
        let dom = &self.domain;
        let p = &self.p;
        let nl = &mut self.nl;

        // Phase 1: pair forces. Work units are fixed chunks of particles (the pairs of a
        // particle are contiguous in the list), so each particle's data is loaded once and the
        // results do not depend on the number of threads.
        let n = p.len();
        // packed per-step copies (see `xr`, `kin`)
        self.xr.resize(n, [0.0; 4]);
        self.kin.resize(n, [0.0; 8]);
        self.xr
            .par_iter_mut()
            .zip(self.kin.par_iter_mut())
            .enumerate()
            .with_min_len(4096)
            .for_each(|(i, (a, b))| {
                let x = p.x[i];
                *a = [x.x, x.y, x.z, p.radius[i]];
                let v = p.v[i] + (hdt * p.inv_mass[i]) * p.force[i];
                let w = p.omega[i] + (hdt * p.inv_inertia[i]) * p.torque[i];
                *b = [v.x, v.y, v.z, p.inv_mass[i], w.x, w.y, w.z, 0.0];
            });
        let xr = &self.xr;
        let kin = &self.kin;
        let own_start = &nl.own_start;
        let pair_j = &nl.pair_j;
        let nchunks = n.div_ceil(PART_CHUNK);
        let mut pieces = Vec::with_capacity(nchunks);
        {
            let mut h: &mut [T::History] = &mut nl.hist;
            let mut o: &mut [PairOut] = &mut self.pair_out;
            let mut fl: &mut [u8] = &mut self.in_contact;
            let mut pw: &mut [f64] = &mut self.pair_power;
            let mut ps: &mut [[f64; 10]] = &mut self.pstats;
            for c in 0..nchunks {
                let lo = own_start[c * PART_CHUNK] as usize;
                let hi = own_start[((c + 1) * PART_CHUNK).min(n)] as usize;
                let (a, rest) = std::mem::take(&mut h).split_at_mut(hi - lo);
                h = rest;
                let (b, rest) = std::mem::take(&mut o).split_at_mut(hi - lo);
                o = rest;
                let (f, rest) = std::mem::take(&mut fl).split_at_mut(hi - lo);
                fl = rest;
                let (pwc, psc) = if want_stats {
                    let (x, rest) = std::mem::take(&mut pw).split_at_mut(hi - lo);
                    pw = rest;
                    let np = ((c + 1) * PART_CHUNK).min(n) - c * PART_CHUNK;
                    let (y, rest) = std::mem::take(&mut ps).split_at_mut(np);
                    ps = rest;
                    (x, y)
                } else {
                    (&mut [][..], &mut [][..])
                };
                pieces.push((c, a, b, f, pwc, psc));
            }
        }
        // Each work unit also sums the forces of its particles' own pairs straight into
        // p.force / p.torque (list order); the gather phase then adds only the reverse pairs.
        let stats: Vec<(f64, usize, M3, usize)> = pieces
            .into_par_iter()
            .zip(self.p.force.par_chunks_mut(PART_CHUNK))
            .zip(self.p.torque.par_chunks_mut(PART_CHUNK))
            .map(|(((c, hist, out, flag, pw, ps), fo), to)| {
                let mut max_ov = 0.0f64;
                let mut at = 0usize;
                let mut vir = M3::zeros();
                let mut nc = 0usize;
                let i0 = c * PART_CHUNK;
                let i1 = ((c + 1) * PART_CHUNK).min(n);
                let base = own_start[i0] as usize;
                for i in i0..i1 {
                    let (k0, k1) = (own_start[i] as usize, own_start[i + 1] as usize);
                    let mut fsum = V3::zeros();
                    let mut qsum = V3::zeros();
                    let [xi0, xi1, xi2, ri] = xr[i];
                    let xi = V3::new(xi0, xi1, xi2);
                    for k in k0..k1 {
                        let kk = k - base;
                        // SAFETY: list indices are < n by construction (built from 0..n).
                        let j = unsafe { *pair_j.get_unchecked(k) } as usize;
                        let [xj0, xj1, xj2, rj] = unsafe { *xr.get_unchecked(j) };
                        let d = dom.delta(&xi, &V3::new(xj0, xj1, xj2));
                        let r2 = d.norm_squared();
                        let rs = ri + rj;
                        if r2 >= rs * rs {
                            if flag[kk] != 0 {
                                // the contact just opened: drop its history and force
                                if T::FRICTIONAL {
                                    hist[kk] = T::History::default();
                                }
                                out[kk] = PairOut::default();
                                flag[kk] = 0;
                            }
                            continue;
                        }
                        flag[kk] = 1;
                        nc += 1;
                        let r = r2.sqrt();
                        let ki = &kin[i];
                        let kj = unsafe { kin.get_unchecked(j) };
                        // one division for 1/r, 1/(R_i+R_j) and m_eff = 1/(1/m_i + 1/m_j)
                        let (imi, imj) = (ki[3], kj[3]);
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
                        let vi = V3::new(ki[0], ki[1], ki[2]);
                        let vj = V3::new(kj[0], kj[1], kj[2]);
                        let wi = V3::new(ki[4], ki[5], ki[6]);
                        let wj = V3::new(kj[4], kj[5], kj[6]);
                        let mut vrel = vi - vj - (arm * (ri * wi + rj * wj)).cross(&nrm);
                        if D::STREAMING {
                            vrel += dom.streaming_velocity(&d);
                        }
                        let pf = law.eval(&nrm, delta, rs, meff, &vrel, &mut hist[kk], dt);
                        let q = -arm * nrm.cross(&pf.ft);
                        out[kk] = PairOut { f: pf.f, q };
                        fsum += pf.f;
                        qsum += q;
                        let ov = delta * inv_rs;
                        if ov > max_ov {
                            max_ov = ov;
                            at = k;
                        }
                        if want_vir {
                            vir += d * pf.f.transpose();
                        }
                        if want_stats {
                            let half = 0.5 * d * pf.f.transpose();
                            let pwr = 0.5 * pf.f.dot(&vrel);
                            pw[kk] = pwr;
                            let acc = &mut ps[i - i0];
                            for (a, b) in acc.iter_mut().zip(half.transpose().iter()) {
                                *a += b;
                            }
                            acc[9] += pwr;
                        }
                    }
                    fo[i - i0] = fsum;
                    to[i - i0] = qsum;
                }
                (max_ov, at, vir, nc)
            })
            .collect();

        let tp = Instant::now();
        let mut diag = StepDiag::default();
        for (ov, at, vir, nc) in &stats {
            if *ov > diag.max_overlap {
                diag.max_overlap = *ov;
                diag.max_overlap_at = (nl.pair_i[*at] as usize, nl.pair_j[*at] as usize);
            }
            diag.virial += vir;
            diag.contacts += nc;
        }

        // Phase 2: gather per particle in list order; walls and gravity.
        let pair_out = &self.pair_out;
        let flags = &self.in_contact;
        let kin = &self.kin;
        let rev_start = &nl.rev_start;
        let rev_k = &nl.rev_k;
        let g = self.body.g();
        let walls = &self.walls;
        let planes = walls.planes();
        let wlaw = walls.law();
        let x = &self.p.x;
        let rad = &self.p.radius;
        let mass = &self.p.mass;
        let pair_i = &nl.pair_i;
        let pair_power = &self.pair_power;
        // Per-particle statistics are written at index i by the work unit that owns i only.
        let pstats_ptr = SyncPtr(self.pstats.as_mut_ptr());
        let body = |ci: usize,
                    fo: &mut [V3],
                    to: &mut [V3],
                    mut wh: Option<&mut [[T::History; MAX_WALLS]]>| {
            let mut wf = [V3::zeros(); MAX_WALLS];
            let mut wmax = 0.0f64;
            let mut wat = 0usize;
            let base = ci * PART_CHUNK;
            for l in 0..fo.len() {
                let i = base + l;
                let mut f = fo[l];
                let mut q = to[l];
                for r in rev_start[i]..rev_start[i + 1] {
                    let k = rev_k[r as usize] as usize;
                    if flags[k] != 0 {
                        let o = &pair_out[k];
                        f -= o.f;
                        q += o.q;
                    }
                }
                let mut t = rad[i] * q;
                // SAFETY: pstats has n entries when want_stats; i is owned by this work unit.
                let mut st = if want_stats {
                    Some(unsafe { &mut *pstats_ptr.get().add(i) })
                } else {
                    None
                };
                if let Some(acc) = st.as_deref_mut() {
                    for r in rev_start[i]..rev_start[i + 1] {
                        let k = rev_k[r as usize] as usize;
                        if flags[k] != 0 {
                            let o = pair_i[k] as usize;
                            let d = dom.delta(&x[o], &x[i]);
                            let half = 0.5 * d * pair_out[k].f.transpose();
                            for (a, b) in acc.iter_mut().zip(half.transpose().iter()) {
                                *a += b;
                            }
                            acc[9] += pair_power[k];
                        }
                    }
                }
                if W::ON {
                    let wl = wlaw.unwrap();
                    let hs = &mut wh.as_mut().unwrap()[l];
                    let ri = rad[i];
                    for (w, pl) in planes.iter().enumerate() {
                        let gap = pl.sign * (x[i][pl.axis] - pl.pos);
                        if gap >= ri {
                            if T::FRICTIONAL {
                                hs[w] = T::History::default();
                            }
                            continue;
                        }
                        let mut nrm = V3::zeros();
                        nrm[pl.axis] = pl.sign;
                        let delta = ri - gap;
                        // contact point on the plane: lever arm = gap
                        // predicted end-of-step velocities, as for pairs
                        let kk = &kin[i];
                        let vi = V3::new(kk[0], kk[1], kk[2]);
                        let wi = V3::new(kk[4], kk[5], kk[6]);
                        let vrel = vi - (gap * wi).cross(&nrm);
                        let pf = wl.eval(&nrm, delta, 2.0 * ri, mass[i], &vrel, &mut hs[w], dt);
                        f += pf.f;
                        t -= gap * nrm.cross(&pf.ft);
                        wf[w] -= pf.f;
                        if let Some(acc) = st.as_deref_mut() {
                            // branch vector from the contact point on the wall to the centre
                            let full = (gap * nrm) * pf.f.transpose();
                            for (a, b) in acc.iter_mut().zip(full.transpose().iter()) {
                                *a += b;
                            }
                            acc[9] += pf.f.dot(&vrel);
                        }
                        let ov = delta / (2.0 * ri);
                        if ov > wmax {
                            wmax = ov;
                            wat = i;
                        }
                    }
                }
                if G::ON {
                    f += mass[i] * g;
                }
                fo[l] = f;
                to[l] = t;
            }
            (wf, wmax, wat)
        };
        let wstats: Vec<([V3; MAX_WALLS], f64, usize)> = if W::ON {
            self.p
                .force
                .par_chunks_mut(PART_CHUNK)
                .zip(self.p.torque.par_chunks_mut(PART_CHUNK))
                .zip(self.wall_hist.par_chunks_mut(PART_CHUNK))
                .enumerate()
                .map(|(ci, ((fo, to), wh))| body(ci, fo, to, Some(wh)))
                .collect()
        } else {
            self.p
                .force
                .par_chunks_mut(PART_CHUNK)
                .zip(self.p.torque.par_chunks_mut(PART_CHUNK))
                .enumerate()
                .map(|(ci, (fo, to))| body(ci, fo, to, None))
                .collect()
        };
        if W::ON {
            for (wf, wmax, wat) in &wstats {
                for (acc, w) in diag.wall_force.iter_mut().zip(wf) {
                    *acc += *w;
                }
                if *wmax > diag.max_overlap {
                    diag.max_overlap = *wmax;
                    diag.max_overlap_at = (*wat, usize::MAX);
                }
            }
        }
        self.diag = diag;
        self.forces_valid = true;
        self.want_stats = false;
        let te = Instant::now();
        self.timers.pair_phase += (tp - tstart).as_secs_f64();
        self.timers.gather_phase += (te - tp).as_secs_f64();
    }
}
