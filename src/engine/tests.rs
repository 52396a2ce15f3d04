//! Engine tests that need its crate-private knobs and counters (`team_cross_room`,
//! `team_prunes`, `fuse_margin`); the kernel's other tests are integration tests in `tests/`
//! (whose `common` module holds the public twins of the set-ups below).

use crate::components::{Gravity, Plane, PlaneWalls};
use crate::contact::{Coulomb, Form, Hooke, LawSpec};
use crate::domain::OrthoBox;
use crate::engine::Engine;
use crate::insert::{insert, SizeDist};
use crate::particles::Particles;
use crate::rng::Rng;
use crate::V3;

/// Dense-ish periodic gas with random velocities.
fn gas(n_target_phi: f64, l: f64, seed: u64, sizes: SizeDist) -> Particles {
    let mut rng = Rng::new(seed);
    let vol = n_target_phi * l * l * l;
    let ds = sizes.diameters_for_volume(vol, &mut rng);
    let x = insert(&ds, V3::zeros(), V3::new(l, l, l), [true; 3], seed, 10_000).unwrap();
    let mut p = Particles::new(x, &ds, 1.0).unwrap();
    for i in 0..p.len() {
        p.v[i] = V3::new(rng.normal(), rng.normal(), rng.normal());
        p.omega[i] = V3::new(rng.normal(), rng.normal(), rng.normal());
    }
    // remove net momentum
    let pm = p.momentum() / p.mass.iter().sum::<f64>();
    for v in p.v.iter_mut() {
        *v -= pm;
    }
    p
}

type WalledGas<F> = Engine<F, Coulomb, OrthoBox, PlaneWalls<F, Coulomb>, Gravity>;

/// A frictional gas (seed `seed`, restitution `e`) between walls at x = 0 and x = l, periodic
/// in y and z, with the body force `g`.
fn walled_gas<F: Form>(l: f64, seed: u64, e: f64, g: V3) -> WalledGas<F> {
    let mut p = gas(0.35, l, seed, SizeDist::Uniform(0.9, 1.1));
    // squeeze x into [0.6, l - 0.6] so some particles touch the walls
    for x in p.x.iter_mut() {
        x.x = 0.6 + x.x * ((l - 1.2) / l);
    }
    let law = LawSpec::new(1e5, e, 0.5);
    let bx = OrthoBox::new(V3::zeros(), V3::new(l, l, l), [false, true, true]).unwrap();
    let walls = PlaneWalls::<F, Coulomb>::new(Plane::pair_across(0, 0.0, l), law).unwrap();
    Engine::new(p, law, bx, walls, Gravity(g), None, 0.2).unwrap()
}

/// Everything a walled run carries between steps, for bitwise comparisons.
fn walled_state<F: Form>(s: &WalledGas<F>) -> (Vec<[f64; 9]>, Vec<f64>, u64) {
    let mut by_id = vec![[0.0; 9]; s.p.len()];
    for i in 0..s.p.len() {
        let (x, v, w) = (s.p.x[i], s.p.v[i], s.p.omega[i]);
        by_id[s.p.id[i] as usize] = [x.x, x.y, x.z, v.x, v.y, v.z, w.x, w.y, w.z];
    }
    let mut scalars: Vec<f64> = s
        .wall_impulse
        .iter()
        .flat_map(|w| w.iter().copied())
        .collect();
    scalars.extend(s.diag.wall_force.iter().flat_map(|w| w.iter().copied()));
    scalars.extend([s.time, s.diag.max_overlap, s.diag.contacts as f64]);
    (by_id, scalars, s.step)
}

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
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
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
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
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
