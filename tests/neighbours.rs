//! Neighbour lists: the displacement bounds behind the list's and the pruned inner list's
//! lifetimes miss no contact (every step checked against brute force over all pairs).

mod common;

use common::{gas, periodic, PeriodicEngine};
use granflow::domain::Domain;
use granflow::insert::SizeDist;
use granflow::particles::Particles;
use granflow::V3;

/// Pairs in contact now, by brute force over all pairs (minimum image).
fn brute_contacts(s: &PeriodicEngine) -> usize {
    let n = s.p.len();
    let mut c = 0;
    for i in 0..n {
        for j in i + 1..n {
            let r = s.domain.delta(&s.p.x[i], &s.p.x[j]).norm();
            c += (r < s.p.radius[i] + s.p.radius[j]) as usize;
        }
    }
    c
}

#[test]
fn list_bounds_miss_no_contact() {
    // The list's lifetime and the inner list's come from a bound on the displacements (the
    // largest speed times dt, summed); if the bound were wrong, a pair could touch without
    // being tested. Count the contacts of every pair by brute force after each step of a
    // fast, dense gas (small skin, frequent builds and prunes) and compare with the contacts
    // the force loop found.
    let l = 8.0;
    let mut p = gas(0.35, l, 23, SizeDist::Uniform(0.8, 1.2));
    for v in p.v.iter_mut() {
        *v *= 5.0;
    }
    let mut s = periodic(p, l, 0.9, 0.3);
    s.tuning.prune_steps = 2.0;
    let (b0, q0) = (s.nl.builds, s.nl.prunes);
    let (mut seen, mut kept) = (0, 0.0f64);
    for _ in 0..600 {
        s.run(1).unwrap();
        kept = kept.max(s.nl.inner_len() as f64 / s.nl.len() as f64);
        let brute = brute_contacts(&s);
        assert_eq!(s.diag.contacts, brute, "step {}", s.step);
        seen += brute;
    }
    assert!(seen > 600, "the gas must have contacts ({seen})");
    let (b, q) = (s.nl.builds - b0, s.nl.prunes - q0);
    assert!(b >= 3 && q > 10 * b, "{b} builds, {q} prunes");
    assert!(kept < 0.6, "the inner list kept up to {kept} of the pairs");
}

#[test]
fn head_on_pairs_are_found_at_the_bound() {
    // The worst case of the displacement bound: two spheres closing head-on, each at the
    // largest speed, from gaps spread over the whole skin. Every contact must be found at
    // the step it forms (a bound too small by any factor misses some: the gaps span three
    // skins, so some pairs enter the list only at a later build).
    let l = 20.0;
    let (mut x, mut v) = (Vec::new(), Vec::new());
    for k in 0..16 {
        let (y, z) = (2.5 + 5.0 * (k % 4) as f64, 2.5 + 5.0 * (k / 4) as f64);
        let gap = 0.9 * (k as f64 + 0.5) / 16.0;
        x.push(V3::new(2.0, y, z));
        x.push(V3::new(3.0 + gap, y, z));
        v.push(V3::new(1.0, 0.0, 0.0));
        v.push(V3::new(-1.0, 0.0, 0.0));
    }
    // The bound measures speeds against a frame moving with the middle of the velocity
    // range: a bulk velocity added to every particle must change neither the contacts
    // found nor how often the list is rebuilt.
    let mut builds = Vec::new();
    for (prune, bulk) in [
        (0.0, V3::zeros()),
        (1.0, V3::zeros()),
        (2.0, V3::zeros()),
        (0.0, V3::new(7.0, -3.0, 2.0)),
        (2.0, V3::new(7.0, -3.0, 2.0)),
    ] {
        let mut p = Particles::new(x.clone(), &[1.0; 32], 1.0).unwrap();
        p.v = v.iter().map(|u| u + bulk).collect();
        let mut s = periodic(p, l, 0.9, 0.3);
        s.tuning.prune_steps = prune;
        let mut touched = 0;
        for _ in 0..3000 {
            s.run(1).unwrap();
            let brute = brute_contacts(&s);
            assert_eq!(
                s.diag.contacts, brute,
                "prune_steps {prune}, bulk {bulk:?}, step {}",
                s.step
            );
            touched += brute;
        }
        assert!(touched > 16, "the pairs must collide");
        builds.push(s.nl.builds);
    }
    // (a bound on the largest speed, 7.9 against 1, would rebuild about 8 times as often)
    assert!(
        builds[3] <= builds[0] + 1 && builds[4] <= builds[2] + 1,
        "{builds:?}"
    );
}
