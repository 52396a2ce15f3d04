//! Bit-identity guard for random insertion: `insert` must keep producing exactly the same
//! positions (and the same failures) for a given input and seed, because stored checksums (the
//! shear-cell checksum, saved channel states) are built on top of it. The reference fingerprints
//! below are the positions produced by the implementation before its data structures were
//! rewritten for speed; they are not physics values. Regenerate them only for a deliberate change
//! of the insertion algorithm (run with `--nocapture`: each case prints its fingerprint).

use granflow::insert::insert;
use granflow::rng::Rng;
use granflow::V3;

/// FNV-1a over the full bit patterns of all coordinates, in order.
fn fingerprint(pos: &[V3]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for p in pos {
        for k in 0..3 {
            for b in p[k].to_bits().to_le_bytes() {
                h ^= b as u64;
                h = h.wrapping_mul(0x0000_0100_0000_01b3);
            }
        }
    }
    h
}

fn diameters(n: usize, lo: f64, hi: f64, seed: u64) -> Vec<f64> {
    let mut rng = Rng::new(seed);
    (0..n).map(|_| rng.range(lo, hi)).collect()
}

fn solid_volume(d: &[f64]) -> f64 {
    d.iter()
        .map(|d| std::f64::consts::PI * d.powi(3) / 6.0)
        .sum()
}

/// Side of the cube holding `d` at volume fraction `phi`.
fn cube_side(d: &[f64], phi: f64) -> f64 {
    (solid_volume(d) / phi).cbrt()
}

struct Case {
    name: &'static str,
    d: Vec<f64>,
    lo: V3,
    hi: V3,
    periodic: [bool; 3],
    seed: u64,
    max_attempts: usize,
}

fn cube(name: &'static str, d: Vec<f64>, phi: f64, periodic: [bool; 3], seed: u64) -> Case {
    let l = cube_side(&d, phi);
    Case {
        name,
        d,
        lo: V3::zeros(),
        hi: V3::new(l, l, l),
        periodic,
        seed,
        max_attempts: 10_000,
    }
}

fn cases() -> Vec<Case> {
    let poly = |n, s| diameters(n, 0.9, 1.1, s);
    let mut v = vec![
        cube("ttt phi0.3 s1", poly(3000, 101), 0.3, [true; 3], 1),
        cube("ttt phi0.3 s2", poly(3000, 102), 0.3, [true; 3], 2),
        cube(
            "ftt phi0.3 s3",
            poly(3000, 103),
            0.3,
            [false, true, true],
            3,
        ),
        cube("fff phi0.3 s4", poly(2000, 104), 0.3, [false; 3], 4),
        cube("fff phi0.05 s5", poly(2000, 105), 0.05, [false; 3], 5),
        cube("ttt phi0.05 s6", poly(2000, 106), 0.05, [true; 3], 6),
        cube(
            "ftt phi0.05 s7",
            poly(2000, 107),
            0.05,
            [false, true, true],
            7,
        ),
        // wide size range: many small spheres share a cell of the largest diameter
        cube(
            "ttt wide phi0.3",
            diameters(4000, 0.2, 1.0, 108),
            0.3,
            [true; 3],
            8,
        ),
        cube(
            "fft wide phi0.2",
            diameters(3000, 0.1, 1.2, 109),
            0.2,
            [false, false, true],
            9,
        ),
        // equal diameters: placement order falls back to the index
        cube("ttt mono phi0.3", vec![1.0; 2500], 0.3, [true; 3], 10),
    ];
    // thin, offset, mixed-periodicity boxes: 1 to 4 cells along some axes
    for (name, w, periodic) in [
        ("thin x1 ttt", 1.5, [true; 3]),
        ("thin x2 ttt", 2.5, [true; 3]),
        ("thin x3 ttt", 3.5, [true; 3]),
        ("thin x4 ttt", 4.7, [true; 3]),
        ("thin x3 ftf", 3.5, [false, true, false]),
        ("thin x2 tft", 2.5, [true, false, true]),
    ] {
        let d = poly(600, 110);
        let lo = V3::new(-3.7, 1.25, 0.5);
        let area = solid_volume(&d) / 0.2 / w;
        let (ly, lz) = (area.sqrt() * 0.8, area.sqrt() / 0.8);
        v.push(Case {
            name,
            d,
            lo,
            hi: lo + V3::new(ly, lz, w),
            periodic,
            seed: 11,
            max_attempts: 10_000,
        });
    }
    v
}

