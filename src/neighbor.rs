//! Cell lists, a Verlet pair list with a skin, and the inner list the force loop tests.
//!
//! The inner list (`NeighborList::prune`) keeps, per force-loop chunk and in list order, the
//! listed pairs within an inner skin of contact: about 3 of the 5 listed pairs per particle
//! in dense flow, for a few per cent of the list's cost every ~16 steps. Pairs left out
//! cannot touch before the next prune (the displacement bound), so the force loop finds
//! exactly the contacts of the whole list, in the same order.
//!
//! The list is a half list in CSR form, built particle by particle after a spatial sort (particles
//! are re-ordered by cell at every build, so neighbours are close in memory). Tangential
//! histories live with the engine, per contact (`crate::history`), and are carried across
//! builds by the stable particle ids.
//!
//! Determinism: the list, the order of pairs and every reduction over them depend only on the
//! positions, never on the number of threads.

use crate::domain::Domain;
use crate::particles::Particles;
use crate::{M3, V3};
use rayon::prelude::*;

/// Particles per block of the force loop (`crate::engine`, its `chunk` module): the inner list keeps the
/// offsets of its pairs per block.
pub const BLOCK: usize = 32;

/// Particles per work unit when building; fixed so that results do not depend on thread count.
const BUILD_CHUNK: usize = 512;
/// Particles per work unit of the force loop, from the number of particles alone (never from
/// the thread count): a pair whose two particles lie in the same chunk is summed in place by
/// that chunk, a pair that crosses into a later chunk goes through a buffer (`cross_*`), and
/// both orders depend only on the list, so any number of threads gives the same bits.
///
/// Chunks are as large as the 16-bit owner indices allow (4096) but at least four, a multiple
/// of four of equal size (so that 1, 2 or 4 threads get equal shares), and no smaller than
/// 256. Large chunks keep most pairs in place: at 6754 particles 4 chunks of 1689 have 0.11
/// of the pairs crossing against 0.28 with 27 chunks of 256, and run 9 % faster on one
/// thread and 5 % on two (`benchmarks/NOTES.md`).
pub fn chunk_size(n: usize) -> usize {
    let k = n.div_ceil(MAX_CHUNK).max(4).next_multiple_of(4);
    n.div_ceil(k).clamp(256, MAX_CHUNK)
}

/// Largest force-loop chunk (owners are 16-bit offsets within a chunk).
pub const MAX_CHUNK: usize = 4096;

