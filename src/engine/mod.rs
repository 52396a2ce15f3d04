//! The time step, generic over its parts: contact law (form `F`, friction `T`), domain `D`,
//! walls `W` and body force `G`. A scene without walls or gravity has none of their code in its
//! step (`W::ON`, `G::ON` are constants, so the branches compile away).
//!
//! One step (velocity Verlet, as LAMMPS `nve/sphere`):
//! 1. half-kick and drift (the domain integrates: a deforming cell moves particles too), in the
//!    same pass as the packed records of the pair loop and (plain NVE) the largest drift
//!    speed (`integrate`);
//! 2. rebuild the pair list (wrapping positions into the cell, sorting particles along a Morton
//!    curve) once a particle may have moved half the skin: the bound is the sum over the steps
//!    of the largest speed times dt (plus, in a deforming cell, the affine approach);
//! 3. prune: every few steps the listed pairs are filtered down to those within an inner skin
//!    of contact, chosen to last about `prune_steps` steps at the current speed; the force loop
//!    then tests only those (dynamic pruning, as in GROMACS). No pair that can touch before the
//!    next prune is dropped, so the contacts and their order, and so the results, are those of
//!    the whole list (`forces`);
//! 4. forces, parallel over fixed chunks of particles whose size depends on N only: a chunk
//!    (`chunk`, in blocks of 32 particles: distance test, contact law on lanes of 4 contacts,
//!    walls and gravity) sums the pairs inside it in place and buffers the pairs reaching into
//!    later chunks; a second pass adds the buffered pairs to their second particles (and applies
//!    the final half-kick; inside one `run` this pass rides on the next step's first pass).
//!    Every floating-point sum has an order fixed by the list, so any number of threads, and
//!    AVX2 or not (`crate::simd`), gives the same bits;
//! 5. second half-kick (and the cell's momentum update) where the domain has its own dynamics.
//!
//! Inside one `run`, stretches of plain steps that need only steps 1 and 4 run in one team of
//! threads (`team`: one parallel region, spin barriers between the passes) instead of forking
//! and joining twice per step; the bits are the same either way. Run-time guards (`guards`)
//! stop an unstable run with a clear error instead of writing NaN.
//!
//! Tangential histories are stored per closed contact (`crate::history`), not per listed pair;
//! `histories` carries them by particle ids (checkpoints, restarts).

use crate::components::{Body, Walls, MAX_WALLS};
use crate::contact::{Form, Friction, Law, LawSpec};
use crate::domain::Domain;
use crate::error::{Error, Result};
use crate::history::HistList;
use crate::neighbor::{chunk_size, NeighborList};
use crate::particles::Particles;
use crate::sampling::{ContactRec, SampleView, Sampler};
use crate::{M3, V3};
use rayon::prelude::*;
use std::time::Instant;

mod chunk;
mod forces;
mod guards;
mod histories;
mod integrate;
mod team;

pub use chunk::PairOut;

/// Default of `Engine::fuse_from`: from this size on the records no longer fit the last-level
/// cache, and reading them from cache in one fused sweep is faster (`benchmarks/NOTES.md`).
pub const FUSE_N: usize = 1 << 16;

/// Target lifetime, in steps, of the inner (pruned) pair list (tuned on the channel workload,
/// `benchmarks/NOTES.md`).
pub const DEFAULT_PRUNE_STEPS: f64 = 16.0;

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
    /// The samplers' work after a sampled step ...
    pub sampling: f64,
}

/// Chunk sums a team made for a completed sampled step: a sampler's index and its parts, one
/// per force-loop chunk in chunk order.
pub(crate) type ChunkParts = Vec<(usize, Vec<Vec<f64>>)>;

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

/// Knobs that change how fast a run goes, never its results (the same bits for any setting;
/// tested).
#[derive(Clone, Debug)]
pub struct Tuning {
    /// Dynamic pruning: the inner list's skin is chosen at each prune so that it lasts about
    /// this many steps at the current largest speed (and, in a deforming cell, strain rate);
    /// 0 turns pruning off (the force loop then tests every listed pair). Results do not
    /// depend on it.
    pub prune_steps: f64,
    /// Run stretches of plain steps in one team of threads (`team`); the results are the
    /// same bits either way (off: every step forks and joins its passes through rayon).
    pub team: bool,
    /// Prunes due inside a team stint are done by the team (each thread its chunks) instead
    /// of ending the stint (on by default; the same results either way).
    pub prune_in_team: bool,
    /// Room kept in the cross index for a prune inside a team (None: an eighth more, +64;
    /// Some(k): the index shrunk, then k more: for tests of the fallback, where a prune that
    /// needs more is done outside).
    pub team_cross_room: Option<usize>,
    /// Systems of at least this many particles run their team steps as one sweep per step
    /// (`team`: each chunk packed, then its forces computed while its records are in
    /// cache); smaller ones in two passes. The same bits either way.
    pub fuse_from: usize,
    /// A fused sweep computes a step's forces before it is known whether the step must
    /// rebuild or prune first (then they are computed again): a step is fused only if it
    /// would not, were its largest drift speed this factor times the last one's.
    pub fuse_margin: f64,
}

