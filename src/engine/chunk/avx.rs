//! AVX2 gathers of the force loop: pair records transposed into lanes of four contacts with
//! shuffles, and the wall test four particles at a time (the same operations lane by lane as the
//! baseline code, so the same bits).

use super::{InnerChunk, Scratch, Shared};
use crate::contact::lanes::{Ln, PairIn};
use crate::contact::{Form, Friction};
use std::arch::x86_64::*;

/// Four 4-double records as four lanes of their components.
#[inline]
#[target_feature(enable = "avx2")]
fn transpose(a: __m256d, b: __m256d, c: __m256d, d: __m256d) -> [__m256d; 4] {
    let t0 = _mm256_unpacklo_pd(a, b); // a0 b0 a2 b2
    let t1 = _mm256_unpackhi_pd(a, b); // a1 b1 a3 b3
    let t2 = _mm256_unpacklo_pd(c, d);
    let t3 = _mm256_unpackhi_pd(c, d);
    [
        _mm256_permute2f128_pd(t0, t2, 0x20),
        _mm256_permute2f128_pd(t1, t3, 0x20),
        _mm256_permute2f128_pd(t0, t2, 0x31),
        _mm256_permute2f128_pd(t1, t3, 0x31),
    ]
}

#[inline]
#[target_feature(enable = "avx2")]
fn ln(v: __m256d) -> Ln<4> {
    // SAFETY: same size, any bit pattern is a valid f64
    Ln(unsafe { std::mem::transmute::<__m256d, [f64; 4]>(v) })
}

/// Load 4 doubles at `p`.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn ld(p: *const f64) -> __m256d {
    unsafe { _mm256_loadu_pd(p) }
}

