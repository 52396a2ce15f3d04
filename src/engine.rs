//! The time step, generic over its parts: contact law (form `F`, friction `T`), domain `D`,
//! walls `W` and body force `G`. A scene without walls or gravity has none of their code in its
//! step (`W::ON`, `G::ON` are constants, so the branches compile away).
//!
//! One step (velocity Verlet, as LAMMPS `nve/sphere`):
//! 1. half-kick and drift (the domain integrates: a deforming cell moves particles too), in the
//!    same pass as the packed records of the pair loop and (plain NVE) the largest drift
//!    speed;
//! 2. rebuild the pair list (wrapping positions into the cell, sorting particles along a Morton
//!    curve) once a particle may have moved half the skin: plain NVE bounds every displacement
//!    by the sum over the steps of the largest speed times dt (no positions kept), a cell that
//!    moves particles itself compares with the positions at the build;
//! 3. prune (plain NVE): every few steps the listed pairs are filtered down to those within an
//!    inner skin of contact, chosen to last about `prune_steps` steps at the current speed; the
//!    force loop then tests only those (dynamic pruning, as in GROMACS). No pair that can touch
//!    before the next prune is dropped, so the contacts and their order, and so the results,
//!    are those of the whole list;
//! 4. forces, parallel over fixed chunks of particles whose size depends on N only: a chunk
//!    (`crate::forceloop`, in blocks of 32 particles: distance test, contact law on lanes of 4
//!    contacts, walls and gravity) sums the pairs inside it in place and buffers the pairs
//!    reaching into later chunks; a second pass adds the buffered pairs to their second
//!    particles (and, for plain NVE, applies the final half-kick; inside one `run` this pass
//!    rides on the next step's first pass). Every floating-point sum has an order fixed by
//!    the list, so any number of threads, and AVX2 or not, gives the same bits;
//! 5. second half-kick (and the cell's momentum update) where the domain has its own dynamics.
//!
//! Inside one `run`, stretches of plain steps that need only steps 1 and 4 run in one team of
//! threads (`team`: one parallel region, spin barriers between the passes) instead of
//! forking and joining twice per step; the bits are the same either way.
//!
//! Tangential histories are stored per closed contact (`crate::history`), not per listed pair.

use crate::contact::{Form, Friction, Law, LawSpec};
use crate::domain::Domain;
use crate::error::{Error, Result};
use crate::history::HistList;
use crate::neighbor::{chunk_size, image_shifts, NeighborList};
use crate::particles::Particles;
use crate::{M3, V3};
use rayon::prelude::*;
use std::time::Instant;

mod team;

/// Default of `Engine::fuse_from`: at 1e6 particles the fused sweep steps 15-20 % faster (the
/// records are read from cache, not memory), at 1e5 4 %, at 2e4 (whose state fits the
/// last-level cache) 9 % slower (`benchmarks/NOTES.md`).
pub const FUSE_N: usize = 1 << 16;

/// Target lifetime, in steps, of the inner (pruned) pair list: measured on the channel
/// workload of issue 6 (benchmarks/NOTES.md).
pub const DEFAULT_PRUNE_STEPS: f64 = 16.0;

/// Most planar walls a scene can have (two side walls and a temporary floor).
pub const MAX_WALLS: usize = 3;

/// A planar wall: the plane x[axis] = pos, particles on the side `sign` (+1: x > pos).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    pub axis: usize,
    pub pos: f64,
    pub sign: f64,
}

