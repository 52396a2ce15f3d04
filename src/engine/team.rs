//! Plain steps run by one team of threads: one parallel region for a stretch of steps
//! instead of two per step.
//!
//! Each of a step's two parallel passes (half-kick/drift/pack, then forces) is only a few
//! chunks long at the papers' sizes, so handing each pass to rayon costs a large share of the
//! threads' time in waiting. A team enters one `rayon::broadcast` and meets at a spin barrier
//! after each pass; within a pass each thread claims first the pieces of its home (the same
//! particles every step, so they stay in its core's cache; the half-kick pass in quarter
//! chunks, the force loop by chunk), then the others' from their far ends, so a thread that
//! arrives late takes fewer pieces (`Claims`).
//!
//! Large systems (`Tuning::fuse_from`) fuse the two passes into one sweep per step: a thread
//! claims a chunk (in descending order), packs it, waits until the later chunks its cross
//! pairs reach are packed (`NeighborList::cross_reach`; claimed earlier, so packed or being
//! packed) and computes its forces while its records are still in cache (they would otherwise
//! come back from memory). The forces are computed before the step knows whether it must
//! rebuild or prune first; a step that may (judged on the last drift speed with a margin,
//! `Tuning::fuse_margin`) runs the two passes instead, and one misjudged computes its forces
//! again outside (the packed records carried through a rebuild, as the forces they were
//! packed from are gone).
//!
//! Determinism is unchanged: every piece and chunk computes exactly what it computes
//! outside the team (a chunk's sums have the order of the list), the displacement bounds are
//! maxima and minima (the same for any grouping), and every decision to leave the team is
//! taken by each thread from the same values.
//!
//! The team runs only plain NVE steps that need nothing else: no list build, no prune, no
//! statistics or virial, no guard check, and a following step in the same `run` (the cross
//! pass and final half-kick are deferred, as in `step_once`). A step that needs more is
//! finished outside once its first pass is done. One team runs at a time in the process
//! (two teams sharing a rayon pool could each hold one thread and wait for the other's);
//! a run that finds the team taken steps the usual way. Measurements: `benchmarks/NOTES.md`.

use super::chunk::{self, ChunkIo, ChunkOut, Shared};
use super::forces::{inner_skin_for, reduce_outs};
use super::integrate::{finish_chunk, list_speed, Drift, KickOut, KickPass};
use super::*;
use crate::neighbor::image_shifts;
use crate::sampling::ChunkView;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Mutex, TryLockError};

/// One team at a time per process (see the module notes).
static TEAM: Mutex<()> = Mutex::new(());

/// Half-kick pass pieces per force-loop chunk (its split is free: per-particle work).
const KICK_SPLIT: usize = 4;

/// A barrier the team's threads spin on (the passes between barriers are tens of
/// microseconds; a sleeping thread would take as long to wake). After a few thousand
/// spins a waiting thread yields its core, so an oversubscribed machine still progresses.
struct Barrier {
    n: usize,
    count: AtomicUsize,
    generation: AtomicUsize,
    /// Set when a thread of the team panics: the others stop waiting and panic too (the
    /// broadcast then reports the panic), instead of spinning forever.
    poisoned: AtomicBool,
}

impl Barrier {
    fn new(n: usize) -> Self {
        Barrier {
            n,
            count: AtomicUsize::new(0),
            generation: AtomicUsize::new(0),
            poisoned: AtomicBool::new(false),
        }
    }

    /// Spin (then yield) until `ready()`; panics if another thread of the team panicked.
    fn wait_for(&self, ready: impl Fn() -> bool) {
        let mut spins = 0u32;
        while !ready() {
            assert!(
                !self.poisoned.load(Ordering::Relaxed),
                "another thread of the step team panicked"
            );
            if spins < 4000 {
                spins += 1;
                std::hint::spin_loop();
            } else {
                std::thread::yield_now();
            }
        }
    }

