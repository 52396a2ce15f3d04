//! Timing of one sample's channel-bin sums (`granflow::sampling::channel::Bins`, the pass the
//! team runs on each force-loop chunk) on random spheres and contacts as many as the study's
//! channel has (6754 particles in 4 chunks, 2475 contacts per chunk, 20 bins):
//!     cargo bench --bench channel_sums [-- REPS]
//! Prints the time per sample with the particles only and with the particles and contacts.
use granflow::sampling::channel::fixtures::random_state;
use granflow::sampling::channel::Bins;
use granflow::sampling::{ChunkView, Sampler, SamplerSpec, Setup};
use granflow::M3;
use std::time::Instant;

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