impl Plane {
    /// The two side walls of a channel across `axis`: x = lo facing +, x = hi facing -.
    pub fn pair_across(axis: usize, lo: f64, hi: f64) -> Vec<Plane> {
        vec![
            Plane {
                axis,
                pos: lo,
                sign: 1.0,
            },
            Plane {
                axis,
                pos: hi,
                sign: -1.0,
            },
        ]
    }
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
    pub fn new(planes: Vec<Plane>, params: LawSpec) -> Result<Self> {
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
    /// The half-kick/drift/pack pass and the final integration (a fused team sweep, which
    /// does both passes chunk by chunk, is counted under `forces`).
    pub integrate: f64,
    /// List builds and prunes.
    pub neighbor: f64,
    /// The force evaluation.
    pub forces: f64,
    /// Of `forces`: the pair loop (the chunks) ...
    pub pair_phase: f64,
    /// ... and the cross-chunk pass with the final half-kick, when not deferred to the next
    /// step's first pass.
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
impl Guards {
    /// Whether an evaluation's largest overlap breaks the guard (a NaN does).
    pub fn overlap_exceeded(&self, d: &StepDiag) -> bool {
        d.max_overlap.is_nan() || d.max_overlap > self.max_overlap
    }
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
    pub nl: NeighborList,
    /// Tangential histories of the closed pair contacts, one sorted list per force-loop chunk
    /// (`crate::history`), and the lists the next evaluation writes.
    pub hist: Vec<HistList<T::History>>,
    pub(crate) hist_next: Vec<HistList<T::History>>,
    /// The same for wall contacts (key: particle within the chunk x MAX_WALLS + wall).
    pub whist: Vec<HistList<T::History>>,
    pub(crate) whist_next: Vec<HistList<T::History>>,
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
    /// Forces of the cross pairs in contact (see [`crate::neighbor::chunk_size`]) at the last
    /// evaluation, compact per chunk; `cross_idx[slot]` is the entry of a cross slot in its
    /// chunk's list, or u32::MAX when the pair is open.
    pub(crate) cross: Vec<Vec<PairOut>>,
    pub(crate) cross_idx: Vec<u32>,
    /// Their stress/power records when `want_stats`.
    cross_stats: Vec<Vec<[f64; 10]>>,
    /// Total energy at the first guard check (closed systems only).
    energy_ref: Option<f64>,
    forces_valid: bool,
    /// The last evaluation left its cross-chunk pass and final half-kick to the next step's
    /// first pass (plain NVE inside `run`; see `step_once`).
    cross_pending: bool,
    /// Dynamic pruning: the inner list's skin is chosen at each prune so that it lasts about
    /// this many steps at the current largest speed (and, in a deforming cell, strain rate);
    /// 0 turns pruning off (the force loop then tests every listed pair). Results do not
    /// depend on it.
    pub prune_steps: f64,
    /// Largest squared drift velocity of the last step relative to the lists' frame
    /// (`NeighborList::frame_v`).
    vmax2: f64,
    /// A deforming cell's kinetic sum sum_i m_i v_i (x) v_i after the last final half-kick.
    kin_sum: M3,
    /// Run stretches of plain steps in one team of threads (`team`); the results are the
    /// same bits either way (off: every step forks and joins its passes through rayon).
    pub team: bool,
    /// Prunes due inside a team stint are done by the team (each thread its chunks) instead
    /// of ending the stint (on by default; the same results either way).
    pub prune_in_team: bool,
    /// Prunes done inside team stints (a count for the tests).
    pub(crate) team_prunes: u64,
    /// Room kept in the cross index for a prune inside a team (None: an eighth more, +64;
    /// Some(k): the index shrunk, then k more: for tests of the fallback, where a prune that
    /// needs more is done outside).
    pub(crate) team_cross_room: Option<usize>,
    /// Systems of at least this many particles run their team steps as one sweep per step
    /// (`team`: each chunk packed, then its forces computed while its records are in
    /// cache); smaller ones in two passes. The same bits either way.
    pub fuse_from: usize,
    /// A fused sweep computes a step's forces before it is known whether the step must
    /// rebuild or prune first (then they are computed again): a step is fused only if it
    /// would not, were its largest drift speed this factor times the last one's.
    pub(crate) fuse_margin: f64,
}

/// Contact duration of the stiffest, lightest pair for a law and a particle set.
pub fn min_contact_time(params: &LawSpec, p: &Particles) -> Result<f64> {
    let m = p.min_mass();
    params.contact_time(0.5 * m)
}

impl<F: Form, T: Friction, D: Domain, W: Walls<F, T>, G: Body> Engine<F, T, D, W, G> {
    /// Build an engine. `dt = None` picks t_c/50 of the stiffest, lightest pair.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        p: Particles,
        law: LawSpec,
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
        let mut e = Engine {
            p,
            law,
            domain,
            walls,
            body,
            nl: NeighborList::new(skin),
            hist: Vec::new(),
            hist_next: Vec::new(),
            whist: Vec::new(),
            whist_next: Vec::new(),
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
            cross_idx: Vec::new(),
            cross_stats: Vec::new(),
            energy_ref: None,
            forces_valid: false,
            cross_pending: false,
            prune_steps: DEFAULT_PRUNE_STEPS,
            vmax2: f64::INFINITY,
            kin_sum: M3::zeros(),
            team: true,
            prune_in_team: true,
            team_prunes: 0,
            team_cross_room: None,
            fuse_from: FUSE_N,
            fuse_margin: 1.25,
        };
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
    /// each pair's periodic image stays fixed between builds); the contact histories follow
    /// their particles' ids into the new list.
    pub fn rebuild(&mut self) {
        self.rebuild_with(false);
    }

    /// `rebuild`; with `carry_kin` the velocity records (`kin`) follow their particles
    /// (a step whose first pass packed them may have overwritten the forces they came from).
    fn rebuild_with(&mut self, carry_kin: bool) {
        self.wrap_all();
        let (pairs, walls) = self.carried_histories();
        let perm = self.nl.build(&mut self.p, &self.domain);
        if let (true, Some(perm)) = (carry_kin, perm) {
            crate::particles::permute_vec(&mut self.kin, &perm);
        }
        self.domain.on_rebuild();
        self.set_histories(&pairs, &walls);
        let freed = self.trim();
        // a large system's build frees tens of megabytes of temporaries
        if freed > RELEASE_BYTES || self.p.len() >= RELEASE_N {
            release_free_memory();
        }
    }

    /// Size the per-chunk and per-cross-slot buffers to the current list (after a build or a
    /// restart; the force loop relies on it).
    fn size_buffers(&mut self) {
        let nchunks = self.p.len().div_ceil(chunk_size(self.p.len()));
        self.hist.resize_with(nchunks, HistList::default);
        self.hist_next.resize_with(nchunks, HistList::default);
        self.whist.resize_with(nchunks, HistList::default);
        self.whist_next.resize_with(nchunks, HistList::default);
        self.cross.resize_with(nchunks, Vec::new);
        self.cross_stats.resize_with(nchunks, Vec::new);
        self.cross_idx.clear();
    }

    /// Keep the per-contact buffers at about 1.25 times what they hold: pushes during a sweep
    /// double a buffer that overflows, and a build is a good moment to give the excess back.
    /// Returns the bytes given back.
    fn trim(&mut self) -> usize {
        fn fit<X>(v: &mut Vec<X>, want: usize) -> usize {
            let want = if want == 0 { 0 } else { want + want / 4 + 16 };
            let had = v.capacity();
            if had > want {
                v.shrink_to(want);
            } else {
                v.reserve_exact(want - v.len());
            }
            had.saturating_sub(v.capacity()) * std::mem::size_of::<X>()
        }
        let mut freed = 0;
        // nothing is kept for parts a scene does not have (no friction: no histories; no
        // walls: no wall histories)
        let np = if T::FRICTIONAL { self.hist.len() } else { 0 };
        let nw = if T::FRICTIONAL && W::ON {
            self.whist.len()
        } else {
            0
        };
        let lists = self.hist.iter_mut().zip(self.hist_next.iter_mut()).take(np);
        let wlists = self
            .whist
            .iter_mut()
            .zip(self.whist_next.iter_mut())
            .take(nw);
        for (a, b) in lists.chain(wlists) {
            let want = a.len();
            for l in [a, b] {
                freed += fit(&mut l.keys, want);
                freed += fit(&mut l.vals, want);
            }
        }
        for c in self.cross.iter_mut() {
            let want = c.len();
            freed += fit(c, want);
        }
        freed
    }

    /// Visit every stored history: `pair(i, j, h)` for pair contacts (internal indices, as
    /// listed), `wall(i, w, h)` for wall contacts. Nothing without friction or a list.
    pub fn for_each_history(
        &self,
        mut pair: impl FnMut(usize, usize, &T::History),
        mut wall: impl FnMut(usize, usize, &T::History),
    ) {
        if !T::FRICTIONAL || !self.nl.valid {
            return;
        }
        let nl = &self.nl;
        let n = self.p.len();
        let ch = chunk_size(n);
        for (c, list) in self.hist.iter().enumerate().take(n.div_ceil(ch)) {
            let base = nl.own_start[c * ch] as usize;
            let mut i = c * ch;
            for (&kk, h) in list.keys.iter().zip(&list.vals) {
                let k = base + kk as usize;
                while nl.own_start[i + 1] as usize <= k {
                    i += 1;
                }
                pair(i, nl.pair_j[k] as usize, h);
            }
        }
        for (c, list) in self.whist.iter().enumerate() {
            for (&key, h) in list.keys.iter().zip(&list.vals) {
                let i = c * ch + key as usize / MAX_WALLS;
                if i < n {
                    wall(i, key as usize % MAX_WALLS, h);
                }
            }
        }
    }

    /// Every stored history with the ids of its particles: pairs (id_i, id_j, h) oriented as
    /// listed, walls (id, wall, h).
    #[allow(clippy::type_complexity)]
    pub fn carried_histories(&self) -> (Vec<(u32, u32, T::History)>, Vec<(u32, u8, T::History)>) {
        let mut pairs = Vec::new();
        let mut walls = Vec::new();
        let id = &self.p.id;
        self.for_each_history(
            |i, j, h| pairs.push((id[i], id[j], *h)),
            |i, w, h| walls.push((id[i], w as u8, *h)),
        );
        (pairs, walls)
    }

    /// Place histories given by particle ids into the current pair list and particle order
    /// (after a build or a restart). A pair no longer listed loses its history.
    pub fn set_histories(
        &mut self,
        pairs: &[(u32, u32, T::History)],
        walls: &[(u32, u8, T::History)],
    ) {
        let ch = chunk_size(self.p.len());
        let n = self.p.len();
        let nchunks = n.div_ceil(ch);
        let nl = &self.nl;
        let mut inv = vec![0usize; n];
        for (i, &id) in self.p.id.iter().enumerate() {
            inv[id as usize] = i;
        }
        let mut pe: Vec<(u64, T::History)> = Vec::with_capacity(pairs.len());
        for &(a, b, h) in pairs {
            let (ia, ib) = (inv[a as usize], inv[b as usize]);
            let (lo, hi, h) = if ia < ib {
                (ia, ib, h)
            } else {
                (ib, ia, T::flip(h))
            };
            if let Some(k) = nl.find(lo, hi) {
                pe.push((k as u64, h));
            }
        }
        pe.sort_unstable_by_key(|e| e.0);
        self.hist = crate::history::distribute(&pe, &nl.chunk_bases());
        let mut we: Vec<(u64, T::History)> = walls
            .iter()
            .map(|&(id, w, h)| ((inv[id as usize] * MAX_WALLS + w as usize) as u64, h))
            .collect();
        we.sort_unstable_by_key(|e| e.0);
        let wb: Vec<u64> = (0..=nchunks)
            .map(|c| ((c * ch).min(n) * MAX_WALLS) as u64)
            .collect();
        self.whist = crate::history::distribute(&we, &wb);
        self.size_buffers();
    }

    /// Every stored pair history (for tests and diagnostics).
    pub fn pair_histories(&self) -> Vec<T::History> {
        self.hist
            .iter()
            .flat_map(|l| l.vals.iter().copied())
            .collect()
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
            // positions are wrapped only by a rebuild: a wrap without one would break the
            // pairs' fixed image codes
            if self.nl.needs_rebuild(&self.p) {
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
        let mut k = 0;
        while k < n {
            // plain steps that need nothing but forces run in one team of threads
            let budget = self.team_budget(n - k);
            if budget > 0 && self.team_ready() {
                if let Some((done, exit)) = self.team_steps(budget) {
                    k += done;
                    match exit {
                        team::TeamExit::Done => {}
                        team::TeamExit::Overlap => {
                            let r = self.check_overlap();
                            self.complete_step();
                            return r;
                        }
                        team::TeamExit::Outside { moved } => {
                            self.step_finish(moved, true, k + 1 < n, Instant::now())?;
                            k += 1;
                        }
                    }
                    continue;
                }
            }
            self.step_once(k + 1 < n)?;
            k += 1;
        }
        Ok(())
    }

    /// How many of the next `left` steps of a run a team may take: each must be followed by
    /// another step of the run and have no guard check due (see `step_once`).
    fn team_budget(&self, left: u64) -> u64 {
        let ce = self.guards.check_every;
        let to_check = if ce == 0 {
            u64::MAX
        } else {
            (ce - (self.step + 1) % ce) % ce
        };
        (left - 1).min(to_check)
    }

    /// One step. `more`: another step of the same `run` follows, so (plain NVE, no
    /// statistics asked for, no guard check due) the cross-chunk pass and the final half-kick
    /// can ride on the next step's first pass: one sweep over the particles fewer per step,
    /// the same arithmetic in the same order (the same bits). Nothing outside `run` sees the
    /// deferred state: the last step of a run, a step whose state a guard reads and a failing
    /// step complete it.
    fn step_once(&mut self, more: bool) -> Result<()> {
        let dt = self.dt;
        let t0 = Instant::now();
        // one pass over the particles: (for plain NVE) the half-kick and drift, then the
        // displacement since the last build and the packed records for the pair loop
        let (moved, packed) = if D::PLAIN_NVE {
            let dr = self.kick_drift_pack();
            self.vmax2 = dr.m2;
            self.nl.add_drift(dr.m2.sqrt(), dt);
            self.nl.frame_v = dr.next_frame();
            // (an infinite drift: the pass did not pack, see `kick_drift_pack`)
            (self.nl.moved_out(), dr.m2.is_finite())
        } else {
            let maps = self.domain.begin_step(dt);
            let m2 = self.kick_drift_pack_affine(&maps);
            self.domain.after_drift(&maps, &mut self.p);
            // the lists' bounds: a pair's gap closes at most at 2 |v|max + |L| r (its image
            // shift moves with the cell)
            self.vmax2 = m2;
            self.nl.add_drift(self.list_speed(m2), dt);
            (self.nl.moved_out(), false)
        };
        self.step_finish(moved, packed, more, t0)
    }

    /// The rest of a step after its first pass (`moved`: the list's displacement bound
    /// reached half the skin; `packed`: the first pass packed the records, which are then
    /// carried through a rebuild rather than packed again, as the forces they were packed
    /// from may be gone (a fused team sweep computes the next ones speculatively);
    /// `t0`: when the step began).
    fn step_finish(&mut self, moved: bool, packed: bool, more: bool, t0: Instant) -> Result<()> {
        let dt = self.dt;
        self.domain.check(self.step)?;
        let t1 = Instant::now();
        if moved || !self.nl.valid || self.domain.rebuild_due(self.nl.skin) {
            self.rebuild_with(packed);
            if packed {
                self.pack_xr();
            } else {
                self.pack();
            }
        }
        if self.nl.prune_due() {
            self.prune();
        }
        let t2 = Instant::now();
        let wf_old = self.diag.wall_force;
        // the final half-kick rides on the force loop's last pass
        let kick = 0.5 * dt;
        let check_due = (self.step + 1).is_multiple_of(self.guards.check_every);
        let defer = D::PLAIN_NVE && more && !check_due;
        self.evaluate(dt, kick, defer);
        if W::ON {
            add_wall_impulse(&mut self.wall_impulse, &wf_old, &self.diag.wall_force, dt);
        }
        let t3 = Instant::now();
        if !D::PLAIN_NVE {
            let (vir, kin) = (self.diag.virial, self.kin_sum);
            self.domain.end_step(dt, &vir, &kin);
        }
        let t4 = Instant::now();
        let tm = &mut self.timers;
        tm.integrate += (t1 - t0).as_secs_f64() + (t4 - t3).as_secs_f64();
        tm.neighbor += (t2 - t1).as_secs_f64();
        tm.forces += (t3 - t2).as_secs_f64();
        self.step += 1;
        self.time += dt;
        if let Err(e) = self.check_overlap() {
            self.complete_step();
            return Err(e);
        }
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
        let ch = chunk_size(self.p.len());
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
        let bases = nl.chunk_bases();
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
                let c = i / ch;
                let mut h = match self.hist.get(c) {
                    Some(l) => l.get((k as u64 - bases[c]) as u32),
                    None => T::History::default(),
                };
                let pf = self.law.eval(&nrm, rs - r, rs, meff, &vrel, &mut h, 0.0);
                out.push((i, j, d, pf.f));
            }
        }
        out
    }

    /// `nve_initial` and `pack` in one pass (same arithmetic, same bits): at large N
    /// the step is bound by memory traffic, and this reads each particle once.
    /// Returns the largest squared drift velocity relative to the lists' frame (their
    /// displacement bounds grow by it times dt) and the velocities' range (the next frame).
    fn kick_drift_pack(&mut self) -> Drift {
        let ch = chunk_size(self.p.len());
        let n = self.p.len();
        if !self.nl.valid || self.nl.own_start.len() != n + 1 {
            self.complete_step();
            crate::domain::nve_initial(&mut self.p, self.dt);
            return Drift {
                m2: f64::INFINITY,
                ..Drift::EMPTY
            };
        }
        let u = self.nl.frame_v;
        // the last step's deferred cross pass and final half-kick, particle by particle
        // ahead of this step's half-kick
        let pending = std::mem::take(&mut self.cross_pending);
        let dt = self.dt;
        let h = 0.5 * dt;
        self.xr.resize(n, [0.0; 4]);
        self.kin.resize(n, [0.0; 8]);
        let p = &mut self.p;
        let pass = KickPass {
            nl: &self.nl,
            cross: &self.cross,
            cstat: &self.cross_stats,
            cidx: &self.cross_idx,
            per: (&p.radius, &p.inv_mass, &p.inv_inertia),
            pending,
            h,
            dt,
            u,
        };
        p.x.par_chunks_mut(ch)
            .zip(p.v.par_chunks_mut(ch))
            .zip(p.omega.par_chunks_mut(ch))
            .zip(p.force.par_chunks_mut(ch))
            .zip(p.torque.par_chunks_mut(ch))
            .zip(self.xr.par_chunks_mut(ch))
            .zip(self.kin.par_chunks_mut(ch))
            .enumerate()
            .map(|(c, ((((((x, v), w), f), t), a), b))| {
                pass.piece::<T>(
                    c * ch,
                    KickOut {
                        x,
                        v,
                        w,
                        f,
                        t,
                        a,
                        b,
                    },
                )
            })
            .reduce(|| Drift::EMPTY, Drift::merge)
    }

    /// A domain's first half-kick and drift (`Domain::begin_step` maps) and the packed
    /// records in one parallel pass (per particle the arithmetic of the domain's own loops,
    /// then of `pack`). Returns the largest squared speed.
    fn kick_drift_pack_affine(&mut self, m: &crate::domain::StepMaps) -> f64 {
        let n = self.p.len();
        let ch = chunk_size(n);
        let dt = self.dt;
        self.xr.resize(n, [0.0; 4]);
        self.kin.resize(n, [0.0; 8]);
        let p = &mut self.p;
        let (f, t, im, ii, rad) = (&p.force, &p.torque, &p.inv_mass, &p.inv_inertia, &p.radius);
        p.x.par_chunks_mut(ch)
            .zip(p.v.par_chunks_mut(ch))
            .zip(p.omega.par_chunks_mut(ch))
            .zip(self.xr.par_chunks_mut(ch))
            .zip(self.kin.par_chunks_mut(ch))
            .enumerate()
            .map(|(c, ((((x, v), w), a), b))| {
                let r = c * ch..c * ch + x.len();
                let k = AffineKick {
                    out: (x, v, w, a, b),
                    src: (
                        &f[r.clone()],
                        &t[r.clone()],
                        &im[r.clone()],
                        &ii[r.clone()],
                        &rad[r],
                    ),
                    m,
                    dt,
                };
                #[cfg(target_arch = "x86_64")]
                if crate::contact::lanes::wide() {
                    // SAFETY: `wide` checked that the CPU has AVX2
                    return unsafe { affine_kick_pack_avx2::<T>(k) };
                }
                affine_kick_pack::<T>(k)
            })
            .reduce(|| 0.0, f64::max)
    }

    /// The speed that bounds how fast a pair's gap can close, per particle (half of it):
    /// the largest drift speed `sqrt(m2)`, plus in a deforming cell the affine part |L| r / 2
    /// at the largest distance a pair can reach contact from, r <= `NeighborList::cut`.
    fn list_speed(&self, m2: f64) -> f64 {
        list_speed(m2, self.domain.affine_rate(), self.nl.cut)
    }

    /// Pack the step records: (x, R) and the velocities predicted to the end of the step,
    /// v(n+1/2) + dt/2 a(n) (and the same for w), with 1/m.
    fn pack(&mut self) {
        let n = self.p.len();
        let ch = chunk_size(n);
        let hdt = 0.5 * self.dt;
        self.xr.resize(n, [0.0; 4]);
        self.kin.resize(n, [0.0; 8]);
        let p = &self.p;
        self.xr
            .par_chunks_mut(ch)
            .zip(self.kin.par_chunks_mut(ch))
            .enumerate()
            .for_each(|(c, (a, b))| {
                for l in 0..a.len() {
                    let i = c * ch + l;
                    a[l] = xr_record(&p.x[i], p.radius[i]);
                    b[l] = kin_record(
                        &p.v[i],
                        &p.omega[i],
                        &p.force[i],
                        &p.torque[i],
                        p.inv_mass[i],
                        p.inv_inertia[i],
                        hdt,
                        p.radius[i],
                    );
                }
            });
    }

    /// The (x, R) records alone (after a rebuild wrapped the positions; see `step_finish`).
    fn pack_xr(&mut self) {
        let p = &self.p;
        self.xr.resize(p.len(), [0.0; 4]);
        self.xr
            .par_iter_mut()
            .zip(p.x.par_iter().zip(p.radius.par_iter()))
            .with_min_len(4096)
            .for_each(|(a, (x, &r))| *a = xr_record(x, r));
    }

    fn check_overlap(&self) -> Result<()> {
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

    /// Evaluate forces without advancing any tangential history: no time has passed (the first
    /// evaluation, or after the state was set from outside). As LAMMPS's setup, which skips
    /// the history update.
    pub fn compute_forces_setup(&mut self) {
        self.pack();
        // the lists' frame from the velocities now, so that the first inner list lasts about
        // `prune_steps` steps like the later ones (and its prune trims the contact lists,
        // which grow by doubling while the first contacts are stored)
        let (u, m2) = self.frame_speed2();
        self.nl.frame_v = u;
        self.vmax2 = m2;
        self.prune();
        self.evaluate(0.0, 0.0, false);
        // the set-up's temporaries (input copies, the first build's) are freed by now
        if self.p.len() >= RELEASE_N {
            release_free_memory();
        }
    }

    /// The middle of the velocities' range (per component) and the largest squared speed
    /// relative to it.
    fn frame_speed2(&self) -> ([f64; 3], f64) {
        let v = &self.p.v;
        let range = v
            .par_iter()
            .with_min_len(4096)
            .fold(
                || Drift::EMPTY,
                |mut d, v| {
                    d.include(v);
                    d
                },
            )
            .reduce(|| Drift::EMPTY, Drift::merge);
        let u = range.next_frame();
        let uv = V3::new(u[0], u[1], u[2]);
        let m2 = v
            .par_iter()
            .with_min_len(4096)
            .map(|v| (v - uv).norm_squared())
            .reduce(|| 0.0, f64::max);
        (u, m2)
    }

    /// Rebuild the inner list from the packed positions (after `pack`): the skin is chosen
    /// so that it lasts `prune_steps` steps at the last step's largest speed relative to the
    /// lists' frame (the whole list where the domain moves particles itself, or pruning is
    /// off).
    fn prune(&mut self) {
        let s_in = inner_skin_for(
            self.prune_steps,
            self.nl.skin,
            self.list_speed(self.vmax2),
            self.dt,
        );
        let shifts = image_shifts(&self.domain.h());
        self.nl.prune(&self.xr, &shifts, s_in);
        self.cross_idx.clear();
        self.cross_idx.resize(self.nl.n_cross(), u32::MAX);
        // the contact lists grow by doubling during the sweeps: give the excess back
        if self.trim() > RELEASE_BYTES {
            release_free_memory();
        }
    }

    /// Finish a step whose cross-chunk pass and final half-kick were deferred.
    fn complete_step(&mut self) {
        if self.cross_pending {
            self.cross_pending = false;
            let _ = self.cross_pass::<false>(0.5 * self.dt);
        }
    }

    /// Forces from the packed records (`pack` or `kick_drift_pack` must have run). `hist_dt`: the
    /// time over which the histories are advanced (dt in a step, 0 at set-up).
    ///
    /// Phase 1, parallel over fixed chunks of particles: each chunk sweeps its particles in
    /// order; a pair inside the chunk is added to both particles at once (j > i, so j has all
    /// its in-chunk contributions from earlier particles before its own pairs are added); a
    /// pair reaching into a later chunk adds to i and writes its force to its cross slot. Walls
    /// and gravity are added by the owner. Phase 2 adds the cross slots to their second
    /// particles in list order. Every sum has one order fixed by the list.
    /// `kick`: 0, or dt/2 to apply the final half-kick of a plain NVE step in the last pass.
    /// `defer`: leave the cross-chunk pass and the final half-kick to the next step's first
    /// pass (ignored when statistics are asked for).
    fn evaluate(&mut self, hist_dt: f64, kick: f64, defer: bool) {
        // the statistics and virial paths are compiled separately, so the plain step carries
        // none of their code (nor its register pressure)
        match (self.want_stats, D::NEEDS_VIRIAL || self.want_virial) {
            (false, false) => self.evaluate_with::<false, false>(hist_dt, kick, defer),
            (false, true) => self.evaluate_with::<false, true>(hist_dt, kick, defer),
            (true, false) => self.evaluate_with::<true, false>(hist_dt, kick, false),
            (true, true) => self.evaluate_with::<true, true>(hist_dt, kick, false),
        }
    }

    fn evaluate_with<const STATS: bool, const VIR: bool>(
        &mut self,
        hist_dt: f64,
        kick: f64,
        defer: bool,
    ) {
        let ch = chunk_size(self.p.len());
        let tstart = Instant::now();
        let dt = hist_dt;
        let want_stats = STATS;
        let n = self.p.len();
        let nchunks = n.div_ceil(ch);
        // sized by every build and restart (size_buffers)
        debug_assert_eq!(self.hist.len(), nchunks);
        debug_assert_eq!(self.cross_idx.len(), self.nl.n_cross());
        if want_stats {
            self.pstats.clear();
            self.pstats.resize(n, [0.0; 10]);
        }
        let law = &self.law;
        let dom = &self.domain;
        let nl = &self.nl;
        let xr = &self.xr;
        let kin = &self.kin;
        let mass = &self.p.mass;

        // the pieces of the per-chunk and per-slot arrays each chunk owns
        let mut cidx_pieces: Vec<&mut [u32]> = Vec::with_capacity(nchunks);
        {
            let mut rest: &mut [u32] = &mut self.cross_idx;
            for c in 0..nchunks {
                let len = (nl.cross_off[c + 1] - nl.cross_off[c]) as usize;
                let (a, r) = std::mem::take(&mut rest).split_at_mut(len);
                rest = r;
                cidx_pieces.push(a);
            }
        }
        let mut ps_pieces = stat_pieces(&mut self.pstats, want_stats, ch, nchunks);
        // what each chunk writes, split off the engine's arrays
        let pieces: Vec<_> = self
            .p
            .force
            .chunks_mut(ch)
            .zip(self.p.torque.chunks_mut(ch))
            .zip(self.hist.iter())
            .zip(self.hist_next.iter_mut())
            .zip(self.whist.iter())
            .zip(self.whist_next.iter_mut())
            .zip(self.cross.iter_mut())
            .zip(self.cross_stats.iter_mut())
            .zip(cidx_pieces)
            .zip(ps_pieces.drain(..))
            .map(
                |(((((((((fo, to), hold), hnew), wold), wnew), cross), cstat), cidx), ps)| {
                    crate::forceloop::ChunkIo {
                        fo,
                        to,
                        hold,
                        hnew,
                        wold,
                        wnew,
                        cross,
                        cstat,
                        cidx,
                        ps,
                    }
                },
            )
            .enumerate()
            .collect();

        let shared = crate::forceloop::Shared::new(
            law,
            dom,
            &self.walls,
            &self.body,
            nl,
            (xr, kin, mass),
            dt,
            ch,
        );
        let results: Vec<ChunkOut> = pieces
            .into_par_iter()
            .map(|(c, io)| crate::forceloop::chunk::<F, T, D, W, G, STATS, VIR>(&shared, c, io))
            .collect();
        std::mem::swap(&mut self.hist, &mut self.hist_next);
        std::mem::swap(&mut self.whist, &mut self.whist_next);

        let tp = Instant::now();
        self.diag = reduce_outs(&results);
        if defer && kick > 0.0 && !STATS {
            self.cross_pending = true;
        } else {
            self.kin_sum = self.cross_pass::<STATS>(kick);
        }
        self.forces_valid = true;
        self.want_stats = false;
        let te = Instant::now();
        self.timers.pair_phase += (tp - tstart).as_secs_f64();
        self.timers.gather_phase += (te - tp).as_secs_f64();
    }

    /// Phase 2: cross pairs in contact onto their second particles, in list order; in a time
    /// step (`kick` = dt/2), the final half-kick in the same pass (the forces of particle i are
    /// complete once its cross pairs are added): plain velocity Verlet, or a deforming cell's
    /// (`Domain::final_kick`), which also returns the kinetic sum sum_i m_i v_i (x) v_i after
    /// the kick, summed per chunk and then over the chunks in order (the same bits for any
    /// thread count; zero otherwise).
    fn cross_pass<const STATS: bool>(&mut self, kick: f64) -> M3 {
        let nl = &self.nl;
        if nl.n_cross() == 0 && kick == 0.0 {
            return M3::zeros();
        }
        let affine = !D::PLAIN_NVE && kick > 0.0;
        let m = self.domain.final_kick();
        let n = self.p.len();
        let ch = chunk_size(n);
        let nchunks = n.div_ceil(ch);
        let (cross, cstat, cidx) = (&self.cross, &self.cross_stats, &self.cross_idx);
        let mut ps_pieces = stat_pieces(&mut self.pstats, STATS, ch, nchunks);
        let p = &mut self.p;
        let (rad, im, ii, mass) = (&p.radius, &p.inv_mass, &p.inv_inertia, &p.mass);
        let chunks = p
            .force
            .par_chunks_mut(ch)
            .zip(p.torque.par_chunks_mut(ch))
            .zip(p.v.par_chunks_mut(ch))
            .zip(p.omega.par_chunks_mut(ch))
            .zip(ps_pieces.par_drain(..))
            .enumerate()
            .map(|(c, ((((fo, to), vo), wo), ps))| {
                let r = c * ch..c * ch + fo.len();
                let src = CrossSrc::new(nl, cross, cstat, cidx, (rad, im, ii), r.clone(), kick);
                let k = CrossChunk {
                    fo,
                    to,
                    vo,
                    wo,
                    ps,
                    s: &src,
                };
                cross_kick_chunk::<STATS, T>(k, affine.then(|| (&m, &mass[r])))
            });
        if affine {
            let sums: Vec<M3> = chunks.collect();
            sums.iter().fold(M3::zeros(), |a, b| a + b)
        } else {
            chunks.for_each(drop);
            M3::zeros()
        }
    }
}

/// What one chunk of the force loop reports.
#[derive(Default)]
pub(crate) struct ChunkOut {
    pub max_ov: f64,
    pub at: (usize, usize),
    pub vir: M3,
    pub contacts: usize,
    pub wall_force: [V3; MAX_WALLS],
}

/// Freed bytes above which a trim of the contact lists returns the heap's free pages.
const RELEASE_BYTES: usize = 1 << 20;
/// Particles from which the set-up and every build return the heap's free pages (their
/// temporaries are tens of megabytes there).
const RELEASE_N: usize = 1 << 16;

/// Give the heap's free pages back to the system after a build. A build's temporaries (cell
/// keys, the permutation, per-chunk pair buffers: ~50 B per particle at its peak) are freed
/// when it ends, but glibc keeps freed memory resident; at 1e6 particles that was ~7 B per
/// particle of resident memory over what the engine holds (`benchmarks/NOTES.md`). The
/// call costs a walk of the free lists, a few milliseconds at 1e6, once per build.
fn release_free_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        extern "C" {
            fn malloc_trim(pad: usize) -> std::ffi::c_int;
        }
        // SAFETY: malloc_trim only returns free memory to the system; glibc provides it
        unsafe {
            malloc_trim(0);
        }
    }
}

