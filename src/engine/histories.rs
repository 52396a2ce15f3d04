//! Tangential histories carried by particle ids: visited, read out for a checkpoint and
//! placed back into the current pair list and particle order after a build or a restart.

use super::{Body, Engine, Walls};
use crate::components::MAX_WALLS;
use crate::contact::{Form, Friction};
use crate::domain::Domain;
use crate::neighbor::chunk_size;

impl<F: Form, T: Friction, D: Domain, W: Walls<F, T>, G: Body> Engine<F, T, D, W, G> {
    /// Visit every stored history: `pair(i, j, h)` for pair contacts (internal indices, as
    /// listed), `wall(i, w, h)` for wall contacts. Nothing without friction or a list.
    pub fn for_each_history(
        &self,
        mut pair: impl FnMut(usize, usize, &T::History),
        mut wall: impl FnMut(usize, usize, &T::History),
    ) {
        if !T::FRICTIONAL || !self.nl.valid {
            return;
        }
        let nl = &self.nl;
        let n = self.p.len();
        let ch = chunk_size(n);
        for (c, list) in self.hist.iter().enumerate().take(n.div_ceil(ch)) {
            let base = nl.own_start[c * ch] as usize;
            let mut i = c * ch;
            for (&kk, h) in list.keys.iter().zip(&list.vals) {
                let k = base + kk as usize;
                while nl.own_start[i + 1] as usize <= k {
                    i += 1;
                }
                pair(i, nl.pair_j[k] as usize, h);
            }
        }
        for (c, list) in self.whist.iter().enumerate() {
            for (&key, h) in list.keys.iter().zip(&list.vals) {
                let i = c * ch + key as usize / MAX_WALLS;
                if i < n {
                    wall(i, key as usize % MAX_WALLS, h);
                }
            }
        }
    }

    /// Every stored history with the ids of its particles: pairs (id_i, id_j, h) oriented as
    /// listed, walls (id, wall, h).
    #[allow(
        clippy::type_complexity,
        reason = "(pair histories, wall histories) as the checkpoint stores them"
    )]
    pub fn carried_histories(&self) -> (Vec<(u32, u32, T::History)>, Vec<(u32, u8, T::History)>) {
        let mut pairs = Vec::new();
        let mut walls = Vec::new();
        let id = &self.p.id;
        self.for_each_history(
            |i, j, h| pairs.push((id[i], id[j], *h)),
            |i, w, h| walls.push((id[i], w as u8, *h)),
        );
        (pairs, walls)
    }

    /// Place histories given by particle ids into the current pair list and particle order
    /// (after a build or a restart). A pair no longer listed loses its history.
    pub fn set_histories(
        &mut self,
        pairs: &[(u32, u32, T::History)],
        walls: &[(u32, u8, T::History)],
    ) {
        let ch = chunk_size(self.p.len());
        let n = self.p.len();
        let nchunks = n.div_ceil(ch);
        let nl = &self.nl;
        let mut inv = vec![0usize; n];
        for (i, &id) in self.p.id.iter().enumerate() {
            inv[id as usize] = i;
        }
        let mut pe: Vec<(u64, T::History)> = Vec::with_capacity(pairs.len());
        for &(a, b, h) in pairs {
            let (ia, ib) = (inv[a as usize], inv[b as usize]);
            let (lo, hi, h) = if ia < ib {
                (ia, ib, h)
            } else {
                (ib, ia, T::flip(h))
            };
            if let Some(k) = nl.find(lo, hi) {
                pe.push((k as u64, h));
            }
        }
        pe.sort_unstable_by_key(|e| e.0);
        self.hist = crate::history::distribute(&pe, &nl.chunk_bases());
        let mut we: Vec<(u64, T::History)> = walls
            .iter()
            .map(|&(id, w, h)| ((inv[id as usize] * MAX_WALLS + w as usize) as u64, h))
            .collect();
        we.sort_unstable_by_key(|e| e.0);
        let wb: Vec<u64> = (0..=nchunks)
            .map(|c| ((c * ch).min(n) * MAX_WALLS) as u64)
            .collect();
        self.whist = crate::history::distribute(&we, &wb);
        self.size_buffers();
    }

    /// Every stored pair history (for tests and diagnostics).
    pub fn pair_histories(&self) -> Vec<T::History> {
        self.hist
            .iter()
            .flat_map(|l| l.vals.iter().copied())
            .collect()
    }
}