#[derive(Clone, Debug)]
pub struct NeighborList {
    pub skin: f64,
    /// Second particle of each pair; pairs of particle i are own_start[i]..own_start[i+1]
    /// (i ascending, j > i).
    pub pair_j: Vec<u32>,
    /// Periodic image of each pair, fixed between builds (positions are wrapped only at a
    /// build): r_ij = x_i - x_j - H n with n in {-1,0,1}^3 coded as 9(n0+1) + 3(n1+1) + n2+1
    /// (see [`image_shifts`]). Replaces a minimum-image computation per pair and step.
    pub pair_img: Vec<u8>,
    /// own_start[i]..own_start[i+1]: pairs whose first particle is i.
    pub own_start: Vec<u32>,
    /// The pairs the force loop tests, per force-loop chunk: the listed pairs that were
    /// within `inner_skin` of contact at the last prune (dynamic pruning, as GROMACS's
    /// inner list). Cross slots below are numbered over these.
    pub inner: Vec<InnerChunk>,
    /// Gap below which a listed pair was kept at the last prune (infinite: every pair).
    pub inner_skin: f64,
    /// Bound on how far any particle has moved since the last prune (sum over the steps of
    /// the largest drift, plus the rounding of the positions).
    pub inner_moved: f64,
    /// Rounding allowance added to both displacement bounds (`moved`, `inner_moved`) per step.
    pub drift_eps: f64,
    pub inner_valid: bool,
    pub prunes: u64,
    /// Cross pairs of the inner list (second particle in a later chunk) are numbered in list
    /// order; chunk c owns slots cross_off[c]..cross_off[c+1].
    pub cross_off: Vec<u32>,
    /// cross_start[j]..cross_start[j+1] index into cross_slot: the cross pairs whose second
    /// particle is j, in list order.
    pub cross_start: Vec<u32>,
    pub cross_slot: Vec<u32>,
    /// The chunk that owns each entry of cross_slot (slots are numbered by chunk).
    pub cross_src: Vec<u16>,
    /// Per chunk the last chunk its cross pairs reach (itself when it has none): the fused
    /// team sweep (`crate::engine`) computes a chunk's forces only once these are packed.
    pub cross_reach: Vec<u32>,
    /// Scratch of `build_cross` (kept to avoid an allocation per prune).
    cross_fill: Vec<u32>,
    /// Bound on how far any particle has moved since the build relative to a moving frame
    /// (the largest drift speed relative to the frame's velocity `frame_v`, times dt, summed
    /// over the steps); no positions are kept. In a deforming cell the bound also counts the
    /// affine part of a pair's relative motion (`Domain::affine_rate`, see `Engine::step_once`).
    ///
    /// Why a frame: a pair's separation changes by Δ_i - Δ_j = (Δ_i - X) - (Δ_j - X) for
    /// any frame displacement X, so 2 max_k |Δ_k - X| bounds it; with X advancing by
    /// `frame_v` dt each step, |Δ_k - X| <= Σ max_k |v_k - frame_v| dt. In a flowing
    /// channel (every particle falling at 2-7 sqrt(g d)) that is 2.5-3 times smaller than
    /// the largest speed, so lists last longer and inner lists keep fewer pairs.
    pub moved: f64,
    /// The frame velocity of the current step (the middle of the last step's range of
    /// velocities, per component; any value keeps the bound valid).
    pub frame_v: [f64; 3],
    /// Positions at the last build, only in a list restored from a checkpoint of an earlier
    /// version (which judged a deforming cell's list by them): its pair images follow from
    /// them (`set_images`), and it is rebuilt at once.
    pub x_build: Vec<[f32; 3]>,
    pub builds: u64,
    pub valid: bool,
    /// Largest centre distance a listed pair had at the last build (2 R_max + skin).
    pub cut: f64,
}

impl NeighborList {
    pub fn new(skin: f64) -> Self {
        NeighborList {
            skin,
            pair_j: vec![],
            pair_img: vec![],
            own_start: vec![],
            inner: vec![],
            inner_skin: f64::INFINITY,
            inner_moved: 0.0,
            frame_v: [0.0; 3],
            drift_eps: 0.0,
            inner_valid: false,
            prunes: 0,
            cross_off: vec![],
            cross_start: vec![],
            cross_slot: vec![],
            cross_src: vec![],
            cross_reach: vec![],
            cross_fill: vec![],
            moved: 0.0,
            x_build: vec![],
            builds: 0,
            valid: false,
            cut: 0.0,
        }
    }

    pub fn len(&self) -> usize {
        self.pair_j.len()
    }
    pub fn is_empty(&self) -> bool {
        self.pair_j.is_empty()
    }
    /// List index of the pair (i, j), i < j, if listed.
    pub fn find(&self, i: usize, j: usize) -> Option<usize> {
        let (a, b) = (self.own_start[i] as usize, self.own_start[i + 1] as usize);
        self.pair_j[a..b]
            .iter()
            .position(|&x| x as usize == j)
            .map(|p| a + p)
    }

    /// First global pair index of every force-loop chunk, then the total.
    pub fn chunk_bases(&self) -> Vec<u64> {
        let ch = chunk_size(self.own_start.len().saturating_sub(1));
        let n = self.own_start.len().saturating_sub(1);
        let mut b: Vec<u64> = (0..n.div_ceil(ch))
            .map(|c| self.own_start[c * ch] as u64)
            .collect();
        b.push(self.pair_j.len() as u64);
        b
    }

    /// Pairs in the inner list.
    pub fn inner_len(&self) -> usize {
        self.inner.iter().map(|c| c.len()).sum()
    }

    /// Number of cross pairs of the inner list (buffered between chunks).
    pub fn n_cross(&self) -> usize {
        self.cross_slot.len()
    }

    /// First particle of every pair (list order), recovered from the CSR offsets.
    pub fn pair_i(&self) -> Vec<u32> {
        let mut out = Vec::with_capacity(self.len());
        for i in 0..self.own_start.len().saturating_sub(1) {
            let c = (self.own_start[i + 1] - self.own_start[i]) as usize;
            out.extend(std::iter::repeat_n(i as u32, c));
        }
        out
    }