/// One step's impulse on each wall by the trapezoid rule (what velocity Verlet applies to the
/// particles), from the wall forces at its start and end. (Always inlined: called out of
/// line from the step team's closure it changed how the force loop was compiled there,
/// -3 % on the step bench.)
#[inline(always)]
fn add_wall_impulse(
    imp: &mut [V3; MAX_WALLS],
    old: &[V3; MAX_WALLS],
    new: &[V3; MAX_WALLS],
    dt: f64,
) {
    for w in 0..MAX_WALLS {
        imp[w] += 0.5 * dt * (old[w] + new[w]);
    }
}

/// The step's diagnostics from the chunks' reports, in chunk order.
fn reduce_outs(results: &[ChunkOut]) -> StepDiag {
    let mut diag = StepDiag::default();
    for o in results {
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
    diag
}

/// Each chunk's slice of the per-particle statistics (empty slices when not asked for).
fn stat_pieces(
    ps: &mut [[f64; 10]],
    want: bool,
    ch: usize,
    nchunks: usize,
) -> Vec<&mut [[f64; 10]]> {
    if want {
        ps.chunks_mut(ch).collect()
    } else {
        (0..nchunks).map(|_| &mut [][..]).collect()
    }
}

/// What the cross-chunk pass reads for one chunk.
struct CrossSrc<'a> {
    /// cross_start of the chunk's particles (one more than the chunk).
    cs: &'a [u32],
    slot: &'a [u32],
    /// Source chunk of each entry of `slot`.
    src: &'a [u16],
    cidx: &'a [u32],
    cross: &'a [Vec<PairOut>],
    cstat: &'a [Vec<[f64; 10]>],
    rad: &'a [f64],
    im: &'a [f64],
    ii: &'a [f64],
    kick: f64,
}