impl Default for Tuning {
    fn default() -> Self {
        Tuning {
            prune_steps: DEFAULT_PRUNE_STEPS,
            team: true,
            prune_in_team: true,
            team_cross_room: None,
            fuse_from: FUSE_N,
            fuse_margin: 1.25,
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
    /// Ask the next force evaluation for the contact records (`crecs`; a sampled step).
    pub want_records: bool,
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
    /// Per chunk, the contacts of the last evaluation with `want_records` or `want_stats`.
    pub(crate) crecs: Vec<Vec<ContactRec>>,
    /// Statistics taken inside the step loop on their triggers (`crate::sampling`).
    pub samplers: Vec<Box<dyn Sampler>>,
    /// Total energy at the first guard check (closed systems only).
    energy_ref: Option<f64>,
    forces_valid: bool,
    /// Knobs of speed, never of results.
    pub tuning: Tuning,
    /// The last evaluation left its cross-chunk pass and final half-kick to the next step's
    /// first pass (plain NVE inside `run`; see `step_once`).
    cross_pending: bool,
    /// Largest squared drift velocity of the last step relative to the lists' frame
    /// (`NeighborList::frame_v`).
    vmax2: f64,
    /// A deforming cell's kinetic sum sum_i m_i v_i (x) v_i after the last final half-kick.
    kin_sum: M3,
    /// Prunes done inside team stints (a count for the tests).
    pub team_prunes: u64,
}

/// Contact duration of the stiffest, lightest pair for a law and a particle set.
pub fn min_contact_time(params: &LawSpec, p: &Particles) -> Result<f64> {
    let m = p.min_mass();
    params.contact_time(0.5 * m)
}

impl<F: Form, T: Friction, D: Domain, W: Walls<F, T>, G: Body> Engine<F, T, D, W, G> {
    /// Build an engine. `dt = None` picks t_c/50 of the stiffest, lightest pair.
    #[allow(
        clippy::too_many_arguments,
        reason = "the engine's type-parameter parts plus dt and skin; scene::build is the friendly front"
    )]
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
        let law = Law::<F, T>::new(law);
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
            want_records: false,
            wall_impulse: [V3::zeros(); MAX_WALLS],
            pstats: Vec::new(),
            cross: Vec::new(),
            cross_idx: Vec::new(),
            cross_stats: Vec::new(),
            crecs: Vec::new(),
            samplers: Vec::new(),
            energy_ref: None,
            forces_valid: false,
            tuning: Tuning::default(),
            cross_pending: false,
            vmax2: f64::INFINITY,
            kin_sum: M3::zeros(),
            team_prunes: 0,
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
        self.crecs.resize_with(nchunks, Vec::new);
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

    /// Advance `n` steps; samplers sample after the steps their triggers name.
    pub fn run(&mut self, n: u64) -> Result<()> {
        self.ensure_forces()?;
        let mut k = 0;
        while k < n {
            // steps to the next sampled one (u64::MAX without samplers)
            let to_sample = crate::sampling::steps_to_next(&self.samplers, self.step);
            let left = n - k;
            // a sampled step's evaluation keeps the contact records if a due sampler reads
            // them, and the step is completed (no pass deferred): the samplers read
            // full-step velocities
            let records = to_sample <= left && {
                let step = self.step + to_sample;
                self.samplers
                    .iter()
                    .any(|s| step.is_multiple_of(s.every()) && s.needs_contacts())
            };
            // plain steps that need nothing but forces run in one team of threads; a stint
            // may end with the sampled step, completed in the team
            let to_check = self.steps_to_check();
            let (budget, complete) = if to_sample <= left && to_sample <= to_check + 1 {
                (to_sample, true)
            } else {
                ((left - 1).min(to_check).min(to_sample - 1), false)
            };
            if budget > 0 && self.team_ready() {
                if let Some((done, exit, parts)) = self.team_steps(budget, complete, records) {
                    k += done;
                    match exit {
                        TeamExit::Done => {
                            if complete && done == budget {
                                self.after_step_checks()?;
                                self.sample(parts)?;
                            }
                        }
                        TeamExit::Overlap => {
                            let r = self.check_overlap();
                            self.complete_step();
                            return r;
                        }
                        TeamExit::Outside { moved } => {
                            // the step the stint left inside, finished here (the sampled one:
                            // with its records, completed)
                            let sampled = complete && done + 1 == budget;
                            self.want_records = sampled && records;
                            self.step_finish(moved, true, !sampled && k + 1 < n, Instant::now())?;
                            k += 1;
                            if sampled {
                                self.sample(Vec::new())?;
                            }
                        }
                    }
                    continue;
                }
            }
            if to_sample == 1 {
                self.want_records = records;
                self.step_once(false)?;
                k += 1;
                self.sample(Vec::new())?;
                continue;
            }
            self.step_once(k + 1 < n)?;
            k += 1;
        }
        Ok(())
    }

