//! The spring–dashpot contact law with tangential history and Coulomb friction.
//!
//! Implements 000_260a8780d7c638a6 Appendix A (A1–A3) and 002_89269f1b918188b3 §2.4 (2.17–2.19).
//! Conventions (002): r_ij = x_i - x_j, n = r_ij/|r_ij| (points from j to i), overlap
//! delta = R_i + R_j - |r_ij|, relative surface velocity at the contact point
//!   v_ij = v_i - v_j - (R_i w_i + R_j w_j) x n                          (002 2.18b, polydisperse)
//! Normal force on i (A1 / 2.17a):   F_n = s (k_n delta n) - s_d c_n v_n
//! Tangential (A2 / 2.17b):          F_t = -s k_t u - s_d c_t v_t,  |F_t| <= mu |F_n|
//! with s = s_d = 1 for the linear law and s = (delta/d_ij)^(1/2) for Hertz (a = 1/2 in A1),
//! d_ij = R_i + R_j the mean diameter of the pair.
//!
//! The law is generic over its *form* (Hooke/Hertz) and its *friction* (Coulomb or none); with
//! `Frictionless` the history type is `()`, so no history is allocated, stored or updated.

pub mod lanes;
pub mod spec;

pub use spec::{Damping, LawInput, LawSpec};

use crate::V3;
use lanes::{Ln, PairIn, PairRes, V};
use std::marker::PhantomData;

/// Normal form of the law: linear (a = 0) or Hertzian (a = 1/2).
pub trait Form: Copy + Send + Sync + 'static + Default + std::fmt::Debug {
    const NAME: &'static str;
    /// (spring factor s, dashpot factor s_d) for overlap delta and pair mean diameter d.
    fn factors(delta: f64, d: f64, tsuji: bool) -> (f64, f64);
    /// Elastic energy stored in a contact of overlap delta (the spring's integral).
    fn elastic_energy(kn: f64, delta: f64, d: f64) -> f64;
    /// Dimensionless damping zeta = c / sqrt(kn m_eff) that gives restitution e_n.
    fn zeta(e_n: f64) -> f64 {
        LawSpec::zeta(e_n)
    }
}

#[derive(Clone, Copy, Debug, Default)]
pub struct Hooke;
impl Form for Hooke {
    const NAME: &'static str = "hooke";
    fn elastic_energy(kn: f64, delta: f64, _: f64) -> f64 {
        0.5 * kn * delta * delta
    }
    #[inline(always)]
    fn factors(_: f64, _: f64, _: bool) -> (f64, f64) {
        (1.0, 1.0)
    }
}

/// Hertz: spring factor (delta/d)^(1/2) (A1 with a = 1/2). With damping given as a rate the
/// dashpot carries the same factor (exactly A1, as LAMMPS `hertz/history`). With damping given as
/// e_n, the dashpot factor is (delta/d)^(1/4) (Tsuji et al. 1992): only then is the restitution
/// independent of impact velocity, so that e_n can be a material parameter. Documented deviation.
#[derive(Clone, Copy, Debug, Default)]
pub struct Hertz;
impl Form for Hertz {
    const NAME: &'static str = "hertz";
    /// integral of kn (x/d)^(1/2) x dx = 2/5 kn x^(5/2) / d^(1/2)
    fn elastic_energy(kn: f64, delta: f64, d: f64) -> f64 {
        0.4 * kn * delta * delta * (delta / d).sqrt()
    }
    #[inline(always)]
    fn factors(delta: f64, d: f64, tsuji: bool) -> (f64, f64) {
        let s = (delta / d).sqrt();
        (s, if tsuji { s.sqrt() } else { s })
    }
    /// With the (delta/d)^(1/4) dashpot, the collision in reduced units y = delta/L,
    /// tau = t/T obeys y'' = -y^(3/2) - zeta y^(1/4) y' whatever the impact speed, so
    /// e_n = g(zeta) is universal; g is inverted numerically (RK4 + bisection, ~10 ms, once).
    fn zeta(e_n: f64) -> f64 {
        hertz_zeta(e_n)
    }
}

/// Restitution of the reduced Hertz–Tsuji collision for damping zeta.
pub fn hertz_restitution(zeta: f64) -> f64 {
    let acc = |y: f64, v: f64| -> f64 {
        let yp = y.max(0.0);
        -yp * yp.sqrt() - zeta * yp.sqrt().sqrt() * v
    };
    let (mut y, mut v) = (0.0f64, 1.0f64);
    let h = 2e-4;
    for _ in 0..200_000 {
        let (k1y, k1v) = (v, acc(y, v));
        let (k2y, k2v) = (v + 0.5 * h * k1v, acc(y + 0.5 * h * k1y, v + 0.5 * h * k1v));
        let (k3y, k3v) = (v + 0.5 * h * k2v, acc(y + 0.5 * h * k2y, v + 0.5 * h * k2v));
        let (k4y, k4v) = (v + h * k3v, acc(y + h * k3y, v + h * k3v));
        let yn = y + h / 6.0 * (k1y + 2.0 * k2y + 2.0 * k3y + k4y);
        let vn = v + h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
        if yn <= 0.0 && y > 0.0 {
            // interpolate the exit velocity linearly within the step
            let f = y / (y - yn);
            return -(v + f * (vn - v));
        }
        y = yn;
        v = vn;
        if v <= 0.0 && y <= 0.0 {
            return 0.0;
        }
    }
    0.0
}