impl<'a> CrossSrc<'a> {
    /// The cross-pass inputs of the chunk of particles `r`: the list's cross slots, the
    /// buffered cross forces and (R, 1/m, 1/I) per particle.
    fn new(
        nl: &'a NeighborList,
        cross: &'a [Vec<PairOut>],
        cstat: &'a [Vec<[f64; 10]>],
        cidx: &'a [u32],
        (rad, im, ii): (&'a [f64], &'a [f64], &'a [f64]),
        r: std::ops::Range<usize>,
        kick: f64,
    ) -> Self {
        CrossSrc {
            cs: &nl.cross_start[r.start..r.end + 1],
            slot: &nl.cross_slot,
            src: &nl.cross_src,
            cidx,
            cross,
            cstat,
            rad: &rad[r.clone()],
            im: &im[r.clone()],
            ii: &ii[r],
            kick,
        }
    }
}

/// One chunk's slices for phase 2 (force, torque, velocity, spin, statistics).
struct CrossChunk<'a, 'b> {
    fo: &'a mut [V3],
    to: &'a mut [V3],
    vo: &'a mut [V3],
    wo: &'a mut [V3],
    ps: &'a mut [[f64; 10]],
    s: &'b CrossSrc<'b>,
}

/// A deforming cell's final half-kick map and the chunk's masses (see `cross_kick`).
type AffineFinal<'a> = Option<(&'a crate::domain::StepMaps, &'a [f64])>;

/// Phase 2 for one chunk: the cross pairs in contact onto their second particles, in list
/// order, then (in a step, `kick` > 0) the final half-kick; AVX2 where the CPU has it (the
/// same bits either way).
fn cross_kick_chunk<const STATS: bool, T: Friction>(k: CrossChunk, aff: AffineFinal) -> M3 {
    #[cfg(target_arch = "x86_64")]
    if crate::contact::lanes::wide() {
        // SAFETY: `wide` checked that the CPU has AVX2
        return unsafe { cross_kick_avx2::<STATS, T>(k, aff) };
    }
    cross_kick::<STATS, T>(k, aff)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn cross_kick_avx2<const STATS: bool, T: Friction>(k: CrossChunk, aff: AffineFinal) -> M3 {
    match aff {
        // SAFETY: this function only runs on AVX2 CPUs
        Some((m, mass)) if !STATS => unsafe { wide::cross_kick_affine::<T>(k, m, mass) },
        _ => cross_kick::<STATS, T>(k, aff),
    }
}

/// The loop of phase 2 over one chunk. With `aff` (a deforming cell in a step, `s.kick` =
/// dt/2) the kick is the cell's and the chunk's kinetic sum is returned (zero otherwise).
#[inline(always)]
fn cross_kick<const STATS: bool, T: Friction>(k: CrossChunk, aff: AffineFinal) -> M3 {
    let CrossChunk {
        fo,
        to,
        vo,
        wo,
        ps,
        s,
    } = k;
    let n = fo.len();
    assert!(to.len() == n && vo.len() == n && wo.len() == n && s.cs.len() == n + 1);
    assert!(s.rad.len() == n && s.im.len() == n && s.ii.len() == n);
    assert!(!STATS || ps.len() == n);
    let mut kin = M3::zeros();
    match aff {
        None => {
            for l in 0..n {
                // SAFETY: l < n, the length of every per-particle slice (asserted above)
                unsafe { cross_one::<STATS, T>(l, fo, to, vo, wo, ps, s) };
            }
        }
        Some((m, mass)) => {
            assert!(mass.len() == n);
            let h2 = s.kick;
            for l in 0..n {
                let (mut f, mut t) = (fo[l], to[l]);
                // SAFETY: l < n, the length of every per-particle slice (asserted above)
                unsafe { cross_sum::<STATS, T>(l, &mut f, &mut t, ps, s) };
                (fo[l], to[l]) = (f, t);
                let vn = m.kick(&vo[l], &f, s.im[l], h2);
                vo[l] = vn;
                if T::FRICTIONAL {
                    wo[l] += h2 * s.ii[l] * t;
                }
                kin += mass[l] * vn * vn.transpose();
            }
        }
    }
    kin
}

/// The cross pairs in contact of particle l of a chunk added onto (f, t), in list order
/// (and their statistics onto ps[l] with STATS).
///
/// # Safety
/// l < the length of s.rad (and ps with STATS); l + 1 < s.cs.len().
#[inline(always)]
unsafe fn cross_sum<const STATS: bool, T: Friction>(
    l: usize,
    f: &mut V3,
    t: &mut V3,
    ps: &mut [[f64; 10]],
    s: &CrossSrc,
) {
    unsafe {
        let (a, b) = (
            *s.cs.get_unchecked(l) as usize,
            *s.cs.get_unchecked(l + 1) as usize,
        );
        for (&sl, &src) in s.slot[a..b].iter().zip(&s.src[a..b]) {
            let e = s.cidx[sl as usize];
            if e != u32::MAX {
                let o = &s.cross[src as usize][e as usize];
                *f -= o.f;
                if T::FRICTIONAL {
                    *t += *s.rad.get_unchecked(l) * o.q;
                }
                if STATS {
                    add10(&mut ps[l], &s.cstat[src as usize][e as usize]);
                }
            }
        }
    }
}

/// Phase 2 for particle l of a chunk: its cross pairs, then (`kick` > 0) its final half-kick.
///
/// # Safety
/// l < the length of fo, to, vo, wo, s.rad, s.im, s.ii (and ps with STATS); l + 1 < s.cs.len().
#[inline(always)]
unsafe fn cross_one<const STATS: bool, T: Friction>(
    l: usize,
    fo: &mut [V3],
    to: &mut [V3],
    vo: &mut [V3],
    wo: &mut [V3],
    ps: &mut [[f64; 10]],
    s: &CrossSrc,
) {
    unsafe {
        let fl = fo.get_unchecked_mut(l);
        let tl = to.get_unchecked_mut(l);
        cross_sum::<STATS, T>(l, fl, tl, ps, s);
        if s.kick > 0.0 {
            // the arithmetic of nve_final
            *vo.get_unchecked_mut(l) += *fl * (s.kick * *s.im.get_unchecked(l));
            if T::FRICTIONAL {
                *wo.get_unchecked_mut(l) += *tl * (s.kick * *s.ii.get_unchecked(l));
            }
        }
    }
}

/// What the fused half-kick, drift and packing pass reads of one chunk.
struct KickSrc<'a> {
    im: &'a [f64],
    ii: &'a [f64],
    rad: &'a [f64],
}

/// What every piece of the fused half-kick, drift and packing pass reads.
struct KickPass<'a> {
    nl: &'a NeighborList,
    /// The cross buffers, their statistics and the cross index (read only when `pending`).
    cross: &'a [Vec<PairOut>],
    cstat: &'a [Vec<[f64; 10]>],
    cidx: &'a [u32],
    /// (R, 1/m, 1/I) per particle.
    per: (&'a [f64], &'a [f64], &'a [f64]),
    /// The last step's cross pass and final half-kick are still to be done.
    pending: bool,
    h: f64,
    dt: f64,
    /// The lists' frame velocity (`NeighborList::frame_v`).
    u: [f64; 3],
}

/// What one piece of that pass writes (its particles' slices, from particle `start` on):
/// positions, velocities, spins, forces and torques, and the packed (x, R) and velocity
/// records.
struct KickOut<'a> {
    x: &'a mut [V3],
    v: &'a mut [V3],
    w: &'a mut [V3],
    f: &'a mut [V3],
    t: &'a mut [V3],
    a: &'a mut [[f64; 4]],
    b: &'a mut [[f64; 8]],
}

