//! Tangential histories stored per contact, not per listed pair.
//!
//! A force-loop chunk keeps the histories of the contacts that were closed at its last
//! evaluation as a list sorted by a key that grows along its sweep (the pair's index within the
//! chunk, or particle x MAX_WALLS + wall for wall contacts). The next sweep merges through the
//! old list with a cursor and writes a new one: a contact that is closed finds its history (or
//! starts from zero), a contact that opened is simply not carried, so the list never holds
//! open pairs and the loop never touches a pair that is not in contact. Memory is proportional
//! to the number of contacts (about one per particle in dense flow) instead of the number of
//! listed pairs (about five).

/// Histories of one chunk, sorted by key.
#[derive(Clone, Debug, Default)]
pub struct HistList<H> {
    pub keys: Vec<u32>,
    pub vals: Vec<H>,
}

impl<H: Copy + Default> HistList<H> {
    pub fn len(&self) -> usize {
        self.keys.len()
    }
    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }
    pub fn clear(&mut self) {
        self.keys.clear();
        self.vals.clear();
    }
    #[inline(always)]
    pub fn push(&mut self, key: u32, h: H) {
        self.keys.push(key);
        self.vals.push(h);
    }
    /// History for `key` by binary search (outside the force loop).
    pub fn get(&self, key: u32) -> H {
        match self.keys.binary_search(&key) {
            Ok(p) => self.vals[p],
            Err(_) => H::default(),
        }
    }
    pub fn bytes(&self) -> usize {
        self.keys.capacity() * 4 + self.vals.capacity() * std::mem::size_of::<H>()
    }
}

/// Merge cursor over an old list: keys must be asked for in increasing order.
pub struct Cursor<'a, H> {
    list: &'a HistList<H>,
    pos: usize,
}

impl<'a, H: Copy + Default> Cursor<'a, H> {
    pub fn new(list: &'a HistList<H>) -> Self {
        Cursor { list, pos: 0 }
    }
    /// The stored history of `key`, or zero if it was not in contact.
    #[inline(always)]
    pub fn take(&mut self, key: u32) -> H {
        let keys = &self.list.keys;
        while self.pos < keys.len() && keys[self.pos] < key {
            self.pos += 1;
        }
        if self.pos < keys.len() && keys[self.pos] == key {
            self.pos += 1;
            self.list.vals[self.pos - 1]
        } else {
            H::default()
        }
    }
}

/// Split entries with global keys (sorted) into per-chunk lists, given each chunk's first
/// global key (`bases`, ascending, with the total as the last element).
pub fn distribute<H: Copy + Default>(entries: &[(u64, H)], bases: &[u64]) -> Vec<HistList<H>> {
    let nchunks = bases.len().saturating_sub(1);
    let mut out: Vec<HistList<H>> = (0..nchunks).map(|_| HistList::default()).collect();
    let mut c = 0usize;
    for &(k, h) in entries {
        while c + 1 < nchunks && k >= bases[c + 1] {
            c += 1;
        }
        if c < nchunks && k >= bases[c] && k < bases[c + 1] {
            out[c].push((k - bases[c]) as u32, h);
        }
    }
    out
}
