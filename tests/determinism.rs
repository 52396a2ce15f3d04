//! Bitwise reproducibility: the same bits for one and two threads, with and without the team
//! of threads, with the AVX2 and the baseline paths, with any pruning interval, with the
//! cross-chunk pass deferred or not, and across a checkpoint restart. (The team's bits with
//! fused sweeps and a full cross index are checked in the kernel's `engine::tests`: they need
//! engine fields the crate does not export.)

mod common;

use common::{gas, periodic, periodic_gas, pool, walled_channel, walled_gas, walled_state};
use granflow::checkpoint::{Reader, Writer};
use granflow::components::{NoBody, NoWalls};
use granflow::contact::{Coulomb, Frictionless, Hertz, Hooke, LawSpec};
use granflow::domain::PrCell;
use granflow::domain::{Domain, OrthoBox};
use granflow::engine::{Engine, DEFAULT_PRUNE_STEPS};
use granflow::insert::SizeDist;
use granflow::{M3, V3};

fn dense_packing_run(threads: usize) -> Vec<V3> {
    let pool = pool(threads);
    pool.install(|| {
        let l = 12.0;
        let p = gas(
            0.35,
            l,
            11,
            SizeDist::Discrete(vec![(0.9, 0.3), (1.0, 0.4), (1.1, 0.3)]),
        );
        let mut s = periodic(p, l, 0.8, 0.2);
        s.run(1000).unwrap();
        let mut out = vec![V3::zeros(); s.p.len()];
        for i in 0..s.p.len() {
            out[s.p.id[i] as usize] = s.p.x[i];
        }
        out
    })
}

#[test]
fn one_and_two_threads_bitwise_identical() {
    let a = dense_packing_run(1);
    let b = dense_packing_run(2);
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(x.as_slice(), y.as_slice());
    }
}

#[test]
fn deferred_cross_pass_changes_no_bits() {
    // Inside one run the cross-chunk pass and the final half-kick ride on the next step's
    // first pass; run(600) must equal 600 x run(1), which never defers.
    let (mut a, mut b) = (periodic_gas(12.0, 5), periodic_gas(12.0, 5));
    assert!(
        a.nl.n_cross() > 0 || a.p.len() > 256,
        "needs cross pairs to test anything"
    );
    a.run(600).unwrap();
    for _ in 0..600 {
        b.run(1).unwrap();
    }
    assert!(a.diag.contacts > 0);
    for (x, y) in a.p.x.iter().zip(&b.p.x) {
        assert_eq!(x.as_slice(), y.as_slice());
    }
    for (x, y) in a.p.v.iter().zip(&b.p.v) {
        assert_eq!(x.as_slice(), y.as_slice());
    }
    for (x, y) in a.p.omega.iter().zip(&b.p.omega) {
        assert_eq!(x.as_slice(), y.as_slice());
    }
}

#[test]
fn team_stops_at_the_same_overlap_error() {
    // The overlap guard trips inside a team's stretch: the same step, message and state as
    // without the team.
    let mk = |team: bool, fused: bool| {
        // gravity strong enough that the wall layers compress over a few hundred steps
        let mut s = walled_gas::<Hooke>(10.0, 29, 0.7, V3::new(-3000.0, 0.0, 0.0));
        s.tuning.team = team;
        if fused {
            s.tuning.fuse_from = 0;
        }
        s
    };
    // the largest overlap over the first 100 and 300 steps of a reference run; a guard
    // between them trips between steps 100 and 300
    let mut r = mk(false, false);
    let mut peak = [0.0f64; 2];
    for k in 0..300 {
        r.run(1).unwrap();
        peak[(k >= 100) as usize] = peak[(k >= 100) as usize].max(r.diag.max_overlap);
    }
    assert!(peak[1] > peak[0] * 1.05, "overlaps do not grow: {peak:?}");
    let limit = 0.5 * (peak[0] + peak[1]);
    let stop = |team: bool, fused: bool| {
        let mut s = mk(team, fused);
        s.guards.max_overlap = limit;
        let err = s.run(1000).unwrap_err();
        (err.to_string(), walled_state(&s))
    };
    let (msg, state) = stop(false, false);
    assert!(msg.contains("overlap"), "{msg}");
    assert!(
        state.2 > 100 && state.2 <= 300,
        "stopped at step {}",
        state.2
    );
    assert_eq!(stop(true, true), (msg.clone(), state.clone()));
    assert_eq!(stop(true, false), (msg, state));
}

/// A walled frictional gas with gravity run with the inner list pruned to last `prune_steps`
/// steps (0: not pruned): positions, velocities and spins by id, and (prunes, builds, mean
/// inner / listed pairs).
fn pruned_run(prune_steps: f64) -> (Vec<[f64; 9]>, u64, u64, f64) {
    let mut s = walled_gas::<Hooke>(10.0, 17, 0.7, V3::new(-2.0, -1.0, 0.0));
    s.tuning.prune_steps = prune_steps;
    let (q0, b0) = (s.nl.prunes, s.nl.builds);
    let mut frac = 0.0;
    for _ in 0..20 {
        s.run(100).unwrap();
        frac += s.nl.inner_len() as f64 / s.nl.len() as f64 / 20.0;
    }
    let mut out = vec![[0.0; 9]; s.p.len()];
    for i in 0..s.p.len() {
        let (x, v, w) = (s.p.x[i], s.p.v[i], s.p.omega[i]);
        out[s.p.id[i] as usize] = [x.x, x.y, x.z, v.x, v.y, v.z, w.x, w.y, w.z];
    }
    (out, s.nl.prunes - q0, s.nl.builds - b0, frac)
}

