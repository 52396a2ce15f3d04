//! Integration passes (velocity Verlet, as LAMMPS `nve/sphere`): the first half-kick and drift
//! fused with the packing of the pair loop's records (plain NVE, or a deforming cell's affine
//! maps), and the cross-chunk pass that completes the forces and applies the final half-kick.
//! Each pass works chunk by chunk with a baseline body and an AVX2 twin (`wide`), chosen by
//! `crate::simd::dispatch`: the same IEEE operations in the same order, so the same bits.

use super::chunk::{add10, PairOut};
use super::forces::stat_pieces;
use super::{Body, Engine, Walls};
use crate::contact::{Form, Friction};
use crate::domain::Domain;
use crate::neighbor::{chunk_size, NeighborList};
use crate::simd::{dispatch, Twin};
use crate::{M3, V3};
use rayon::prelude::*;
use std::marker::PhantomData;

#[cfg(target_arch = "x86_64")]
mod wide;

impl<F: Form, T: Friction, D: Domain, W: Walls<F, T>, G: Body> Engine<F, T, D, W, G> {
    /// `nve_initial` and `pack` in one pass (same arithmetic, same bits): at large N
    /// the step is bound by memory traffic, and this reads each particle once.
    /// Returns the largest squared drift velocity relative to the lists' frame (their
    /// displacement bounds grow by it times dt) and the velocities' range (the next frame).
    pub(super) fn kick_drift_pack(&mut self) -> Drift {
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
    pub(super) fn kick_drift_pack_affine(&mut self, m: &crate::domain::StepMaps) -> f64 {
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
                dispatch(Akp::<T>(k, PhantomData))
            })
            .reduce(|| 0.0, f64::max)
    }

    /// The speed that bounds how fast a pair's gap can close, per particle (half of it):
    /// the largest drift speed `sqrt(m2)`, plus in a deforming cell the affine part |L| r / 2
    /// at the largest distance a pair can reach contact from, r <= `NeighborList::cut`.
    pub(super) fn list_speed(&self, m2: f64) -> f64 {
        list_speed(m2, self.domain.affine_rate(), self.nl.cut)
    }

    /// Pack the step records: (x, R) and the velocities predicted to the end of the step,
    /// v(n+1/2) + dt/2 a(n) (and the same for w), with 1/m.
    pub(super) fn pack(&mut self) {
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
    pub(super) fn pack_xr(&mut self) {
        let p = &self.p;
        self.xr.resize(p.len(), [0.0; 4]);
        self.xr
            .par_iter_mut()
            .zip(p.x.par_iter().zip(p.radius.par_iter()))
            .with_min_len(4096)
            .for_each(|(a, (x, &r))| *a = xr_record(x, r));
    }

    /// The middle of the velocities' range (per component) and the largest squared speed
    /// relative to it.
    pub(super) fn frame_speed2(&self) -> ([f64; 3], f64) {
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

    /// Finish a step whose cross-chunk pass and final half-kick were deferred.
    pub(super) fn complete_step(&mut self) {
        if self.cross_pending {
            self.cross_pending = false;
            let _ = self.cross_pass::<false>(0.5 * self.dt);
        }
    }

    /// Phase 2: cross pairs in contact onto their second particles, in list order; in a time
    /// step (`kick` = dt/2), the final half-kick in the same pass (the forces of particle i are
    /// complete once its cross pairs are added): plain velocity Verlet, or a deforming cell's
    /// (`Domain::final_kick`), which also returns the kinetic sum sum_i m_i v_i (x) v_i after
    /// the kick, summed per chunk and then over the chunks in order (the same bits for any
    /// thread count; zero otherwise).
    pub(super) fn cross_pass<const STATS: bool>(&mut self, kick: f64) -> M3 {
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

/// The cross buffers, their statistics and the cross index, as the cross pass reads them.
pub(super) type CrossBufs<'a> = (&'a [Vec<PairOut>], &'a [Vec<[f64; 10]>], &'a [u32]);

/// The cross pass and final half-kick of one chunk's particles `r` alone (`cross_pass` for
/// one chunk, plain NVE: a team's completed last step); `f, t, v, w` are the chunk's slices.
#[allow(
    clippy::too_many_arguments,
    reason = "one chunk's slices of the team's shared arrays, passed as they are split"
)]
pub(super) fn finish_chunk<T: Friction>(
    nl: &NeighborList,
    (cross, cstat, cidx): CrossBufs,
    per: (&[f64], &[f64], &[f64]),
    r: std::ops::Range<usize>,
    kick: f64,
    (fo, to): (&mut [V3], &mut [V3]),
    vo: &mut [V3],
    wo: &mut [V3],
) {
    let src = CrossSrc::new(nl, cross, cstat, cidx, per, r, kick);
    let k = CrossChunk {
        fo,
        to,
        vo,
        wo,
        ps: &mut [],
        s: &src,
    };
    cross_kick_chunk::<false, T>(k, None);
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

/// Phase 2 for one chunk for [`dispatch`]: the cross pairs in contact onto their second
/// particles, in list order, then (in a step, `kick` > 0) the final half-kick (the same bits on
/// either path).
struct CrossKick<'a, 'b, 'c, const STATS: bool, T>(
    CrossChunk<'a, 'b>,
    AffineFinal<'c>,
    PhantomData<T>,
);

impl<const STATS: bool, T: Friction> Twin for CrossKick<'_, '_, '_, STATS, T> {
    type Out = M3;
    #[inline(always)]
    fn base(self) -> M3 {
        cross_kick::<STATS, T>(self.0, self.1)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn avx2(self) -> M3 {
        match self.1 {
            // SAFETY: the caller runs this only on AVX2 CPUs
            Some((m, mass)) if !STATS => unsafe { wide::cross_kick_affine::<T>(self.0, m, mass) },
            aff => cross_kick::<STATS, T>(self.0, aff),
        }
    }
}

