//! Random insertion of non-overlapping polydisperse spheres (random sequential addition).
//! Random sequential addition jams near phi ~ 0.38; denser states are made by compression or by
//! the scenes' preparation protocols (pouring under gravity, or the stress-controlled cell).

use crate::error::{Error, Result};
use crate::rng::Rng;
use crate::V3;
use std::collections::HashMap;

/// Particle size distribution (diameters).
#[derive(Clone, Debug, PartialEq)]
pub enum SizeDist {
    /// All particles of one diameter.
    Mono(f64),
    /// Discrete mix: (diameter, number fraction) pairs, e.g. 30% 0.9 / 40% 1.0 / 30% 1.1.
    Discrete(Vec<(f64, f64)>),
    /// Uniform diameters in [lo, hi].
    Uniform(f64, f64),
}

impl SizeDist {
    pub fn validate(&self) -> Result<()> {
        match self {
            SizeDist::Mono(d) => crate::error::check_positive("diameter", *d),
            SizeDist::Discrete(v) => {
                if v.is_empty() {
                    return Err(Error::param(
                        "sizes",
                        "[]",
                        "at least one (diameter, fraction)",
                    ));
                }
                let mut tot = 0.0;
                for (d, f) in v {
                    crate::error::check_positive("diameter", *d)?;
                    if !(f.is_finite() && *f >= 0.0) {
                        return Err(Error::param("size fraction", f, "a number >= 0"));
                    }
                    tot += f;
                }
                if (tot - 1.0).abs() > 1e-6 {
                    return Err(Error::param(
                        "size fractions (sum)",
                        tot,
                        "fractions summing to 1",
                    ));
                }
                Ok(())
            }
            SizeDist::Uniform(lo, hi) => {
                crate::error::check_positive("diameter min", *lo)?;
                if !(hi.is_finite() && hi >= lo) {
                    return Err(Error::param(
                        "diameter max",
                        hi,
                        format!(">= diameter min = {lo}"),
                    ));
                }
                Ok(())
            }
        }
    }

    pub fn max(&self) -> f64 {
        match self {
            SizeDist::Mono(d) => *d,
            SizeDist::Discrete(v) => v.iter().map(|x| x.0).fold(0.0, f64::max),
            SizeDist::Uniform(_, hi) => *hi,
        }
    }

    /// Draw one diameter.
    pub fn sample(&self, rng: &mut Rng) -> f64 {
        match self {
            SizeDist::Mono(d) => *d,
            SizeDist::Discrete(v) => {
                let u = rng.uniform();
                let mut acc = 0.0;
                for (d, f) in v {
                    acc += f;
                    if u < acc {
                        return *d;
                    }
                }
                v.last().unwrap().0
            }
            SizeDist::Uniform(lo, hi) => rng.range(*lo, *hi),
        }
    }

    /// Diameters totalling (as closely as whole particles allow) a solid volume `vsolid`.
    /// Discrete mixes are filled by exact number fractions (largest remainder), then shuffled.
    pub fn diameters_for_volume(&self, vsolid: f64, rng: &mut Rng) -> Vec<f64> {
        let vol = |d: f64| std::f64::consts::PI * d * d * d / 6.0;
        match self {
            SizeDist::Discrete(v) => {
                let mean_vol: f64 = v.iter().map(|(d, f)| f * vol(*d)).sum();
                let n = (vsolid / mean_vol).round().max(1.0) as usize;
                let mut counts: Vec<usize> = v
                    .iter()
                    .map(|(_, f)| (f * n as f64).floor() as usize)
                    .collect();
                let mut rem: Vec<(f64, usize)> = v
                    .iter()
                    .enumerate()
                    .map(|(k, (_, f))| (f * n as f64 - counts[k] as f64, k))
                    .collect();
                rem.sort_by(|a, b| b.0.partial_cmp(&a.0).unwrap().then(a.1.cmp(&b.1)));
                let mut left = n - counts.iter().sum::<usize>();
                for (_, k) in rem {
                    if left == 0 {
                        break;
                    }
                    counts[k] += 1;
                    left -= 1;
                }
                let mut out = Vec::with_capacity(n);
                for (k, (d, _)) in v.iter().enumerate() {
                    out.extend(std::iter::repeat_n(*d, counts[k]));
                }
                // Fisher–Yates
                for i in (1..out.len()).rev() {
                    let j = (rng.uniform() * (i + 1) as f64) as usize;
                    out.swap(i, j.min(i));
                }
                out
            }
            _ => {
                let mut out = Vec::new();
                let mut tot = 0.0;
                while tot < vsolid {
                    let d = self.sample(rng);
                    // stop at the particle that brings the total closest to the target
                    if tot + vol(d) - vsolid > vsolid - tot {
                        break;
                    }
                    tot += vol(d);
                    out.push(d);
                }
                if out.is_empty() {
                    out.push(self.sample(rng));
                }
                out
            }
        }
    }
}

