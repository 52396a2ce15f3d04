//! Checkpoints: the complete dynamic state (particles in their internal order, the pair list
//! with its histories, wall histories, forces of the last step, domain state, step and time) so
//! that a restart continues bitwise identically to a run that never stopped.
//!
//! Format: magic `GFCK`, u32 version, then named sections (name, kind, count, little-endian
//! payload). Written to `path.tmp`, fsynced, then renamed over `path`: a file already written is
//! never left half-written, and a crash while writing leaves the previous checkpoint intact.

use crate::error::{Error, Result};
use std::io::{Read, Write};
use std::path::Path;

const MAGIC: &[u8; 4] = b"GFCK";
const VERSION: u32 = 1;

#[derive(Default)]
pub struct Writer {
    sections: Vec<(String, u8, Vec<u8>, u64)>,
}

#[derive(Default)]
pub struct Reader {
    sections: Vec<(String, u8, Vec<u8>, u64)>,
}

impl Writer {
    pub fn new() -> Self {
        Self::default()
    }
    pub fn f64s(&mut self, name: &str, v: &[f64]) {
        let mut b = Vec::with_capacity(8 * v.len());
        for x in v {
            b.extend_from_slice(&x.to_le_bytes());
        }
        self.sections.push((name.into(), 0, b, v.len() as u64));
    }
    pub fn u32s(&mut self, name: &str, v: &[u32]) {
        let mut b = Vec::with_capacity(4 * v.len());
        for x in v {
            b.extend_from_slice(&x.to_le_bytes());
        }
        self.sections.push((name.into(), 1, b, v.len() as u64));
    }
    pub fn i32s(&mut self, name: &str, v: &[i32]) {
        let mut b = Vec::with_capacity(4 * v.len());
        for x in v {
            b.extend_from_slice(&x.to_le_bytes());
        }
        self.sections.push((name.into(), 2, b, v.len() as u64));
    }
    pub fn u64s(&mut self, name: &str, v: &[u64]) {
        let mut b = Vec::with_capacity(8 * v.len());
        for x in v {
            b.extend_from_slice(&x.to_le_bytes());
        }
        self.sections.push((name.into(), 3, b, v.len() as u64));
    }
    pub fn text(&mut self, name: &str, s: &str) {
        self.sections
            .push((name.into(), 4, s.as_bytes().to_vec(), s.len() as u64));
    }
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::new();
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&VERSION.to_le_bytes());
        out.extend_from_slice(&(self.sections.len() as u64).to_le_bytes());
        for (name, kind, b, n) in &self.sections {
            out.extend_from_slice(&(name.len() as u32).to_le_bytes());
            out.extend_from_slice(name.as_bytes());
            out.push(*kind);
            out.extend_from_slice(&n.to_le_bytes());
            out.extend_from_slice(&(b.len() as u64).to_le_bytes());
            out.extend_from_slice(b);
        }
        // trailing checksum so a truncated or corrupted file is detected on load
        let sum = fnv1a(&out);
        out.extend_from_slice(&sum.to_le_bytes());
        out
    }
    /// Atomic write: tmp file, fsync, rename, fsync the directory.
    pub fn write_atomic(&self, path: &Path) -> Result<()> {
        let bytes = self.to_bytes();
        let tmp = path.with_extension("tmp");
        {
            let mut f = std::fs::File::create(&tmp)?;
            f.write_all(&bytes)?;
            f.sync_all()?;
        }
        std::fs::rename(&tmp, path)?;
        if let Some(dir) = path.parent() {
            if let Ok(d) = std::fs::File::open(if dir.as_os_str().is_empty() {
                Path::new(".")
            } else {
                dir
            }) {
                let _ = d.sync_all();
            }
        }
        Ok(())
    }
}

