//! One chunk of the pair force loop (see `Engine::evaluate` in `super::forces`), in three passes over blocks of
//! `BLOCK` particles:
//! 1. the distance test over the block's listed pairs, appending the contacts (in list order)
//!    to a per-thread buffer;
//! 2. the contact law on lanes of `LANES` contacts (`crate::contact::lanes`), and the sums of the
//!    forces and torques onto both particles in list order;
//! 3. walls and gravity, particle by particle.
//!
//! Compiled twice: with AVX2 (four lanes per instruction, the pair records transposed into
//! lanes with shuffles) and for baseline x86-64; the CPU picks at run time
//! (`crate::simd::dispatch`). Both do the same IEEE operations in the same order, and the sums
//! have the order of the pair list, so the result is the same bits for either path and any
//! number of threads.

use crate::components::{Body, Plane, Walls, MAX_WALLS};
use crate::contact::lanes::{Ln, PairIn, V};
use crate::contact::{Form, Friction, Law};
use crate::domain::Domain;
use crate::history::{Cursor, HistList};
use crate::neighbor::{image_shifts, InnerChunk, NeighborList};
use crate::sampling::{ContactRec, WALL};
use crate::simd::{dispatch, Twin};
use crate::{M3, V3};
use std::cell::RefCell;
use std::marker::PhantomData;

/// Particles per block: the block's contacts stay in L1.
use crate::neighbor::BLOCK;
/// Contacts per lane group of the law.
const LANES: usize = 4;
/// Pass 1 prefetches the partners' positions this many pairs ahead.
const AHEAD: usize = 16;

/// What every chunk reads.
pub(crate) struct Shared<'a, F: Form, T: Friction, D> {
    pub law: &'a Law<F, T>,
    pub dom: &'a D,
    pub planes: &'a [Plane],
    pub wlaw: Option<&'a Law<F, T>>,
    pub g: V3,
    /// The pairs to test, per chunk (`NeighborList::prune`), and the full list's second
    /// particles and image codes they point to.
    pub inner: &'a [InnerChunk],
    /// The full list's offsets per particle (owners of an unpruned chunk's pairs).
    pub own_start: &'a [u32],
    pub pair_j: &'a [u32],
    pub pair_img: &'a [u8],
    /// Periodic image shifts by image code, padded to 4 doubles.
    pub shifts: [[f64; 4]; 27],
    /// (x, R) per particle.
    pub xr: &'a [[f64; 4]],
    /// (v, 1/m, w, R) per particle, v and w predicted to the end of the step.
    pub kin: &'a [[f64; 8]],
    pub mass: &'a [f64],
    pub dt: f64,
    pub ch: usize,
}

impl<'a, F: Form, T: Friction, D: Domain> Shared<'a, F, T, D> {
    /// What every chunk of one evaluation reads, from the engine's parts.
    #[allow(
        clippy::too_many_arguments,
        reason = "the engine's parts a chunk reads, gathered once per evaluation"
    )]
    pub fn new<W: Walls<F, T>, G: Body>(
        law: &'a Law<F, T>,
        dom: &'a D,
        walls: &'a W,
        body: &G,
        nl: &'a NeighborList,
        (xr, kin, mass): (&'a [[f64; 4]], &'a [[f64; 8]], &'a [f64]),
        dt: f64,
        ch: usize,
    ) -> Self {
        Shared {
            law,
            dom,
            planes: walls.planes(),
            wlaw: walls.law(),
            g: body.g(),
            inner: &nl.inner,
            own_start: &nl.own_start,
            pair_j: &nl.pair_j,
            pair_img: &nl.pair_img,
            shifts: image_shifts(&dom.h()),
            xr,
            kin,
            mass,
            dt,
            ch,
        }
    }
}

/// What one chunk writes.
pub(crate) struct ChunkIo<'a, H> {
    pub fo: &'a mut [V3],
    pub to: &'a mut [V3],
    pub hold: &'a HistList<H>,
    pub hnew: &'a mut HistList<H>,
    pub wold: &'a HistList<H>,
    pub wnew: &'a mut HistList<H>,
    pub cross: &'a mut Vec<PairOut>,
    pub cstat: &'a mut Vec<[f64; 10]>,
    pub cidx: &'a mut [u32],
    pub ps: &'a mut [[f64; 10]],
    /// The chunk's contacts for samplers (written only by an evaluation with statistics).
    pub crec: &'a mut Vec<ContactRec>,
}