/// Place spheres of the given diameters without overlap, uniformly at random in the box
/// [lo, hi] (centres kept at least a radius from non-periodic faces). Largest first.
///
/// Every attempt draws its centre with `rng.range` along x, y, z in turn, and is rejected when
/// `|d|^2 < (r + r_j)^2` for a sphere j of the 27 cells (of side >= the largest diameter)
/// around it, with `d` the minimum-image difference of centres. These decisions, and so the
/// positions, are reproduced bit for bit: stored checksums depend on them.
pub fn insert(
    diameters: &[f64],
    lo: V3,
    hi: V3,
    periodic: [bool; 3],
    seed: u64,
    max_attempts: usize,
) -> Result<Vec<V3>> {
    let mut rng = Rng::new(seed);
    let len = hi - lo;
    for k in 0..3 {
        crate::error::check_positive("region length", len[k])?;
    }
    if diameters.is_empty() {
        return Ok(Vec::new());
    }
    let dmax = diameters.iter().cloned().fold(0.0, f64::max);
    let mut order: Vec<usize> = (0..diameters.len()).collect();
    order.sort_by(|&a, &b| {
        diameters[b]
            .partial_cmp(&diameters[a])
            .unwrap()
            .then(a.cmp(&b))
    });
    let vsolid: f64 = diameters
        .iter()
        .map(|d| std::f64::consts::PI * d.powi(3) / 6.0)
        .sum();
    let phi = vsolid / (len.x * len.y * len.z);
    let job = Job {
        diameters,
        order: &order,
        lo,
        hi,
        periodic,
        max_attempts,
        dmax,
        phi,
    };
    let mut grid = Grid::new(diameters, lo, len, periodic, dmax);
    let wrap = grid.exact.contains(&true);
    let rng = &mut rng;
    match (grid.per, wrap) {
        (1, false) => job.run::<1, false>(&mut grid, rng),
        (2, false) => job.run::<2, false>(&mut grid, rng),
        (4, false) => job.run::<4, false>(&mut grid, rng),
        (_, false) => job.run::<8, false>(&mut grid, rng),
        (1, true) => job.run::<1, true>(&mut grid, rng),
        (2, true) => job.run::<2, true>(&mut grid, rng),
        (4, true) => job.run::<4, true>(&mut grid, rng),
        (_, true) => job.run::<8, true>(&mut grid, rng),
    }
}

// The grid keeps each placed sphere as 8 bytes: its centre's offset within its cell in units of
// 1/QMAX of the cell side and its radius in units of 1/RQMAX of the largest radius (0: empty
// slot). That decides almost every pair from memory that stays in cache; a pair within the
// quantization error of contact is decided by the exact test on the exact positions.
const QMAX: f64 = 65534.0;
const RQMAX: f64 = 65000.0;
/// Attempts drawn ahead of the one being tested, so that their cells can be prefetched (the
/// draws are the same, in the same order, whether an attempt succeeds or not).
const AHEAD: usize = 8;
/// The 9 rows of 3 cells along x searched, as (y, z) neighbour indices ([`Near`]: 0 the own
/// cell, 1 and 2 the two sides): the own row, the 4 sharing a face, then the 4 sharing an edge.
const ROWS: [(usize, usize); 9] = [
    (0, 0),
    (1, 0),
    (2, 0),
    (0, 1),
    (0, 2),
    (1, 1),
    (2, 1),
    (1, 2),
    (2, 2),
];

/// The cells at offsets 0, -1, +1 of one cell along one axis.
#[derive(Clone, Copy)]
struct Near {
    /// cell index times the axis stride; the grid's cell count (past every real index) for a
    /// cell outside a wall or one already listed (axes of 1 or 2 periodic cells)
    idx: [usize; 3],
    /// the offset in cells of the image searched
    off: [f64; 3],
    /// what the minimum image subtracts from a difference of coordinates: 0 or +-length
    shift: [f64; 3],
}