    /// Wait for every thread of the team. Release/acquire: what a thread wrote before the
    /// barrier is seen by every thread after it.
    fn wait(&self) {
        let g = self.generation.load(Ordering::Acquire);
        if self.count.fetch_add(1, Ordering::AcqRel) + 1 == self.n {
            self.count.store(0, Ordering::Relaxed);
            self.generation.store(g.wrapping_add(1), Ordering::Release);
            return;
        }
        self.wait_for(|| self.generation.load(Ordering::Acquire) != g);
    }
}

/// Poisons the barrier if its thread unwinds.
struct PoisonOnPanic<'a>(&'a Barrier);

impl Drop for PoisonOnPanic<'_> {
    fn drop(&mut self) {
        if std::thread::panicking() {
            self.0.poisoned.store(true, Ordering::Relaxed);
        }
    }
}

/// A pointer the team's threads share; each pass writes disjoint ranges through it, and
/// passes are separated by the barrier.
#[derive(Clone, Copy)]
struct Ptr<X>(*mut X);
// SAFETY: used only as described above (disjoint writes within a pass, barrier between)
unsafe impl<X> Send for Ptr<X> {}
unsafe impl<X> Sync for Ptr<X> {}

impl<X> Ptr<X> {
    /// The pointer (a method, so that a closure captures the whole `Ptr`, which is `Sync`).
    fn get(&self) -> *mut X {
        self.0
    }
    /// # Safety
    /// `r` lies within the allocation and no other thread touches it during the pass.
    #[allow(
        clippy::mut_from_ref,
        reason = "disjoint ranges of one buffer handed to the team's threads; the caller guarantees exclusivity (see Safety)"
    )]
    unsafe fn slice_mut(&self, r: std::ops::Range<usize>) -> &mut [X] {
        unsafe { std::slice::from_raw_parts_mut(self.0.add(r.start), r.end - r.start) }
    }
    /// # Safety
    /// `r` lies within the allocation and no thread writes it during the pass.
    unsafe fn slice(&self, r: std::ops::Range<usize>) -> &[X] {
        unsafe { std::slice::from_raw_parts(self.0.add(r.start), r.end - r.start) }
    }
}

/// Pieces of a pass claimed by the threads of a team. Each thread has a home range (the same
/// particles in both passes and every step, so they stay in its core's cache), takes its
/// own pieces first, then the others' from their far ends (a thread that finishes early
/// helps the slowest without taking what the owner is about to start).
struct Claims {
    /// The pass that last claimed each piece, one cache line pair each: a piece's flag is
    /// swapped by its owner every pass, and flags sharing a line with the other thread's
    /// would make every claim a cross-core transfer (~0.4 us round trip on this VM at times).
    by: Vec<Slot>,
    /// Per thread its order of pieces.
    order: Vec<Vec<usize>>,
}

impl Claims {
    /// `pieces` pieces, `per_chunk` of them per force-loop chunk; the chunks are dealt to the
    /// threads back and forth (0, 1, 1, 0 for two threads and four chunks): early chunks
    /// send the cross-chunk pairs (more force-loop work), late ones receive them (more
    /// half-kick work), so each thread gets some of both.
    fn new(pieces: usize, per_chunk: usize, threads: usize) -> Self {
        let owner = |k: usize| {
            let c = k / per_chunk;
            if (c / threads).is_multiple_of(2) {
                c % threads
            } else {
                threads - 1 - c % threads
            }
        };
        let home = |t: usize| (0..pieces).filter(move |&k| owner(k) == t);
        let order = (0..threads)
            .map(|t| {
                let mut o: Vec<usize> = home(t).collect();
                for d in 1..threads {
                    let mut other: Vec<usize> = home((t + d) % threads).collect();
                    other.reverse();
                    o.extend(other);
                }
                o
            })
            .collect();
        Claims {
            by: (0..pieces).map(|_| Slot(AtomicUsize::new(0))).collect(),
            order,
        }
    }

