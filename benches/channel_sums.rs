//! Timing of one sample's channel-bin sums (`granflow::sampling::channel::Bins`, the pass the
//! team runs on each force-loop chunk) on random spheres and contacts as many as the study's
//! channel has (6754 particles in 4 chunks, 2475 contacts per chunk, 20 bins):
//!     cargo bench --bench channel_sums [-- REPS]
//! Prints the time per sample with the particles only and with the particles and contacts.
use granflow::particles::Particles;
use granflow::rng::Rng;
use granflow::sampling::channel::Bins;
use granflow::sampling::{ChunkView, ContactRec, Sampler, SamplerSpec, Setup, WALL};
use granflow::{M3, V3};
use std::time::Instant;

/// Random spheres (d 0.8..1.2) in a 20 x 30 x 10 channel, and `per` random contacts for
/// each chunk of `ch` (a tenth on walls; branch vectors of a contact's length in any
/// direction, some along y: no length across x).
fn random_state(n: usize, ch: usize, per: usize) -> (Particles, Vec<Vec<ContactRec>>) {
    let mut rng = Rng::new(7);
    let x: Vec<V3> = (0..n)
        .map(|_| {
            V3::new(
                20.0 * rng.uniform(),
                30.0 * rng.uniform(),
                10.0 * rng.uniform(),
            )
        })
        .collect();
    let d: Vec<f64> = (0..n).map(|_| 0.8 + 0.4 * rng.uniform()).collect();
    let mut p = Particles::new(x, &d, 1.0).unwrap();
    for i in 0..n {
        p.v[i] = V3::new(
            rng.uniform() - 0.5,
            rng.uniform() - 0.5,
            rng.uniform() - 0.5,
        );
        p.omega[i] = V3::new(rng.uniform(), rng.uniform(), rng.uniform());
    }
    let recs = (0..n.div_ceil(ch))
        .map(|c| {
            let len = ch.min(n - c * ch);
            (0..per)
                .map(|k| {
                    let i = c * ch + (k * 7) % len;
                    let wall = rng.uniform() < 0.1;
                    let u = V3::new(
                        rng.uniform() - 0.5,
                        rng.uniform() - 0.5,
                        rng.uniform() - 0.5,
                    );
                    let dv = if k % 97 == 0 {
                        V3::new(0.0, 1.0, 0.0)
                    } else {
                        u.normalize() * (0.5 + 0.6 * rng.uniform())
                    };
                    ContactRec {
                        i: i as u32,
                        j: if wall { WALL } else { ((i + 1) % n) as u32 },
                        d: dv,
                        f: V3::new(rng.uniform() - 0.5, rng.uniform() - 0.5, rng.uniform()),
                        power: -rng.uniform(),
                    }
                })
                .collect()
        })
        .collect();
    (p, recs)
}

fn main() {
    // `cargo bench` passes `--bench`; the first number given is the repetition count
    let reps: usize = std::env::args()
        .skip(1)
        .find_map(|a| a.parse().ok())
        .unwrap_or(1000);
    let (n, ch) = (6754, 1689);
    let (p, recs) = random_state(n, ch, 2475);
    let spec = SamplerSpec {
        every: 1,
        window: 1,
        edges: (0..=20).map(|k| k as f64).collect(),
        columns: None,
    };
    let setup = Setup {
        p: &p,
        h: M3::identity(),
        widths: [20.0, 30.0, 10.0],
        periodic: [false, true, true],
        walls: 2,
    };
    let bins = Bins::new(&spec, &setup).unwrap();
    let mut sink = 0.0;
    let mut time = |with: bool| {
        let t = Instant::now();
        for _ in 0..reps {
            for (c, r) in recs.iter().enumerate() {
                let rc = if with { &r[..] } else { &[][..] };
                let cv = ChunkView::of(&p, c * ch..((c + 1) * ch).min(n), rc);
                let part = bins.chunk_part(&cv).unwrap();
                sink += part[part.len() / 2];
            }
        }
        t.elapsed().as_secs_f64() / reps as f64
    };
    let tp = time(false);
    let tc = time(true);
    println!(
        "channel bin sums per sample: particles {:.1} us, particles and contacts {:.1} us ({sink})",
        tp * 1e6,
        tc * 1e6
    );
}