/// Pass 1 with AVX2: the block's listed pairs four at a time, across particles (the
/// arithmetic of the baseline `filter`, lane by lane: d = (x_i - x_j) - shift on whole
/// (x, R) records, then transposed into lanes).
///
/// # Safety
/// AVX2 CPU; `sc` fitted to the block's pairs.
#[allow(
    clippy::too_many_arguments,
    reason = "AVX2 twin of chunk::filter with the same arguments"
)]
#[inline]
#[target_feature(enable = "avx2")]
pub(super) unsafe fn filter<F: Form, T: Friction, D>(
    s: &Shared<F, T, D>,
    ic: &InnerChunk,
    own: &[u16],
    pair_key: &[u32],
    sc: &mut Scratch,
    i0: usize,
    i1: usize,
    xs: &mut usize,
) -> usize {
    let xr = s.xr;
    let (kb, ke) = (0, pair_key.len());
    // the full list's partners and image codes of the chunk, indexed by key
    let (pair_j, pair_img) = (
        &s.pair_j[ic.base as usize..],
        &s.pair_img[ic.base as usize..],
    );
    // keys are < span by construction (`prune_chunk`)
    assert!(ic.span as usize <= pair_j.len().min(pair_img.len()));
    assert!(ke <= own.len());
    debug_assert!(pair_key.iter().all(|&q| q < ic.span));
    let i0 = i0 as u32;
    let mut nc = 0usize;
    // cross slots stay open (u32::MAX) unless pass 2 finds them closed
    let mut x = *xs;
    let rmask = _mm256_castsi256_pd(_mm256_set_epi64x(-1, 0, 0, 0));
    let lim = _mm_set1_epi32(i1 as i32 - 1);
    let (ids, recs) = (sc.ids.as_mut_ptr(), sc.rec.as_mut_ptr());
    let mut k = kb;
    while k < ke {
        let m = (ke - k).min(4);
        // SAFETY: k + 4 <= ke <= the lists' lengths (asserted) on the fast path;
        // otherwise lanes past the block's pairs repeat its last pair (masked off below)
        let (mut is, mut ks) = ([0u32; 4], [0u32; 4]);
        unsafe {
            if m == 4 {
                let o = std::ptr::read_unaligned(own.as_ptr().add(k) as *const [u16; 4]);
                for l in 0..4 {
                    is[l] = i0 + o[l] as u32;
                }
                ks = std::ptr::read_unaligned(pair_key.as_ptr().add(k) as *const [u32; 4]);
            } else {
                for l in 0..4 {
                    let q = k + l.min(m - 1);
                    is[l] = i0 + *own.get_unchecked(q) as u32;
                    ks[l] = *pair_key.get_unchecked(q);
                }
            }
        }
        // SAFETY: keys < span <= the lengths (asserted above)
        let (mut js, mut cs) = ([0u32; 4], [0u8; 4]);
        for l in 0..4 {
            // SAFETY: as above
            unsafe {
                js[l] = *pair_j.get_unchecked(ks[l] as usize);
                cs[l] = *pair_img.get_unchecked(ks[l] as usize);
            }
        }
        // SAFETY: i, j < n (the list is built from 0..n), image codes < 27
        // (plain loops, not array maps, here and below: a closure does not inherit
        // the function's AVX2, and left out of line it cost 12 % of the step)
        let mut rec = [_mm256_setzero_pd(); 4];
        for l in 0..4 {
            // SAFETY: as above
            unsafe {
                let xi = ld(xr.get_unchecked(is[l] as usize).as_ptr());
                let xj = ld(xr.get_unchecked(js[l] as usize).as_ptr());
                let sh = ld(s.shifts.get_unchecked(cs[l] as usize).as_ptr());
                // (dx, dy, dz, R_i + R_j)
                rec[l] = _mm256_blendv_pd(
                    _mm256_sub_pd(_mm256_sub_pd(xi, xj), sh),
                    _mm256_add_pd(xi, xj),
                    rmask,
                );
            }
        }
        // the velocity records of the partners, for pass 2 (at large N they would
        // otherwise come from the last-level cache one contact at a time)
        for &j in &js {
            // SAFETY: a prefetch of an address in the array
            unsafe { _mm_prefetch::<_MM_HINT_T0>(s.kin.as_ptr().add(j as usize) as *const i8) };
        }
        // and the position records of the partners a few groups ahead
        if k + super::AHEAD + 4 <= ke {
            for l in 0..4 {
                // SAFETY: k + AHEAD + l < ke <= pair_key.len(); keys < span <= the
                // list's length; a prefetch of an address in the array
                unsafe {
                    let q = *pair_key.get_unchecked(k + super::AHEAD + l) as usize;
                    let j = *pair_j.get_unchecked(q) as usize;
                    _mm_prefetch::<_MM_HINT_T0>(xr.as_ptr().add(j) as *const i8);
                }
            }
        }
        let [dx, dy, dz, rs] = transpose(rec[0], rec[1], rec[2], rec[3]);
        let r2 = _mm256_add_pd(
            _mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy)),
            _mm256_mul_pd(dz, dz),
        );
        // contact: !(r2 >= rs^2), exactly the baseline test (NaN included)
        let closed = _mm256_cmp_pd::<_CMP_NGE_UQ>(r2, _mm256_mul_pd(rs, rs));
        let lanes = (1u32 << m) - 1;
        let cmask = (_mm256_movemask_pd(closed) as u32) & lanes;
        // SAFETY: 16 bytes each
        let (iv, jv) = unsafe {
            (
                _mm_loadu_si128(is.as_ptr() as *const __m128i),
                _mm_loadu_si128(js.as_ptr() as *const __m128i),
            )
        };
        // cross pairs (j >= i1; indices < 2^31), numbered in list order, open ones
        // included: slot = x + the cross lanes before this one
        let xv = _mm_cmpgt_epi32(jv, lim);
        let xmask = (_mm_movemask_ps(_mm_castsi128_ps(xv)) as u32) & lanes;
        // SAFETY: xmask < 16
        let before = unsafe { _mm_loadu_si128(PREFIX[xmask as usize].as_ptr() as *const __m128i) };
        let slot = _mm_blendv_epi8(
            _mm_set1_epi32(-1),
            _mm_add_epi32(_mm_set1_epi32(x as i32), before),
            xv,
        );
        // SAFETY: 16 bytes
        let kk = unsafe { _mm_loadu_si128(ks.as_ptr() as *const __m128i) };
        // (i, j, kk, slot) per lane
        let t0 = _mm_unpacklo_epi32(iv, jv);
        let t1 = _mm_unpackhi_epi32(iv, jv);
        let t2 = _mm_unpacklo_epi32(kk, slot);
        let t3 = _mm_unpackhi_epi32(kk, slot);
        let idr = [
            _mm_unpacklo_epi64(t0, t2),
            _mm_unpackhi_epi64(t0, t2),
            _mm_unpacklo_epi64(t1, t3),
            _mm_unpackhi_epi64(t1, t3),
        ];
        // every lane is written at the next free place, which advances only for a
        // contact: no branch on the (unpredictable) test
        for l in 0..4 {
            // SAFETY: nc <= the block's pairs, and the scratch has 4 places more
            unsafe {
                _mm_storeu_si128(ids.add(nc) as *mut __m128i, idr[l]);
                _mm256_storeu_pd(recs.add(nc) as *mut f64, rec[l]);
            }
            nc += ((cmask >> l) & 1) as usize;
        }
        x += xmask.count_ones() as usize;
        k += 4;
    }
    *xs = x;
    nc
}