impl KickPass<'_> {
    /// The pass over the particles start..start + o.x.len().
    #[inline(always)]
    fn piece<T: Friction>(&self, start: usize, o: KickOut) -> Drift {
        let r = start..start + o.x.len();
        let (rad, im, ii) = self.per;
        let src = KickSrc {
            im: &im[r.clone()],
            ii: &ii[r.clone()],
            rad: &rad[r.clone()],
        };
        // (the cross index exists only while a pass is pending: a restored state has none
        // until its first prune)
        let cx = self.pending.then(|| {
            CrossSrc::new(
                self.nl, self.cross, self.cstat, self.cidx, self.per, r, self.h,
            )
        });
        kick_drift_pack_chunk::<T>(KickChunk {
            out: o,
            s: &src,
            pend: cx.as_ref(),
            h: self.h,
            dt: self.dt,
            u: self.u,
        })
    }
}

/// One chunk's slices for the fused half-kick, drift and packing pass, and what it reads.
struct KickChunk<'a, 'b> {
    out: KickOut<'a>,
    s: &'b KickSrc<'b>,
    /// The last step's deferred cross pass and final half-kick, if any.
    pend: Option<&'b CrossSrc<'b>>,
    h: f64,
    dt: f64,
    /// The frame velocity the drift speeds are measured against (`NeighborList::moved`).
    u: [f64; 3],
}

