//! Cell lists and a Verlet pair list with a skin.
//!
//! The list is a half list in CSR form, built particle by particle after a spatial sort (particles
//! are re-ordered by cell at every build, so neighbours are close in memory). Each pair stores its
//! tangential history in list order, so the force loop streams through pairs with no lookups.
//! Histories are carried across rebuilds by the stable particle ids; a history is reset to zero
//! whenever its contact opens, so a contact that re-forms starts from zero displacement.
//!
//! Determinism: the list, the order of pairs and every reduction over them depend only on the
//! positions, never on the number of threads.

use crate::contact::Friction;
use crate::domain::Domain;
use crate::particles::Particles;
use crate::V3;
use rayon::prelude::*;
use std::collections::HashMap;

/// Particles per work unit when building; fixed so that results do not depend on thread count.
const BUILD_CHUNK: usize = 512;

#[derive(Clone, Debug)]
pub struct NeighborList<T: Friction> {
    pub skin: f64,
    /// First particle of each pair (pairs of particle i are contiguous, i ascending).
    pub pair_i: Vec<u32>,
    pub pair_j: Vec<u32>,
    /// Tangential history per pair, in list order (zero-sized without friction).
    pub hist: Vec<T::History>,
    /// own_start[i]..own_start[i+1]: pairs whose first particle is i.
    pub own_start: Vec<u32>,
    /// rev_start[j]..rev_start[j+1] index into rev_k: pairs whose second particle is j.
    pub rev_start: Vec<u32>,
    pub rev_k: Vec<u32>,
    /// Positions at the last build (for the half-skin criterion).
    pub x_build: Vec<V3>,
    pub builds: u64,
    pub valid: bool,
}

impl<T: Friction> NeighborList<T> {
    pub fn new(skin: f64) -> Self {
        NeighborList {
            skin,
            pair_i: vec![],
            pair_j: vec![],
            hist: vec![],
            own_start: vec![],
            rev_start: vec![],
            rev_k: vec![],
            x_build: vec![],
            builds: 0,
            valid: false,
        }
    }

    pub fn len(&self) -> usize {
        self.pair_i.len()
    }
    pub fn is_empty(&self) -> bool {
        self.pair_i.is_empty()
    }

    /// True if some particle moved more than half the skin since the last build.
    pub fn needs_rebuild<D: Domain>(&self, p: &Particles, dom: &D) -> bool {
        if !self.valid || self.x_build.len() != p.len() {
            return true;
        }
        let lim = 0.25 * self.skin * self.skin;
        p.x.par_iter()
            .zip(self.x_build.par_iter())
            .with_min_len(4096)
            .any(|(x, x0)| dom.delta(x, x0).norm_squared() > lim)
    }