/// Per-thread contact buffer of a block, sized to the largest block seen (no allocation per
/// step). Contact c: `ids[c]` = (particle i, partner j, pair index within the chunk (the
/// history key), cross slot or u32::MAX for an in-chunk pair) and `rec[c]` = (branch vector,
/// R_i + R_j): one 16-byte and one 32-byte record, each written with one store.
#[derive(Default)]
struct Scratch {
    ids: Vec<[u32; 4]>,
    rec: Vec<[f64; 4]>,
    /// Owners and keys of the current block of an unpruned chunk.
    dense: DenseBlock,
}

impl Scratch {
    /// Room for `contacts` plus a lane group of padding.
    fn fit(&mut self, contacts: usize) {
        let want = contacts + LANES;
        if self.ids.len() < want {
            self.ids.resize(want, [0; 4]);
            self.rec.resize(want, [0.0; 4]);
        }
    }
}

/// Owners and keys of a block of an unpruned chunk (`InnerChunk::dense`), which stores
/// neither: every pair of the full list, in order.
#[derive(Default)]
struct DenseBlock {
    own: Vec<u16>,
    key: Vec<u32>,
}

impl DenseBlock {
    /// The pairs of particles b0..b1 of the chunk starting at particle i0 and pair `base`.
    #[inline(never)]
    fn fill(&mut self, own_start: &[u32], base: u32, b0: usize, b1: usize, i0: usize) {
        self.own.clear();
        for i in b0..b1 {
            let c = (own_start[i + 1] - own_start[i]) as usize;
            self.own.extend(std::iter::repeat_n((i - i0) as u16, c));
        }
        self.key.clear();
        self.key.extend(own_start[b0] - base..own_start[b1] - base);
    }
}

