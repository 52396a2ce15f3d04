//! AVX2 twins of the integration passes: each 3-vector in the low lanes of one AVX register
//! (loaded as 16 + 8 bytes, the fourth lane zero), the same IEEE operations in the same order
//! as the baseline bodies, so the same bits.

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
fn kick(lc: &[__m256d; 3], tr: __m256d, h2: __m256d, v: __m256d, f: __m256d, im: f64) -> __m256d {
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
