//! Samplers: statistics computed inside the step loop, as LAMMPS `fix ave/chunk` does.
//!
//! A scene configures its samplers when it is built ([`make`], the one registry of sampler
//! kinds). The engine runs each on its trigger (every `every` steps, at steps that are
//! multiples of it): it asks that step's force evaluation for the contact records and
//! per-particle sums a sampler reads ([`SampleView`]), then hands the sampler the state after
//! the step. A sampler accumulates window sums and closes a window into a [`Table`] (one Arrow
//! record batch in the bindings); closed tables wait in the sampler until the front end takes
//! them, and at most one window is open per sampler. Its open window rides in checkpoints
//! ([`Sampler::save`]), so a run resumed mid-window gives the same bits.
//!
//! An engine without samplers steps exactly as before: the trigger check is one comparison
//! per `run` stretch.

use crate::error::{Error, Result};
use crate::particles::Particles;
use crate::table::{Column, Table};
use crate::{M3, V3};

pub mod cell;
pub mod cell_obs;
pub mod channel;

/// `ContactRec::j` of a wall contact.
pub const WALL: u32 = u32::MAX;

/// One contact of a force evaluation with statistics: particles `i`, `j` (internal indices;
/// `j = WALL` for a wall contact), the branch vector `d` (pairs: r_ij = x_i - x_j with the
/// pair's periodic image; walls: from the contact point to the centre), the force on `i` and
/// the contact's power f . v_rel (negative when dissipating; pairs: shared half and half).
#[derive(Clone, Copy, Debug, Default)]
pub struct ContactRec {
    pub i: u32,
    pub j: u32,
    pub d: V3,
    pub f: V3,
    pub power: f64,
}

/// What a sampler reads after a step whose force evaluation kept statistics.
pub struct SampleView<'a> {
    pub step: u64,
    pub time: f64,
    /// The particles after the step (internal order; velocities full-step).
    pub p: &'a Particles,
    /// The contacts of the step's evaluation, per force-loop chunk, in list order.
    pub contacts: &'a [Vec<ContactRec>],
    /// Contacts counted by the evaluation and its largest overlap / mean diameter.
    pub n_contacts: usize,
    pub max_overlap: f64,
    /// Force exerted by the particles on each wall, and its time integral since the start.
    pub wall_force: &'a [V3],
    pub wall_impulse: &'a [V3],
    /// Cell matrix (columns = cell vectors) and the box widths.
    pub h: M3,
    pub widths: [f64; 3],
    /// The domain's named observables (a deforming cell's L, stresses and tilt flips).
    pub observables: Vec<(String, f64)>,
    /// The elastic energy stored in the contacts, when a due sampler asked for it.
    pub elastic: Option<f64>,
}

impl SampleView<'_> {
    /// A domain observable by name (0 when the domain has none of that name).
    pub fn observable(&self, name: &str) -> f64 {
        self.observables
            .iter()
            .find(|o| o.0 == name)
            .map_or(0.0, |o| o.1)
    }
    /// The nine components `prefix_xx` .. `prefix_zz` as a tensor.
    pub fn tensor(&self, prefix: &str) -> M3 {
        const AX: [&str; 3] = ["x", "y", "z"];
        M3::from_fn(|a, b| self.observable(&format!("{prefix}_{}{}", AX[a], AX[b])))
    }
}

/// One force-loop chunk of a sampled step: its particles `r`, everyone's positions, radii,
/// masses and inverse moments of inertia, the chunk's own velocities and spins (indexed from `r.start`), and its contact
/// records. The team of threads hands it to [`Sampler::chunk_part`] right after completing the
/// chunk, while its particles are in cache and the other chunks are still being completed.
pub struct ChunkView<'a> {
    pub r: std::ops::Range<usize>,
    pub x: &'a [V3],
    pub radius: &'a [f64],
    pub mass: &'a [f64],
    pub inv_inertia: &'a [f64],
    pub v: &'a [V3],
    pub omega: &'a [V3],
    pub recs: &'a [ContactRec],
}

impl<'a> ChunkView<'a> {
    /// Chunk `r` of the particles `p`, with its records `recs`.
    pub fn of(p: &'a Particles, r: std::ops::Range<usize>, recs: &'a [ContactRec]) -> Self {
        ChunkView {
            v: &p.v[r.clone()],
            omega: &p.omega[r.clone()],
            r,
            x: &p.x,
            radius: &p.radius,
            mass: &p.mass,
            inv_inertia: &p.inv_inertia,
            recs,
        }
    }
}

