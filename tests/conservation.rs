//! Conservation laws: energy of an elastic frictionless gas (and its second-order error in
//! dt), linear and angular momentum of frictional dissipative gases.

mod common;

use common::{free_box, gas, periodic, Free};
use granflow::components::{NoBody, NoWalls};
use granflow::contact::{Coulomb, Frictionless, Hooke, LawSpec};
use granflow::domain::{Domain, OrthoBox};
use granflow::engine::{min_contact_time, Engine};
use granflow::insert::SizeDist;
use granflow::V3;

fn elastic_energy<D: Domain>(e: &Engine<Hooke, Frictionless, D, NoWalls, NoBody>) -> f64 {
    let mut u = 0.0;
    let pair_i = e.nl.pair_i();
    for (&i, &j) in pair_i.iter().zip(&e.nl.pair_j) {
        let (i, j) = (i as usize, j as usize);
        let d = Domain::delta(&e.domain, &e.p.x[i], &e.p.x[j]).norm();
        let delta = e.p.radius[i] + e.p.radius[j] - d;
        if delta > 0.0 {
            u += 0.5 * e.law.params.kn * delta * delta;
        }
    }
    u
}

fn energy_drift(dt_frac: f64, steps: u64) -> f64 {
    let l = 8.0;
    let p = gas(0.3, l, 7, SizeDist::Uniform(0.9, 1.1));
    let law = LawSpec::new(1e4, 1.0, 0.0);
    let tc = min_contact_time(&law, &p).unwrap();
    let bx = OrthoBox::periodic_cube(l).unwrap();
    let mut s: Engine<Hooke, Frictionless, OrthoBox, NoWalls, NoBody> =
        Engine::new(p, law, bx, NoWalls, NoBody, Some(tc * dt_frac), 0.3).unwrap();
    s.ensure_forces().unwrap();
    let e0 = {
        let (a, b) = s.p.kinetic_energy();
        a + b + elastic_energy(&s)
    };
    let mut maxdev = 0.0f64;
    for _ in 0..steps / 10 {
        s.run(10).unwrap();
        let (a, b) = s.p.kinetic_energy();
        let e = a + b + elastic_energy(&s);
        maxdev = maxdev.max((e - e0).abs() / e0);
    }
    maxdev
}

#[test]
fn energy_conserved_elastic_frictionless_gas_and_second_order() {
    // 1e4 steps at dt = t_c/1000: the largest deviation of the total (kinetic + elastic)
    // energy from its initial value
    let d1 = energy_drift(1.0 / 1000.0, 10_000);
    assert!(d1 < 1e-6, "relative energy error {d1}");
    // same simulated time at dt/2 and dt/4: error ~ dt^2
    let d2 = energy_drift(1.0 / 2000.0, 20_000);
    let d3 = energy_drift(1.0 / 4000.0, 40_000);
    let order = (d1 / d3).log2() / 2.0;
    eprintln!(
        "energy error t_c/1000: {d1:.3e}, /2000: {d2:.3e}, /4000: {d3:.3e}, order {order:.3}"
    );
    assert!((order - 2.0).abs() < 0.2, "order {order}");
}

#[test]
fn momentum_and_angular_momentum_conserved() {
    // periodic frictional dissipative gas: linear momentum to round-off
    let l = 8.0;
    let p = gas(
        0.35,
        l,
        3,
        SizeDist::Discrete(vec![(0.9, 0.3), (1.0, 0.4), (1.1, 0.3)]),
    );
    let mut s = periodic(p, l, 0.7, 0.2);
    let p0 = s.p.momentum();
    let scale: f64 = s.p.mass.iter().zip(&s.p.v).map(|(m, v)| m * v.norm()).sum();
    s.run(2000).unwrap();
    assert!(s.diag.contacts > 0 || !s.nl.is_empty());
    let p1 = s.p.momentum();
    assert!(
        (p1 - p0).norm() < 1e-12 * scale,
        "dp = {:e}",
        (p1 - p0).norm()
    );

    // free space cluster with friction: orbital + spin angular momentum conserved
    let p = gas(0.3, 6.0, 5, SizeDist::Uniform(0.8, 1.3));
    let mut p = p;
    for x in p.x.iter_mut() {
        *x += V3::new(7.0, 7.0, 7.0);
    }
    let law = LawSpec::new(1e5, 0.7, 0.5);
    let mut s: Free<Hooke, Coulomb> =
        Engine::new(p, law, free_box(), NoWalls, NoBody, None, 0.2).unwrap();
    let ang = |s: &Free<Hooke, Coulomb>| -> V3 {
        let mut l = V3::zeros();
        for i in 0..s.p.len() {
            l += s.p.mass[i] * s.p.x[i].cross(&s.p.v[i]) + s.p.inertia(i) * s.p.omega[i];
        }
        l
    };
    let l0 = ang(&s);
    let lscale: f64 = (0..s.p.len())
        .map(|i| s.p.mass[i] * s.p.x[i].norm() * s.p.v[i].norm())
        .sum();
    s.run(2000).unwrap();
    let l1 = ang(&s);
    assert!(
        (l1 - l0).norm() < 1e-10 * lscale,
        "dL = {:e} (scale {lscale:e})",
        (l1 - l0).norm()
    );
}