    /// True if some particle may have moved half the skin since the last build.
    pub fn needs_rebuild(&self, p: &Particles) -> bool {
        !self.valid || self.own_start.len() != p.len() + 1 || self.moved_out()
    }

    /// Plain NVE: the bound on the displacements since the build reached half the skin.
    #[inline]
    pub fn moved_out(&self) -> bool {
        self.out_of_skin(self.moved)
    }

    /// Whether a displacement bound `moved` reaches half the skin (a copy of the bound kept
    /// outside the list, as a step team keeps one per thread, is judged the same way).
    #[inline]
    pub fn out_of_skin(&self, moved: f64) -> bool {
        2.0 * moved >= self.skin
    }

    /// What one step adds to the displacement bounds: its largest speed relative to
    /// `frame_v` times dt, plus the rounding of the positions.
    #[inline]
    pub fn step_drift(&self, vmax: f64, dt: f64) -> f64 {
        vmax * dt + self.drift_eps
    }

    /// Add one step's drift (`step_drift`) to the displacement bounds of the list and of the
    /// inner list.
    #[inline]
    pub fn add_drift(&mut self, vmax: f64, dt: f64) {
        let d = self.step_drift(vmax, dt);
        self.moved += d;
        self.inner_moved += d;
    }

    /// Rebuild: spatially sort particles (along a Morton curve of cells) and rebuild the pair
    /// list. The engine carries the contact histories over by particle id. Returns the
    /// permutation applied to the particles (new index -> old), if not the identity.
    pub fn build<D: Domain>(&mut self, p: &mut Particles, dom: &D) -> Option<Vec<usize>> {
        let n = p.len();
        // 2. cells in fractional coordinates
        let rmax = p.max_radius();
        let cut = 2.0 * rmax + self.skin;
        self.cut = cut;
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
        // Cells are visited in Morton (Z-curve) order: a run of consecutive particles (a
        // force-loop chunk) is then a compact blob, so few of its pairs reach into another
        // chunk and neighbours sit close in memory at any system size.
        let rank_of = morton_ranks(nb);

        // 3. counting sort by cell rank (stable) -> permutation
        let mut start = vec![0u32; ncell + 1];
        for &c in &cells {
            start[rank_of[c as usize] as usize + 1] += 1;
        }
        for c in 0..ncell {
            start[c + 1] += start[c];
        }
        let mut fill = start.clone();
        let mut perm = vec![0usize; n];
        for (i, &c) in cells.iter().enumerate() {
            let r = rank_of[c as usize] as usize;
            perm[fill[r] as usize] = i;
            fill[r] += 1;
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
        let hinv = dom.h().try_inverse().unwrap_or_else(M3::zeros);
        let chunks: Vec<(Vec<u32>, Vec<u32>, Vec<u8>)> = (0..n.div_ceil(BUILD_CHUNK))
            .into_par_iter()
            .map(|ch| {
                let lo = ch * BUILD_CHUNK;
                let hi = ((ch + 1) * BUILD_CHUNK).min(n);
                let mut counts = Vec::with_capacity(hi - lo);
                let mut js = Vec::with_capacity((hi - lo) * 8);
                let mut imgs = Vec::with_capacity((hi - lo) * 8);
                // particle ranges of the neighbour cells after the current one along the
                // curve (j > i), in curve order and merged where contiguous: the partners
                // come out sorted
                let mut runs: Vec<(usize, usize)> = Vec::with_capacity(27);
                let mut ranks: Vec<usize> = Vec::with_capacity(27);
                let mut cur = usize::MAX;
                let tabs = &tabs;
                for i in lo..hi {
                    let c = cell_sorted[i] as usize;
                    let own = rank_of[c] as usize;
                    if c != cur {
                        cur = c;
                        let (cx, cy, cz) = (c % nb[0], (c / nb[0]) % nb[1], c / (nb[0] * nb[1]));
                        let (tz, nz) = tabs[2][cz];
                        let (ty, ny) = tabs[1][cy];
                        let (tx, nx) = tabs[0][cx];
                        ranks.clear();
                        for &oz in &tz[..nz] {
                            for &oy in &ty[..ny] {
                                for &ox in &tx[..nx] {
                                    let r = rank_of[(oz * nb[1] + oy) * nb[0] + ox] as usize;
                                    if r > own {
                                        ranks.push(r);
                                    }
                                }
                            }
                        }
                        ranks.sort_unstable();
                        runs.clear();
                        for &r in &ranks {
                            let (a, b) = (start_ref[r] as usize, start_ref[r + 1] as usize);
                            match runs.last_mut() {
                                Some(last) if last.1 == a => last.1 = b,
                                _ if a < b => runs.push((a, b)),
                                _ => {}
                            }
                        }
                    }
                    let xi = x[i];
                    let ri = rad[i] + skin;
                    let before = js.len();
                    let own_run = (i + 1, start_ref[own + 1] as usize);
                    for &(a, b) in std::iter::once(&own_run).chain(&runs) {
                        for j in a..b {
                            let d = dom.delta(&xi, &x[j]);
                            let rc = ri + rad[j];
                            if d.norm_squared() < rc * rc {
                                js.push(j as u32);
                                imgs.push(image_code(&hinv, &((xi - x[j]) - d)));
                            }
                        }
                    }
                    counts.push((js.len() - before) as u32);
                }
                (counts, js, imgs)
            })
            .collect();

        // 5. CSR (exact capacities: no growth slack in the largest arrays)
        let np_total: usize = chunks.iter().map(|c| c.1.len()).sum();
        self.pair_j = Vec::with_capacity(np_total);
        self.pair_img = Vec::with_capacity(np_total);
        self.own_start.clear();
        self.own_start.reserve(n + 1);
        self.own_start.push(0);
        for (counts, js, imgs) in &chunks {
            for &c in counts {
                let s = *self.own_start.last().unwrap();
                self.own_start.push(s + c);
            }
            self.pair_j.extend_from_slice(js);
            self.pair_img.extend_from_slice(imgs);
        }
        self.inner_valid = false;

        let xmax = p.x.iter().map(|x| x.amax()).fold(0.0f64, f64::max);
        self.moved = 0.0;
        // (kept only by lists restored from checkpoints of earlier versions)
        self.x_build = Vec::new();
        // a drift x + v dt rounds by at most half an ulp per coordinate; positions stay
        // within half a skin of where they were wrapped until the next build
        self.drift_eps = 4.0 * f64::EPSILON * (1.0 + xmax + self.skin);
        if !D::PLAIN_NVE {
            // a deforming cell's drift x' = (1 + dt L) x + dt v and image shifts H n round
            // by a few ulps of |H| (which the list's bound lets grow by well under 2x)
            self.drift_eps += 16.0 * f64::EPSILON * (2.0 * dom.h().norm() + cut);
        }
        self.builds += 1;
        self.valid = true;
        (!identity).then_some(perm)
    }

    /// Image code of every pair from the positions at the build (`x_build` on a restart).
    pub fn set_images<D: Domain>(&mut self, x: &[V3], dom: &D, hinv: &M3) {
        let n = x.len();
        let mut img = vec![0u8; self.pair_j.len()];
        for i in 0..n {
            let (a, b) = (self.own_start[i] as usize, self.own_start[i + 1] as usize);
            for (slot, &j) in img[a..b].iter_mut().zip(&self.pair_j[a..b]) {
                let j = j as usize;
                let shift = (x[i] - x[j]) - dom.delta(&x[i], &x[j]);
                *slot = image_code(hinv, &shift);
            }
        }
        self.pair_img = img;
    }

    /// True if the inner list may have lost a pair that is now within contact: some
    /// particle may have moved half the inner skin since the prune.
    pub fn prune_due(&self) -> bool {
        self.prune_due_at(self.inner_moved)
    }

    /// `prune_due` for an inner bound `inner_moved` kept outside the list.
    #[inline]
    pub fn prune_due_at(&self, inner_moved: f64) -> bool {
        !self.inner_valid || 2.0 * inner_moved >= self.inner_skin
    }

    /// Keep, per force-loop chunk and in list order, the listed pairs with a gap below
    /// `inner_skin` (positions from the packed (x, R) records; `shifts` by image code), then
    /// number the cross pairs. Between prunes every pair that can touch is kept as long as
    /// no particle moved `inner_skin / 2` (`prune_due`), so the force loop sees exactly the
    /// contacts, in the same order, as over the whole list: pruning changes no result.
    pub fn prune(&mut self, xr: &[[f64; 4]], shifts: &[[f64; 4]; 27], inner_skin: f64) {
        let n = self.own_start.len().saturating_sub(1);
        let ch = chunk_size(n);
        let nchunks = n.div_ceil(ch);
        self.inner.resize_with(nchunks, InnerChunk::default);
        let (own_start, pair_j, pair_img) = (&self.own_start, &self.pair_j, &self.pair_img);
        self.inner.par_iter_mut().enumerate().for_each(|(c, ic)| {
            prune_chunk(ic, c, own_start, pair_j, pair_img, xr, shifts, inner_skin);
        });
        self.prune_finish(inner_skin);
    }

    /// `prune`'s per-chunk part for chunk `c`, for a team of threads that prunes its chunks
    /// in place (`prune_finish` then runs once). The inner list must already have its
    /// chunks (a first `prune` made them).
    ///
    /// # Safety
    /// `this` points to a live list; no other thread works on chunk `c` meanwhile, and none
    /// writes the list's other fields until every chunk is done.
    pub(crate) unsafe fn prune_part(
        this: *mut NeighborList,
        c: usize,
        xr: &[[f64; 4]],
        shifts: &[[f64; 4]; 27],
        inner_skin: f64,
    ) {
        // SAFETY (caller): shared views of fields no one writes, and chunk c alone
        unsafe {
            let nl = &*this;
            assert!(c < nl.inner.len());
            // (`as_ptr` takes no reference to the other chunks)
            let ic = &mut *(nl.inner.as_ptr() as *mut InnerChunk).add(c);
            prune_chunk(
                ic,
                c,
                &nl.own_start,
                &nl.pair_j,
                &nl.pair_img,
                xr,
                shifts,
                inner_skin,
            );
        }
    }

    /// The serial end of a prune: number the cross pairs, set the inner bound.
    pub(crate) fn prune_finish(&mut self, inner_skin: f64) {
        let n = self.own_start.len().saturating_sub(1);
        self.build_cross(n);
        self.inner_skin = inner_skin;
        self.inner_moved = 0.0;
        self.inner_valid = true;
        self.prunes += 1;
    }

    /// Number the inner list's cross pairs and index them by second particle.
    fn build_cross(&mut self, n: usize) {
        let ch = chunk_size(n);
        let nchunks = n.div_ceil(ch);
        self.cross_off.clear();
        self.cross_off.reserve(nchunks + 1);
        let mut total = 0u32;
        for ic in &self.inner {
            self.cross_off.push(total);
            total += ic.xj.len() as u32;
        }
        self.cross_off.push(total);
        self.cross_start.clear();
        self.cross_start.resize(n + 1, 0);
        for ic in &self.inner {
            for &j in &ic.xj {
                self.cross_start[j as usize + 1] += 1;
            }
        }
        for j in 0..n {
            self.cross_start[j + 1] += self.cross_start[j];
        }
        assert!(
            nchunks <= u16::MAX as usize + 1,
            "too many force-loop chunks"
        );
        self.cross_slot.clear();
        self.cross_slot.resize(total as usize, 0);
        self.cross_src.clear();
        self.cross_src.resize(total as usize, 0);
        // where the next cross pair of each second particle goes (kept between prunes)
        let mut fill = std::mem::take(&mut self.cross_fill);
        fill.clear();
        fill.extend_from_slice(&self.cross_start[..n]);
        self.cross_reach.clear();
        for (c, ic) in self.inner.iter().enumerate() {
            let slots = self.cross_off[c]..;
            let mut reach = c;
            for (s, &j) in slots.zip(&ic.xj) {
                let f = &mut fill[j as usize];
                self.cross_slot[*f as usize] = s;
                self.cross_src[*f as usize] = c as u16;
                *f += 1;
                reach = reach.max(j as usize / ch);
            }
            self.cross_reach.push(reach as u32);
        }
        self.cross_fill = fill;
    }
}

/// The inner list of the chunk of particles i0..i1: every pair is written at the next free
/// place, which advances only for a kept pair (no branch on the unpredictable test).
#[allow(
    clippy::too_many_arguments,
    reason = "one chunk's inner list from the list's separate arrays (borrowed apart for the parallel prune)"
)]
fn prune_chunk(
    ic: &mut InnerChunk,
    c: usize,
    own_start: &[u32],
    pair_j: &[u32],
    pair_img: &[u8],
    xr: &[[f64; 4]],
    shifts: &[[f64; 4]; 27],
    inner_skin: f64,
) {
    let n = own_start.len() - 1;
    let ch = chunk_size(n);
    let (i0, i1) = (c * ch, ((c + 1) * ch).min(n));
    let (kb, ke) = (own_start[i0] as usize, own_start[i1] as usize);
    let m = ke - kb;
    ic.base = kb as u32;
    ic.span = m as u32;
    ic.block.clear();
    if inner_skin == f64::INFINITY {
        // every pair kept: nothing stored per pair (the force loop reads the full list)
        ic.dense = true;
        ic.key = Vec::new();
        ic.own = Vec::new();
        ic.block.extend(
            (i0..i1)
                .step_by(BLOCK)
                .chain(std::iter::once(i1))
                .map(|i| own_start[i] - kb as u32),
        );
        ic.xj.clear();
        ic.xj
            .extend(pair_j[kb..ke].iter().filter(|&&j| j as usize >= i1));
        return;
    }
    ic.dense = false;
    PRUNE_SCRATCH.with(|cell| {
        let (sk, so, sx) = &mut *cell.borrow_mut();
        // room for every pair; the kept ones are copied out at the end, so the chunk's
        // lists hold no more than they keep
        if sk.len() < m {
            sk.resize(m, 0);
            so.resize(m, 0);
            sx.resize(m, 0);
        }
        let (pj, pi) = (&pair_j[kb..ke], &pair_img[kb..ke]);
        let (keys, owns, xjs) = (&mut sk[..m], &mut so[..m], &mut sx[..m]);
        let mut len = 0usize;
        let mut ncross = 0usize;
        for i in i0..i1 {
            if (i - i0).is_multiple_of(BLOCK) {
                ic.block.push(len as u32);
            }
            let [xi0, xi1, xi2, ri] = xr[i];
            let (k0, k1) = (own_start[i] as usize - kb, own_start[i + 1] as usize - kb);
            assert!(k0 <= k1 && k1 <= m);
            for k in k0..k1 {
                // SAFETY: k < m, the length of pj, pi, keys and owns; list partners are < n (the
                // list is built from 0..n, checked in debug builds); image codes < 27
                let (j, img) = unsafe { (*pj.get_unchecked(k), *pi.get_unchecked(k)) };
                debug_assert!((j as usize) < xr.len() && img < 27);
                let [xj0, xj1, xj2, rj] = unsafe { *xr.get_unchecked(j as usize) };
                let sh = unsafe { shifts.get_unchecked(img as usize) };
                let (dx, dy, dz) = (xi0 - xj0 - sh[0], xi1 - xj1 - sh[1], xi2 - xj2 - sh[2]);
                let r2 = dx * dx + dy * dy + dz * dz;
                let cut = ri + rj + inner_skin;
                // a NaN distance is kept: the force loop reports it as a contact
                #[allow(
                    clippy::neg_cmp_op_on_partial_ord,
                    reason = "!(a >= b) keeps a NaN distance on purpose"
                )]
                let keep = !(r2 >= cut * cut);
                // written at the next free place (len <= k < m), kept by advancing it
                // (and a cross partner at the next free place of its own list, ncross <= len)
                unsafe {
                    *keys.get_unchecked_mut(len) = k as u32;
                    *owns.get_unchecked_mut(len) = (i - i0) as u16;
                    *xjs.get_unchecked_mut(ncross) = j;
                }
                len += keep as usize;
                ncross += (keep && j as usize >= i1) as usize;
            }
        }
        ic.block.push(len as u32);
        ic.key.clear();
        ic.key.reserve_exact(len);
        ic.key.extend_from_slice(&keys[..len]);
        ic.own.clear();
        ic.own.reserve_exact(len);
        ic.own.extend_from_slice(&owns[..len]);
        ic.xj.clear();
        ic.xj.extend_from_slice(&xjs[..ncross]);
    });
}

