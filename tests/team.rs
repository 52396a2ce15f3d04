//! The team of threads (`engine::team`) changes no bits. Alone in its own test binary: a
//! process runs one team at a time, and a run that finds the team taken by another test steps
//! the usual way, which would change the counts of prunes done inside the team asserted here.

mod common;

use common::{pool, walled_gas, walled_state};
use granflow::contact::Hooke;
use granflow::V3;

#[test]
fn team_steps_change_no_bits() {
    // Stretches of plain steps run in one team of threads (`engine::team`): the same bits
    // as stepping through rayon, with walls, gravity, builds and prunes inside the run, for
    // one and two threads; and two runs sharing a pool at once (one team at a time: the
    // other steps the usual way) neither deadlock nor change.
    // Fused sweeps (`fuse`: the fusing margin) too: with a margin of 0 every step is fused,
    // so the steps that build or prune first compute their forces twice (the first time
    // with the lists out of date, and overwriting the forces the records came from).
    // Prunes due inside a stint are done by the team (`prune_in_team`), or outside when the
    // cross index has no room for them (`team_cross_room` Some(0): some of each).
    let run_with = |team: bool, threads: usize, fuse: Option<f64>, room: Option<usize>| {
        let pool = pool(threads);
        pool.install(|| {
            let mut s = walled_gas::<Hooke>(10.0, 23, 0.7, V3::new(-2.0, -1.0, 0.0));
            s.tuning.team = team;
            s.tuning.team_cross_room = room;
            if let Some(m) = fuse {
                s.tuning.fuse_from = 0;
                s.tuning.fuse_margin = m;
            }
            s.run(700).unwrap();
            (walled_state(&s), s.nl.builds, s.nl.prunes, s.team_prunes)
        })
    };
    let run = |team: bool, threads: usize, fuse: Option<f64>| {
        let (st, b, p, _) = run_with(team, threads, fuse, None);
        (st, b, p)
    };
    let (want, builds, prunes) = run(false, 2, None);
    assert!(builds > 1 && prunes > 3, "builds {builds} prunes {prunes}");
    assert!(want.1[..3].iter().any(|&c| c != 0.0), "no wall impulse");
    for threads in [2, 1] {
        let (st, b, p, tp) = run_with(true, threads, None, None);
        assert_eq!(st, want, "{threads} threads");
        assert_eq!((b, p), (builds, prunes));
        assert!(tp > 0 && tp < prunes, "prunes in the team {tp} of {prunes}");
        let (st, _, p, tq) = run_with(true, threads, None, Some(0));
        assert_eq!(st, want, "{threads} threads, no room");
        assert_eq!(p, prunes);
        assert!(
            tq < tp,
            "without room: {tq} prunes in the team, with room {tp}"
        );
    }
    for fuse in [Some(0.0), Some(1.25)] {
        assert_eq!(run(true, 2, fuse).0, want, "fused {fuse:?}");
        assert_eq!(run(true, 1, fuse).0, want, "fused {fuse:?}");
    }
    let pool = pool(2);
    let (a, b) = pool.install(|| {
        let go = || {
            let mut s = walled_gas::<Hooke>(10.0, 23, 0.7, V3::new(-2.0, -1.0, 0.0));
            s.run(700).unwrap();
            walled_state(&s)
        };
        rayon::join(go, go)
    });
    assert_eq!(a, want);
    assert_eq!(b, want);
}