/// A sample's per-chunk parts in chunk order: those the team made (`given`, when it made one
/// for every chunk), else `part` of each force-loop chunk of the view's particles with that
/// chunk's contact records, computed here in parallel. Either way each chunk is summed apart
/// and the caller adds them in chunk order: the bits do not depend on the thread count or on
/// who summed a chunk.
pub(crate) fn chunk_parts(
    given: Vec<Vec<f64>>,
    v: &SampleView,
    part: impl Fn(&ChunkView) -> Vec<f64> + Sync,
) -> Vec<Vec<f64>> {
    use rayon::prelude::*;
    let n = v.p.len();
    let ch = crate::neighbor::chunk_size(n);
    let nch = n.div_ceil(ch);
    if given.len() == nch {
        return given;
    }
    (0..nch)
        .into_par_iter()
        .map(|c| {
            let recs = v.contacts.get(c).map_or(&[][..], |x| &x[..]);
            part(&ChunkView::of(v.p, c * ch..((c + 1) * ch).min(n), recs))
        })
        .collect()
}

/// What a sampler kind is configured with (the bindings check types; [`make`] checks values).
#[derive(Clone, Debug, Default)]
pub struct SamplerSpec {
    /// Sample every this many steps (at multiples of it in the step count).
    pub every: u64,
    /// Samples per window (window kinds; a series hands its rows over in batches of it).
    pub window: u64,
    /// Bin edges across the channel (channel bins).
    pub edges: Vec<f64>,
    /// The columns to output (None: all); each must be one of the kind's.
    pub columns: Option<Vec<String>>,
}

/// The state a sampler is set up against (its first sample may come much later).
pub struct Setup<'a> {
    pub p: &'a Particles,
    pub h: M3,
    pub widths: [f64; 3],
    pub periodic: [bool; 3],
    pub walls: usize,
}

pub trait Sampler: Send + Sync {
    /// The kind's name in the registry.
    fn kind(&self) -> &'static str;
    /// The name of the table it writes ("bins", "series").
    fn table(&self) -> &'static str;
    fn every(&self) -> u64;
    /// Every column it outputs, in order.
    fn columns(&self) -> Vec<&'static str>;
    /// Whether it reads the step's contacts (then the sampled step keeps them).
    fn needs_contacts(&self) -> bool {
        true
    }
    /// Whether it reads the elastic energy (a sum over the contacts, computed for it).
    fn needs_elastic(&self) -> bool {
        false
    }
    /// Take one sample of the state after a step.
    fn sample(&mut self, v: &SampleView) -> Result<()>;
    /// Its sums over one force-loop chunk of a sampled step (None: it has no such part), made
    /// by the team's thread that completed the chunk; the engine hands them back in chunk
    /// order through `set_parts` before the `sample` that uses them. They must be what that
    /// `sample` would compute itself, bit for bit (it does when given none).
    fn chunk_part(&self, _c: &ChunkView) -> Option<Vec<f64>> {
        None
    }
    /// The parts of the coming sample, one per chunk in chunk order.
    fn set_parts(&mut self, _parts: Vec<Vec<f64>>) {}
    /// The tables closed since the last call (all columns), oldest first.
    fn take(&mut self) -> Vec<Table>;
    /// The open window (and anything not yet taken), for a checkpoint.
    fn save(&self) -> Vec<f64>;
    /// Restore what `save` wrote.
    fn load(&mut self, s: &[f64]) -> Result<()>;
    /// Bytes held: the open window and what waits to be taken.
    fn bytes(&self) -> usize;
}

/// Bytes held by a table's columns.
pub(crate) fn table_bytes(t: &Table) -> usize {
    t.columns.iter().map(|c| 8 * c.2.len()).sum()
}

/// The sampler kinds, for error messages.
pub const KINDS: [&str; 4] = ["channel_bins", "channel_series", "cell_series", "series"];