/// `super::wall_mask` four particles at a time (the same operations lane by lane).
///
/// # Safety
/// AVX2 CPU.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) unsafe fn wall_mask<F: Form, T: Friction, D>(
    s: &Shared<F, T, D>,
    b0: usize,
    b1: usize,
) -> u32 {
    let xr = &s.xr[b0..b1];
    let n = xr.len();
    let mut m = 0u32;
    let mut l = 0;
    while l < n {
        // a short last group repeats its last particle (bits past n dropped below)
        // SAFETY: indices clamped to n - 1 < xr.len()
        let mut r = [_mm256_setzero_pd(); 4];
        for (q, rq) in r.iter_mut().enumerate() {
            *rq = unsafe { ld(xr.get_unchecked((l + q).min(n - 1)).as_ptr()) };
        }
        let c = transpose(r[0], r[1], r[2], r[3]);
        let mut t = _mm256_setzero_pd();
        for pl in s.planes {
            let gap = _mm256_mul_pd(
                _mm256_set1_pd(pl.sign),
                _mm256_sub_pd(c[pl.axis.min(2)], _mm256_set1_pd(pl.pos)),
            );
            t = _mm256_or_pd(t, _mm256_cmp_pd::<_CMP_NGE_UQ>(gap, c[3]));
        }
        m |= (_mm256_movemask_pd(t) as u32) << l;
        l += 4;
    }
    if n < 32 {
        m &= (1u32 << n) - 1;
    }
    m
}

/// PREFIX[m][l]: the set bits of m below bit l.
const PREFIX: [[u32; 4]; 16] = {
    let mut t = [[0u32; 4]; 16];
    let mut m = 0;
    while m < 16 {
        let mut l = 0;
        while l < 4 {
            t[m][l] = ((m as u32) & ((1u32 << l) - 1)).count_ones();
            l += 1;
        }
        m += 1;
    }
    t
};

/// Half `off` (0: v and 1/m, 4: w and R) of the velocity records of four particles,
/// transposed into lanes.
///
/// # Safety
/// AVX2 CPU; every index < kin.len().
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn kin4(kin: &[[f64; 8]], ix: [usize; 4], off: usize) -> [__m256d; 4] {
    unsafe {
        let mut r = [_mm256_setzero_pd(); 4];
        for l in 0..4 {
            r[l] = ld(kin.get_unchecked(ix[l]).as_ptr().add(off));
        }
        transpose(r[0], r[1], r[2], r[3])
    }
}

/// Pass 2's gather with AVX2: the (v, 1/m) and (w, R) halves of four particles' records
/// transposed into lanes.
///
/// # Safety
/// AVX2 CPU; `cl(l) <` the number of contacts.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) unsafe fn gather<T: Friction>(
    s: &Shared<impl Form, T, impl Sized>,
    sc: &Scratch,
    cl: impl Fn(usize) -> usize,
    p: &mut PairIn<4>,
) {
    unsafe {
        let mut r = [_mm256_setzero_pd(); 4];
        let (mut ci, mut cj) = ([0usize; 4], [0usize; 4]);
        for l in 0..4 {
            let q = cl(l);
            r[l] = ld(sc.rec.get_unchecked(q).as_ptr());
            let id = sc.ids.get_unchecked(q);
            ci[l] = id[0] as usize;
            cj[l] = id[1] as usize;
        }
        let [dx, dy, dz, rs] = transpose(r[0], r[1], r[2], r[3]);
        // R_i + R_j as pass 1 added them
        p.rs = ln(rs);
        p.d.x = ln(dx);
        p.d.y = ln(dy);
        p.d.z = ln(dz);
        // the squared distance of pass 1, recomputed (same operations, same bits)
        p.r2 = ln(_mm256_add_pd(
            _mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy)),
            _mm256_mul_pd(dz, dz),
        ));
        let kin = s.kin;
        let [vx, vy, vz, im] = kin4(kin, ci, 0);
        p.vi.x = ln(vx);
        p.vi.y = ln(vy);
        p.vi.z = ln(vz);
        p.imi = ln(im);
        let [vx, vy, vz, im] = kin4(kin, cj, 0);
        p.vj.x = ln(vx);
        p.vj.y = ln(vy);
        p.vj.z = ln(vz);
        p.imj = ln(im);
        if T::FRICTIONAL {
            // spins and radii only matter with friction (torques, surface velocity)
            let [wx, wy, wz, r] = kin4(kin, ci, 4);
            p.ri = ln(r);
            p.wi.x = ln(wx);
            p.wi.y = ln(wy);
            p.wi.z = ln(wz);
            let [wx, wy, wz, r] = kin4(kin, cj, 4);
            p.rj = ln(r);
            p.wj.x = ln(wx);
            p.wj.y = ln(wy);
            p.wj.z = ln(wz);
        }
    }
}
