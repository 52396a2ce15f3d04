//! An orthogonal box with a periodic flag per axis.

use super::Domain;
use crate::error::{Error, Result};
use crate::{M3, V3};

/// Orthogonal box [lo, lo + len) with a periodic flag per axis.
#[derive(Clone, Debug)]
pub struct OrthoBox {
    pub lo: V3,
    pub len: V3,
    pub periodic: [bool; 3],
    /// L and 1/L on periodic axes, 0 on walled ones.
    per_len: V3,
    inv_len: V3,
}

impl OrthoBox {
    pub fn new(lo: V3, len: V3, periodic: [bool; 3]) -> Result<Self> {
        for k in 0..3 {
            let name = ["box length x", "box length y", "box length z"][k];
            crate::error::check_positive(name, len[k])?;
            if !lo[k].is_finite() {
                return Err(Error::param("box origin", lo[k], "finite"));
            }
        }
        let per_len = V3::from_fn(|k, _| if periodic[k] { len[k] } else { 0.0 });
        let inv_len = V3::from_fn(|k, _| if periodic[k] { 1.0 / len[k] } else { 0.0 });
        Ok(OrthoBox {
            lo,
            len,
            periodic,
            per_len,
            inv_len,
        })
    }
    pub fn periodic_cube(l: f64) -> Result<Self> {
        Self::new(V3::zeros(), V3::new(l, l, l), [true; 3])
    }
}

impl Domain for OrthoBox {
    const NAME: &'static str = "orthogonal box";
    const CLOSED: bool = true;
    fn periodic(&self) -> [bool; 3] {
        self.periodic
    }
    #[inline(always)]
    fn delta(&self, xi: &V3, xj: &V3) -> V3 {
        // d - L round(d/L) with a branch-free round-to-nearest (adding and subtracting
        // 1.5 * 2^52 rounds any |x| < 2^51 exactly): no libm call, vectorisable. On walled axes
        // inv_len = per_len = 0, so nothing is shifted.
        const MAGIC: f64 = 6_755_399_441_055_744.0;
        let mut d = xi - xj;
        for k in 0..3 {
            let s = (d[k] * self.inv_len[k] + MAGIC) - MAGIC;
            d[k] -= self.per_len[k] * s;
        }
        d
    }
    #[inline]
    fn wrap(&self, x: &mut V3, image: &mut [i32; 3]) {
        for k in 0..3 {
            if self.periodic[k] {
                let l = self.len[k];
                let s = ((x[k] - self.lo[k]) / l).floor();
                if s != 0.0 {
                    x[k] -= s * l;
                    image[k] += s as i32;
                    // guard against x == lo + len after rounding
                    if x[k] >= self.lo[k] + l {
                        x[k] -= l;
                        image[k] += 1;
                    }
                }
            }
        }
    }
    #[inline]
    fn frac(&self, x: &V3) -> V3 {
        let mut s = V3::zeros();
        for k in 0..3 {
            let f = (x[k] - self.lo[k]) / self.len[k];
            s[k] = f.clamp(0.0, 1.0 - 1e-12);
        }
        s
    }
    fn widths(&self) -> V3 {
        self.len
    }
    fn volume(&self) -> f64 {
        self.len.x * self.len.y * self.len.z
    }
    fn h(&self) -> M3 {
        M3::from_diagonal(&self.len)
    }
    fn origin(&self) -> V3 {
        self.lo
    }
}