struct Grid {
    lo: V3,
    len: V3,
    nb: [usize; 3],
    ncells: usize,
    /// periodic axes of fewer than 5 cells, where the exact test finds the minimum image by
    /// rounding, as the reference does; with 5 or more, centres in neighbour cells are less than
    /// 2 cells (under half a period) apart through the image listed in [`Near`], its minimum
    exact: [bool; 3],
    side: [f64; 3],
    step: [f64; 3],
    rstep: f64,
    /// bound on the quantized distance's error; infinite: every pair is tested exactly
    margin: f64,
    /// slots per cell (1, 2, 4 or 8); spheres past them are kept in `extra`
    per: usize,
    /// per cell: the `per` quantized x offsets, then y, then z, then radii
    slots: Vec<u16>,
    /// the sphere in each slot
    who: Vec<u32>,
    /// bit per cell: spheres in `extra`
    over: Vec<u64>,
    extra: HashMap<usize, Vec<u32>>,
    near: [Vec<Near>; 3],
    stride: [usize; 3],
    nbf: [f64; 3],
    inv: [f64; 3],
    /// index offsets of the rows of `ROWS`
    rows: [isize; 9],
}

impl Grid {
    fn new(diameters: &[f64], lo: V3, len: V3, periodic: [bool; 3], dmax: f64) -> Grid {
        let nb: [usize; 3] = std::array::from_fn(|k| ((len[k] / dmax).floor() as usize).max(1));
        let ncells = nb[0] * nb[1] * nb[2];
        // about twice the mean occupancy: few cells overflow
        let per = (2 * diameters.len())
            .div_ceil(ncells)
            .next_power_of_two()
            .min(8);
        let exact: [bool; 3] = std::array::from_fn(|k| periodic[k] && nb[k] < 5);
        let side: [f64; 3] = std::array::from_fn(|k| len[k] / nb[k] as f64);
        let step: [f64; 3] = std::array::from_fn(|k| side[k] / QMAX);
        let rstep = 0.5 * dmax / RQMAX;
        // Error of a quantized difference of centres against the exact one, per axis: half a
        // step, plus generous room for the f64 roundings of both (relative to the coordinates'
        // magnitude); thrice that on `exact` axes, where the two may take mirror images.
        let big = (0..3)
            .map(|k| lo[k].abs().max((lo[k] + len[k]).abs()))
            .fold(0.0, f64::max);
        let e: [f64; 3] = std::array::from_fn(|k| {
            let ek = 0.505 * step[k] + 64.0 * f64::EPSILON * (big + len[k]);
            if exact[k] {
                3.0 * ek
            } else {
                ek
            }
        });
        let m = 1.01 * (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt() + 1.01 * rstep;
        let valid = diameters.iter().all(|d| d.is_finite() && *d > 0.0);
        let margin = if valid && m.is_finite() {
            m + 1e-9 * (dmax + m)
        } else {
            f64::INFINITY
        };
        let stride = [1, nb[0], nb[0] * nb[1]];
        let near = std::array::from_fn(|k| {
            let m = nb[k] as i64;
            (0..m)
                .map(|c| {
                    let mut e = Near {
                        idx: [ncells; 3],
                        off: [0.0; 3],
                        shift: [0.0; 3],
                    };
                    let mut seen = [usize::MAX; 3];
                    for (s, o) in [0i64, -1, 1].into_iter().enumerate() {
                        let v = c + o;
                        let (w, shift) = if (0..m).contains(&v) {
                            (v as usize, 0.0)
                        } else if periodic[k] {
                            (
                                v.rem_euclid(m) as usize,
                                if v < 0 { -len[k] } else { len[k] },
                            )
                        } else {
                            continue;
                        };
                        if !seen.contains(&w) {
                            seen[s] = w;
                            e.idx[s] = w * stride[k];
                            e.off[s] = o as f64;
                            e.shift[s] = shift;
                        }
                    }
                    e
                })
                .collect()
        });
        let (sy, sz) = (stride[1] as isize, stride[2] as isize);
        Grid {
            lo,
            len,
            nb,
            ncells,
            exact,
            side,
            step,
            rstep,
            margin,
            per,
            slots: vec![0; ncells * per * 4],
            who: vec![0; ncells * per],
            over: vec![0; ncells.div_ceil(64)],
            extra: HashMap::new(),
            near,
            stride,
            nbf: std::array::from_fn(|k| nb[k] as f64),
            inv: std::array::from_fn(|k| nb[k] as f64 / len[k]),
            rows: [0, -sy, sy, -sz, sz, -sy - sz, sy - sz, -sy + sz, sy + sz],
        }
    }

    /// Start loading the rows around `x` (cells off the grid or wrapped give useless but
    /// harmless addresses).
    fn prefetch(&self, x: &[f64; 3]) {
        let c: [isize; 3] =
            std::array::from_fn(|k| ((x[k] - self.lo[k]) * self.inv[k]) as i32 as isize);
        let ci = c[0] + c[1] * self.stride[1] as isize + c[2] * self.stride[2] as isize;
        let per = 4 * self.per as isize;
        let base = self.slots.as_ptr();
        for &row in &self.rows {
            let first = (ci + row - 1) * per;
            prefetch(base.wrapping_offset(first));
            prefetch(base.wrapping_offset(first + 3 * per - 1));
        }
    }

    /// Whether a sphere of radius `r` at `x` (in cell `c`, at `u` in cell units) overlaps a
    /// placed one, as the reference test decides.
    #[inline(always)]
    fn clash<const PER: usize, const WRAP: bool>(
        &self,
        x: &[f64; 3],
        c: &[usize; 3],
        u: &[f64; 3],
        r: f64,
        pos: &[V3],
        diameters: &[f64],
    ) -> bool {
        let (margin, rstep) = (self.margin, self.rstep);
        let t: [&Near; 3] = std::array::from_fn(|k| &self.near[k][c[k]]);
        // centre minus each neighbour cell's origin, per axis; the nearer side searched first
        let mut g = [[0.0; 3]; 3];
        let mut ord = [[0, 1, 2]; 3];
        for k in 0..3 {
            let f = u[k] - c[k] as f64;
            g[k] = std::array::from_fn(|s| (f - t[k].off[s]) * self.side[k]);
            if f >= 0.5 {
                ord[k] = [0, 2, 1];
            }
        }
        // the reference arithmetic (on non-`exact` axes the shift is the minimum image)
        let exact_hit = |j: u32, shift: [f64; 3]| -> bool {
            let j = j as usize;
            let rs = r + 0.5 * diameters[j];
            let mut d = [0.0; 3];
            for k in 0..3 {
                let dk = x[k] - pos[j][k];
                d[k] = if WRAP && self.exact[k] {
                    dk - self.len[k] * (dk / self.len[k]).round()
                } else {
                    dk - shift[k]
                };
            }
            d[0] * d[0] + d[1] * d[1] + d[2] * d[2] < rs * rs
        };
        for &(jy, jz) in &ROWS {
            let (iy, iz) = (ord[1][jy], ord[2][jz]);
            let row = t[2].idx[iz] + t[1].idx[iy];
            for &ix in &ord[0] {
                let ci = row + t[0].idx[ix];
                if ci >= self.ncells {
                    continue;
                }
                let cell = &self.slots[ci * 4 * PER..ci * 4 * PER + 4 * PER];
                let gc = [g[0][ix], g[1][iy], g[2][iz]];
                let mut d2 = [0.0; PER];
                for k in 0..3 {
                    for s in 0..PER {
                        let mut d = gc[k] - cell[k * PER + s] as f64 * self.step[k];
                        if WRAP && self.exact[k] {
                            d -= self.len[k] * (d / self.len[k]).round();
                        }
                        d2[s] += d * d;
                    }
                }
                // per slot: surely apart, surely overlapping, or too close to call
                let mut sure = false;
                let mut unsure = 0u32;
                for s in 0..PER {
                    let rq = cell[3 * PER + s];
                    let rs = r + rq as f64 * rstep;
                    let (far, close) = (rs + margin, rs - margin);
                    let maybe = (rq != 0) & (d2[s] < far * far);
                    let yes = maybe & (close > 0.0) & (d2[s] < close * close);
                    sure |= yes;
                    unsure |= ((maybe & !yes) as u32) << s;
                }
                if sure {
                    return true;
                }
                let full = cell[4 * PER - 1] != 0;
                if unsure != 0 || full {
                    let shift = [t[0].shift[ix], t[1].shift[iy], t[2].shift[iz]];
                    while unsure != 0 {
                        let s = unsure.trailing_zeros() as usize;
                        unsure &= unsure - 1;
                        if exact_hit(self.who[ci * PER + s], shift) {
                            return true;
                        }
                    }
                    if full
                        && self.over[ci >> 6] >> (ci & 63) & 1 != 0
                        && self.extra[&ci].iter().any(|&j| exact_hit(j, shift))
                    {
                        return true;
                    }
                }
            }
        }
        false
    }

    fn add<const PER: usize>(&mut self, i: usize, c: &[usize; 3], u: &[f64; 3], r: f64) {
        let ci = c[0] * self.stride[0] + c[1] * self.stride[1] + c[2] * self.stride[2];
        let base = ci * 4 * PER;
        match (0..PER).find(|&s| self.slots[base + 3 * PER + s] == 0) {
            Some(s) => {
                for k in 0..3 {
                    let q = ((u[k] - c[k] as f64) * QMAX + 0.5) as u16;
                    self.slots[base + k * PER + s] = q.min(QMAX as u16);
                }
                self.slots[base + 3 * PER + s] = ((r / self.rstep + 0.5) as u16).max(1);
                self.who[ci * PER + s] = i as u32;
            }
            None => {
                self.over[ci >> 6] |= 1 << (ci & 63);
                self.extra.entry(ci).or_default().push(i as u32);
            }
        }
    }
}

#[inline(always)]
fn prefetch(p: *const u16) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch is a hint: it never faults and reads nothing, whatever the address.
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(p as *const i8)
    };
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// The inputs of one insertion.
struct Job<'a> {
    diameters: &'a [f64],
    order: &'a [usize],
    lo: V3,
    hi: V3,
    periodic: [bool; 3],
    max_attempts: usize,
    dmax: f64,
    phi: f64,
}

