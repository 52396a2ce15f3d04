//! The pair contact law evaluated on `L` contacts at once.
//!
//! The force loop gathers the contacts of a few particles into a small buffer and evaluates the
//! law on lanes of `L` contacts: every operation is elementwise on `[f64; L]`, which the
//! compiler turns into packed instructions (two lanes per SSE2 instruction on baseline x86-64,
//! four per AVX2 instruction where the CPU has it, chosen at run time). Branches of the scalar
//! law (history rotation, Coulomb cap) become selects.
//!
//! Every lane performs the same IEEE operations in the same order whatever the width or the
//! instruction set (no fused multiply-add: Rust never contracts a*b + c), so the AVX2 and the
//! baseline paths give the same bits.

use std::ops::{Add, Div, Mul, Neg, Sub};

/// `L` doubles, one per contact.
#[derive(Clone, Copy, Debug)]
pub struct Ln<const L: usize>(pub [f64; L]);

/// `L` booleans (a per-lane condition).
#[derive(Clone, Copy, Debug)]
pub struct Mask<const L: usize>(pub [bool; L]);

impl<const L: usize> Ln<L> {
    #[inline(always)]
    pub fn splat(v: f64) -> Self {
        Ln([v; L])
    }
    #[inline(always)]
    fn map(self, f: impl Fn(f64) -> f64) -> Self {
        let mut o = self.0;
        for v in o.iter_mut() {
            *v = f(*v);
        }
        Ln(o)
    }
    #[inline(always)]
    fn zip(self, b: Self, f: impl Fn(f64, f64) -> f64) -> Self {
        let mut o = self.0;
        for (v, w) in o.iter_mut().zip(b.0) {
            *v = f(*v, w);
        }
        Ln(o)
    }
    #[inline(always)]
    fn cmp(self, b: Self, f: impl Fn(f64, f64) -> bool) -> Mask<L> {
        let mut o = [false; L];
        #[allow(
            clippy::needless_range_loop,
            reason = "lane by lane over arrays of the same const length L"
        )]
        for l in 0..L {
            o[l] = f(self.0[l], b.0[l]);
        }
        Mask(o)
    }
    #[inline(always)]
    pub fn sqrt(self) -> Self {
        self.map(f64::sqrt)
    }
    #[inline(always)]
    pub fn abs(self) -> Self {
        self.map(f64::abs)
    }
    #[inline(always)]
    pub fn gt(self, b: Self) -> Mask<L> {
        self.cmp(b, |x, y| x > y)
    }
    #[inline(always)]
    pub fn ne(self, b: Self) -> Mask<L> {
        self.cmp(b, |x, y| x != y)
    }
}

impl<const L: usize> Mask<L> {
    #[inline(always)]
    pub fn and(self, b: Self) -> Self {
        let mut o = self.0;
        for (v, w) in o.iter_mut().zip(b.0) {
            *v &= w;
        }
        Mask(o)
    }
    /// Lane-wise `if self { a } else { b }`.
    #[inline(always)]
    pub fn select(self, a: Ln<L>, b: Ln<L>) -> Ln<L> {
        let mut o = b.0;
        #[allow(
            clippy::needless_range_loop,
            reason = "lane by lane over arrays of the same const length L"
        )]
        for l in 0..L {
            if self.0[l] {
                o[l] = a.0[l];
            }
        }
        Ln(o)
    }
    #[inline(always)]
    pub fn select3(self, a: V<L>, b: V<L>) -> V<L> {
        V {
            x: self.select(a.x, b.x),
            y: self.select(a.y, b.y),
            z: self.select(a.z, b.z),
        }
    }
}

macro_rules! ln_op {
    ($tr:ident, $f:ident, $op:tt) => {
        impl<const L: usize> $tr for Ln<L> {
            type Output = Self;
            #[inline(always)]
            fn $f(self, b: Self) -> Self {
                self.zip(b, |x, y| x $op y)
            }
        }
    };
}
ln_op!(Add, add, +);
ln_op!(Sub, sub, -);
ln_op!(Mul, mul, *);
ln_op!(Div, div, /);

impl<const L: usize> Neg for Ln<L> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        self.map(|x| -x)
    }
}

/// `L` three-vectors, stored by component.
#[derive(Clone, Copy, Debug)]
pub struct V<const L: usize> {
    pub x: Ln<L>,
    pub y: Ln<L>,
    pub z: Ln<L>,
}

