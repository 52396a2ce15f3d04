//! The channel's samplers (000_260a8780d7c638a6 eqs 2.1–2.5; columns in docs/columns.md):
//! `bins`, window averages in slabs across x between the walls (here), and `series`, one row
//! per sample of whole-channel quantities (its own file, `channel/series.rs`).
//!
//! Bins: particle quantities (count, velocity, spin, temperature, kinetic stress, power) go to
//! the bin holding the particle's centre; the volume fraction uses the exact sphere–slab
//! intersection volumes; each pair contact's r_ij (x) f_ij is shared among the bins its branch
//! vector crosses in proportion to the length inside each (000 assigns half to each particle's
//! bin; the length rule makes each bin's stress divergence balance its forces), and a wall
//! contact's lies in the bin of its particle. The temperature (2.3) and the kinetic stress use
//! fluctuations about the window's bin means; Gamma (2.5) is -(1/V) sum_i P_i with each
//! contact's power split half and half (walls in full).

use super::{
    check_finite, check_window, chunk_parts, ChunkView, SampleView, Sampler, SamplerSpec, Setup,
    WALL,
};
use crate::error::{Error, Result};
use crate::table::Table;
use std::f64::consts::PI;

/// Random channel states for the tests and the channel_sums bench (not part of the API).
#[doc(hidden)]
pub mod fixtures;
mod series;
pub use series::Series;

const SIGMA: [&str; 9] = ["xx", "xy", "xz", "yx", "yy", "yz", "zx", "zy", "zz"];

/// Accumulator layout per bin: count, vol, m, mv (3), mvv (9), I, Iw (3), Iww, sc (9), P.
const COUNT: usize = 0;
const VOL: usize = 1;
const M: usize = 2;
const MV: usize = 3;
const MVV: usize = 6;
const IN: usize = 15;
const IW: usize = 16;
const IWW: usize = 19;
const SC: usize = 20;
const P: usize = 29;
const NACC: usize = 30;
/// The particle terms' part of the layout (COUNT ..= IWW).
const ROW: usize = 20;

/// Volume of a sphere of radius r lying below a plane at signed height z above its centre.
#[inline(always)]
fn cap_below(z: f64, r: f64) -> f64 {
    // (`clamp` without its check that -r <= r: NaN stays NaN, as with clamp)
    let zc = if z < -r {
        -r
    } else if z > r {
        r
    } else {
        z
    };
    let a = r + zc;
    a * a * (3.0 * r - a) * (PI / 3.0)
}

/// The bin of coordinate x: numpy's `clip(searchsorted(edges, x, 'right') - 1, 0, nb - 1)`.
#[cfg(test)]
fn bin_of(edges: &[f64], x: f64) -> usize {
    let nb = edges.len() - 1;
    edges
        .partition_point(|&e| e <= x)
        .saturating_sub(1)
        .min(nb - 1)
}

/// The bins' edges with a fast lookup: a guess from the interior's mean width, corrected
/// against the edges themselves (so exactly `bin_of`'s answer, in a step or two).
struct Lookup {
    edges: Vec<f64>,
    lo: f64,
    inv_w: f64,
}

impl Lookup {
    fn new(edges: &[f64]) -> Self {
        let nb = edges.len() - 1;
        // the interior between the first and last inner edges (wall bins may differ)
        let (a, b) = if nb > 2 {
            (edges[1], edges[nb - 1])
        } else {
            (edges[0], edges[nb])
        };
        let span = if nb > 2 { (nb - 2) as f64 } else { nb as f64 };
        Lookup {
            edges: edges.to_vec(),
            lo: a,
            inv_w: span / (b - a),
        }
    }

    #[inline]
    fn bin(&self, x: f64) -> usize {
        let e = &self.edges;
        let nb = e.len() - 1;
        let g = (x - self.lo) * self.inv_w + if nb > 2 { 1.0 } else { 0.0 };
        // (NaN and far-out values clamp to the end bins, as bin_of does)
        let mut k = if g >= 0.0 {
            (g as usize).min(nb - 1)
        } else {
            0
        };
        while k > 0 && x < e[k] {
            k -= 1;
        }
        while k + 1 < nb && x >= e[k + 1] {
            k += 1;
        }
        k
    }