/// Result of a cross pair: force on i, and q = -(r/(R_i+R_j)) n x F_t so that the torques are
/// R_i q on i and R_j q on j.
#[derive(Clone, Copy, Debug, Default)]
pub struct PairOut {
    pub f: V3,
    pub q: V3,
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

thread_local! {
    static SCRATCH: RefCell<Scratch> = RefCell::new(Scratch::default());
}

/// Forces of chunk `c` with the instruction set chosen at run time.
pub(crate) fn chunk<F, T, D, W, G, const STATS: bool, const VIR: bool>(
    s: &Shared<F, T, D>,
    c: usize,
    io: ChunkIo<T::History>,
) -> ChunkOut
where
    F: Form,
    T: Friction,
    D: Domain,
    W: Walls<F, T>,
    G: Body,
{
    dispatch(ChunkPass::<F, T, D, W, G, STATS, VIR> {
        s,
        c,
        io,
        _walls: PhantomData,
    })
}

/// One chunk's force pass for [`dispatch`]: the same body, with the AVX2 gathers in the twin.
struct ChunkPass<'s, 'a, F: Form, T: Friction, D, W, G, const STATS: bool, const VIR: bool> {
    s: &'s Shared<'s, F, T, D>,
    c: usize,
    io: ChunkIo<'a, T::History>,
    _walls: PhantomData<(W, G)>,
}

impl<F, T, D, W, G, const STATS: bool, const VIR: bool> Twin
    for ChunkPass<'_, '_, F, T, D, W, G, STATS, VIR>
where
    F: Form,
    T: Friction,
    D: Domain,
    W: Walls<F, T>,
    G: Body,
{
    type Out = ChunkOut;
    #[inline(always)]
    fn base(self) -> ChunkOut {
        chunk_impl::<F, T, D, W, G, STATS, VIR, false>(self.s, self.c, self.io)
    }
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn avx2(self) -> ChunkOut {
        chunk_impl::<F, T, D, W, G, STATS, VIR, true>(self.s, self.c, self.io)
    }
}

#[inline(always)]
fn chunk_impl<F, T, D, W, G, const STATS: bool, const VIR: bool, const AVX: bool>(
    s: &Shared<F, T, D>,
    c: usize,
    io: ChunkIo<T::History>,
) -> ChunkOut
where
    F: Form,
    T: Friction,
    D: Domain,
    W: Walls<F, T>,
    G: Body,
{
    let ChunkIo {
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
    } = io;
    // The chunk's growing lists are worked on as locals and put back at the end: their
    // headers lie side by side with the other chunks' (two or three to a cache line), so a
    // push through them would write a line another core is writing (false sharing; on a
    // Zen 5 VM two threads ran 1.6x slower per core whenever the layout put two chunks of
    // different threads on one line).
    let (hnew_out, wnew_out, cross_out, cstat_out) = (hnew, wnew, cross, cstat);
    let mut hnew_l = std::mem::take(hnew_out);
    let mut wnew_l = std::mem::take(wnew_out);
    let mut cross_l = std::mem::take(cross_out);
    let mut cstat_l = std::mem::take(cstat_out);
    let (hnew, wnew, cross, cstat) = (&mut hnew_l, &mut wnew_l, &mut cross_l, &mut cstat_l);
    let mut out = ChunkOut::default();
    let i0 = c * s.ch;
    let i1 = i0 + fo.len();
    let ic = &s.inner[c];
    assert_eq!(ic.block.len(), fo.len().div_ceil(BLOCK) + 1);
    let mut xs = 0usize;
    let mut hc = Cursor::new(hold);
    let mut wc = Cursor::new(wold);
    hnew.clear();
    wnew.clear();
    cross.clear();
    cstat.clear();
    if STATS {
        crec.clear();
    }
    if G::ON {
        // the body force first: one store per particle instead of a zero and a late add
        let m = &s.mass[i0..i1];
        fo.iter_mut().zip(m).for_each(|(f, &m)| *f = m * s.g);
    } else {
        fo.iter_mut().for_each(|f| *f = V3::zeros());
    }
    if T::FRICTIONAL {
        // without friction nothing ever writes a torque: they stay zero
        to.iter_mut().for_each(|t| *t = V3::zeros());
    }
    // a cross slot stays open (u32::MAX) unless pass 2 finds the pair in contact
    cidx.fill(u32::MAX);
    // the thread's scratch, taken out for the chunk (the loop then lives in this function,
    // compiled with its instruction set, not in a closure the compiler may keep apart)
    let mut scratch = SCRATCH.with(|cell| cell.take());
    let sc = &mut scratch;
    // (out of the scratch while the blocks borrow it)
    let mut dense = std::mem::take(&mut sc.dense);
    let mut b0 = i0;
    while b0 < i1 {
        let b1 = (b0 + BLOCK).min(i1);
        // the block's pairs in the inner list: their owners and keys
        let bi = (b0 - i0) / BLOCK;
        let (kb, ke) = (ic.block[bi] as usize, ic.block[bi + 1] as usize);
        sc.fit(ke - kb);
        let (own, key): (&[u16], &[u32]) = if ic.dense {
            dense.fill(s.own_start, ic.base, b0, b1, i0);
            (&dense.own, &dense.key)
        } else {
            (&ic.own[kb..ke], &ic.key[kb..ke])
        };
        let nc = if AVX {
            #[cfg(target_arch = "x86_64")]
            // SAFETY: AVX is only true in `chunk_avx2`, which runs only on AVX2 CPUs.
            unsafe {
                avx::filter(s, ic, own, key, sc, i0, i1, &mut xs)
            }
            #[cfg(not(target_arch = "x86_64"))]
            unreachable!()
        } else {
            filter(s, ic, own, key, sc, i0, i1, &mut xs)
        };
        out.contacts += nc;
        let mut sums = Sums {
            i0,
            fo: &mut *fo,
            to: &mut *to,
            cross: &mut *cross,
            cstat: &mut *cstat,
            cidx: &mut *cidx,
            ps: &mut *ps,
            crec: &mut *crec,
            out: &mut out,
        };
        law_and_sums::<F, T, D, STATS, VIR, AVX>(s, sc, nc, &mut hc, hnew, &mut sums);
        // which of the block's particles touch a wall (most touch none)
        let touch = if W::ON {
            if AVX {
                #[cfg(target_arch = "x86_64")]
                // SAFETY: AVX is only true in `chunk_avx2`, which runs only on AVX2 CPUs
                unsafe {
                    avx::wall_mask(s, b0, b1)
                }
                #[cfg(not(target_arch = "x86_64"))]
                unreachable!()
            } else {
                wall_mask(s, b0, b1)
            }
        } else {
            0
        };
        // only the particles that may touch, in order (the wall histories' keys ascend)
        let mut m = touch;
        while m != 0 {
            let i = b0 + m.trailing_zeros() as usize;
            m &= m - 1;
            wall_contacts::<F, T, W, STATS>(s, i, i0, fo, to, ps, crec, &mut wc, wnew, &mut out);
        }
        b0 = b1;
    }
    sc.dense = dense;
    SCRATCH.with(|cell| cell.replace(scratch));
    debug_assert_eq!(xs, cidx.len());
    (*hnew_out, *wnew_out, *cross_out, *cstat_out) = (hnew_l, wnew_l, cross_l, cstat_l);
    out
}

/// Pass 1 (baseline): the distance test over a block's pairs of the inner list (owner and
/// key of each; the chunk is particles i0..i1), contacts appended in list order. Returns
/// their number. Cross slots are numbered in list order, open ones included.
#[allow(
    clippy::too_many_arguments,
    reason = "hot inlined pass: its inputs stay separate registers/borrows"
)]
#[inline(always)]
fn filter<F: Form, T: Friction, D>(
    s: &Shared<F, T, D>,
    ic: &InnerChunk,
    own: &[u16],
    pk: &[u32],
    sc: &mut Scratch,
    i0: usize,
    i1: usize,
    xs: &mut usize,
) -> usize {
    let xr = s.xr;
    let mut nc = 0usize;
    assert_eq!(own.len(), pk.len());
    let (pj, pi) = (
        &s.pair_j[ic.base as usize..],
        &s.pair_img[ic.base as usize..],
    );
    for k in 0..pk.len() {
        let i = i0 + own[k] as usize;
        let j = pj[pk[k] as usize] as usize;
        let is_cross = j >= i1;
        // SAFETY: list indices are < n by construction (built from 0..n); image codes < 27;
        // the scratch holds at least the block's pairs (`fit`)
        let [xi0, xi1, xi2, ri] = unsafe { *xr.get_unchecked(i) };
        let [xj0, xj1, xj2, rj] = unsafe { *xr.get_unchecked(j) };
        let sh = unsafe { s.shifts.get_unchecked(pi[pk[k] as usize] as usize) };
        let dx = xi0 - xj0 - sh[0];
        let dy = xi1 - xj1 - sh[1];
        let dz = xi2 - xj2 - sh[2];
        let r2 = dx * dx + dy * dy + dz * dz;
        let rs = ri + rj;
        if r2 >= rs * rs {
            // open: nothing stored (its history, if any, is not carried on)
            *xs += is_cross as usize;
            continue;
        }
        let slot = if is_cross { *xs as u32 } else { u32::MAX };
        unsafe {
            *sc.ids.get_unchecked_mut(nc) = [i as u32, j as u32, pk[k], slot];
            *sc.rec.get_unchecked_mut(nc) = [dx, dy, dz, rs];
        }
        *xs += is_cross as usize;
        nc += 1;
    }
    nc
}