    /// Steps before the next one whose end has a guard check (0: the next step has one).
    fn steps_to_check(&self) -> u64 {
        let ce = self.guards.check_every;
        if ce == 0 {
            u64::MAX
        } else {
            (ce - (self.step + 1) % ce) % ce
        }
    }

    /// The guard checks due after the step just completed (every `check_every` steps).
    fn after_step_checks(&mut self) -> Result<()> {
        if self.step.is_multiple_of(self.guards.check_every) {
            self.check_finite()?;
            if D::CLOSED && !G::ON {
                self.check_energy()?;
            }
        }
        Ok(())
    }

    /// Hand the state after a sampled step to the samplers due at this step.
    /// `parts`: the chunk sums the team made for this step (`Sampler::chunk_part`), by
    /// sampler index.
    fn sample(&mut self, parts: ChunkParts) -> Result<()> {
        let t0 = Instant::now();
        let r = self.sample_due(parts);
        self.timers.sampling += t0.elapsed().as_secs_f64();
        r
    }

    /// `sample` without its timer.
    fn sample_due(&mut self, mut parts: ChunkParts) -> Result<()> {
        let nw = self.walls.planes().len();
        let step = self.step;
        let elastic = self
            .samplers
            .iter()
            .any(|s| step.is_multiple_of(s.every()) && s.needs_elastic())
            .then(|| self.elastic_energy_sum());
        let view = SampleView {
            step: self.step,
            time: self.time,
            p: &self.p,
            contacts: &self.crecs,
            n_contacts: self.diag.contacts,
            max_overlap: self.diag.max_overlap,
            wall_force: &self.diag.wall_force[..nw],
            wall_impulse: &self.wall_impulse[..nw],
            h: self.domain.h(),
            widths: self.domain.widths().into(),
            observables: self.domain.observables(),
            elastic,
        };
        for (si, s) in self.samplers.iter_mut().enumerate() {
            if step.is_multiple_of(s.every()) {
                if let Some(k) = parts.iter().position(|q| q.0 == si) {
                    s.set_parts(parts.swap_remove(k).1);
                }
                s.sample(&view)?;
            }
        }
        Ok(())
    }

    /// Add a sampler of `kind` (`crate::sampling::make`); it samples from the next step on.
    pub fn add_sampler(&mut self, kind: &str, spec: crate::sampling::SamplerSpec) -> Result<()> {
        let planes = self.walls.planes().len();
        let setup = crate::sampling::Setup {
            p: &self.p,
            h: self.domain.h(),
            widths: self.domain.widths().into(),
            periodic: self.domain.periodic(),
            walls: planes,
        };
        let s = crate::sampling::make(kind, spec, &setup)?;
        if self.samplers.iter().any(|o| o.table() == s.table()) {
            return Err(Error::param(
                "sampler",
                kind,
                format!(
                    "one sampler per table: this simulation has a '{}' table already",
                    s.table()
                ),
            ));
        }
        self.samplers.push(s);
        Ok(())
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
        self.after_step_checks()
    }
}

/// How a team stint ended.
enum TeamExit {
    /// The steps asked for are done (the last one's cross pass deferred).
    Done,
    /// A step's first pass is done and the step needs what the team does not do (a build,
    /// a prune, a failed domain check): `step_finish` completes it with this `moved`.
    Outside { moved: bool },
    /// The last step's force evaluation exceeded the overlap guard (`check_overlap` reports).
    Overlap,
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