/// What the half-kick pass reports for the displacement bounds: the largest squared drift
/// speed relative to the frame velocity, and the range of the drift velocities (from which
/// the next step's frame velocity is taken). Maxima and minima: the same for any chunking.
#[derive(Clone, Copy, Debug)]
struct Drift {
    m2: f64,
    lo: [f64; 3],
    hi: [f64; 3],
}

impl Drift {
    const EMPTY: Drift = Drift {
        m2: 0.0,
        lo: [f64::INFINITY; 3],
        hi: [f64::NEG_INFINITY; 3],
    };

    /// Widen the velocity range to include `v`.
    #[inline(always)]
    fn include(&mut self, v: &V3) {
        for c in 0..3 {
            self.lo[c] = self.lo[c].min(v[c]);
            self.hi[c] = self.hi[c].max(v[c]);
        }
    }

    fn merge(a: Drift, b: Drift) -> Drift {
        Drift {
            m2: a.m2.max(b.m2),
            lo: [0, 1, 2].map(|c| a.lo[c].min(b.lo[c])),
            hi: [0, 1, 2].map(|c| a.hi[c].max(b.hi[c])),
        }
    }

    /// The middle of the velocity range, per component (zero if it is not finite: a NaN
    /// velocity, which the finite check reports, or no particles).
    fn next_frame(&self) -> [f64; 3] {
        let m = [0, 1, 2].map(|c| 0.5 * self.lo[c] + 0.5 * self.hi[c]);
        if m.iter().all(|c| c.is_finite()) {
            m
        } else {
            [0.0; 3]
        }
    }
}