/// Where pass 2 adds its forces.
struct Sums<'a, 'b> {
    i0: usize,
    fo: &'a mut [V3],
    to: &'a mut [V3],
    cross: &'a mut Vec<PairOut>,
    cstat: &'a mut Vec<[f64; 10]>,
    cidx: &'a mut [u32],
    ps: &'a mut [[f64; 10]],
    crec: &'a mut Vec<ContactRec>,
    out: &'b mut ChunkOut,
}

/// `Domain::streaming_velocity` (P r) / w on lanes of contacts: per row ((P0 dx + P1 dy) +
/// P2 dz) / w, nalgebra's order, so the same bits as one contact at a time.
#[inline(always)]
fn streaming_on_lanes<const L: usize>(pg: &M3, wg: f64, d: &V<L>) -> V<L> {
    let row = |r: usize| {
        let c = |k: usize| Ln::<L>::splat(pg[(r, k)]);
        (c(0) * d.x + c(1) * d.y + c(2) * d.z) / Ln::splat(wg)
    };
    V {
        x: row(0),
        y: row(1),
        z: row(2),
    }
}

/// Pass 2: the law on lanes of contacts, then each contact's force and torques onto its two
/// particles (in-chunk partners in place, cross partners through the chunk's buffer), in
/// list order: the order, and so the bits, of a one-pair-at-a-time loop.
#[inline(always)]
fn law_and_sums<F, T, D, const STATS: bool, const VIR: bool, const AVX: bool>(
    s: &Shared<F, T, D>,
    sc: &mut Scratch,
    nc: usize,
    hc: &mut Cursor<T::History>,
    hnew: &mut HistList<T::History>,
    o: &mut Sums,
) where
    F: Form,
    T: Friction,
    D: Domain,
{
    const L: usize = LANES;
    assert!(nc + L <= sc.ids.len());
    let z = Ln::<L>::splat(0.0);
    let zv = V { x: z, y: z, z };
    let mut p = PairIn {
        d: zv,
        r2: z,
        rs: z,
        ri: z,
        rj: z,
        imi: z,
        imj: z,
        vi: zv,
        vj: zv,
        wi: zv,
        wj: zv,
        sv: zv,
        u: zv,
    };
    // the new histories are written in place (`hv0`) as the groups are evaluated
    if T::FRICTIONAL {
        hnew.vals.reserve(nc);
    }
    let hv0 = hnew.vals.as_mut_ptr().wrapping_add(hnew.vals.len());
    let (pg, wg) = s.dom.streaming_map();
    // the virial's columns (lane 3 unused), so that a contact's r (x) f is three packed
    // multiply-adds: per element vir_rc + d_r f_c, the operations of `vir += d * f^T`
    let mut vc = [[0.0f64; 4]; 3];
    if VIR {
        for (c, col) in vc.iter_mut().enumerate() {
            for (x, v) in col.iter_mut().zip(o.out.vir.column(c).iter()) {
                *x = *v;
            }
        }
    }
    let mut b = 0;
    while b < nc {
        // a short last group repeats its last contact (results not used)
        let cl = |l: usize| (b + l).min(nc - 1);
        if AVX {
            #[cfg(target_arch = "x86_64")]
            // SAFETY: AVX only in `chunk_avx2`; indices come from pass 1 (< n), and
            // b + L <= the scratch length (asserted above).
            unsafe {
                avx::gather::<T>(s, sc, cl, &mut p)
            };
        } else {
            for l in 0..L {
                let c = cl(l);
                let [i, j, _, _] = sc.ids[c].map(|v| v as usize);
                let [dx, dy, dz, rs] = sc.rec[c];
                p.rs.0[l] = rs;
                p.d.x.0[l] = dx;
                p.d.y.0[l] = dy;
                p.d.z.0[l] = dz;
                // the squared distance of pass 1, recomputed (same operations, same bits)
                p.r2.0[l] = dx * dx + dy * dy + dz * dz;
                let (ki, kj) = (&s.kin[i], &s.kin[j]);
                p.imi.0[l] = ki[3];
                p.imj.0[l] = kj[3];
                p.vi.x.0[l] = ki[0];
                p.vi.y.0[l] = ki[1];
                p.vi.z.0[l] = ki[2];
                p.vj.x.0[l] = kj[0];
                p.vj.y.0[l] = kj[1];
                p.vj.z.0[l] = kj[2];
                if T::FRICTIONAL {
                    p.ri.0[l] = ki[7];
                    p.rj.0[l] = kj[7];
                    p.wi.x.0[l] = ki[4];
                    p.wi.y.0[l] = ki[5];
                    p.wi.z.0[l] = ki[6];
                    p.wj.x.0[l] = kj[4];
                    p.wj.y.0[l] = kj[5];
                    p.wj.z.0[l] = kj[6];
                }
            }
        }
        let m = L.min(nc - b);
        if T::FRICTIONAL {
            for l in 0..m {
                let u = T::to_array(&hc.take(sc.ids[b + l][2]));
                p.u.x.0[l] = u[0];
                p.u.y.0[l] = u[1];
                p.u.z.0[l] = u[2];
            }
        }
        if D::STREAMING {
            p.sv = streaming_on_lanes(&pg, wg, &p.d);
        }
        let r = s.law.eval_pairs::<L>(&p, s.dt, D::STREAMING);
        if VIR {
            // a loop of its own, so that the columns stay in registers across the group
            let mut cols = vc;
            for l in 0..m {
                let d = [p.d.x.0[l], p.d.y.0[l], p.d.z.0[l], 0.0];
                for (col, fc) in cols.iter_mut().zip([r.f.x.0[l], r.f.y.0[l], r.f.z.0[l]]) {
                    for k in 0..4 {
                        col[k] += d[k] * fc;
                    }
                }
            }
            vc = cols;
        }
        for l in 0..m {
            let c = b + l;
            if T::FRICTIONAL {
                // the new history, in list order, straight into its place
                // SAFETY: c < nc, and nc places were reserved past hv0 (below the loop, the
                // length grows by nc once every one of them is written)
                unsafe {
                    hv0.add(c)
                        .write(T::from_array([r.u.x.0[l], r.u.y.0[l], r.u.z.0[l]]))
                };
            }
            // SAFETY: c < nc <= the scratch length; li, lj are in the chunk (pass 1: i is,
            // and an in-chunk partner j < i1)
            let [i, j, _, slot] = unsafe { *sc.ids.get_unchecked(c) };
            let (i, j) = (i as usize, j as usize);
            let f = V3::new(r.f.x.0[l], r.f.y.0[l], r.f.z.0[l]);
            let q = V3::new(r.q.x.0[l], r.q.y.0[l], r.q.z.0[l]);
            let li = i - o.i0;
            debug_assert!(li < o.fo.len() && li < o.to.len());
            unsafe { *o.fo.get_unchecked_mut(li) += f };
            if T::FRICTIONAL {
                unsafe { *o.to.get_unchecked_mut(li) += p.ri.0[l] * q };
            }
            let is_cross = slot != u32::MAX;
            if is_cross {
                o.cidx[slot as usize] = o.cross.len() as u32;
                o.cross.push(PairOut { f, q });
            } else {
                let lj = j - o.i0;
                debug_assert!(lj < o.fo.len() && lj < o.to.len());
                unsafe { *o.fo.get_unchecked_mut(lj) -= f };
                if T::FRICTIONAL {
                    unsafe { *o.to.get_unchecked_mut(lj) += p.rj.0[l] * q };
                }
            }
            let ov = r.ov.0[l];
            if ov > o.out.max_ov {
                o.out.max_ov = ov;
                o.out.at = (i, j);
            }
            if STATS {
                let d = V3::new(p.d.x.0[l], p.d.y.0[l], p.d.z.0[l]);
                let vrel = V3::new(r.vrel.x.0[l], r.vrel.y.0[l], r.vrel.z.0[l]);
                let power = f.dot(&vrel);
                o.crec.push(ContactRec {
                    i: i as u32,
                    j: j as u32,
                    d,
                    f,
                    power,
                });
                // (the per-particle sums only when asked for: empty otherwise)
                if !o.ps.is_empty() {
                    let half = 0.5 * d * f.transpose();
                    let mut rec = [0.0; 10];
                    for (a, b) in rec.iter_mut().zip(half.transpose().iter()) {
                        *a = *b;
                    }
                    rec[9] = 0.5 * power;
                    add10(&mut o.ps[li], &rec);
                    if is_cross {
                        o.cstat.push(rec);
                    } else {
                        add10(&mut o.ps[j - o.i0], &rec);
                    }
                }
            }
        }
        b += L;
    }
    if VIR {
        for (c, col) in vc.iter().enumerate() {
            for (v, x) in o.out.vir.column_mut(c).iter_mut().zip(col) {
                *v = *x;
            }
        }
    }
    if T::FRICTIONAL {
        hnew.keys.extend(sc.ids[..nc].iter().map(|e| e[2]));
        // SAFETY: places len..len + nc were reserved and written above
        unsafe { hnew.vals.set_len(hnew.vals.len() + nc) };
    }
}