/// [`CrossKick`] with the instruction set chosen at run time.
fn cross_kick_chunk<const STATS: bool, T: Friction>(k: CrossChunk, aff: AffineFinal) -> M3 {
    dispatch(CrossKick::<STATS, T>(k, aff, PhantomData))
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
pub(super) struct KickPass<'a> {
    pub(super) nl: &'a NeighborList,
    /// The cross buffers, their statistics and the cross index (read only when `pending`).
    pub(super) cross: &'a [Vec<PairOut>],
    pub(super) cstat: &'a [Vec<[f64; 10]>],
    pub(super) cidx: &'a [u32],
    /// (R, 1/m, 1/I) per particle.
    pub(super) per: (&'a [f64], &'a [f64], &'a [f64]),
    /// The last step's cross pass and final half-kick are still to be done.
    pub(super) pending: bool,
    pub(super) h: f64,
    pub(super) dt: f64,
    /// The lists' frame velocity (`NeighborList::frame_v`).
    pub(super) u: [f64; 3],
}

/// What one piece of that pass writes (its particles' slices, from particle `start` on):
/// positions, velocities, spins, forces and torques, and the packed (x, R) and velocity
/// records.
pub(super) struct KickOut<'a> {
    pub(super) x: &'a mut [V3],
    pub(super) v: &'a mut [V3],
    pub(super) w: &'a mut [V3],
    pub(super) f: &'a mut [V3],
    pub(super) t: &'a mut [V3],
    pub(super) a: &'a mut [[f64; 4]],
    pub(super) b: &'a mut [[f64; 8]],
}

impl KickPass<'_> {
    /// The pass over the particles start..start + o.x.len().
    #[inline(always)]
    pub(super) fn piece<T: Friction>(&self, start: usize, o: KickOut) -> Drift {
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
pub(super) struct Drift {
    pub(super) m2: f64,
    lo: [f64; 3],
    hi: [f64; 3],
}

impl Drift {
    pub(super) const EMPTY: Drift = Drift {
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

    pub(super) fn merge(a: Drift, b: Drift) -> Drift {
        Drift {
            m2: a.m2.max(b.m2),
            lo: [0, 1, 2].map(|c| a.lo[c].min(b.lo[c])),
            hi: [0, 1, 2].map(|c| a.hi[c].max(b.hi[c])),
        }
    }

    /// The middle of the velocity range, per component (zero if it is not finite: a NaN
    /// velocity, which the finite check reports, or no particles).
    pub(super) fn next_frame(&self) -> [f64; 3] {
        let m = [0, 1, 2].map(|c| 0.5 * self.lo[c] + 0.5 * self.hi[c]);
        if m.iter().all(|c| c.is_finite()) {
            m
        } else {
            [0.0; 3]
        }
    }
}

/// Half-kick, drift and step records of one chunk (plain NVE) for [`dispatch`] (elementwise
/// arithmetic: the same bits on either path). Returns the largest squared drift velocity
/// relative to the frame, and the velocities' range (`Drift`).
struct Kdp<'a, 'b, T>(KickChunk<'a, 'b>, PhantomData<T>);

impl<T: Friction> Twin for Kdp<'_, '_, T> {
    type Out = Drift;
    #[inline(always)]
    fn base(self) -> Drift {
        kdp::<T>(self.0)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn avx2(self) -> Drift {
        // SAFETY: the caller runs this only on AVX2 CPUs
        unsafe { wide::kdp::<T>(self.0) }
    }
}

/// [`Kdp`] with the instruction set chosen at run time.
fn kick_drift_pack_chunk<T: Friction>(k: KickChunk) -> Drift {
    dispatch(Kdp::<T>(k, PhantomData))
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
#[allow(
    clippy::type_complexity,
    reason = "five written and five read slices of one chunk, named by the doc above"
)]
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

/// A deforming cell's first half-kick, drift and packing of one chunk for [`dispatch`] (the
/// same IEEE operations on either path: the same bits).
struct Akp<'a, 'b, T>(AffineKick<'a, 'b>, PhantomData<T>);

impl<T: Friction> Twin for Akp<'_, '_, T> {
    type Out = f64;
    #[inline(always)]
    fn base(self) -> f64 {
        affine_kick_pack::<T>(self.0)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn avx2(self) -> f64 {
        // SAFETY: the caller runs this only on AVX2 CPUs
        unsafe { wide::akp::<T>(self.0) }
    }
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
pub(super) fn list_speed(m2: f64, affine_rate: f64, cut: f64) -> f64 {
    m2.sqrt() + 0.5 * affine_rate * cut
}

/// Packed position record of the pair loop: (x, R).
#[inline(always)]
pub(super) fn xr_record(x: &V3, r: f64) -> [f64; 4] {
    [x.x, x.y, x.z, r]
}

/// Packed velocity record of the pair loop: v and w predicted to the end of the step
/// (v + h f/m, w + h t/I, h = dt/2), 1/m and R: the law's gather reads (v, 1/m) and (w, R)
/// as two 32-byte halves.
#[inline(always)]
#[allow(
    clippy::too_many_arguments,
    reason = "one record from a particle's scalars, inlined into hot loops: a struct would only rename them"
)]
fn kin_record(v: &V3, w: &V3, f: &V3, t: &V3, im: f64, ii: f64, h: f64, r: f64) -> [f64; 8] {
    let vp = v + (h * im) * f;
    let wp = w + (h * ii) * t;
    [vp.x, vp.y, vp.z, im, wp.x, wp.y, wp.z, r]
}