fn hertz_zeta(e_n: f64) -> f64 {
    if e_n >= 1.0 {
        return 0.0;
    }
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    while hertz_restitution(hi) > e_n && hi < 1e3 {
        hi *= 2.0;
    }
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if hertz_restitution(mid) > e_n {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Tangential part of the law.
pub trait Friction: Copy + Send + Sync + 'static + Default + std::fmt::Debug {
    /// Per-contact tangential history: `[f64; 3]` with friction, `()` without.
    type History: Copy + Default + Send + Sync + 'static + std::fmt::Debug + PartialEq;
    const FRICTIONAL: bool;
    const NAME: &'static str;
    /// Negate a history (the pair's orientation i <-> j was swapped).
    fn flip(h: Self::History) -> Self::History;
    fn to_array(h: &Self::History) -> [f64; 3];
    fn from_array(a: [f64; 3]) -> Self::History;
}

#[derive(Clone, Copy, Debug, Default)]
pub struct Frictionless;
impl Friction for Frictionless {
    type History = ();
    const FRICTIONAL: bool = false;
    const NAME: &'static str = "frictionless";
    fn flip(_: ()) {}
    fn to_array(_: &()) -> [f64; 3] {
        [0.0; 3]
    }
    fn from_array(_: [f64; 3]) {}
}

#[derive(Clone, Copy, Debug, Default)]
pub struct Coulomb;
impl Friction for Coulomb {
    type History = [f64; 3];
    const FRICTIONAL: bool = true;
    const NAME: &'static str = "coulomb";
    fn flip(h: [f64; 3]) -> [f64; 3] {
        [-h[0], -h[1], -h[2]]
    }
    fn to_array(h: &[f64; 3]) -> [f64; 3] {
        *h
    }
    fn from_array(a: [f64; 3]) -> [f64; 3] {
        a
    }
}

/// A contact law ready to evaluate: form `F`, friction `T`.
#[derive(Clone, Copy, Debug)]
pub struct Law<F: Form, T: Friction> {
    pub params: LawSpec,
    kn: f64,
    kt: f64,
    /// Normal damping coefficient (force per velocity) = alpha m_eff + beta sqrt(m_eff): covers
    /// both the rate form (alpha = xi_n, beta = 0) and the restitution form (alpha = 0,
    /// beta = zeta sqrt(kn)) without a branch in the hot loop.
    alpha: f64,
    beta: f64,
    ratio_t: f64,
    mu: f64,
    tsuji: bool,
    _p: PhantomData<(F, T)>,
}

/// Output of one pair evaluation: total force on i and the tangential force on i.
#[derive(Clone, Copy, Debug, Default)]
pub struct PairForce {
    pub f: V3,
    pub ft: V3,
}

impl<F: Form, T: Friction> Law<F, T> {
    /// The law of a resolved spec ([`LawSpec::resolve`] validated it; it is not checked again).
    pub fn new(params: LawSpec) -> Self {
        let (alpha, beta, tsuji) = match params.damping {
            Damping::Restitution(e) => (0.0, F::zeta(e) * params.kn.sqrt(), true),
            Damping::Rate(x) => (x, 0.0, false),
        };
        Law {
            params,
            kn: params.kn,
            kt: params.kt,
            alpha,
            beta,
            ratio_t: params.xi_t_ratio,
            mu: params.mu,
            tsuji,
            _p: PhantomData,
        }
    }

    pub fn name() -> String {
        format!("{}/{}", F::NAME, T::NAME)
    }

    /// Normal damping coefficient (force per unit normal velocity) for a pair of mass m_eff.
    #[inline(always)]
    pub fn damping_coefficient(&self, m_eff: f64) -> f64 {
        self.alpha * m_eff + self.beta * m_eff.sqrt()
    }

    /// The pair law on `L` contacts at once (`crate::contact::lanes`): the geometry and the reduced mass
    /// from the branch vector (the normal from j to i, the lever arms r R_i/(R_i+R_j)), the
    /// relative surface velocity, then [`Law::law_core`]. `stream`: add the streaming
    /// velocity difference `c.sv` (a deforming cell).
    #[inline(always)]
    pub(crate) fn eval_pairs<const L: usize>(
        &self,
        c: &PairIn<L>,
        dt: f64,
        stream: bool,
    ) -> PairRes<L> {
        let sp = Ln::<L>::splat;
        let rs = c.rs;
        let r = c.r2.sqrt();
        let ims = c.imi + c.imj;
        // one division for 1/r, 1/(R_i+R_j) and m_eff = 1/(1/m_i + 1/m_j)
        let q = sp(1.0) / (r * rs * ims);
        let inv_r = rs * ims * q;
        let inv_rs = r * ims * q;
        let meff = r * rs * q;
        let n = c.d.scale(inv_r);
        let delta = rs - r;
        // lever arms l_i = r R_i/(R_i+R_j): the contact point lies on the branch vector and
        // the pair torques conserve angular momentum; for equal spheres 002 (2.18b)
        let arm = r * inv_rs;
        let mut vrel = c.vi - c.vj;
        if T::FRICTIONAL {
            // without friction only v_n matters, and spin adds nothing to it ((w x n) . n = 0)
            vrel = vrel - (c.wi.scale(c.ri) + c.wj.scale(c.rj)).scale(arm).cross(&n);
        }
        if stream {
            vrel = vrel + c.sv;
        }
        let (fnv, ft, u) = self.law_core(&n, delta, rs, meff, &vrel, c.u, dt);
        PairRes {
            f: fnv + ft,
            q: n.cross(&ft).scale(-arm),
            u,
            ov: delta * inv_rs,
            vrel,
        }
    }

    /// The law on `L` contacts given their geometry (000 A1-A3): unit normal `n` (from j to
    /// i), overlap `delta`, pair mean diameter `d`, reduced mass, relative surface velocity
    /// and tangential displacement `u` from the last step. Returns the normal force, the
    /// tangential force (on i) and the updated displacement. The branches of the history
    /// rotation and of the Coulomb cap are selects, so one code serves lanes of pairs and
    /// single wall contacts (L = 1).
    #[allow(
        clippy::too_many_arguments,
        reason = "the law's inputs on lanes, inlined into the force loop: each stays its own register"
    )]
    #[inline(always)]
    fn law_core<const L: usize>(
        &self,
        n: &V<L>,
        delta: Ln<L>,
        d: Ln<L>,
        meff: Ln<L>,
        vrel: &V<L>,
        u: V<L>,
        dt: f64,
    ) -> (V<L>, V<L>, V<L>) {
        let sp = Ln::<L>::splat;
        let zero = sp(0.0);
        let (mut s, mut sd) = ([1.0; L], [1.0; L]);
        for l in 0..L {
            (s[l], sd[l]) = F::factors(delta.0[l], d.0[l], self.tsuji);
        }
        let (s, sd) = (Ln(s), Ln(sd));
        let cn = (sp(self.alpha) * meff + sp(self.beta) * meff.sqrt()) * sd;
        let vn = vrel.dot(n);
        let fn_s = s * sp(self.kn) * delta - cn * vn;
        let fnv = n.scale(fn_s);
        if !T::FRICTIONAL {
            return (fnv, V::zero(), u);
        }
        let vt = *vrel - n.scale(vn);
        let kt = s * sp(self.kt);
        let ct = sp(self.ratio_t) * cn;
        let lim = sp(self.mu) * fn_s.abs();
        // A3 / 2.19: u is carried along by the rotation of the normal: project onto the
        // current tangent plane and restore |u| (when u is nonzero and the normal turned)
        let u2 = u.dot(&u);
        let un = u.dot(n);
        let up = u - n.scale(un);
        let p2 = u2 - un * un;
        let turned = p2.gt(zero).and(un.ne(zero));
        let up = turned.select3(up.scale((u2 / p2).sqrt()), up);
        let u = u2.gt(zero).select3(up, u);
        let u = u + vt.scale(sp(dt));
        let ft = u.scale(-kt) - vt.scale(ct);
        let ft2 = ft.dot(&ft);
        // sliding (A2, second line): cap |F_t| at mu |F_n|, and make the stored displacement
        // consistent with the capped force
        let slip = ft2.gt(lim * lim);
        let ft = slip.select3(ft.scale(lim / ft2.sqrt()), ft);
        let u = slip
            .and(kt.gt(zero))
            .select3((-(ft + vt.scale(ct))).div(kt), u);
        (fnv, ft, u)
    }

    /// Evaluate the law for one contact (walls, checks): [`Law::law_core`] on one lane.
    /// `n`: unit normal (from j to i), `delta` > 0 overlap, `d` pair mean diameter,
    /// `vrel`: relative surface velocity of i w.r.t. j at the contact.
    #[inline(always)]
    #[allow(
        clippy::too_many_arguments,
        reason = "one contact's geometry, mass, velocity and history, as in 002 (2.17)"
    )]
    pub fn eval(
        &self,
        n: &V3,
        delta: f64,
        d: f64,
        m_eff: f64,
        vrel: &V3,
        hist: &mut T::History,
        dt: f64,
    ) -> PairForce {
        let one = |a: &V3| V {
            x: Ln([a.x]),
            y: Ln([a.y]),
            z: Ln([a.z]),
        };
        let back = |a: &V<1>| V3::new(a.x.0[0], a.y.0[0], a.z.0[0]);
        let u = T::to_array(hist);
        let (fnv, ft, u) = self.law_core::<1>(
            &one(n),
            Ln([delta]),
            Ln([d]),
            Ln([m_eff]),
            &one(vrel),
            one(&V3::new(u[0], u[1], u[2])),
            dt,
        );
        *hist = T::from_array([u.x.0[0], u.y.0[0], u.z.0[0]]);
        let (fnv, ft) = (back(&fnv), back(&ft));
        PairForce { f: fnv + ft, ft }
    }
}
