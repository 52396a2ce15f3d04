//! Random insertion of non-overlapping polydisperse spheres (random sequential addition).
//! Random sequential addition jams near phi ~ 0.38; denser states are made by compression or by
//! the scenes' preparation protocols (pouring under gravity, or the stress-controlled cell).

use crate::error::{Error, Result};
use crate::rng::Rng;
use crate::V3;

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
    let dmax = diameters.iter().cloned().fold(0.0, f64::max);
    let nb: Vec<usize> = (0..3)
        .map(|k| ((len[k] / dmax).floor() as usize).max(1))
        .collect();
    let mut grid: Vec<Vec<u32>> = vec![Vec::new(); nb[0] * nb[1] * nb[2]];
    let mut order: Vec<usize> = (0..diameters.len()).collect();
    order.sort_by(|&a, &b| {
        diameters[b]
            .partial_cmp(&diameters[a])
            .unwrap()
            .then(a.cmp(&b))
    });
    let mut pos = vec![V3::zeros(); diameters.len()];
    let cell = |x: &V3| -> [usize; 3] {
        let mut c = [0; 3];
        for k in 0..3 {
            c[k] = (((x[k] - lo[k]) / len[k] * nb[k] as f64) as usize).min(nb[k] - 1);
        }
        c
    };
    let mdelta = |a: &V3, b: &V3| -> V3 {
        let mut d = a - b;
        for k in 0..3 {
            if periodic[k] {
                d[k] -= len[k] * (d[k] / len[k]).round();
            }
        }
        d
    };
    let vsolid: f64 = diameters
        .iter()
        .map(|d| std::f64::consts::PI * d.powi(3) / 6.0)
        .sum();
    let phi = vsolid / (len.x * len.y * len.z);
    for (placed, &i) in order.iter().enumerate() {
        let r = 0.5 * diameters[i];
        let mut ok = false;
        for _ in 0..max_attempts {
            let mut x = V3::zeros();
            for k in 0..3 {
                let (a, b) = if periodic[k] {
                    (lo[k], hi[k])
                } else {
                    (lo[k] + r, hi[k] - r)
                };
                if b < a {
                    return Err(Error::param(
                        "region",
                        format!("{:?}", len.as_slice()),
                        format!("wider than the largest diameter {dmax}"),
                    ));
                }
                x[k] = rng.range(a, b);
            }
            let c = cell(&x);
            let mut clash = false;
            'outer: for dz in -1i64..=1 {
                for dy in -1i64..=1 {
                    for dx in -1i64..=1 {
                        let off = [dx, dy, dz];
                        let mut cc = [0usize; 3];
                        let mut skip = false;
                        for k in 0..3 {
                            let v = c[k] as i64 + off[k];
                            let m = nb[k] as i64;
                            cc[k] = if periodic[k] {
                                v.rem_euclid(m) as usize
                            } else if v < 0 || v >= m {
                                skip = true;
                                0
                            } else {
                                v as usize
                            };
                        }
                        if skip {
                            continue;
                        }
                        for &j in &grid[(cc[2] * nb[1] + cc[1]) * nb[0] + cc[0]] {
                            let j = j as usize;
                            let rs = r + 0.5 * diameters[j];
                            if mdelta(&x, &pos[j]).norm_squared() < rs * rs {
                                clash = true;
                                break 'outer;
                            }
                        }
                    }
                }
            }
            if !clash {
                pos[i] = x;
                grid[(c[2] * nb[1] + c[1]) * nb[0] + c[0]].push(i as u32);
                ok = true;
                break;
            }
        }
        if !ok {
            return Err(Error::Configuration {
                message: format!(
                    "random insertion failed after placing {placed} of {} spheres \
                     (target phi = {phi:.3}); random sequential insertion jams near phi ~ 0.38: \
                     insert at lower phi and compress, or use a scene's preparation",
                    diameters.len()
                ),
            });
        }
    }
    Ok(pos)
}
