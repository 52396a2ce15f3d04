//! Sampled steps completed inside the team of threads change no bits. Alone in its own test
//! binary, as `team.rs`: a process runs one team at a time, so a test beside it would make
//! the other's stints step the usual way.

mod common;

use common::{pool, walled_gas, walled_state};
use granflow::contact::Hooke;
use granflow::V3;

#[test]
fn sampled_steps_in_the_team_change_no_bits() {
    // A stint may end with a sampled step completed inside the team (its contact records
    // kept, its cross pass and final half-kick done there): the same trajectory and the same
    // tables as sampling outside the team, for one and two threads, with fused sweeps, and
    // with runs that end on a sampled step or just after one.
    use granflow::sampling::SamplerSpec;
    let run_with = |team: bool, threads: usize, fuse: bool| {
        let pool = pool(threads);
        pool.install(|| {
            let mut s = walled_gas::<Hooke>(10.0, 23, 0.7, V3::new(-2.0, -1.0, 0.0));
            s.tuning.team = team;
            if fuse {
                s.tuning.fuse_from = 0;
                s.tuning.fuse_margin = 1.25;
            }
            let edges: Vec<f64> = (0..=8).map(|k| k as f64 * 10.0 / 8.0).collect();
            for (kind, every) in [("channel_bins", 7), ("channel_series", 5)] {
                let spec = SamplerSpec {
                    every,
                    window: 3,
                    edges: edges.clone(),
                    columns: None,
                };
                s.add_sampler(kind, spec).unwrap();
            }
            // runs ending on a sampled step (35), just after one (36) and between (the rest)
            for n in [35, 36, 200, 429] {
                s.run(n).unwrap();
            }
            let tables: Vec<_> = s.samplers.iter_mut().flat_map(|x| x.take()).collect();
            (walled_state(&s), tables)
        })
    };
    let (want, tables) = run_with(false, 2, false);
    // 700 steps: 33 bins windows (of 3 samples every 7 steps) and 140 series rows in windows
    assert_eq!(tables.iter().filter(|t| t.columns.len() > 30).count(), 33);
    for threads in [2, 1] {
        for fuse in [false, true] {
            let (st, t) = run_with(true, threads, fuse);
            assert_eq!(st, want, "{threads} threads, fused {fuse}");
            assert!(t == tables, "tables: {threads} threads, fused {fuse}");
        }
    }
}