impl<const L: usize> V<L> {
    #[inline(always)]
    pub fn zero() -> Self {
        let z = Ln::splat(0.0);
        V { x: z, y: z, z }
    }
    /// The same arithmetic as nalgebra's 3-vector dot: (x x' + y y') + z z'.
    #[inline(always)]
    pub fn dot(&self, b: &Self) -> Ln<L> {
        self.x * b.x + self.y * b.y + self.z * b.z
    }
    #[inline(always)]
    pub fn cross(&self, b: &Self) -> Self {
        V {
            x: self.y * b.z - self.z * b.y,
            y: self.z * b.x - self.x * b.z,
            z: self.x * b.y - self.y * b.x,
        }
    }
    /// Every component times the lane's scalar.
    #[inline(always)]
    pub fn scale(&self, s: Ln<L>) -> Self {
        V {
            x: s * self.x,
            y: s * self.y,
            z: s * self.z,
        }
    }
    #[inline(always)]
    pub fn div(&self, s: Ln<L>) -> Self {
        V {
            x: self.x / s,
            y: self.y / s,
            z: self.z / s,
        }
    }
}

impl<const L: usize> Add for V<L> {
    type Output = Self;
    #[inline(always)]
    fn add(self, b: Self) -> Self {
        V {
            x: self.x + b.x,
            y: self.y + b.y,
            z: self.z + b.z,
        }
    }
}

impl<const L: usize> Sub for V<L> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, b: Self) -> Self {
        V {
            x: self.x - b.x,
            y: self.y - b.y,
            z: self.z - b.z,
        }
    }
}

impl<const L: usize> Neg for V<L> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        V {
            x: -self.x,
            y: -self.y,
            z: -self.z,
        }
    }
}

/// What the law needs of `L` pair contacts.
#[derive(Clone, Copy, Debug)]
pub struct PairIn<const L: usize> {
    /// Branch vector x_i - x_j (with its periodic image) and its squared length.
    pub d: V<L>,
    pub r2: Ln<L>,
    /// R_i + R_j.
    pub rs: Ln<L>,
    /// R_i and R_j (read only with friction).
    pub ri: Ln<L>,
    pub rj: Ln<L>,
    pub imi: Ln<L>,
    pub imj: Ln<L>,
    /// Velocities predicted to the end of the step (see `Engine::evaluate`).
    pub vi: V<L>,
    pub vj: V<L>,
    pub wi: V<L>,
    pub wj: V<L>,
    /// Streaming-velocity difference of a deforming cell (zero otherwise).
    pub sv: V<L>,
    /// Tangential elastic displacement from the last step (zero without friction).
    pub u: V<L>,
}

/// What the law gives back for `L` pair contacts.
#[derive(Clone, Copy, Debug)]
pub struct PairRes<const L: usize> {
    /// Force on i.
    pub f: V<L>,
    /// q = -(r/(R_i+R_j)) n x F_t: the torques are R_i q on i and R_j q on j.
    pub q: V<L>,
    /// Updated tangential displacement.
    pub u: V<L>,
    /// Overlap / (R_i + R_j).
    pub ov: Ln<L>,
    /// Relative surface velocity at the contact (for the dissipation statistics).
    pub vrel: V<L>,
}

/// Whether the law runs on AVX2 (four lanes per instruction): the CPU has it and it was not
/// turned off with `set_wide(false)` or `GRANFLOW_NO_AVX2=1` in the environment. Either way
/// the results are the same bits.
pub fn wide() -> bool {
    use std::sync::atomic::Ordering;
    match WIDE.load(Ordering::Relaxed) {
        0 => {
            let on = detect() && std::env::var_os("GRANFLOW_NO_AVX2").is_none_or(|v| v.is_empty());
            WIDE.store(if on { 2 } else { 1 }, Ordering::Relaxed);
            on
        }
        s => s == 2,
    }
}

/// Use AVX2 when available (`true`) or the baseline instructions (`false`).
pub fn set_wide(on: bool) {
    let on = on && detect();
    WIDE.store(if on { 2 } else { 1 }, std::sync::atomic::Ordering::Relaxed);
}

/// 0: not decided yet, 1: baseline, 2: AVX2.
static WIDE: std::sync::atomic::AtomicU8 = std::sync::atomic::AtomicU8::new(0);

fn detect() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}