thread_local! {
    /// Keys, owners and cross partners of a chunk's pairs while pruning.
    #[allow(clippy::type_complexity, reason = "three scratch vectors, named by the doc above")]
    static PRUNE_SCRATCH: std::cell::RefCell<(Vec<u32>, Vec<u16>, Vec<u32>)> =
        const { std::cell::RefCell::new((Vec::new(), Vec::new(), Vec::new())) };
}

/// One force-loop chunk's part of the inner list (see `NeighborList::prune`).
#[derive(Clone, Debug, Default)]
pub struct InnerChunk {
    /// block[b]..block[b + 1]: the pairs of the chunk's particles b BLOCK .. (b + 1) BLOCK
    /// (a block of the force loop).
    pub block: Vec<u32>,
    /// Each pair's index in the full list counted from the chunk's first pair (`base`): its
    /// second particle and image code are read there, and it is the key of its history.
    pub key: Vec<u32>,
    pub base: u32,
    /// The chunk's pairs in the full list: every key is below it.
    pub span: u32,
    /// First particle of each pair, counted from the chunk's first particle (chunks hold at
    /// most 4096 particles).
    pub own: Vec<u16>,
    /// Second particles of the pairs that reach into a later chunk (cross pairs), in list
    /// order (numbering the cross pairs at a prune reads these instead of walking every
    /// kept pair again).
    pub xj: Vec<u32>,
    /// Every pair of the chunk kept (no pruning: an infinite inner skin): `key` and `own`
    /// stay empty, the keys are 0..span and the owners follow from the list's offsets.
    pub dense: bool,
}