/// Half-kick, drift and step records of one chunk (plain NVE), with AVX2 where the CPU has
/// it (elementwise arithmetic: the same bits either way). Returns the largest squared drift
/// velocity relative to the frame, and the velocities' range (`Drift`).
fn kick_drift_pack_chunk<T: Friction>(k: KickChunk) -> Drift {
    #[cfg(target_arch = "x86_64")]
    if crate::contact::lanes::wide() {
        // SAFETY: `wide` checked that the CPU has AVX2
        return unsafe { kdp_avx2::<T>(k) };
    }
    kdp::<T>(k)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn kdp_avx2<T: Friction>(k: KickChunk) -> Drift {
    // SAFETY: this function only runs on AVX2 CPUs
    unsafe { wide::kdp::<T>(k) }
}

/// `kdp` with each 3-vector in the low lanes of one AVX register (loaded as 16 + 8 bytes, the
/// fourth lane zero): the same IEEE operations in the same order, so the same bits.
#[cfg(target_arch = "x86_64")]
mod wide {
    use super::{AffineKick, CrossChunk, CrossSrc, Drift, KickChunk, KickOut, PairOut};
    use crate::contact::Friction;
    use crate::domain::StepMaps;
    use crate::M3;
    use crate::V3;
    use std::arch::x86_64::*;

    /// A 3-vector at `p` in lanes 0-2 (lane 3 zero).
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn ld3(p: *const f64) -> __m256d {
        unsafe {
            _mm256_insertf128_pd(
                _mm256_castpd128_pd256(_mm_loadu_pd(p)),
                _mm_load_sd(p.add(2)),
                1,
            )
        }
    }

    /// Store lanes 0-2 at `p`.
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn st3(p: *mut f64, v: __m256d) {
        unsafe {
            _mm_storeu_pd(p, _mm256_castpd256_pd128(v));
            _mm_store_sd(p.add(2), _mm256_extractf128_pd(v, 1));
        }
    }

    #[inline]
    #[target_feature(enable = "avx2")]
    fn lanes(v: __m256d) -> [f64; 4] {
        // SAFETY: same size, any bit pattern is a valid f64
        unsafe { std::mem::transmute::<__m256d, [f64; 4]>(v) }
    }

    /// The cross pairs in contact of particle l added onto (f, t) (`super::cross_sum`).
    ///
    /// Without `target_feature` of its own so that it can be `inline(always)`: it is only
    /// called from AVX2 functions, into which it is inlined.
    ///
    /// # Safety
    /// AVX2; l < the chunk's length, l + 1 < s.cs.len().
    #[inline(always)]
    unsafe fn cross_sum<T: Friction>(l: usize, f: &mut __m256d, t: &mut __m256d, s: &CrossSrc) {
        unsafe {
            let (a, b) = (
                *s.cs.get_unchecked(l) as usize,
                *s.cs.get_unchecked(l + 1) as usize,
            );
            for (&sl, &src) in s.slot[a..b].iter().zip(&s.src[a..b]) {
                let e = s.cidx[sl as usize];
                if e != u32::MAX {
                    let o: &PairOut = &s.cross[src as usize][e as usize];
                    *f = _mm256_sub_pd(*f, ld3(o.f.as_ptr()));
                    if T::FRICTIONAL {
                        let r = _mm256_set1_pd(*s.rad.get_unchecked(l));
                        *t = _mm256_add_pd(*t, _mm256_mul_pd(r, ld3(o.q.as_ptr())));
                    }
                }
            }
        }
    }

    /// # Safety
    /// AVX2 CPU.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn kdp<T: Friction>(k: KickChunk) -> Drift {
        let KickChunk {
            out:
                KickOut {
                    x,
                    v,
                    w,
                    f,
                    t,
                    a,
                    b,
                },
            s,
            pend,
            h,
            dt,
            u,
        } = k;
        let n = x.len();
        assert!(v.len() == n && w.len() == n && f.len() == n && t.len() == n);
        assert!(a.len() == n && b.len() == n);
        assert!(s.im.len() == n && s.ii.len() == n && s.rad.len() == n);
        if let Some(cx) = pend {
            assert!(cx.cs.len() == n + 1 && cx.rad.len() == n && cx.im.len() == n);
            assert!(cx.ii.len() == n);
        }
        let ptr = |q: &mut [V3]| q.as_mut_ptr() as *mut f64;
        let (px, pv, pw, pf, pt) = (ptr(x), ptr(v), ptr(w), ptr(f), ptr(t));
        let vdt = _mm256_set1_pd(dt);
        let uf = _mm256_setr_pd(u[0], u[1], u[2], 0.0);
        let mut vm = _mm_setzero_pd();
        let (mut vlo, mut vhi) = (
            _mm256_set1_pd(f64::INFINITY),
            _mm256_set1_pd(f64::NEG_INFINITY),
        );
        for l in 0..n {
            // SAFETY: l < n, the length of every slice (asserted above); a 3-vector is 3
            // doubles at 3 l
            unsafe {
                let o = 3 * l;
                let mut fl = ld3(pf.add(o));
                let mut tl = ld3(pt.add(o));
                let mut vl = ld3(pv.add(o));
                let mut wl = ld3(pw.add(o));
                let (iml, iil, rl) = (
                    *s.im.get_unchecked(l),
                    *s.ii.get_unchecked(l),
                    *s.rad.get_unchecked(l),
                );
                let hm = _mm256_set1_pd(h * iml);
                let hi = _mm256_set1_pd(h * iil);
                if let Some(cx) = pend {
                    cross_sum::<T>(l, &mut fl, &mut tl, cx);
                    st3(pf.add(o), fl);
                    let km = _mm256_set1_pd(cx.kick * *cx.im.get_unchecked(l));
                    vl = _mm256_add_pd(vl, _mm256_mul_pd(fl, km));
                    if T::FRICTIONAL {
                        st3(pt.add(o), tl);
                        let ki = _mm256_set1_pd(cx.kick * *cx.ii.get_unchecked(l));
                        wl = _mm256_add_pd(wl, _mm256_mul_pd(tl, ki));
                    }
                }
                let vn = _mm256_add_pd(vl, _mm256_mul_pd(fl, hm));
                st3(pv.add(o), vn);
                let xn = _mm256_add_pd(ld3(px.add(o)), _mm256_mul_pd(vn, vdt));
                st3(px.add(o), xn);
                let [vx, vy, vz, _] = lanes(_mm256_sub_pd(vn, uf));
                // maxsd(new, acc) keeps acc for a NaN, as f64::max does, without the
                // latter's NaN fix-up on the loop-carried chain
                vm = _mm_max_sd(_mm_set_sd(vx * vx + vy * vy + vz * vz), vm);
                // (as f64::min/max for numbers; NaN is reported by the finite check)
                vlo = _mm256_min_pd(vlo, vn);
                vhi = _mm256_max_pd(vhi, vn);
                if T::FRICTIONAL {
                    wl = _mm256_add_pd(wl, _mm256_mul_pd(tl, hi));
                    st3(pw.add(o), wl);
                }
                // (v + h f/m, 1/m) and (w + h t/I, R): kin_record's arithmetic
                let vp = _mm256_add_pd(vn, _mm256_mul_pd(hm, fl));
                let wp = if T::FRICTIONAL {
                    _mm256_add_pd(wl, _mm256_mul_pd(hi, tl))
                } else {
                    wl
                };
                put_records(
                    a.get_unchecked_mut(l),
                    b.get_unchecked_mut(l),
                    (xn, vp, wp),
                    iml,
                    rl,
                );
            }
        }
        let ([l0, l1, l2, _], [h0, h1, h2, _]) = (lanes(vlo), lanes(vhi));
        Drift {
            m2: _mm_cvtsd_f64(vm),
            lo: [l0, l1, l2],
            hi: [h0, h1, h2],
        }
    }

    /// The two step records of a particle: (x, R) and (v + h f/m, 1/m, w + h t/I, R), from
    /// the predicted velocities `vp`, `wp` (`kin_record`'s arithmetic, done by the caller).
    ///
    /// # Safety
    /// AVX2 CPU.
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn put_records(
        a: &mut [f64; 4],
        b: &mut [f64; 8],
        (xn, vp, wp): (__m256d, __m256d, __m256d),
        im: f64,
        r: f64,
    ) {
        let rr = _mm256_set1_pd(r);
        // SAFETY: 4 and 8 doubles
        unsafe {
            _mm256_storeu_pd(a.as_mut_ptr(), _mm256_blend_pd::<0b1000>(xn, rr));
            let kb = b.as_mut_ptr();
            _mm256_storeu_pd(kb, _mm256_blend_pd::<0b1000>(vp, _mm256_set1_pd(im)));
            _mm256_storeu_pd(kb.add(4), _mm256_blend_pd::<0b1000>(wp, rr));
        }
    }

    /// A 3x3 matrix's columns, each in lanes 0-2.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn cols(m: &M3) -> [__m256d; 3] {
        let p = m.as_slice().as_ptr();
        // SAFETY: a column-major 3x3 matrix is 9 contiguous doubles
        unsafe { [ld3(p), ld3(p.add(3)), ld3(p.add(6))] }
    }

    /// m v with m given by its columns: per row ((m0 v0 + m1 v1) + m2 v2), nalgebra's order.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn mv(c: &[__m256d; 3], v: __m256d) -> __m256d {
        let [a, b, d] = splat3(v);
        let s = _mm256_add_pd(_mm256_mul_pd(c[0], a), _mm256_mul_pd(c[1], b));
        _mm256_add_pd(s, _mm256_mul_pd(c[2], d))
    }

    /// Lanes 0, 1 and 2 of `v`, each broadcast to a whole register (in registers: no trip
    /// through memory as `lanes` takes).
    #[inline]
    #[target_feature(enable = "avx2")]
    fn splat3(v: __m256d) -> [__m256d; 3] {
        [
            _mm256_permute4x64_pd::<0x00>(v),
            _mm256_permute4x64_pd::<0x55>(v),
            _mm256_permute4x64_pd::<0xAA>(v),
        ]
    }

    /// v0 v0 + v1 v1 + v2 v2 in that order (lane 0), as nalgebra's `norm_squared`.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn norm2(v: __m256d) -> __m128d {
        let q = _mm256_mul_pd(v, v);
        let lo = _mm256_castpd256_pd128(q);
        let s = _mm_add_sd(lo, _mm_unpackhi_pd(lo, lo));
        _mm_add_sd(s, _mm256_extractf128_pd::<1>(q))
    }

    /// `StepMaps::kick`: v + h2 (f/m - L v - tr v), the same operations in the same order.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn kick(
        lc: &[__m256d; 3],
        tr: __m256d,
        h2: __m256d,
        v: __m256d,
        f: __m256d,
        im: f64,
    ) -> __m256d {
        let a = _mm256_sub_pd(_mm256_mul_pd(f, _mm256_set1_pd(im)), mv(lc, v));
        let a = _mm256_sub_pd(a, _mm256_mul_pd(tr, v));
        _mm256_add_pd(v, _mm256_mul_pd(h2, a))
    }

    /// `super::affine_kick_pack` with each 3-vector in the low lanes of one register: the
    /// same IEEE operations in the same order, so the same bits.
    ///
    /// # Safety
    /// AVX2 CPU.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn akp<T: Friction>(k: AffineKick) -> f64 {
        let AffineKick {
            out: (x, v, w, a, b),
            src: (f, t, im, ii, rad),
            m,
            dt,
        } = k;
        let n = x.len();
        assert!(v.len() == n && w.len() == n && a.len() == n && b.len() == n);
        assert!(f.len() >= n && t.len() >= n && im.len() >= n && ii.len() >= n);
        assert!(rad.len() >= n);
        let h2 = 0.5 * dt;
        let (lc, ac) = (cols(&m.l), cols(&m.a));
        let (vtr, vh2, vdt) = (_mm256_set1_pd(m.tr), _mm256_set1_pd(h2), _mm256_set1_pd(dt));
        let cptr = |q: &[V3]| q.as_ptr() as *const f64;
        let ptr = |q: &mut [V3]| q.as_mut_ptr() as *mut f64;
        let (px, pv, pw) = (ptr(x), ptr(v), ptr(w));
        let (pf, pt) = (cptr(f), cptr(t));
        let mut vm = _mm_setzero_pd();
        for l in 0..n {
            // SAFETY: l < n, the length of every slice (asserted above); a 3-vector is 3
            // doubles at 3 l
            unsafe {
                let o = 3 * l;
                let (fl, tl, vl) = (ld3(pf.add(o)), ld3(pt.add(o)), ld3(pv.add(o)));
                let (iml, iil, rl) = (
                    *im.get_unchecked(l),
                    *ii.get_unchecked(l),
                    *rad.get_unchecked(l),
                );
                let vn = kick(&lc, vtr, vh2, vl, fl, iml);
                st3(pv.add(o), vn);
                // h2/I: the spin's kick and its record
                let hi = _mm256_set1_pd(h2 * iil);
                // without friction there are no torques: spins never change
                let wn = if T::FRICTIONAL {
                    let wn = _mm256_add_pd(ld3(pw.add(o)), _mm256_mul_pd(hi, tl));
                    st3(pw.add(o), wn);
                    wn
                } else {
                    ld3(pw.add(o))
                };
                let xn = _mm256_add_pd(mv(&ac, ld3(px.add(o))), _mm256_mul_pd(vdt, vn));
                st3(px.add(o), xn);
                // maxsd(new, acc) keeps acc for a NaN, as f64::max does
                vm = _mm_max_sd(norm2(vn), vm);
                // kin_record's arithmetic
                let vp = _mm256_add_pd(vn, _mm256_mul_pd(_mm256_set1_pd(h2 * iml), fl));
                let wp = _mm256_add_pd(wn, _mm256_mul_pd(hi, tl));
                put_records(
                    a.get_unchecked_mut(l),
                    b.get_unchecked_mut(l),
                    (xn, vp, wp),
                    iml,
                    rl,
                );
            }
        }
        _mm_cvtsd_f64(vm)
    }

    /// `super::cross_kick` of a deforming cell in a step, without statistics: the cross
    /// pairs, the cell's final half-kick and the chunk's kinetic sum sum_l m v v^T (per
    /// element (m v_r) v_c, as nalgebra's outer product), the same bits.
    ///
    /// # Safety
    /// AVX2 CPU.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn cross_kick_affine<T: Friction>(
        k: CrossChunk,
        m: &StepMaps,
        mass: &[f64],
    ) -> M3 {
        let CrossChunk {
            fo, to, vo, wo, s, ..
        } = k;
        let n = fo.len();
        assert!(to.len() == n && vo.len() == n && wo.len() == n && s.cs.len() == n + 1);
        assert!(s.rad.len() == n && s.im.len() == n && s.ii.len() == n && mass.len() == n);
        let h2 = s.kick;
        let lc = cols(&m.l);
        let (vtr, vh2) = (_mm256_set1_pd(m.tr), _mm256_set1_pd(h2));
        let ptr = |q: &mut [V3]| q.as_mut_ptr() as *mut f64;
        let (pf, pt, pv, pw) = (ptr(fo), ptr(to), ptr(vo), ptr(wo));
        let mut kc = [_mm256_setzero_pd(); 3];
        for l in 0..n {
            // SAFETY: l < n, the length of every per-particle slice (asserted above)
            unsafe {
                let o = 3 * l;
                let (mut f, mut t) = (ld3(pf.add(o)), ld3(pt.add(o)));
                cross_sum::<T>(l, &mut f, &mut t, s);
                st3(pf.add(o), f);
                st3(pt.add(o), t);
                let vn = kick(&lc, vtr, vh2, ld3(pv.add(o)), f, *s.im.get_unchecked(l));
                st3(pv.add(o), vn);
                if T::FRICTIONAL {
                    let k = _mm256_set1_pd(h2 * *s.ii.get_unchecked(l));
                    st3(
                        pw.add(o),
                        _mm256_add_pd(ld3(pw.add(o)), _mm256_mul_pd(k, t)),
                    );
                }
                let mv = _mm256_mul_pd(_mm256_set1_pd(*mass.get_unchecked(l)), vn);
                let [a, b, c] = splat3(vn);
                kc[0] = _mm256_add_pd(kc[0], _mm256_mul_pd(mv, a));
                kc[1] = _mm256_add_pd(kc[1], _mm256_mul_pd(mv, b));
                kc[2] = _mm256_add_pd(kc[2], _mm256_mul_pd(mv, c));
            }
        }
        let ([a0, a1, a2, _], [b0, b1, b2, _], [c0, c1, c2, _]) =
            (lanes(kc[0]), lanes(kc[1]), lanes(kc[2]));
        M3::new(a0, b0, c0, a1, b1, c1, a2, b2, c2)
    }
}

