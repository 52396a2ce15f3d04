//! Step throughput on a packing file (f64 LE: N, Lx, Ly, Lz, then x y z d per particle),
//! for profiling (`valgrind --tool=callgrind`) and quick timing:
//!     cargo bench --bench step -- FILE STEPS THREADS [mu]
use granflow::contact::{Coulomb, Frictionless, Hooke, LawParams};
use granflow::domain::OrthoBox;
use granflow::engine::{Engine, NoBody, NoWalls};
use granflow::particles::Particles;
use granflow::V3;
use std::time::Instant;

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let file = a.get(1).cloned().unwrap_or("/tmp/packing20k.bin".into());
    let steps: u64 = a.get(2).and_then(|s| s.parse().ok()).unwrap_or(500);
    let threads: usize = a.get(3).and_then(|s| s.parse().ok()).unwrap_or(1);
    let mu: f64 = a.get(4).and_then(|s| s.parse().ok()).unwrap_or(0.5);
    let raw = std::fs::read(&file).expect("packing file");
    let v: Vec<f64> = raw
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
        .collect();
    let n = v[0] as usize;
    let l = V3::new(v[1], v[2], v[3]);
    let mut x = Vec::with_capacity(n);
    let mut d = Vec::with_capacity(n);
    for i in 0..n {
        let r = &v[4 + 4 * i..8 + 4 * i];
        x.push(V3::new(r[0], r[1], r[2]));
        d.push(r[3]);
    }
    let mut p = Particles::new(x, &d, 1.0).unwrap();
    let mut s: u64 = 12345;
    for vi in p.v.iter_mut() {
        for k in 0..3 {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            vi[k] = ((s >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.1;
        }
    }
    let law = LawParams::new(1e6, 0.82, mu);
    let bx = OrthoBox::new(V3::zeros(), l, [true; 3]).unwrap();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let t0 = Instant::now();
        let builds;
        if mu > 0.0 {
            let mut e: Engine<Hooke, Coulomb, OrthoBox, NoWalls, NoBody> =
                Engine::new(p, law, bx, NoWalls, NoBody, Some(1.2e-4), 0.2).unwrap();
            e.run(steps).unwrap();
            builds = e.nl.builds;
            println!("{:?} pairs/particle {:.2} contacts/particle {:.2}", e.timers, e.nl.len() as f64 / e.p.len() as f64, e.diag.contacts as f64 / e.p.len() as f64);
        } else {
            let mut e: Engine<Hooke, Frictionless, OrthoBox, NoWalls, NoBody> =
                Engine::new(p, law, bx, NoWalls, NoBody, Some(1.2e-4), 0.2).unwrap();
            e.run(steps).unwrap();
            builds = e.nl.builds;
            println!("{:?} pairs/particle {:.2} contacts/particle {:.2}", e.timers, e.nl.len() as f64 / e.p.len() as f64, e.diag.contacts as f64 / e.p.len() as f64);
        }
        let el = t0.elapsed().as_secs_f64();
        println!(
            "N={n} steps={steps} threads={threads} mu={mu}: {:.3e} particle-steps/s ({builds} builds)",
            n as f64 * steps as f64 / el
        );
    });
}