    /// The bins from `lo`'s to `hi`'s, walked from bin `b` (which holds a point between).
    fn reach(&self, b: usize, lo: f64, hi: f64) -> (usize, usize) {
        let (e, nb) = (&self.edges, self.edges.len() - 1);
        let (mut k0, mut k1) = (b, b);
        while k0 > 0 && lo < e[k0] {
            k0 -= 1;
        }
        while k1 + 1 < nb && hi >= e[k1 + 1] {
            k1 += 1;
        }
        (k0, k1)
    }

    /// One chunk's sums: its particles and its contacts.
    #[inline(always)]
    fn sums(&self, c: &ChunkView) -> Vec<[f64; NACC]> {
        let (r, recs) = (c.r.clone(), c.recs);
        let edges = &self.edges;
        let nb = edges.len() - 1;
        let mut acc = vec![[0.0; NACC]; nb];
        // each particle's bin, for its contacts
        let r0 = r.start;
        let mut bins: Vec<u32> = Vec::with_capacity(r.len());
        for i in r {
            let x = c.x[i];
            let rad = c.radius[i];
            let m = c.mass[i];
            let (vi, w) = (c.v[i - r0], c.omega[i - r0]);
            let vi = [vi.x, vi.y, vi.z];
            let w = [w.x, w.y, w.z];
            let dia = 2.0 * rad;
            let inertia = m * dia * dia * 0.1;
            let b = self.bin(x.x);
            bins.push(b as u32);
            // the particle's terms as one row (zeros where it adds nothing: the volume, the
            // kinetic sums' lower triangle, filled in when the window closes), added whole
            let mut row = [0.0; ROW];
            row[COUNT] = 1.0;
            row[M] = m;
            for k in 0..3 {
                row[MV + k] = m * vi[k];
                row[IW + k] = inertia * w[k];
            }
            for ka in 0..3 {
                for kb in ka..3 {
                    row[MVV + 3 * ka + kb] = m * vi[ka] * vi[kb];
                }
            }
            row[IN] = inertia;
            row[IWW] = inertia * (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
            for (x, y) in acc[b][..ROW].iter_mut().zip(&row) {
                *x += y;
            }
            // the sphere's volume in each slab it reaches, as differences of the caps below
            // the slab's edges (`cap_below` clamps: 0 below the sphere, all of it above).
            // Usually it reaches at most the bins beside its own: the caps below its bin's
            // two edges give all three (a bin beside it that it does not reach gets +0);
            // else a walk over the bins.
            let (lo, hi) = (x.x - rad, x.x + rad);
            if (b == 0 || lo >= edges[b - 1]) && (b + 2 > nb || hi < edges[b + 2]) {
                let whole = cap_below(rad, rad);
                let c_lo = cap_below(edges[b] - x.x, rad);
                let c_hi = cap_below(edges[b + 1] - x.x, rad);
                if b > 0 {
                    acc[b - 1][VOL] += c_lo;
                }
                acc[b][VOL] += c_hi - c_lo;
                if b + 1 < nb {
                    acc[b + 1][VOL] += whole - c_hi;
                }
                continue;
            }
            let (k0, k1) = self.reach(b, lo, hi);
            let mut prev = cap_below(edges[k0] - x.x, rad);
            for (k, slab) in acc.iter_mut().enumerate().take(k1 + 1).skip(k0) {
                let next = cap_below(edges[k + 1] - x.x, rad);
                slab[VOL] += next - prev;
                prev = next;
            }
        }
        // contact stress: walls in their particle's bin, pairs along their branch vectors
        for rec in recs {
            let d = [rec.d.x, rec.d.y, rec.d.z];
            let f = [rec.f.x, rec.f.y, rec.f.z];
            let full: [f64; 9] = std::array::from_fn(|k| d[k / 3] * f[k % 3]);
            let ii = rec.i as usize;
            let xi = c.x[ii].x;
            // (a chunk's records are its own particles'; any other is looked up)
            let bi = match ii.checked_sub(r0).and_then(|k| bins.get(k)) {
                Some(&b) => b as usize,
                None => self.bin(xi),
            };
            if rec.j == WALL {
                let a = &mut acc[bi];
                for k in 0..9 {
                    a[SC + k] += full[k];
                }
                a[P] += rec.power;
                continue;
            }
            // the segment from x_i to x_j: usually within x_i's bin and the two beside it
            // (its end bins found without walks), else walked
            let xj = xi - d[0];
            let (lo, hi) = (xi.min(xj), xi.max(xj));
            let (kl, kh) = (bi.saturating_sub(1), (bi + 1).min(nb - 1));
            let (k0, k1) = if lo >= edges[kl] && hi < edges[kh + 1] {
                // (it starts in bin bi)
                let k0 = if bi > 0 && lo < edges[bi] { bi - 1 } else { bi };
                let k1 = if bi + 1 < nb && hi >= edges[bi + 1] {
                    bi + 1
                } else {
                    bi
                };
                (k0, k1)
            } else {
                self.reach(bi, lo, hi)
            };
            // the power half and half, to the bins of the two centres (x_j's bin from the
            // branch vector: no walk to particle j; the channel is not periodic across x)
            let half = 0.5 * rec.power;
            acc[bi][P] += half;
            acc[if xj < xi { k0 } else { k1 }][P] += half;
            // a segment in one bin (or too short to split) gives all of it to that bin; else
            // each bin from k0 to k1 its length inside. (The bins it does not reach get
            // nothing: adding their +-0 would not change a sum that starts at +0.)
            let span = hi - lo;
            if k0 == k1 || span < 1e-12 {
                let a = &mut acc[k0];
                for q in 0..9 {
                    a[SC + q] += full[q];
                }
                continue;
            }
            let inv = 1.0 / span;
            for k in k0..=k1 {
                let share = (hi.min(edges[k + 1]) - lo.max(edges[k])).max(0.0) * inv;
                let a = &mut acc[k];
                for q in 0..9 {
                    a[SC + q] += share * full[q];
                }
            }
        }
        acc
    }
}

/// One chunk's sums as a pass with an AVX2 twin (the same operations, compiled wider).
struct ChunkSums<'a, 'b>(&'a Lookup, &'a ChunkView<'b>);

impl crate::simd::Twin for ChunkSums<'_, '_> {
    type Out = Vec<[f64; NACC]>;
    #[inline(always)]
    fn base(self) -> Self::Out {
        self.0.sums(self.1)
    }
}

/// numpy.gradient (second order inside, first order at the ends) of y over points x.
fn gradient(y: &[f64], x: &[f64]) -> Vec<f64> {
    let n = y.len();
    if n < 2 {
        return vec![0.0; n];
    }
    let mut g = vec![0.0; n];
    g[0] = (y[1] - y[0]) / (x[1] - x[0]);
    g[n - 1] = (y[n - 1] - y[n - 2]) / (x[n - 1] - x[n - 2]);
    for i in 1..n - 1 {
        let hs = x[i] - x[i - 1];
        let hd = x[i + 1] - x[i];
        g[i] = (hs * hs * y[i + 1] + (hd * hd - hs * hs) * y[i] - hd * hd * y[i - 1])
            / (hs * hd * (hd + hs));
    }
    g
}

/// The `bins` table's window sampler.
pub struct Bins {
    every: u64,
    window: u64,
    /// The bin edges and their lookup.
    lookup: Lookup,
    /// Bin volumes (width x H x B).
    vbin: Vec<f64>,
    /// The open window: its sums, samples, start time; and the next window's index.
    acc: Vec<[f64; NACC]>,
    n: u64,
    t0: f64,
    index: u64,
    closed: Vec<Table>,
    /// The coming sample's chunk sums, when the team made them (else empty).
    parts: Vec<Vec<f64>>,
}

impl Bins {
    pub fn new(spec: &SamplerSpec, setup: &Setup) -> Result<Self> {
        check_window("channel_bins", spec.window)?;
        let e = &spec.edges;
        let w = setup.widths[0];
        if e.len() < 2 || e.iter().any(|x| !x.is_finite()) || e.windows(2).any(|p| p[1] <= p[0]) {
            return Err(Error::param(
                "channel_bins.edges",
                format!("{e:?}"),
                "at least two finite, strictly increasing bin edges",
            ));
        }
        if setup.periodic[0] || setup.walls < 2 {
            return Err(Error::param(
                "channel_bins",
                "this simulation",
                "a channel: walls across x (the bins are slabs between them)",
            ));
        }
        if e[0] != 0.0 || e[e.len() - 1] != w {
            return Err(Error::param(
                "channel_bins.edges",
                format!("[{}, ..., {}]", e[0], e[e.len() - 1]),
                format!(
                    "edges from the wall x = 0 to the wall x = W = {w} (bins tiling the channel)"
                ),
            ));
        }
        let area = setup.widths[1] * setup.widths[2];
        let vbin = e.windows(2).map(|p| (p[1] - p[0]) * area).collect();
        let nb = e.len() - 1;
        Ok(Bins {
            every: spec.every,
            window: spec.window,
            lookup: Lookup::new(e),
            vbin,
            acc: vec![[0.0; NACC]; nb],
            n: 0,
            t0: 0.0,
            index: 0,
            closed: Vec::new(),
            parts: Vec::new(),
        })
    }

    /// The sums of one sample, added to the open window: each force-loop chunk's particles
    /// and contacts summed apart (`chunk_parts`: by the team as it completes the chunks, or
    /// here), then added in chunk order.
    fn accumulate(&mut self, v: &SampleView) {
        let given = std::mem::take(&mut self.parts);
        let parts = chunk_parts(given, v, |c| self.chunk_sums(c));
        for part in parts {
            for (a, b) in self.acc.iter_mut().zip(part.chunks_exact(NACC)) {
                for (x, y) in a.iter_mut().zip(b) {
                    *x += y;
                }
            }
        }
    }

    /// One chunk's sums, flat (bin after bin).
    fn chunk_sums(&self, c: &ChunkView) -> Vec<f64> {
        let sums = crate::simd::dispatch(ChunkSums(&self.lookup, c));
        sums.into_iter().flatten().collect()
    }

    /// The rows of the window closed at time `t1`.
    fn close(&mut self, t1: f64) -> Table {
        let ns = self.n as f64;
        let nb = self.acc.len();
        let edges = &self.lookup.edges;
        let a = &self.acc;
        let vb: Vec<f64> = self.vbin.iter().map(|v| v * ns).collect();
        let xc: Vec<f64> = edges.windows(2).map(|p| 0.5 * (p[1] + p[0])).collect();
        let mut u = vec![[0.0; 3]; nb];
        let mut om = vec![[0.0; 3]; nb];
        let mut temp = vec![0.0; nb];
        let mut sk = vec![[0.0; 9]; nb];
        let mut sc = vec![[0.0; 9]; nb];
        for b in 0..nb {
            let mut s = a[b];
            // the kinetic sums were kept on the upper triangle
            s[MVV + 3] = s[MVV + 1];
            s[MVV + 6] = s[MVV + 2];
            s[MVV + 7] = s[MVV + 5];
            let msafe = if s[M] > 0.0 { s[M] } else { 1.0 };
            let isafe = if s[IN] > 0.0 { s[IN] } else { 1.0 };
            for k in 0..3 {
                u[b][k] = s[MV + k] / msafe;
                om[b][k] = s[IW + k] / isafe;
            }
            let mvu: f64 = (0..3).map(|k| s[MV + k] * u[b][k]).sum();
            let iwo: f64 = (0..3).map(|k| s[IW + k] * om[b][k]).sum();
            let ft = s[MVV] + s[MVV + 4] + s[MVV + 8] - mvu;
            let fr = s[IWW] - iwo;
            let cnt = s[COUNT];
            temp[b] = if cnt > 0.0 {
                (ft + fr) / (6.0 * cnt)
            } else {
                0.0
            };
            for k in 0..9 {
                sk[b][k] = (s[MVV + k] - s[MV + k / 3] * u[b][k % 3]) / vb[b];
                sc[b][k] = s[SC + k] / vb[b];
            }
        }
        let uy: Vec<f64> = (0..nb)
            .map(|b| if a[b][M] > 0.0 { u[b][1] } else { 0.0 })
            .collect();
        let dudx = gradient(&uy, &xc);
        let col = |f: &dyn Fn(usize) -> f64| (0..nb).map(f).collect::<Vec<f64>>();
        let mut t = Table::new();
        t.push_i64("window", "", vec![self.index as i64; nb]);
        t.push_f64("t0", "sqrt(d/g)", vec![self.t0; nb]);
        t.push_f64("t1", "sqrt(d/g)", vec![t1; nb]);
        t.push_i64("n_samples", "", vec![self.n as i64; nb]);
        t.push_i64("bin", "", (0..nb as i64).collect());
        t.push_f64("x_lo", "d", edges[..nb].to_vec());
        t.push_f64("x_hi", "d", edges[1..].to_vec());
        t.push_f64("x", "d", xc.clone());
        t.push_f64("count", "", col(&|b| a[b][COUNT] / ns));
        t.push_f64("phi", "", col(&|b| a[b][VOL] / vb[b]));
        for (k, c) in ["u_x", "u_y", "u_z"].iter().enumerate() {
            t.push_f64(c, "sqrt(g d)", col(&|b| u[b][k]));
        }
        for (k, c) in ["w_x", "w_y", "w_z"].iter().enumerate() {
            t.push_f64(c, "sqrt(g/d)", col(&|b| om[b][k]));
        }
        t.push_f64("T", "g d", temp);
        let stress = "rho_p g d";
        for (k, c) in SIGMA.iter().enumerate() {
            t.push_f64(&format!("sigma_{c}"), stress, col(&|b| sk[b][k] + sc[b][k]));
        }
        for (k, c) in SIGMA.iter().enumerate() {
            t.push_f64(&format!("sigma_c_{c}"), stress, col(&|b| sc[b][k]));
        }
        for (k, c) in SIGMA.iter().enumerate() {
            t.push_f64(&format!("sigma_k_{c}"), stress, col(&|b| sk[b][k]));
        }
        t.push_f64("Gamma", "rho_p g^1.5 d^0.5", col(&|b| -a[b][P] / vb[b]));
        t.push_f64(
            "shear_production",
            "rho_p g^1.5 d^0.5",
            col(&|b| (sk[b][1] + sc[b][1]) * dudx[b]),
        );
        t.metadata
            .push(("granflow.sampler".into(), "channel_bins".into()));
        t
    }

    /// The columns in order (built once: the stress names are made from their parts).
    pub fn column_names() -> Vec<&'static str> {
        static NAMES: std::sync::OnceLock<Vec<String>> = std::sync::OnceLock::new();
        let names = NAMES.get_or_init(|| {
            let mut c: Vec<String> = [
                "window",
                "t0",
                "t1",
                "n_samples",
                "bin",
                "x_lo",
                "x_hi",
                "x",
                "count",
                "phi",
                "u_x",
                "u_y",
                "u_z",
                "w_x",
                "w_y",
                "w_z",
                "T",
            ]
            .map(String::from)
            .to_vec();
            for pre in ["sigma_", "sigma_c_", "sigma_k_"] {
                c.extend(SIGMA.iter().map(|s| format!("{pre}{s}")));
            }
            c.extend(["Gamma".to_string(), "shear_production".to_string()]);
            c
        });
        names.iter().map(String::as_str).collect()
    }
}

impl Sampler for Bins {
    fn kind(&self) -> &'static str {
        "channel_bins"
    }
    fn table(&self) -> &'static str {
        "bins"
    }
    fn every(&self) -> u64 {
        self.every
    }
    fn columns(&self) -> Vec<&'static str> {
        Self::column_names()
    }
    fn chunk_part(&self, c: &ChunkView) -> Option<Vec<f64>> {
        Some(self.chunk_sums(c))
    }
    fn set_parts(&mut self, parts: Vec<Vec<f64>>) {
        self.parts = parts;
    }
    fn sample(&mut self, v: &SampleView) -> Result<()> {
        if self.n == 0 {
            self.t0 = v.time;
        }
        self.accumulate(v);
        self.n += 1;
        if self.n >= self.window {
            let t = self.close(v.time);
            check_finite("channel bins", v.step, &t)?;
            self.closed.push(t);
            self.index += 1;
            self.n = 0;
            self.acc.iter_mut().for_each(|a| *a = [0.0; NACC]);
        }
        Ok(())
    }
    fn take(&mut self) -> Vec<Table> {
        std::mem::take(&mut self.closed)
    }
    fn save(&self) -> Vec<f64> {
        let mut s = vec![self.n as f64, self.t0, self.index as f64];
        s.extend(self.acc.iter().flatten());
        s
    }
    fn load(&mut self, s: &[f64]) -> Result<()> {
        if s.len() != 3 + NACC * self.acc.len() {
            return Err(Error::Io {
                message: "checkpoint: the channel bins' open window has another number of bins \
                          than this sampler"
                    .into(),
            });
        }
        self.n = s[0] as u64;
        self.t0 = s[1];
        self.index = s[2] as u64;
        for (a, c) in self.acc.iter_mut().zip(s[3..].chunks_exact(NACC)) {
            a.copy_from_slice(c);
        }
        Ok(())
    }
    fn bytes(&self) -> usize {
        8 * NACC * self.acc.len() + self.closed.iter().map(super::table_bytes).sum::<usize>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::ContactRec;

    #[test]
    fn fast_lookup_is_searchsorted() {
        let mut edges = vec![0.0, 1.5];
        edges.extend((1..18).map(|k| 1.5 + k as f64 * (17.0 / 17.0)));
        edges.push(20.0);
        let odd = [0.0, 0.7, 3.1, 3.2, 9.0];
        for e in [&edges[..], &odd[..], &[0.0, 5.0][..], &[0.0, 2.0, 5.0][..]] {
            let l = Lookup::new(e);
            let top = e[e.len() - 1];
            for k in -100..2200 {
                let x = k as f64 * top / 2000.0;
                assert_eq!(l.bin(x), bin_of(e, x), "x = {x}, edges {e:?}");
            }
            for &x in e {
                assert_eq!(l.bin(x), bin_of(e, x));
                assert_eq!(l.bin(x - 1e-15), bin_of(e, x - 1e-15));
            }
            assert_eq!(l.bin(f64::NAN), bin_of(e, f64::NAN));
            assert_eq!(l.bin(f64::INFINITY), bin_of(e, f64::INFINITY));
            assert_eq!(l.bin(-f64::INFINITY), bin_of(e, -f64::INFINITY));
        }
    }

    fn view_of<'a>(
        p: &'a crate::particles::Particles,
        recs: &'a [Vec<ContactRec>],
    ) -> SampleView<'a> {
        const WF: [crate::V3; 2] = [crate::V3::new(0.0, 0.0, 0.0); 2];
        SampleView {
            step: 1,
            time: 0.0,
            p,
            contacts: recs,
            n_contacts: 0,
            max_overlap: 0.0,
            wall_force: &WF,
            wall_impulse: &WF,
            h: crate::M3::identity(),
            widths: [20.0, 30.0, 10.0],
            observables: vec![],
            elastic: None,
        }
    }

    /// The new sums give the bits of the walking version they replaced, on random spheres and
    /// contacts over uniform bins with wall bins, narrow bins (spheres over four bins: the
    /// walk), and uneven bins.
    #[test]
    fn sums_keep_their_bits() {
        let (n, ch) = (3000, 750);
        let (p, recs) = super::fixtures::random_state(n, ch, 1100);
        let view = view_of(&p, &recs);
        let mut uniform = vec![0.0, 1.5];
        uniform.extend((1..18).map(|k| 1.5 + k as f64));
        uniform.push(20.0);
        let narrow: Vec<f64> = (0..=64).map(|k| k as f64 * 20.0 / 64.0).collect();
        let uneven = [0.0, 0.7, 3.1, 3.2, 9.0, 9.4, 15.0, 20.0];
        for e in [&uniform[..], &narrow[..], &uneven[..], &[0.0, 20.0][..]] {
            let l = Lookup::new(e);
            for (c, rc) in recs.iter().enumerate() {
                let r = c * ch..(c + 1) * ch;
                let (a, b) = (
                    l.sums(&ChunkView::of(&p, r.clone(), rc)),
                    sums_before(&l, &view, r, rc),
                );
                for (x, y) in a.iter().zip(&b) {
                    for (u, w) in x.iter().zip(y) {
                        assert!(u.to_bits() == w.to_bits(), "edges {e:?}: {u:e} != {w:e}");
                    }
                }
            }
        }
    }

    /// The sums as first written (walks and branches): the reference of `sums`' bits.
    fn sums_before(
        l: &Lookup,
        v: &SampleView,
        r: std::ops::Range<usize>,
        recs: &[ContactRec],
    ) -> Vec<[f64; NACC]> {
        let p = v.p;
        let edges = &l.edges;
        let nb = edges.len() - 1;
        let mut acc = vec![[0.0; NACC]; nb];
        // each particle's bin, for its contacts
        let r0 = r.start;
        let mut bins: Vec<u32> = Vec::with_capacity(r.len());
        for i in r {
            let x = p.x[i];
            let rad = p.radius[i];
            let m = p.mass[i];
            let vi = [p.v[i].x, p.v[i].y, p.v[i].z];
            let w = [p.omega[i].x, p.omega[i].y, p.omega[i].z];
            let dia = 2.0 * rad;
            let inertia = m * dia * dia * 0.1;
            let b = l.bin(x.x);
            bins.push(b as u32);
            let a = &mut acc[b];
            a[COUNT] += 1.0;
            a[M] += m;
            for k in 0..3 {
                a[MV + k] += m * vi[k];
                a[IW + k] += inertia * w[k];
            }
            // the upper triangle (the lower one is filled in when the window closes)
            for ka in 0..3 {
                for kb in ka..3 {
                    a[MVV + 3 * ka + kb] += m * vi[ka] * vi[kb];
                }
            }
            a[IN] += inertia;
            a[IWW] += inertia * (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
            // the sphere's volume in each slab it reaches: the caps below the edges it
            // crosses (an edge beyond its reach cuts off nothing or the whole sphere)
            let (lo, hi) = (x.x - rad, x.x + rad);
            let (mut k0, mut k1) = (b, b);
            while k0 > 0 && lo < edges[k0] {
                k0 -= 1;
            }
            while k1 + 1 < nb && hi >= edges[k1 + 1] {
                k1 += 1;
            }
            let whole = cap_below(rad, rad);
            let cut = |e: f64| {
                let z = e - x.x;
                if z <= -rad {
                    0.0
                } else if z >= rad {
                    whole
                } else {
                    cap_below(z, rad)
                }
            };
            let mut prev = cut(edges[k0]);
            for (k, slab) in acc.iter_mut().enumerate().take(k1 + 1).skip(k0) {
                let next = cut(edges[k + 1]);
                slab[VOL] += next - prev;
                prev = next;
            }
        }
        // contact stress: walls in their particle's bin, pairs along their branch vectors
        for c in recs {
            let d = [c.d.x, c.d.y, c.d.z];
            let f = [c.f.x, c.f.y, c.f.z];
            let full: [f64; 9] = std::array::from_fn(|k| d[k / 3] * f[k % 3]);
            let ii = c.i as usize;
            let xi = p.x[ii].x;
            // (a chunk's records are its own particles'; any other is looked up)
            let bi = match ii.checked_sub(r0).and_then(|k| bins.get(k)) {
                Some(&b) => b as usize,
                None => l.bin(xi),
            };
            if c.j == WALL {
                let a = &mut acc[bi];
                for k in 0..9 {
                    a[SC + k] += full[k];
                }
                a[P] += c.power;
                continue;
            }
            // the bins from x_i's to x_j's, searched from x_i's
            let xj = xi - d[0];
            let (lo, hi) = (xi.min(xj), xi.max(xj));
            let (mut k0, mut k1) = (bi, bi);
            while k0 > 0 && lo < edges[k0] {
                k0 -= 1;
            }
            while k1 + 1 < nb && hi >= edges[k1 + 1] {
                k1 += 1;
            }
            // the power half and half, to the bins of the two centres (x_j's bin from the
            // branch vector: no walk to particle j; the channel is not periodic across x)
            let half = 0.5 * c.power;
            acc[bi][P] += half;
            acc[if xj < xi { k0 } else { k1 }][P] += half;
            let span = hi - lo;
            if k0 == k1 || span < 1e-12 {
                let a = &mut acc[k0];
                for q in 0..9 {
                    a[SC + q] += full[q];
                }
                continue;
            }
            let inv = 1.0 / span;
            for k in k0..=k1 {
                let ov = hi.min(edges[k + 1]) - lo.max(edges[k]);
                let share = ov.max(0.0) * inv;
                let a = &mut acc[k];
                for q in 0..9 {
                    a[SC + q] += share * full[q];
                }
            }
        }
        acc
    }

    #[test]
    fn gradient_is_numpys() {
        // numpy.gradient([1, 4, 9, 25], [0, 1, 2, 4]) = [3, 4, 6, 8]
        let g = gradient(&[1.0, 4.0, 9.0, 25.0], &[0.0, 1.0, 2.0, 4.0]);
        let want = [3.0, 4.0, 6.0, 8.0];
        for (a, b) in g.iter().zip(want) {
            assert!((a - b).abs() < 1e-12, "{g:?}");
        }
    }

    #[test]
    fn caps_sum_to_the_sphere() {
        let r = 0.55;
        let edges = [0.0, 1.5, 2.5, 3.5, 8.3];
        let x = 2.4;
        let v: f64 = edges
            .windows(2)
            .map(|e| cap_below(e[1] - x, r) - cap_below(e[0] - x, r))
            .sum();
        assert!((v - 4.0 / 3.0 * PI * r * r * r).abs() < 1e-14);
    }
}