#[test]
fn pruning_changes_no_bits() {
    // The force loop tests only the pairs kept at the last prune; as long as no particle
    // can have closed the gap since, it sees exactly the contacts of the whole list, in the
    // same order: any pruning interval gives the same bits as none.
    let (a, qa, ba, fa) = pruned_run(0.0);
    // (one more: the engine's first inner list was pruned before pruning was turned off)
    assert!(
        qa <= ba + 1,
        "without pruning the inner list follows the list: {qa} > {ba} + 1"
    );
    assert!(fa > 0.999);
    for k in [1.0, 4.0, DEFAULT_PRUNE_STEPS] {
        let (b, qb, bb, fb) = pruned_run(k);
        assert!(qb > 2 * bb, "prune_steps {k}: {qb} prunes for {bb} builds");
        assert!(
            fb < 0.9,
            "prune_steps {k}: the inner list kept {fb} of the pairs"
        );
        let differ = a.iter().zip(&b).filter(|(u, v)| u != v).count();
        assert_eq!(
            differ, 0,
            "prune_steps {k} changed the trajectory of {differ} particles"
        );
    }
}

/// Positions, velocities and (one statistics step) the per-particle stress records of a
/// walled Hertz channel with gravity, and positions of a frictionless periodic packing.
fn walled_hertz_and_frictionless_runs() -> (Vec<V3>, Vec<V3>, Vec<[f64; 10]>, Vec<V3>) {
    let l = 8.0;
    let s = walled_channel::<Hertz>(l, 1500);
    let p2 = gas(0.35, l, 3, SizeDist::Uniform(0.9, 1.1));
    let mut f: Engine<Hooke, Frictionless, OrthoBox, NoWalls, NoBody> = Engine::new(
        p2,
        LawSpec::new(1e5, 0.8, 0.0),
        OrthoBox::periodic_cube(l).unwrap(),
        NoWalls,
        NoBody,
        None,
        0.2,
    )
    .unwrap();
    f.run(1500).unwrap();
    (
        s.p.x.clone(),
        s.p.v.clone(),
        s.pstats.clone(),
        f.p.x.clone(),
    )
}

/// Positions, velocities and the cell matrix of a stress-controlled cell compacting and
/// shearing (its own AVX2 passes, the streaming velocity and the virial on lanes).
fn sheared_cell_run() -> (Vec<V3>, Vec<V3>, M3) {
    let l = 9.0;
    let p = gas(0.3, l, 23, SizeDist::Uniform(0.8, 1.2));
    let cell = PrCell::new(l, p.len(), 0.5, 20.0, 8.0).unwrap();
    let mut e: Engine<Hooke, Coulomb, PrCell, NoWalls, NoBody> = Engine::new(
        p,
        LawSpec::new(1e4, 0.7, 0.5),
        cell,
        NoWalls,
        NoBody,
        None,
        0.3,
    )
    .unwrap();
    e.run(3000).unwrap();
    assert!(e.diag.contacts > 50, "{}", e.diag.contacts);
    (e.p.x.clone(), e.p.v.clone(), e.domain.h())
}

#[test]
fn avx2_and_baseline_paths_bitwise_identical() {
    // The force loop runs with AVX2 where the CPU has it and with baseline x86-64 otherwise;
    // both must give the same bits (same IEEE operations, same order). One test only: the
    // switch is global, and a second test flipping it concurrently would blur the check.
    // Without AVX2 on this CPU both runs take the baseline path.
    let same = |u: &[V3], v: &[V3]| {
        assert_eq!(u.len(), v.len());
        for (x, y) in u.iter().zip(v) {
            assert_eq!(x.as_slice(), y.as_slice());
        }
    };
    let wide = granflow::contact::lanes::wide();
    granflow::contact::lanes::set_wide(false);
    let a = (dense_packing_run(2), walled_hertz_and_frictionless_runs());
    let ca = sheared_cell_run();
    granflow::contact::lanes::set_wide(true);
    let b = (dense_packing_run(2), walled_hertz_and_frictionless_runs());
    let cb = sheared_cell_run();
    granflow::contact::lanes::set_wide(wide);
    same(&ca.0, &cb.0);
    same(&ca.1, &cb.1);
    assert_eq!(ca.2.as_slice(), cb.2.as_slice());
    same(&a.0, &b.0);
    same(&a.1 .0, &b.1 .0);
    same(&a.1 .1, &b.1 .1);
    assert!(a.1 .2.iter().any(|r| r.iter().any(|&v| v != 0.0)));
    assert_eq!(a.1 .2, b.1 .2);
    same(&a.1 .3, &b.1 .3);
}

#[test]
fn checkpoint_restart_is_bitwise_identical() {
    let l = 8.0;
    let mk = || periodic_gas(l, 21);
    let mut a = mk();
    a.run(700).unwrap();
    let mut b = mk();
    b.run(333).unwrap();
    let mut w = Writer::new();
    b.save_state(&mut w);
    let bytes = w.to_bytes();
    drop(b);
    let mut c = mk();
    c.load_state(&Reader::from_bytes(&bytes).unwrap()).unwrap();
    c.run(367).unwrap();
    assert_eq!(a.step, c.step);
    for i in 0..a.p.len() {
        assert_eq!(a.p.id[i], c.p.id[i]);
        assert_eq!(a.p.x[i].as_slice(), c.p.x[i].as_slice());
        assert_eq!(a.p.omega[i].as_slice(), c.p.omega[i].as_slice());
    }
    // a corrupted file is refused, not half-read
    let mut bad = bytes.clone();
    bad[100] ^= 1;
    assert!(Reader::from_bytes(&bad).is_err());
    assert!(Reader::from_bytes(&bytes[..bytes.len() / 2]).is_err());
}