impl Job<'_> {
    fn run<const PER: usize, const WRAP: bool>(
        &self,
        grid: &mut Grid,
        rng: &mut Rng,
    ) -> Result<Vec<V3>> {
        let (lo, hi, len) = (self.lo, self.hi, self.hi - self.lo);
        let mut pos = vec![V3::zeros(); self.diameters.len()];
        let draw = |rng: &mut Rng| [rng.uniform(), rng.uniform(), rng.uniform()];
        let mut ahead = [[0.0; 3]; AHEAD];
        for u in &mut ahead {
            *u = draw(rng);
        }
        let mut next = 0;
        for (placed, &i) in self.order.iter().enumerate() {
            let r = 0.5 * self.diameters[i];
            let mut a = [0.0; 3];
            let mut w = [0.0; 3];
            for k in 0..3 {
                let (ak, bk) = if self.periodic[k] {
                    (lo[k], hi[k])
                } else {
                    (lo[k] + r, hi[k] - r)
                };
                if self.max_attempts > 0 && bk < ak {
                    return Err(Error::param(
                        "region",
                        format!("{:?}", len.as_slice()),
                        format!("wider than the largest diameter {}", self.dmax),
                    ));
                }
                (a[k], w[k]) = (ak, bk - ak);
            }
            let mut ok = false;
            for _ in 0..self.max_attempts {
                // rng.range(a, b) = a + (b - a) * rng.uniform()
                let x: [f64; 3] = std::array::from_fn(|k| a[k] + w[k] * ahead[next][k]);
                ahead[next] = draw(rng);
                grid.prefetch(&std::array::from_fn(|k| a[k] + w[k] * ahead[next][k]));
                next = (next + 1) % AHEAD;
                let u: [f64; 3] =
                    std::array::from_fn(|k| (x[k] - grid.lo[k]) / grid.len[k] * grid.nbf[k]);
                let c: [usize; 3] = std::array::from_fn(|k| (u[k] as usize).min(grid.nb[k] - 1));
                if !grid.clash::<PER, WRAP>(&x, &c, &u, r, &pos, self.diameters) {
                    pos[i] = V3::from(x);
                    grid.add::<PER>(i, &c, &u, r);
                    ok = true;
                    break;
                }
            }
            if !ok {
                return Err(Error::Configuration {
                    message: format!(
                        "random insertion failed after placing {placed} of {} spheres \
                         (target phi = {:.3}); random sequential insertion jams near phi ~ 0.38: \
                         insert at lower phi and compress, or use a scene's preparation",
                        self.diameters.len(),
                        self.phi
                    ),
                });
            }
        }
        Ok(pos)
    }
}