/// Pass 3 for particle i: wall contacts, after all its pair contacts (the body force was
/// the first term of its sum).
#[allow(
    clippy::too_many_arguments,
    reason = "hot inlined pass: its inputs stay separate registers/borrows"
)]
#[inline(always)]
fn wall_contacts<F, T, W, const STATS: bool>(
    s: &Shared<F, T, impl Domain>,
    i: usize,
    i0: usize,
    fo: &mut [V3],
    to: &mut [V3],
    ps: &mut [[f64; 10]],
    crec: &mut Vec<ContactRec>,
    wc: &mut Cursor<T::History>,
    wnew: &mut HistList<T::History>,
    out: &mut ChunkOut,
) where
    F: Form,
    T: Friction,
    W: Walls<F, T>,
{
    let li = i - i0;
    // (called only for the particles `wall_mask` found near a wall)
    if W::ON {
        let mut fsum = fo[li];
        let mut tsum = to[li];
        let [x0, x1, x2, ri] = s.xr[i];
        let xi = [x0, x1, x2];
        let ki = &s.kin[i];
        let vi = V3::new(ki[0], ki[1], ki[2]);
        let wi = V3::new(ki[4], ki[5], ki[6]);
        let wl = s.wlaw.unwrap();
        for (w, pl) in s.planes.iter().enumerate() {
            let gap = pl.sign * (xi[pl.axis] - pl.pos);
            if gap >= ri {
                continue;
            }
            let mut nrm = V3::zeros();
            nrm[pl.axis] = pl.sign;
            let delta = ri - gap;
            // contact point on the plane: lever arm = gap; predicted end-of-step
            // velocities, as for pairs
            let vrel = if T::FRICTIONAL {
                vi - (gap * wi).cross(&nrm)
            } else {
                vi
            };
            let key = (li * MAX_WALLS + w) as u32;
            let mut h = if T::FRICTIONAL {
                wc.take(key)
            } else {
                T::History::default()
            };
            let pf = wl.eval(&nrm, delta, 2.0 * ri, s.mass[i], &vrel, &mut h, s.dt);
            if T::FRICTIONAL {
                wnew.push(key, h);
            }
            fsum += pf.f;
            if T::FRICTIONAL {
                tsum -= gap * nrm.cross(&pf.ft);
            }
            out.wall_force[w] -= pf.f;
            if STATS {
                // branch vector from the contact point on the wall to the centre
                crec.push(ContactRec {
                    i: i as u32,
                    j: WALL,
                    d: gap * nrm,
                    f: pf.f,
                    power: pf.f.dot(&vrel),
                });
                if !ps.is_empty() {
                    let full = (gap * nrm) * pf.f.transpose();
                    let acc = &mut ps[li];
                    for (a, b) in acc.iter_mut().zip(full.transpose().iter()) {
                        *a += b;
                    }
                    acc[9] += pf.f.dot(&vrel);
                }
            }
            let ov = delta / (2.0 * ri);
            if ov > out.max_ov {
                out.max_ov = ov;
                out.at = (i, usize::MAX);
            }
        }
        fo[li] = fsum;
        to[li] = tsum;
    }
}

