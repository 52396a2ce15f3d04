//! The stress-controlled (Parrinello-Rahman) cell: lattice flips, the minimum image at large
//! tilt, and a sheared cell's lists (no missed contact, pruning changes no bits).

mod common;

use common::gas;
use granflow::components::{NoBody, NoWalls};
use granflow::contact::{Coulomb, Frictionless, Hooke, LawSpec};
use granflow::domain::Domain;
use granflow::domain::PrCell;
use granflow::engine::Engine;
use granflow::insert::SizeDist;
use granflow::rng::Rng;
use granflow::V3;

#[test]
fn cell_flip_changes_no_contact_force() {
    // a dense-ish frictionless gas in a cell whose tilt is just below half a box length
    let l = 8.0;
    let mut p = gas(0.12, l, 31, SizeDist::Uniform(0.9, 1.1));
    let law = LawSpec::new(1e4, 0.8, 0.0);
    let mut cell = PrCell::new(l, 50.max(p.len()), 1.0, 1e-3, 0.0).unwrap();
    let mut h = cell.h;
    h[(0, 1)] = 0.499 * l;
    cell.set_h(h);
    // the same reduced coordinates in the tilted cell (sheared gas: some pairs now overlap)
    for x in p.x.iter_mut() {
        *x = h * (*x / l);
    }
    let mut a: Engine<Hooke, Frictionless, PrCell, NoWalls, NoBody> =
        Engine::new(p.clone(), law, cell.clone(), NoWalls, NoBody, None, 0.3).unwrap();
    let mut cell2 = cell;
    // the equivalent lattice after a flip
    h[(0, 1)] = 0.499 * l - l;
    cell2.set_h(h);
    let mut b: Engine<Hooke, Frictionless, PrCell, NoWalls, NoBody> =
        Engine::new(p, law, cell2, NoWalls, NoBody, None, 0.3).unwrap();
    a.ensure_forces().unwrap();
    b.ensure_forces().unwrap();
    assert!(a.diag.contacts > 0);
    assert_eq!(a.diag.contacts, b.diag.contacts);
    let fa: Vec<V3> = (0..a.p.len())
        .map(|k| {
            let i = a.p.id.iter().position(|&q| q as usize == k).unwrap();
            a.p.force[i]
        })
        .collect();
    for (k, fk) in fa.iter().enumerate() {
        let i = b.p.id.iter().position(|&q| q as usize == k).unwrap();
        let d = (b.p.force[i] - fk).norm();
        assert!(d <= 1e-9 * fk.norm().max(1e-6), "particle {k}: {d:e}");
    }
}

#[test]
fn cell_min_image_matches_brute_force_at_large_tilt() {
    let l = 8.0;
    let mut rng = Rng::new(5);
    for &tilt in &[0.0, 0.3, 0.499, -0.499] {
        let mut cell = PrCell::new(l, 100, 1.0, 1e-3, 0.0).unwrap();
        let mut h = cell.h;
        h[(0, 1)] = tilt * l;
        h[(0, 2)] = 0.2 * tilt * l;
        h[(1, 2)] = -0.3 * tilt * l;
        cell.set_h(h);
        let h = cell.h;
        let mut c2 = cell.clone();
        c2.set_h(h);
        for _ in 0..2000 {
            let xi = h * V3::new(rng.uniform(), rng.uniform(), rng.uniform());
            let xj = h * V3::new(rng.uniform(), rng.uniform(), rng.uniform());
            let d = c2.delta(&xi, &xj);
            let mut best = f64::INFINITY;
            for a in -2..=2 {
                for b in -2..=2 {
                    for c in -2..=2 {
                        let img = h * V3::new(a as f64, b as f64, c as f64);
                        best = best.min((xi - xj - img).norm());
                    }
                }
            }
            // the rounding image must be the nearest whenever that is within the cutoff range
            if best < 2.0 {
                assert!(
                    (d.norm() - best).abs() < 1e-9,
                    "tilt {tilt}: {} vs {best}",
                    d.norm()
                );
            }
        }
    }
}

/// A sheared stress-controlled cell: the lists' displacement bounds count the cell's strain
/// rate and a flip of the lattice forces a rebuild, so at every checked step the contacts the
/// engine found are all the pairs in contact (brute force over the minimum image), and the
/// pruned inner list gives the same bits as testing every listed pair.
#[test]
fn sheared_cell_pruning_changes_no_bits_and_misses_no_contact() {
    let l = 9.0;
    let mut p = gas(0.3, l, 17, SizeDist::Uniform(0.8, 1.2));
    // at rest: the pairs first close by the cell's affine motion alone, which the inner
    // list's bound must count
    p.v.iter_mut().for_each(|v| *v = V3::zeros());
    p.omega.iter_mut().for_each(|w| *w = V3::zeros());
    let law = LawSpec::new(1e4, 0.7, 0.5);
    // pressure and shear stress well above the gas's: the cell compacts and shears
    let cell = PrCell::new(l, p.len(), 0.5, 20.0, 8.0).unwrap();
    let run = |prune: f64| {
        let mut e: Engine<Hooke, Coulomb, PrCell, NoWalls, NoBody> =
            Engine::new(p.clone(), law, cell.clone(), NoWalls, NoBody, None, 0.3).unwrap();
        e.tuning.prune_steps = prune;
        let mut fewer = false;
        for k in 0..500 {
            e.run(if k < 200 { 1 } else { 20 }).unwrap();
            fewer |= e.nl.inner_len() < e.nl.len();
            let n = e.p.len();
            let mut brute = 0;
            for i in 0..n {
                for j in i + 1..n {
                    let d = e.domain.delta(&e.p.x[i], &e.p.x[j]).norm();
                    if d < e.p.radius[i] + e.p.radius[j] {
                        brute += 1;
                    }
                }
            }
            assert_eq!(e.diag.contacts, brute, "step {}", e.step);
        }
        let mut by_id = vec![[0.0; 6]; e.p.len()];
        for i in 0..e.p.len() {
            let (x, v) = (e.p.x[i], e.p.v[i]);
            by_id[e.p.id[i] as usize] = [x.x, x.y, x.z, v.x, v.y, v.z];
        }
        (by_id, fewer, e.nl.prunes, e.diag.contacts, e.domain.flips)
    };
    let (a, fewer, prunes, contacts, flips) = run(16.0);
    let (b, _, _, _, _) = run(0.0);
    assert!(fewer, "the inner list was never pruned");
    assert!(
        prunes > 10 && contacts > 100 && flips > 0,
        "{prunes} {contacts} {flips}"
    );
    assert!(a == b, "pruning changed the trajectory");
}