/// Make a sampler of `kind` (one of [`KINDS`]).
pub fn make(kind: &str, spec: SamplerSpec, setup: &Setup) -> Result<Box<dyn Sampler>> {
    if spec.every < 1 {
        return Err(Error::param(
            format!("{kind}.every"),
            spec.every,
            "an integer >= 1 (steps between samples)",
        ));
    }
    let columns = spec.columns.clone();
    let s: Box<dyn Sampler> = match kind {
        "channel_bins" => Box::new(channel::Bins::new(&spec, setup)?),
        "channel_series" => Box::new(channel::Series::new(&spec, setup)?),
        "cell_series" => Box::new(cell::Series::new(&spec, setup)?),
        "series" => Box::new(Energies::new(&spec)),
        _ => {
            return Err(Error::param(
                "sampler",
                kind,
                format!("one of {}", KINDS.join(", ")),
            ))
        }
    };
    match columns {
        None => Ok(s),
        Some(cols) => {
            let all = s.columns();
            if let Some(bad) = cols.iter().find(|c| !all.contains(&c.as_str())) {
                return Err(Error::param(
                    format!("{kind}.columns"),
                    bad,
                    format!("names from {}", all.join(", ")),
                ));
            }
            Ok(Box::new(Select { inner: s, cols }))
        }
    }
}

/// The `series` of any simulation: energies, contacts and the largest overlap per sample
/// (step, t, ke_trans, ke_rot, elastic, n_contacts, max_overlap).
pub struct Energies {
    every: u64,
    rows: Rows,
}

const ENERGIES: [&str; 7] = [
    "step",
    "t",
    "ke_trans",
    "ke_rot",
    "elastic",
    "n_contacts",
    "max_overlap",
];

impl Energies {
    fn new(spec: &SamplerSpec) -> Self {
        Energies {
            every: spec.every,
            rows: Rows::new(ENERGIES.to_vec(), vec![""; ENERGIES.len()], &["step"]),
        }
    }
}

impl Sampler for Energies {
    fn kind(&self) -> &'static str {
        "series"
    }
    fn table(&self) -> &'static str {
        "series"
    }
    fn every(&self) -> u64 {
        self.every
    }
    fn columns(&self) -> Vec<&'static str> {
        ENERGIES.to_vec()
    }
    fn needs_contacts(&self) -> bool {
        false
    }
    fn needs_elastic(&self) -> bool {
        true
    }
    fn sample(&mut self, v: &SampleView) -> Result<()> {
        let (ket, ker) = v.p.kinetic_energy();
        let row = [
            v.step as f64,
            v.time,
            ket,
            ker,
            v.elastic.unwrap_or(0.0),
            v.n_contacts as f64,
            v.max_overlap,
        ];
        self.rows.push_finite("series", v.step, &row)
    }
    fn take(&mut self) -> Vec<Table> {
        self.rows.take("series")
    }
    fn save(&self) -> Vec<f64> {
        self.rows.flat()
    }
    fn load(&mut self, s: &[f64]) -> Result<()> {
        self.rows.set_flat(s)
    }
    fn bytes(&self) -> usize {
        self.rows.bytes()
    }
}

/// Window length check shared by the window kinds.
pub(crate) fn check_window(kind: &str, window: u64) -> Result<()> {
    if window < 1 {
        return Err(Error::param(
            format!("{kind}.window"),
            window,
            "an integer >= 1 (samples per window)",
        ));
    }
    Ok(())
}

/// A sampler whose tables keep only the asked-for columns.
struct Select {
    inner: Box<dyn Sampler>,
    cols: Vec<String>,
}

impl Sampler for Select {
    fn kind(&self) -> &'static str {
        self.inner.kind()
    }
    fn table(&self) -> &'static str {
        self.inner.table()
    }
    fn every(&self) -> u64 {
        self.inner.every()
    }
    fn needs_contacts(&self) -> bool {
        self.inner.needs_contacts()
    }
    fn needs_elastic(&self) -> bool {
        self.inner.needs_elastic()
    }
    fn columns(&self) -> Vec<&'static str> {
        self.inner
            .columns()
            .into_iter()
            .filter(|c| self.cols.iter().any(|k| k == c))
            .collect()
    }
    fn sample(&mut self, v: &SampleView) -> Result<()> {
        self.inner.sample(v)
    }
    fn take(&mut self) -> Vec<Table> {
        let mut out = self.inner.take();
        for t in &mut out {
            t.columns.retain(|c| self.cols.contains(&c.0));
        }
        out
    }
    fn save(&self) -> Vec<f64> {
        self.inner.save()
    }
    fn load(&mut self, s: &[f64]) -> Result<()> {
        self.inner.load(s)
    }
    fn bytes(&self) -> usize {
        self.inner.bytes()
    }
}