#[inline(always)]
fn kdp<T: Friction>(k: KickChunk) -> Drift {
    let KickChunk {
        out:
            KickOut {
                x,
                v,
                w,
                f,
                t,
                a,
                b,
            },
        s,
        pend,
        h,
        dt,
        u,
    } = k;
    let uf = V3::new(u[0], u[1], u[2]);
    let mut dr = Drift::EMPTY;
    let n = x.len();
    // equal lengths let the compiler drop the bounds checks
    let (v, w, a, b) = (&mut v[..n], &mut w[..n], &mut a[..n], &mut b[..n]);
    let (f, t) = (&mut f[..n], &mut t[..n]);
    let (im, ii, rad) = (&s.im[..n], &s.ii[..n], &s.rad[..n]);
    if let Some(cx) = pend {
        assert!(cx.cs.len() == n + 1 && cx.rad.len() == n && cx.im.len() == n);
        assert!(cx.ii.len() == n);
    }
    let mut vm = 0.0f64;
    for l in 0..n {
        // every value read and written once, kept in registers in between
        let (mut fl, mut tl, mut vl, mut wl) = (f[l], t[l], v[l], w[l]);
        let (hm, hi) = (h * im[l], h * ii[l]);
        if let Some(cx) = pend {
            // the last step's cross pairs and final half-kick (the arithmetic of cross_one)
            // SAFETY: l < n, the length of every per-particle slice (asserted above)
            unsafe { cross_sum::<false, T>(l, &mut fl, &mut tl, &mut [], cx) };
            f[l] = fl;
            vl += fl * (cx.kick * cx.im[l]);
            if T::FRICTIONAL {
                t[l] = tl;
                wl += tl * (cx.kick * cx.ii[l]);
            }
        }
        let vn = vl + fl * hm;
        v[l] = vn;
        let xn = x[l] + vn * dt;
        x[l] = xn;
        let d = vn - uf;
        vm = vm.max(d.x * d.x + d.y * d.y + d.z * d.z);
        dr.include(&vn);
        // without friction there are no torques: spins never change
        if T::FRICTIONAL {
            wl += tl * hi;
            w[l] = wl;
        }
        a[l] = xr_record(&xn, rad[l]);
        b[l] = if T::FRICTIONAL {
            kin_record(&vn, &wl, &fl, &tl, im[l], ii[l], h, rad[l])
        } else {
            let vp = vn + hm * fl;
            [vp.x, vp.y, vp.z, im[l], wl.x, wl.y, wl.z, rad[l]]
        };
    }
    dr.m2 = vm;
    dr
}

/// One chunk's slices for a deforming cell's first half-kick, drift and packing: (x, v, w,
/// (x, R) records, velocity records) written, (f, t, 1/m, 1/I, R) read.
#[allow(clippy::type_complexity)]
struct AffineKick<'a, 'b> {
    out: (
        &'a mut [V3],
        &'a mut [V3],
        &'a mut [V3],
        &'a mut [[f64; 4]],
        &'a mut [[f64; 8]],
    ),
    src: (&'b [V3], &'b [V3], &'b [f64], &'b [f64], &'b [f64]),
    m: &'b crate::domain::StepMaps,
    dt: f64,
}

/// `affine_kick_pack` compiled for AVX2 (the same IEEE operations: the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn affine_kick_pack_avx2<T: Friction>(k: AffineKick) -> f64 {
    // SAFETY: this function only runs on AVX2 CPUs
    unsafe { wide::akp::<T>(k) }
}

/// The loop of `Engine::kick_drift_pack_affine` over one chunk; returns the largest squared
/// speed. (A plain function, not a closure, so that the AVX2 twin inlines it.)
#[inline(always)]
fn affine_kick_pack<T: Friction>(k: AffineKick) -> f64 {
    let AffineKick {
        out: (x, v, w, a, b),
        src: (f, t, im, ii, rad),
        m,
        dt,
    } = k;
    let h2 = 0.5 * dt;
    let n = x.len();
    // equal lengths let the compiler drop the bounds checks
    let (v, w, a, b) = (&mut v[..n], &mut w[..n], &mut a[..n], &mut b[..n]);
    let (f, t, im, ii, rad) = (&f[..n], &t[..n], &im[..n], &ii[..n], &rad[..n]);
    let mut m2 = 0.0f64;
    for l in 0..n {
        let vn = m.kick(&v[l], &f[l], im[l], h2);
        // without friction there are no torques: spins never change
        let wn = if T::FRICTIONAL {
            w[l] + h2 * ii[l] * t[l]
        } else {
            w[l]
        };
        let xn = m.a * x[l] + dt * vn;
        (v[l], w[l], x[l]) = (vn, wn, xn);
        m2 = m2.max(vn.norm_squared());
        a[l] = xr_record(&xn, rad[l]);
        b[l] = kin_record(&vn, &wn, &f[l], &t[l], im[l], ii[l], h2, rad[l]);
    }
    m2
}

/// `Engine::list_speed` from its parts (the domain's affine rate, the list's reach).
#[inline]
fn list_speed(m2: f64, affine_rate: f64, cut: f64) -> f64 {
    m2.sqrt() + 0.5 * affine_rate * cut
}

/// The inner skin of a prune (`Engine::prune`): chosen to last `prune_steps` steps at the
/// gap-closing speed `speed` (`list_speed`), within 1/50 of the outer skin and below half of
/// it (else every pair is kept: no pruning, infinite).
fn inner_skin_for(prune_steps: f64, skin: f64, speed: f64, dt: f64) -> f64 {
    if prune_steps > 0.0 {
        let want = 2.0 * speed * dt * prune_steps;
        // below 1/50 of the skin a prune would keep hardly fewer pairs
        let s = want.max(0.02 * skin);
        // at the outer skin it would keep them all: no pruning
        if s < 0.5 * skin {
            s
        } else {
            f64::INFINITY
        }
    } else {
        f64::INFINITY
    }
}

/// Packed position record of the pair loop: (x, R).
#[inline(always)]
fn xr_record(x: &V3, r: f64) -> [f64; 4] {
    [x.x, x.y, x.z, r]
}

/// Packed velocity record of the pair loop: v and w predicted to the end of the step
/// (v + h f/m, w + h t/I, h = dt/2), 1/m and R: the law's gather reads (v, 1/m) and (w, R)
/// as two 32-byte halves.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn kin_record(v: &V3, w: &V3, f: &V3, t: &V3, im: f64, ii: f64, h: f64, r: f64) -> [f64; 8] {
    let vp = v + (h * im) * f;
    let wp = w + (h * ii) * t;
    [vp.x, vp.y, vp.z, im, wp.x, wp.y, wp.z, r]
}

#[inline(always)]
fn add10(acc: &mut [f64; 10], rec: &[f64; 10]) {
    for (a, b) in acc.iter_mut().zip(rec) {
        *a += b;
    }
}