    /// Rebuild: spatially sort particles (returns the permutation applied, new[k] = old[perm[k]]),
    /// rebuild the pair list, carry the histories of open contacts over by particle id.
    pub fn build<D: Domain>(&mut self, p: &mut Particles, dom: &D) -> Vec<usize> {
        let frictional = T::FRICTIONAL;
        let n = p.len();
        // 1. histories of contacts, keyed by stable ids, oriented from the smaller id
        let mut carried: HashMap<u64, (T::History, bool)> = HashMap::new();
        if frictional && self.valid {
            let zero = T::History::default();
            for k in 0..self.pair_i.len() {
                let h = self.hist[k];
                if h != zero {
                    let a = p.id[self.pair_i[k] as usize];
                    let b = p.id[self.pair_j[k] as usize];
                    let (key, flipped) = pair_key(a, b);
                    carried.insert(key, (h, flipped));
                }
            }
        }

        // 2. cells in fractional coordinates
        let rmax = p.max_radius();
        let cut = 2.0 * rmax + self.skin;
        let w = dom.widths();
        let per = dom.periodic();
        let mut nb = [1usize; 3];
        for k in 0..3 {
            nb[k] = ((w[k] / cut).floor() as usize).clamp(1, 1 << 10);
        }
        let ncell = nb[0] * nb[1] * nb[2];
        let cell_of = |x: &V3| -> usize {
            let s = dom.frac(x);
            let mut c = [0usize; 3];
            for k in 0..3 {
                c[k] = ((s[k] * nb[k] as f64) as usize).min(nb[k] - 1);
            }
            (c[2] * nb[1] + c[1]) * nb[0] + c[0]
        };
        let cells: Vec<u32> = p.x.par_iter().map(|x| cell_of(x) as u32).collect();

        // 3. counting sort by cell (stable) -> permutation
        let mut start = vec![0u32; ncell + 1];
        for &c in &cells {
            start[c as usize + 1] += 1;
        }
        for c in 0..ncell {
            start[c + 1] += start[c];
        }
        let mut fill = start.clone();
        let mut perm = vec![0usize; n];
        for (i, &c) in cells.iter().enumerate() {
            perm[fill[c as usize] as usize] = i;
            fill[c as usize] += 1;
        }
        let identity = perm.iter().enumerate().all(|(k, &v)| k == v);
        if !identity {
            p.permute(&perm);
        }
        let cell_sorted: Vec<u32> = perm.iter().map(|&o| cells[o]).collect();

        // 4. neighbour cells per axis and cell coordinate, de-duplicated (a periodic axis with
        // fewer than 3 cells would otherwise visit a cell twice); computed once per build.
        let tabs: Vec<Vec<([usize; 3], usize)>> = (0..3)
            .map(|k| {
                let m = nb[k] as isize;
                (0..nb[k])
                    .map(|c| {
                        let mut v = [0usize; 3];
                        let mut cnt = 0;
                        for o in -1isize..=1 {
                            let cc = c as isize + o;
                            let cc = if per[k] {
                                cc.rem_euclid(m)
                            } else if cc < 0 || cc >= m {
                                continue;
                            } else {
                                cc
                            } as usize;
                            if !v[..cnt].contains(&cc) {
                                v[cnt] = cc;
                                cnt += 1;
                            }
                        }
                        (v, cnt)
                    })
                    .collect()
            })
            .collect();
        let skin = self.skin;
        let x = &p.x;
        let rad = &p.radius;
        let start_ref = &start;
        let chunks: Vec<(Vec<u32>, Vec<u32>)> = (0..n.div_ceil(BUILD_CHUNK))
            .into_par_iter()
            .map(|ch| {
                let lo = ch * BUILD_CHUNK;
                let hi = ((ch + 1) * BUILD_CHUNK).min(n);
                let mut counts = Vec::with_capacity(hi - lo);
                let mut js = Vec::with_capacity((hi - lo) * 8);
                let mut cand: Vec<u32> = Vec::with_capacity(64);
                let tabs = &tabs;
                for i in lo..hi {
                    let c = cell_sorted[i] as usize;
                    let cx = c % nb[0];
                    let cy = (c / nb[0]) % nb[1];
                    let cz = c / (nb[0] * nb[1]);
                    cand.clear();
                    let (tz, nz) = tabs[2][cz];
                    let (ty, ny) = tabs[1][cy];
                    let (tx, nx) = tabs[0][cx];
                    for &oz in &tz[..nz] {
                        for &oy in &ty[..ny] {
                            for &ox in &tx[..nx] {
                                let cc = (oz * nb[1] + oy) * nb[0] + ox;
                                let (a, b) = (start_ref[cc] as usize, start_ref[cc + 1] as usize);
                                let xi = x[i];
                                let ri = rad[i] + skin;
                                for j in a.max(i + 1)..b.max(i + 1) {
                                    let d = dom.delta(&xi, &x[j]);
                                    let rc = ri + rad[j];
                                    if d.norm_squared() < rc * rc {
                                        cand.push(j as u32);
                                    }
                                }
                            }
                        }
                    }
                    cand.sort_unstable();
                    counts.push(cand.len() as u32);
                    js.extend_from_slice(&cand);
                }
                (counts, js)
            })
            .collect();

        // 5. CSR (exact capacities: no growth slack in the largest arrays)
        let np_total: usize = chunks.iter().map(|c| c.1.len()).sum();
        self.pair_i = Vec::with_capacity(np_total);
        self.pair_j = Vec::with_capacity(np_total);
        self.own_start.clear();
        self.own_start.reserve(n + 1);
        self.own_start.push(0);
        self.pair_i.clear();
        self.pair_j.clear();
        let mut i = 0u32;
        for (counts, js) in &chunks {
            for &c in counts {
                let s = *self.own_start.last().unwrap();
                self.own_start.push(s + c);
                self.pair_i.extend(std::iter::repeat_n(i, c as usize));
                i += 1;
            }
            self.pair_j.extend_from_slice(js);
        }
        let np = self.pair_i.len();
        // reverse index: pairs by second particle, in ascending pair order
        self.rev_start.clear();
        self.rev_start.resize(n + 1, 0);
        for &j in &self.pair_j {
            self.rev_start[j as usize + 1] += 1;
        }
        for j in 0..n {
            self.rev_start[j + 1] += self.rev_start[j];
        }
        self.rev_k = vec![0; np];
        let mut fillr = self.rev_start.clone();
        for (k, &j) in self.pair_j.iter().enumerate() {
            self.rev_k[fillr[j as usize] as usize] = k as u32;
            fillr[j as usize] += 1;
        }

        // 6. histories
        self.hist = vec![T::History::default(); np];
        if frictional && !carried.is_empty() {
            for k in 0..np {
                let a = p.id[self.pair_i[k] as usize];
                let b = p.id[self.pair_j[k] as usize];
                let (key, flipped) = pair_key(a, b);
                if let Some(&(h, was_flipped)) = carried.get(&key) {
                    self.hist[k] = if flipped == was_flipped {
                        h
                    } else {
                        T::flip(h)
                    };
                }
            }
        }
        self.x_build.clear();
        self.x_build.extend_from_slice(&p.x);
        self.builds += 1;
        self.valid = true;
        if identity {
            Vec::new()
        } else {
            perm
        }
    }
}

/// Key of an unordered pair of ids, and whether (a, b) is the reverse of the key's order.
#[inline]
pub fn pair_key(a: u32, b: u32) -> (u64, bool) {
    if a < b {
        (((a as u64) << 32) | b as u64, false)
    } else {
        (((b as u64) << 32) | a as u64, true)
    }
}