/// Bit l set: particle b0 + l (l < BLOCK) may touch a wall: the test of `wall_contacts`'s
/// loop, negated (a NaN gap counts as touching there too).
#[inline(always)]
fn wall_mask<F: Form, T: Friction, D>(s: &Shared<F, T, D>, b0: usize, b1: usize) -> u32 {
    let mut m = 0u32;
    for (l, x) in s.xr[b0..b1].iter().enumerate() {
        #[allow(
            clippy::neg_cmp_op_on_partial_ord,
            reason = "!(a >= b) is true for NaN on purpose: a NaN position counts as touching"
        )]
        let t = s
            .planes
            .iter()
            .any(|pl| !(pl.sign * (x[pl.axis] - pl.pos) >= x[3]));
        m |= (t as u32) << l;
    }
    m
}

#[inline(always)]
pub(crate) fn add10(acc: &mut [f64; 10], rec: &[f64; 10]) {
    for (a, b) in acc.iter_mut().zip(rec) {
        *a += b;
    }
}

#[cfg(target_arch = "x86_64")]
mod avx;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streaming_on_lanes_matches_the_domain_bitwise() {
        use crate::domain::PrCell;
        let mut cell = PrCell::new(9.0, 400, 0.5, 20.0, 8.0).unwrap();
        // a cell velocity gradient with every entry set, as in a sheared, breathing cell
        cell.pg = M3::new(0.31, -1.7, 0.023, 2.9, -0.11, 0.77, -0.5, 1.3, 0.9) * 1e-3;
        let (pg, wg) = cell.streaming_map();
        let rs = [
            V3::new(0.3, -1.1, 0.7),
            V3::new(-2.13, 0.017, 1.9),
            V3::new(1e-3, 3.3, -0.41),
            V3::new(0.9, 0.9, -0.9),
        ];
        let lane = |k: usize| Ln([rs[0][k], rs[1][k], rs[2][k], rs[3][k]]);
        let d = V {
            x: lane(0),
            y: lane(1),
            z: lane(2),
        };
        let sv = streaming_on_lanes(&pg, wg, &d);
        for (l, r) in rs.iter().enumerate() {
            let one = cell.streaming_velocity(r);
            assert_eq!([sv.x.0[l], sv.y.0[l], sv.z.0[l]], [one.x, one.y, one.z]);
        }
    }
}
