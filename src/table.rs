//! A minimal column-major table: what samplers produce and the bindings turn into Arrow record
//! batches (one copy-free hand-over per window). Kept free of Arrow so the kernel stays lean.

#[derive(Clone, Debug, PartialEq)]
pub enum Column {
    F64(Vec<f64>),
    I64(Vec<i64>),
}

impl Column {
    pub fn len(&self) -> usize {
        match self {
            Column::F64(v) => v.len(),
            Column::I64(v) => v.len(),
        }
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[derive(Clone, Debug, Default, PartialEq)]
pub struct Table {
    /// (name, unit, data). Names follow the papers' symbols (see docs/columns.md).
    pub columns: Vec<(String, String, Column)>,
    /// Table-level metadata (key, value), e.g. the sampler's description.
    pub metadata: Vec<(String, String)>,
}

impl Table {
    pub fn new() -> Self {
        Self::default()
    }
    pub fn nrows(&self) -> usize {
        self.columns.first().map(|c| c.2.len()).unwrap_or(0)
    }
    pub fn push_f64(&mut self, name: &str, unit: &str, data: Vec<f64>) {
        self.columns
            .push((name.to_string(), unit.to_string(), Column::F64(data)));
    }
    pub fn push_i64(&mut self, name: &str, unit: &str, data: Vec<i64>) {
        self.columns
            .push((name.to_string(), unit.to_string(), Column::I64(data)));
    }
    pub fn get(&self, name: &str) -> Option<&Column> {
        self.columns.iter().find(|c| c.0 == name).map(|c| &c.2)
    }
    /// Append the rows of another table with the same columns.
    pub fn append(&mut self, other: &Table) {
        if self.columns.is_empty() {
            *self = other.clone();
            return;
        }
        for (c, o) in self.columns.iter_mut().zip(other.columns.iter()) {
            match (&mut c.2, &o.2) {
                (Column::F64(a), Column::F64(b)) => a.extend_from_slice(b),
                (Column::I64(a), Column::I64(b)) => a.extend_from_slice(b),
                _ => panic!("column type mismatch for {}", c.0),
            }
        }
    }
    /// True if any f64 cell is NaN or infinite (results must never carry NaN).
    pub fn has_nonfinite(&self) -> bool {
        self.columns.iter().any(|c| match &c.2 {
            Column::F64(v) => v.iter().any(|x| !x.is_finite()),
            _ => false,
        })
    }
}
