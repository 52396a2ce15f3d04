//! Force evaluation: the pair loop over fixed chunks (`super::chunk`), the reduction of the
//! chunks' reports, the inner list's prunes, and the contact list recomputed for samplers.

use super::chunk::{ChunkIo, ChunkOut, Shared};
use super::{release_free_memory, Body, Engine, StepDiag, Walls, RELEASE_BYTES, RELEASE_N};
use crate::contact::{Form, Friction};
use crate::domain::Domain;
use crate::neighbor::{chunk_size, image_shifts};
use crate::V3;
use rayon::prelude::*;
use std::time::Instant;

impl<F: Form, T: Friction, D: Domain, W: Walls<F, T>, G: Body> Engine<F, T, D, W, G> {
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

    /// Rebuild the inner list from the packed positions (after `pack`): the skin is chosen
    /// so that it lasts `prune_steps` steps at the last step's largest speed relative to the
    /// lists' frame (the whole list where the domain moves particles itself, or pruning is
    /// off).
    pub(super) fn prune(&mut self) {
        let s_in = inner_skin_for(
            self.tuning.prune_steps,
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
    pub(super) fn evaluate(&mut self, hist_dt: f64, kick: f64, defer: bool) {
        // the statistics and virial paths are compiled separately, so the plain step carries
        // none of their code (nor its register pressure)
        match (
            self.want_stats || self.want_records,
            D::NEEDS_VIRIAL || self.want_virial,
        ) {
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
        // (the per-particle sums only when asked for them; samplers read the contact records)
        let want_stats = STATS && self.want_stats;
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
            .zip(self.crecs.iter_mut())
            .map(
                |(
                    (((((((((fo, to), hold), hnew), wold), wnew), cross), cstat), cidx), ps),
                    crec,
                )| {
                    ChunkIo {
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
                        crec,
                    }
                },
            )
            .enumerate()
            .collect();

        let shared = Shared::new(
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
            .map(|(c, io)| super::chunk::chunk::<F, T, D, W, G, STATS, VIR>(&shared, c, io))
            .collect();
        std::mem::swap(&mut self.hist, &mut self.hist_next);
        std::mem::swap(&mut self.whist, &mut self.whist_next);

        let tp = Instant::now();
        self.diag = reduce_outs(&results);
        if defer && kick > 0.0 && !STATS {
            self.cross_pending = true;
        } else if want_stats {
            self.kin_sum = self.cross_pass::<true>(kick);
        } else {
            self.kin_sum = self.cross_pass::<false>(kick);
        }
        self.forces_valid = true;
        self.want_stats = false;
        self.want_records = false;
        let te = Instant::now();
        self.timers.pair_phase += (tp - tstart).as_secs_f64();
        self.timers.gather_phase += (te - tp).as_secs_f64();
    }
}

/// The step's diagnostics from the chunks' reports, in chunk order.
pub(super) fn reduce_outs(results: &[ChunkOut]) -> StepDiag {
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
pub(super) fn stat_pieces(
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

/// The inner skin of a prune (`Engine::prune`): chosen to last `prune_steps` steps at the
/// gap-closing speed `speed` (`list_speed`), within 1/50 of the outer skin and below half of
/// it (else every pair is kept: no pruning, infinite).
pub(super) fn inner_skin_for(prune_steps: f64, skin: f64, speed: f64, dt: f64) -> f64 {
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