/// Steps from `step` to the next step at which any of `samplers` samples (>= 1; u64::MAX with
/// none).
pub fn steps_to_next(samplers: &[Box<dyn Sampler>], step: u64) -> u64 {
    samplers
        .iter()
        .map(|s| s.every() - step % s.every())
        .min()
        .unwrap_or(u64::MAX)
}

/// The error of a non-finite value in a sampler's column (results never carry NaN).
pub(crate) fn nonfinite(kind: &str, step: u64, column: &str) -> Error {
    Error::Instability {
        step,
        particles: vec![],
        message: format!("non-finite value in {kind} column {column}"),
        cause: "the state itself went bad (the kernel's guards check it only every few \
                steps) or a bin is degenerate"
            .into(),
    }
}

/// A table's rows must never carry NaN: name the first bad column.
pub(crate) fn check_finite(kind: &str, step: u64, t: &Table) -> Result<()> {
    for (name, _, col) in &t.columns {
        if let Column::F64(v) = col {
            if v.iter().any(|x| !x.is_finite()) {
                return Err(nonfinite(kind, step, name));
            }
        }
    }
    Ok(())
}

/// Rows of f64 values buffered column by column (a series between hand-overs).
#[derive(Clone, Debug, Default)]
pub(crate) struct Rows {
    pub names: Vec<&'static str>,
    /// Columns stored as i64 in the table (step counters).
    pub ints: Vec<&'static str>,
    pub units: Vec<&'static str>,
    pub data: Vec<Vec<f64>>,
}

impl Rows {
    pub fn new(names: Vec<&'static str>, units: Vec<&'static str>, ints: &[&'static str]) -> Self {
        let data = vec![Vec::new(); names.len()];
        Rows {
            names,
            ints: ints.to_vec(),
            units,
            data,
        }
    }
    pub fn len(&self) -> usize {
        self.data.first().map_or(0, Vec::len)
    }
    pub fn bytes(&self) -> usize {
        self.data.iter().map(|c| 8 * c.capacity()).sum()
    }
    pub fn push(&mut self, row: &[f64]) {
        debug_assert_eq!(row.len(), self.data.len());
        for (c, v) in self.data.iter_mut().zip(row) {
            c.push(*v);
        }
    }
    /// `push`, refusing a row with a non-finite value (naming its column).
    pub fn push_finite(&mut self, kind: &str, step: u64, row: &[f64]) -> Result<()> {
        if let Some(k) = row.iter().position(|x| !x.is_finite()) {
            return Err(nonfinite(kind, step, self.names[k]));
        }
        self.push(row);
        Ok(())
    }
    /// The buffered rows as one table naming its sampler (none when empty); the buffer is
    /// left empty.
    pub fn take(&mut self, sampler: &str) -> Vec<Table> {
        if self.len() == 0 {
            return Vec::new();
        }
        let mut t = self.drain();
        t.metadata.push(("granflow.sampler".into(), sampler.into()));
        vec![t]
    }
    /// The buffered rows as a table; the buffer is left empty.
    pub fn drain(&mut self) -> Table {
        let mut t = Table::new();
        for ((name, unit), col) in self.names.iter().zip(&self.units).zip(&mut self.data) {
            let col = std::mem::take(col);
            if self.ints.contains(name) {
                t.push_i64(name, unit, col.iter().map(|&v| v as i64).collect());
            } else {
                t.push_f64(name, unit, col);
            }
        }
        t
    }
    /// Row-major flattening, for a checkpoint.
    pub fn flat(&self) -> Vec<f64> {
        let n = self.len();
        let mut out = Vec::with_capacity(n * self.data.len());
        for r in 0..n {
            out.extend(self.data.iter().map(|c| c[r]));
        }
        out
    }
    /// Restore what `flat` wrote (empty: no rows).
    pub fn set_flat(&mut self, s: &[f64]) -> Result<()> {
        let w = self.data.len();
        if w == 0 || !s.len().is_multiple_of(w) {
            return Err(Error::Io {
                message: "checkpoint: a sampler's buffered rows have the wrong size".into(),
            });
        }
        for c in &mut self.data {
            c.clear();
        }
        for row in s.chunks_exact(w) {
            self.push(row);
        }
        Ok(())
    }
}