fn fnv1a(b: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &x in b {
        h ^= x as u64;
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

fn bad(msg: impl Into<String>) -> Error {
    Error::Io {
        message: format!("checkpoint: {}", msg.into()),
    }
}

impl Reader {
    pub fn read(path: &Path) -> Result<Self> {
        let mut b = Vec::new();
        std::fs::File::open(path)
            .map_err(|e| bad(format!("cannot open {}: {e}", path.display())))?
            .read_to_end(&mut b)?;
        Self::from_bytes(&b)
    }
    pub fn from_bytes(b: &[u8]) -> Result<Self> {
        if b.len() < 24 || &b[0..4] != MAGIC {
            return Err(bad("not a granflow checkpoint"));
        }
        let (body, tail) = b.split_at(b.len() - 8);
        if fnv1a(body) != u64::from_le_bytes(tail.try_into().unwrap()) {
            return Err(bad("checksum mismatch (truncated or corrupted file)"));
        }
        let ver = u32::from_le_bytes(b[4..8].try_into().unwrap());
        if ver != VERSION {
            return Err(bad(format!("version {ver}, this granflow reads {VERSION}")));
        }
        let ns = u64::from_le_bytes(b[8..16].try_into().unwrap()) as usize;
        let mut off = 16;
        let mut sections = Vec::with_capacity(ns);
        let take = |off: &mut usize, n: usize| -> Result<&[u8]> {
            if *off + n > body.len() {
                return Err(bad("truncated"));
            }
            let s = &body[*off..*off + n];
            *off += n;
            Ok(s)
        };
        for _ in 0..ns {
            let nl = u32::from_le_bytes(take(&mut off, 4)?.try_into().unwrap()) as usize;
            let name = String::from_utf8_lossy(take(&mut off, nl)?).to_string();
            let kind = take(&mut off, 1)?[0];
            let n = u64::from_le_bytes(take(&mut off, 8)?.try_into().unwrap());
            let len = u64::from_le_bytes(take(&mut off, 8)?.try_into().unwrap()) as usize;
            let payload = take(&mut off, len)?.to_vec();
            sections.push((name, kind, payload, n));
        }
        Ok(Reader { sections })
    }
    fn get(&self, name: &str, kind: u8) -> Result<&(String, u8, Vec<u8>, u64)> {
        self.sections
            .iter()
            .find(|s| s.0 == name && s.1 == kind)
            .ok_or_else(|| bad(format!("missing section {name}")))
    }
    pub fn has(&self, name: &str) -> bool {
        self.sections.iter().any(|s| s.0 == name)
    }
    pub fn f64s(&self, name: &str) -> Result<Vec<f64>> {
        let s = self.get(name, 0)?;
        Ok(s.2
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
            .collect())
    }
    pub fn u32s(&self, name: &str) -> Result<Vec<u32>> {
        let s = self.get(name, 1)?;
        Ok(s.2
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
            .collect())
    }
    pub fn i32s(&self, name: &str) -> Result<Vec<i32>> {
        let s = self.get(name, 2)?;
        Ok(s.2
            .chunks_exact(4)
            .map(|c| i32::from_le_bytes(c.try_into().unwrap()))
            .collect())
    }
    pub fn u64s(&self, name: &str) -> Result<Vec<u64>> {
        let s = self.get(name, 3)?;
        Ok(s.2
            .chunks_exact(8)
            .map(|c| u64::from_le_bytes(c.try_into().unwrap()))
            .collect())
    }
    pub fn text(&self, name: &str) -> Result<String> {
        let s = self.get(name, 4)?;
        Ok(String::from_utf8_lossy(&s.2).to_string())
    }
}

pub fn flat_v3(v: &[crate::V3]) -> Vec<f64> {
    v.iter().flat_map(|x| [x.x, x.y, x.z]).collect()
}
pub fn unflat_v3(v: &[f64]) -> Vec<crate::V3> {
    v.chunks_exact(3)
        .map(|c| crate::V3::new(c[0], c[1], c[2]))
        .collect()
}