/// Fingerprints of the positions from the implementation before the speed rewrite.
const REFERENCE: [(&str, u64); 16] = [
    ("ttt phi0.3 s1", 0x34e8d2f656e5861c),
    ("ttt phi0.3 s2", 0x6a8c60d6dc9ddac6),
    ("ftt phi0.3 s3", 0x4733b49e97954bb5),
    ("fff phi0.3 s4", 0xfadf90876053339d),
    ("fff phi0.05 s5", 0x9b06a3055eb2f49b),
    ("ttt phi0.05 s6", 0x51d0f808d57ca493),
    ("ftt phi0.05 s7", 0x173a53fa2ddcdaeb),
    ("ttt wide phi0.3", 0x49328d438de01f6e),
    ("fft wide phi0.2", 0x6bec21587ba549c7),
    ("ttt mono phi0.3", 0x67d4f51dbf4faa72),
    ("thin x1 ttt", 0xb21d00011483f717),
    ("thin x2 ttt", 0x75ad1c8b6a2c4deb),
    ("thin x3 ttt", 0x24eb78923b6716e7),
    ("thin x4 ttt", 0x74a170e0994b40b9),
    ("thin x3 ftf", 0x19eb46d6c56e09ee),
    ("thin x2 tft", 0xaa4fe68934ce5140),
];

#[test]
fn positions_are_bit_identical_to_reference() {
    let cases = cases();
    assert_eq!(cases.len(), REFERENCE.len());
    let mut bad = Vec::new();
    for (c, (name, want)) in cases.iter().zip(REFERENCE) {
        assert_eq!(c.name, name);
        let pos = insert(&c.d, c.lo, c.hi, c.periodic, c.seed, c.max_attempts)
            .unwrap_or_else(|e| panic!("{}: {e}", c.name));
        assert_eq!(pos.len(), c.d.len());
        let got = fingerprint(&pos);
        println!("    (\"{}\", {got:#018x}),", c.name);
        if got != want {
            bad.push(c.name);
        }
    }
    assert!(bad.is_empty(), "positions changed for {bad:?}");
}

fn error_text(d: &[f64], lo: V3, hi: V3, periodic: [bool; 3], seed: u64, max: usize) -> String {
    match insert(d, lo, hi, periodic, seed, max) {
        Ok(_) => panic!("insertion was expected to fail"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn impossible_volume_fraction_is_refused() {
    let d = diameters(2000, 0.9, 1.1, 120);
    let l = cube_side(&d, 0.6);
    let msg = error_text(&d, V3::zeros(), V3::new(l, l, l), [true; 3], 1, 10_000);
    // (1024 placed is the reference implementation's count for this input)
    assert!(
        msg.starts_with(
            "random insertion failed after placing 1024 of 2000 spheres (target phi = 0.600)"
        ),
        "{msg}"
    );
}

#[test]
fn failures_are_identical_to_reference() {
    // the number placed before giving up depends on every accept/reject decision
    let d = diameters(3000, 0.9, 1.1, 121);
    let l = cube_side(&d, 0.3);
    let msg = error_text(&d, V3::zeros(), V3::new(l, l, l), [true; 3], 2, 3);
    assert!(
        msg.starts_with("random insertion failed after placing 257 of 3000 "),
        "{msg}"
    );
    let msg = error_text(&d, V3::zeros(), V3::new(l, l, l), [true; 3], 2, 0);
    assert!(
        msg.starts_with("random insertion failed after placing 0 of 3000 "),
        "{msg}"
    );
    // a non-periodic side narrower than the largest diameter
    let msg = error_text(
        &d,
        V3::zeros(),
        V3::new(l, 1.05, l),
        [true, false, true],
        2,
        10,
    );
    assert_eq!(
        msg,
        "invalid region = [17.421232959025016, 1.05, 17.421232959025016]: \
         allowed wider than the largest diameter 1.0999109974983672"
    );
    let msg = error_text(&d, V3::zeros(), V3::new(l, -1.0, l), [true; 3], 2, 10);
    assert_eq!(
        msg,
        "invalid region length = -1: allowed a finite number > 0"
    );
}