    /// The pieces thread `me` gets in pass `pass` (numbered from 1, never reused).
    fn take(&self, me: usize, pass: usize) -> impl Iterator<Item = usize> + '_ {
        self.order[me]
            .iter()
            .copied()
            // (a plain load first: a piece already taken costs no read-for-ownership)
            .filter(move |&k| {
                let f = &self.by[k].0;
                f.load(Ordering::Relaxed) != pass && f.swap(pass, Ordering::Relaxed) != pass
            })
    }
}

/// A claim flag alone on its 128 bytes (a line and its adjacent-line prefetch partner).
#[repr(align(128))]
struct Slot(AtomicUsize);

/// The displacement bounds each thread keeps (the same on all: they see the same drifts).
#[derive(Clone, Copy)]
struct Track {
    moved: f64,
    inner_moved: f64,
    frame_v: [f64; 3],
    vmax2: f64,
}

impl Track {
    /// After a step that adds `dd` to the bounds: (a rebuild is due, a prune is due).
    fn due_after(&self, nl: &NeighborList, dd: f64) -> (bool, bool) {
        (
            nl.out_of_skin(self.moved + dd),
            nl.prune_due_at(self.inner_moved + dd),
        )
    }
}

impl<F, T, D, W, G> Engine<F, T, D, W, G>
where
    F: Form,
    T: Friction,
    D: Domain,
    W: Walls<F, T>,
    G: Body,
{
    /// Whether the next steps may run in a team: plain NVE, nothing but forces asked for, the
    /// lists and forces valid.
    pub(super) fn team_ready(&self) -> bool {
        let n = self.p.len();
        self.tuning.team
            && D::PLAIN_NVE
            && !D::NEEDS_VIRIAL
            && !self.want_virial
            && !self.want_stats
            && !self.want_records
            && self.forces_valid
            && self.nl.valid
            && self.nl.inner_valid
            && self.nl.own_start.len() == n + 1
            && self.xr.len() == n
            && self.kin.len() == n
            && self.hist.len() == n.div_ceil(chunk_size(n))
            && self.cross_idx.len() == self.nl.n_cross()
            && self.nl.cross_reach.len() == n.div_ceil(chunk_size(n))
    }

    /// Up to `budget` plain steps (each followed by another step of the same run, none with
    /// a guard check due) in one team. With `complete`, the last of them is a sampled step:
    /// it is completed in the team (its cross pass and final half-kick done, nothing
    /// deferred), its evaluation keeping the contact records if `records`, and it may be the
    /// run's last or have a guard check due (the caller checks). Returns the steps done, how
    /// the stint ended and the due samplers' chunk sums of a completed last step; `None` when
    /// another team holds the process's team (step the usual way).
    pub(super) fn team_steps(
        &mut self,
        budget: u64,
        complete: bool,
        records: bool,
    ) -> Option<(u64, TeamExit, ChunkParts)> {
        let _guard = match TEAM.try_lock() {
            Ok(g) => g,
            Err(TryLockError::Poisoned(e)) => e.into_inner(),
            Err(TryLockError::WouldBlock) => return None,
        };
        let n = self.p.len();
        let ch = chunk_size(n);
        let nch = n.div_ceil(ch);
        let kp = ch.div_ceil(KICK_SPLIT);
        let nkp = nch * KICK_SPLIT;
        let dt = self.dt;
        let h = 0.5 * dt;
        let step0 = self.step;
        let first_pending = self.cross_pending;
        let track0 = Track {
            moved: self.nl.moved,
            inner_moved: self.nl.inner_moved,
            frame_v: self.nl.frame_v,
            vmax2: self.vmax2,
        };
        let wf0 = self.diag.wall_force;
        // the samplers due at a completed last step, whose chunk sums the team makes as it
        // completes the chunks (one slot per sampler and chunk)
        let samplers = &self.samplers;
        let due: Vec<usize> = if complete {
            let at = step0 + budget;
            (0..samplers.len())
                .filter(|&k| at.is_multiple_of(samplers[k].every()))
                .collect()
        } else {
            Vec::new()
        };

        // what the passes write, as shared pointers; what they only read, as references
        let Particles {
            x,
            v,
            omega,
            force,
            torque,
            radius,
            mass,
            inv_mass,
            inv_inertia,
            ..
        } = &mut self.p;
        let (px, pv, pw, pf, pt) = (
            Ptr(x.as_mut_ptr()),
            Ptr(v.as_mut_ptr()),
            Ptr(omega.as_mut_ptr()),
            Ptr(force.as_mut_ptr()),
            Ptr(torque.as_mut_ptr()),
        );
        let (pxr, pkin) = (Ptr(self.xr.as_mut_ptr()), Ptr(self.kin.as_mut_ptr()));
        // the histories alternate between the two sets of lists, step by step
        let phist = [
            Ptr(self.hist.as_mut_ptr()),
            Ptr(self.hist_next.as_mut_ptr()),
        ];
        let pwhist = [
            Ptr(self.whist.as_mut_ptr()),
            Ptr(self.whist_next.as_mut_ptr()),
        ];
        let pcross = Ptr(self.cross.as_mut_ptr());
        let pcstat = Ptr(self.cross_stats.as_mut_ptr());
        // (written only by a completed last step that keeps the contact records)
        let pcrec = Ptr(self.crecs.as_mut_ptr());
        // room for the cross index of a prune inside the team (it must not move: every
        // thread holds its address); a prune that needs more is done outside
        let more_cross = match self.tuning.team_cross_room {
            Some(k) => {
                self.cross_idx.shrink_to_fit();
                k
            }
            None => self.cross_idx.len() / 8 + 64,
        };
        self.cross_idx.reserve(more_cross);
        let pruned = AtomicUsize::new(0);
        let pcidx = Ptr(self.cross_idx.as_mut_ptr());
        let pcidx_vec = Ptr(&mut self.cross_idx as *mut Vec<u32>);
        let cidx_cap = self.cross_idx.capacity();
        let (rad, im, ii, mass): (&[f64], &[f64], &[f64], &[f64]) =
            (radius, inv_mass, inv_inertia, mass);
        // the lists: read by every thread, changed only by a prune inside the team (chunks
        // by their threads, the rest by thread 0, between barriers), so each thread takes a
        // fresh view after it
        let pnl = Ptr(&mut self.nl as *mut NeighborList);
        let (law, dom) = (&self.law, &self.domain);
        let prune_steps = self.tuning.prune_steps;
        let in_team_prune = self.tuning.prune_in_team;
        let (walls, body) = (&self.walls, &self.body);
        let guards = &self.guards;

        let threads = rayon::current_num_threads();
        let barrier = Barrier::new(threads);
        let kick_claims = Claims::new(nkp, KICK_SPLIT, threads);
        let chunk_claims = Claims::new(nch, 1, threads);
        let prune_claims = Claims::new(nch, 1, threads);
        let finish_claims = Claims::new(nch, 1, threads);
        let mut parts: Vec<Option<Vec<f64>>> = vec![None; due.len() * nch];
        let pparts = Ptr(parts.as_mut_ptr());
        // per thread its drift of the pass, per chunk its report (each written by one thread
        // in a pass, read by all after the barrier); two sets, by the parity of the step: a
        // fused step has no barrier between reading one step's and writing the next one's (a
        // thread may start the next sweep while another still reads), but one between that
        // and writing the step after
        let mut drifts = vec![Drift::EMPTY; 2 * threads];
        let mut outs: Vec<ChunkOut> = (0..2 * nch).map(|_| ChunkOut::default()).collect();
        let (pdrift, pouts) = (Ptr(drifts.as_mut_ptr()), Ptr(outs.as_mut_ptr()));
        // the leader's (thread 0's) account: pass times and wall impulses
        let leader: Mutex<(f64, f64)> = Mutex::new((0.0, 0.0));
        let wall_sum: Mutex<[V3; MAX_WALLS]> = Mutex::new(self.wall_impulse);

        // the fused sweep (large systems): chunks claimed in descending order from one
        // counter (the p-th fused sweep claims (p-1) nch .. p nch); each chunk's pass number
        // once packed
        let fused = n >= self.tuning.fuse_from;
        let margin = self.tuning.fuse_margin;
        let next = AtomicUsize::new(0);
        let packed: Vec<AtomicUsize> = (0..nch).map(|_| AtomicUsize::new(0)).collect();

        let results = rayon::broadcast(|ctx| {
            let me = ctx.index();
            let _poison = PoisonOnPanic(&barrier);
            let mut track = track0;
            let mut pending = first_pending;
            let mut done = 0u64;
            let mut last_diag = None;
            // fused sweeps done (the same count on every thread: they decide alike)
            let mut fpass = 0usize;
            loop {
                // SAFETY: no thread changes the lists until this view's last use (below)
                let nl: &NeighborList = unsafe { &*pnl.get() };
                let ncidx = nl.n_cross();
                let tk = Instant::now();
                let pass_no = 1 + done as usize;
                let par = (done % 2) as usize;
                // pass 1: the last step's cross pass and final half-kick, this step's
                // half-kick, drift and records
                let mut dr = Drift::EMPTY;
                // SAFETY (the pass): each piece is claimed once, the pieces are disjoint
                // ranges of the per-particle arrays, and nothing else is written during the
                // pass; the cross buffers and index are only read
                let pass = unsafe {
                    KickPass {
                        nl,
                        cross: pcross.slice(0..nch),
                        cstat: pcstat.slice(0..nch),
                        cidx: pcidx.slice(0..ncidx),
                        per: (rad, im, ii),
                        pending,
                        h,
                        dt,
                        u: track.frame_v,
                    }
                };
                // pass 1 over the particles r (a claimed piece)
                let kick_piece = |r: std::ops::Range<usize>| {
                    // SAFETY: a claimed piece: no other thread touches its particles in the pass
                    let o = unsafe {
                        KickOut {
                            x: px.slice_mut(r.clone()),
                            v: pv.slice_mut(r.clone()),
                            w: pw.slice_mut(r.clone()),
                            f: pf.slice_mut(r.clone()),
                            t: pt.slice_mut(r.clone()),
                            a: pxr.slice_mut(r.clone()),
                            b: pkin.slice_mut(r.clone()),
                        }
                    };
                    pass.piece::<T>(r.start, o)
                };
                // the last step of a stint that completes it (a sampled step)
                let last = complete && done + 1 == budget;
                // chunk c's forces (pass 2), its report into outs[c]; the contact records kept
                // when the completed last step wants them
                let force_chunk = |c: usize, shared: &Shared<F, T, D>, nl: &NeighborList| {
                    let r = c * ch..((c + 1) * ch).min(n);
                    let (c0, c1) = (nl.cross_off[c] as usize, nl.cross_off[c + 1] as usize);
                    // SAFETY: each chunk is claimed once per pass; it writes its own range of
                    // forces and torques, its own history lists, cross buffer and slots
                    let o = unsafe {
                        let io = ChunkIo {
                            fo: pf.slice_mut(r.clone()),
                            to: pt.slice_mut(r.clone()),
                            hold: &*phist[par].0.add(c),
                            hnew: &mut *phist[1 - par].0.add(c),
                            wold: &*pwhist[par].0.add(c),
                            wnew: &mut *pwhist[1 - par].0.add(c),
                            cross: &mut *pcross.0.add(c),
                            cstat: &mut *pcstat.0.add(c),
                            cidx: pcidx.slice_mut(c0..c1),
                            ps: &mut [],
                            crec: &mut *pcrec.get().add(c),
                        };
                        if last && records {
                            chunk::chunk::<F, T, D, W, G, true, false>(shared, c, io)
                        } else {
                            chunk::chunk::<F, T, D, W, G, false, false>(shared, c, io)
                        }
                    };
                    // SAFETY: chunk c's report is written by the thread that took it
                    unsafe { *pouts.0.add(par * nch + c) = o };
                };
                // fuse this step unless it may end the stint (then the forces of a fused sweep
                // would be computed for nothing): judged on the last step's drift speed with a
                // margin (a misjudged step is still right, only slower)
                let fuse = fused
                    && !last
                    && track.due_after(nl, nl.step_drift(margin * track.vmax2.sqrt(), dt))
                        == (false, false);
                if fuse {
                    // SAFETY: other threads write records within these slices during the
                    // sweep, but a chunk's forces read only its own and those of the chunks
                    // it waited for (below), which no thread writes again in the sweep: no
                    // record is written while it is read. (Raw pointers instead of slices
                    // would say so more plainly, but cost the force loop the slices' aliasing
                    // facts: 7 % slower at 6754 particles.)
                    let recs = unsafe { (pxr.slice(0..n), pkin.slice(0..n), mass) };
                    let shared = Shared::new(law, dom, walls, body, nl, recs, dt, ch);
                    fpass += 1;
                    let lim = fpass * nch;
                    loop {
                        let k = next.load(Ordering::Relaxed);
                        if k >= lim {
                            break;
                        }
                        if next
                            .compare_exchange_weak(k, k + 1, Ordering::Relaxed, Ordering::Relaxed)
                            .is_err()
                        {
                            continue;
                        }
                        let c = lim - 1 - k;
                        let r = c * ch..((c + 1) * ch).min(n);
                        dr = Drift::merge(dr, kick_piece(r.clone()));
                        packed[c].store(pass_no, Ordering::Release);
                        // the chunks whose records its cross pairs read, and whose pending
                        // pass reads its cross buffer (which its forces overwrite), packed;
                        // they were claimed before it, so they are packed or being packed
                        for p in &packed[c + 1..=nl.cross_reach[c] as usize] {
                            barrier.wait_for(|| p.load(Ordering::Acquire) == pass_no);
                        }
                        force_chunk(c, &shared, nl);
                    }
                } else {
                    for k in kick_claims.take(me, pass_no) {
                        // sub-piece k % KICK_SPLIT of chunk k / KICK_SPLIT
                        let c0 = (k / KICK_SPLIT) * ch;
                        let c1 = (c0 + ch).min(n);
                        let a = (c0 + (k % KICK_SPLIT) * kp).min(c1);
                        let r = a..(a + kp).min(c1);
                        dr = Drift::merge(dr, kick_piece(r));
                    }
                }
                // SAFETY: slot `me` of this parity is this thread's alone during the pass
                unsafe { *pdrift.0.add(par * threads + me) = dr };
                barrier.wait();
                // SAFETY: this parity's slots are written again two steps on, after a barrier
                // every thread passes once done reading them
                let dr = unsafe { pdrift.slice(par * threads..(par + 1) * threads) }
                    .iter()
                    .fold(Drift::EMPTY, |a, d| Drift::merge(a, *d));
                pending = true;
                // the bounds of `step_once`, on every thread alike
                track.vmax2 = dr.m2;
                let dd = nl.step_drift(dr.m2.sqrt(), dt);
                let (moved, prune) = track.due_after(nl, dd);
                track.moved += dd;
                track.inner_moved += dd;
                track.frame_v = dr.next_frame();
                let step = step0 + done;
                // a due prune is done here, unless the step was fused (its forces are then
                // computed again outside) or it must rebuild
                let prune_here = prune && in_team_prune && !fuse;
                if moved
                    || (prune && !prune_here)
                    || dom.check(step).is_err()
                    || dom.rebuild_due(nl.skin)
                {
                    // (a fused sweep computed this step's forces with lists now out of
                    // date: they are computed again outside, from the records)
                    return (done, track, TeamExit::Outside { moved }, last_diag);
                }
                let nl = if prune_here {
                    // `Engine::prune` (same inner skin, same chunks), its chunks shared out
                    let speed = list_speed(track.vmax2, dom.affine_rate(), nl.cut);
                    let s_in = inner_skin_for(prune_steps, nl.skin, speed, dt);
                    let shifts = image_shifts(&dom.h());
                    // SAFETY: the records are only read until the next pass
                    let xr = unsafe { pxr.slice(0..n) };
                    for c in prune_claims.take(me, pass_no) {
                        // SAFETY: chunk c is this thread's alone; nothing else in the lists
                        // is written until the barrier
                        unsafe { NeighborList::prune_part(pnl.get(), c, xr, &shifts, s_in) };
                    }
                    barrier.wait();
                    // SAFETY: the chunks are done; read only until the next barrier
                    let cross_needed: usize =
                        unsafe { (*pnl.get()).inner.iter().map(|ic| ic.xj.len()).sum() };
                    if cross_needed > cidx_cap {
                        // (the cross index would move: the step's prune is done again outside,
                        // from the same records, to the same chunks; no thread writes the
                        // lists before then)
                        return (done, track, TeamExit::Outside { moved }, last_diag);
                    }
                    barrier.wait();
                    if me == 0 {
                        // SAFETY: the other threads wait at the barrier holding no view
                        unsafe {
                            (*pnl.get()).prune_finish(s_in);
                            pruned.fetch_add(1, Ordering::Relaxed);
                            let ci = &mut *pcidx_vec.get();
                            ci.clear();
                            ci.resize(cross_needed, u32::MAX);
                            debug_assert_eq!(ci.as_mut_ptr(), pcidx.0);
                        }
                    }
                    barrier.wait();
                    track.inner_moved = 0.0;
                    // SAFETY: no thread changes the lists again in this step
                    unsafe { &*pnl.get() }
                } else {
                    nl
                };
                let tf = Instant::now();
                if !fuse {
                    // pass 2: forces, chunk by chunk
                    // SAFETY: the records are only read in this pass
                    let recs = unsafe { (pxr.slice(0..n), pkin.slice(0..n), mass) };
                    let shared = Shared::new(law, dom, walls, body, nl, recs, dt, ch);
                    for c in chunk_claims.take(me, pass_no) {
                        force_chunk(c, &shared, nl);
                    }
                    barrier.wait();
                }
                if last {
                    // complete the step: the cross pass and final half-kick (as `cross_pass`),
                    // chunk by chunk; the forces, velocities and spins are then full-step
                    // SAFETY: the forces' cross buffers and index are only read; each chunk is
                    // claimed once and writes only its own particles
                    let bufs = unsafe {
                        (
                            pcross.slice(0..nch),
                            pcstat.slice(0..nch),
                            pcidx.slice(0..nl.n_cross()),
                        )
                    };
                    for c in finish_claims.take(me, pass_no) {
                        let r = c * ch..((c + 1) * ch).min(n);
                        // SAFETY: chunk c is this thread's alone in this pass
                        unsafe {
                            finish_chunk::<T>(
                                nl,
                                bufs,
                                (rad, im, ii),
                                r.clone(),
                                h,
                                (pf.slice_mut(r.clone()), pt.slice_mut(r.clone())),
                                pv.slice_mut(r.clone()),
                                pw.slice_mut(r.clone()),
                            )
                        };
                        if due.is_empty() {
                            continue;
                        }
                        // the due samplers' sums over the chunk, while it is in cache
                        // SAFETY: no thread writes positions in this pass; the chunk's
                        // velocities and spins are this thread's, completed just above; its
                        // records were written in the force pass; each slot is this chunk's
                        let cv = unsafe {
                            ChunkView {
                                x: px.slice(0..n),
                                radius: rad,
                                mass,
                                inv_inertia: ii,
                                v: pv.slice(r.clone()),
                                omega: pw.slice(r.clone()),
                                recs: if records { &*pcrec.get().add(c) } else { &[] },
                                r,
                            }
                        };
                        for (k, &si) in due.iter().enumerate() {
                            let part = samplers[si].chunk_part(&cv);
                            unsafe { *pparts.get().add(k * nch + c) = part };
                        }
                    }
                    barrier.wait();
                }
                done += 1;
                // SAFETY: as for the drifts
                let diag = reduce_outs(unsafe { pouts.slice(par * nch..(par + 1) * nch) });
                if me == 0 {
                    let te = Instant::now();
                    let mut l = leader.lock().unwrap();
                    if fuse {
                        // (a fused sweep is timed as forces)
                        l.1 += (te - tk).as_secs_f64();
                    } else {
                        l.0 += (tf - tk).as_secs_f64();
                        l.1 += (te - tf).as_secs_f64();
                    }
                    if W::ON {
                        // from the wall forces of the last step (before the team's first)
                        let old = last_diag
                            .as_ref()
                            .map_or(&wf0, |d: &StepDiag| &d.wall_force);
                        add_wall_impulse(&mut wall_sum.lock().unwrap(), old, &diag.wall_force, dt);
                    }
                }
                let bad = guards.overlap_exceeded(&diag);
                last_diag = Some(diag);
                if bad || done == budget {
                    let exit = if bad {
                        TeamExit::Overlap
                    } else {
                        TeamExit::Done
                    };
                    return (done, track, exit, last_diag);
                }
            }
        });

        // every thread ended at the same step for the same reason; the first one's account
        let (done, track, exit, last_diag) =
            results.into_iter().next().expect("a team of one or more");
        let pruned = pruned.into_inner() as u64;
        self.team_prunes += pruned;
        if pruned > 0 && self.trim() > RELEASE_BYTES {
            // (as `Engine::prune` does: the contact lists grow by doubling in the sweeps)
            release_free_memory();
        }
        if done % 2 == 1 {
            std::mem::swap(&mut self.hist, &mut self.hist_next);
            std::mem::swap(&mut self.whist, &mut self.whist_next);
        }
        if let Some(d) = last_diag {
            self.diag = d;
        }
        // the due samplers' parts of a completed last step (a sampler's only when it gave
        // one for every chunk)
        let parts: ChunkParts = if complete && done == budget {
            due.iter()
                .zip(parts.chunks_exact_mut(nch))
                .filter_map(|(&si, p)| {
                    let mine: Option<Vec<Vec<f64>>> = p.iter_mut().map(Option::take).collect();
                    mine.map(|m| (si, m))
                })
                .collect()
        } else {
            Vec::new()
        };
        // a stint that ends inside a step has done that step's first pass, which took the
        // pending cross pass; one that completed its last step has nothing pending;
        // otherwise the last step's cross pass is pending
        self.cross_pending = match exit {
            TeamExit::Outside { .. } => false,
            TeamExit::Done | TeamExit::Overlap => !(complete && done == budget),
        };
        self.wall_impulse = wall_sum.into_inner().unwrap();
        let (ti, tf) = leader.into_inner().unwrap();
        self.timers.integrate += ti;
        self.timers.forces += tf;
        self.timers.pair_phase += tf;
        self.nl.moved = track.moved;
        self.nl.inner_moved = track.inner_moved;
        self.nl.frame_v = track.frame_v;
        self.vmax2 = track.vmax2;
        self.step += done;
        // step by step, as `step_once` adds it (the same bits)
        for _ in 0..done {
            self.time += dt;
        }
        Some((done, exit, parts))
    }
}