impl InnerChunk {
    /// Number of pairs kept.
    pub fn len(&self) -> usize {
        if self.dense {
            self.span as usize
        } else {
            self.key.len()
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Second particle of each pair.
    pub fn partners<'a>(&'a self, pair_j: &'a [u32]) -> impl Iterator<Item = u32> + 'a {
        let pj = &pair_j[self.base as usize..];
        (0..self.len()).map(move |q| {
            let k = if self.dense { q } else { self.key[q] as usize };
            pj[k]
        })
    }

    pub fn bytes(&self) -> usize {
        self.block.capacity() * 4
            + self.key.capacity() * 4
            + self.own.capacity() * 2
            + self.xj.capacity() * 4
    }
}

/// Image code (see `NeighborList::pair_img`) of a lattice shift H n.
#[inline]
fn image_code(hinv: &M3, shift: &V3) -> u8 {
    let s = hinv * shift;
    let c = |a: f64| (a.round().clamp(-1.0, 1.0) + 1.0) as u8;
    9 * c(s[0]) + 3 * c(s[1]) + c(s[2])
}

/// A stored single-precision position as a vector.
#[inline(always)]
pub fn widen(x: &[f32; 3]) -> V3 {
    V3::new(x[0] as f64, x[1] as f64, x[2] as f64)
}

/// Rank of every cell (linear index (z nb_y + y) nb_x + x) along the Morton curve.
fn morton_ranks(nb: [usize; 3]) -> Vec<u32> {
    fn spread(v: usize) -> u64 {
        // bits of v (< 2^10) to every third bit
        let mut x = v as u64 & 0x3ff;
        x = (x | (x << 16)) & 0x0300_00ff;
        x = (x | (x << 8)) & 0x0300_f00f;
        x = (x | (x << 4)) & 0x030c_30c3;
        (x | (x << 2)) & 0x0924_9249
    }
    let ncell = nb[0] * nb[1] * nb[2];
    let mut codes: Vec<(u64, u32)> = (0..ncell)
        .map(|c| {
            let (x, y, z) = (c % nb[0], (c / nb[0]) % nb[1], c / (nb[0] * nb[1]));
            (spread(x) | spread(y) << 1 | spread(z) << 2, c as u32)
        })
        .collect();
    codes.sort_unstable();
    let mut rank = vec![0u32; ncell];
    for (r, &(_, c)) in codes.iter().enumerate() {
        rank[c as usize] = r as u32;
    }
    rank
}

/// The 27 lattice shifts H n indexed by image code (see `pair_img`), padded to 4 doubles as
/// the force loop loads them.
pub fn image_shifts(h: &M3) -> [[f64; 4]; 27] {
    let mut t = [[0.0; 4]; 27];
    for (c, v) in t.iter_mut().enumerate() {
        let n = V3::new(
            (c / 9) as f64 - 1.0,
            ((c / 3) % 3) as f64 - 1.0,
            (c % 3) as f64 - 1.0,
        );
        let s = h * n;
        *v = [s.x, s.y, s.z, 0.0];
    }
    t
}
