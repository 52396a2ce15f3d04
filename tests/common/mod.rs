//! Set-ups shared by the kernel's integration tests (`tests/*.rs`, each its own binary; a
//! binary uses only some of them).
#![allow(dead_code, reason = "each test binary uses only some of the set-ups")]

use granflow::components::{Gravity, NoBody, NoWalls, Plane, PlaneWalls};
use granflow::contact::{Coulomb, Form, Hooke, LawSpec};
use granflow::domain::OrthoBox;
use granflow::engine::Engine;
use granflow::insert::{insert, SizeDist};
use granflow::particles::Particles;
use granflow::rng::Rng;
use granflow::V3;

/// An engine in free space (no walls, no body force).
pub type Free<F, T> = Engine<F, T, OrthoBox, NoWalls, NoBody>;

/// A closed (non-periodic) box of side 20 at the origin.
pub fn free_box() -> OrthoBox {
    OrthoBox::new(V3::zeros(), V3::new(20.0, 20.0, 20.0), [false; 3]).unwrap()
}

/// Dense-ish periodic gas with random velocities.
pub fn gas(n_target_phi: f64, l: f64, seed: u64, sizes: SizeDist) -> Particles {
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

pub type PeriodicEngine = Engine<Hooke, Coulomb, OrthoBox, NoWalls, NoBody>;

/// Particles `p` in a periodic cube of side l: linear law kn = 1e5, restitution e, mu = 0.5.
pub fn periodic(p: Particles, l: f64, e: f64, skin: f64) -> PeriodicEngine {
    Engine::new(
        p,
        LawSpec::new(1e5, e, 0.5),
        OrthoBox::periodic_cube(l).unwrap(),
        NoWalls,
        NoBody,
        None,
        skin,
    )
    .unwrap()
}

/// A frictional gas (phi = 0.35) in a periodic cube of side l.
pub fn periodic_gas(l: f64, seed: u64) -> PeriodicEngine {
    periodic(gas(0.35, l, seed, SizeDist::Uniform(0.9, 1.1)), l, 0.8, 0.2)
}

pub type WalledGas<F> = Engine<F, Coulomb, OrthoBox, PlaneWalls<F, Coulomb>, Gravity>;

/// A frictional gas (seed `seed`, restitution `e`) between walls at x = 0 and x = l, periodic
/// in y and z, with the body force `g`.
pub fn walled_gas<F: Form>(l: f64, seed: u64, e: f64, g: V3) -> WalledGas<F> {
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

/// A gas between walls at x = 0 and x = l with gravity towards the first, run `steps` steps,
/// then one step with the virial and the per-particle statistics.
pub fn walled_channel<F: Form>(l: f64, steps: u64) -> WalledGas<F> {
    let mut s = walled_gas::<F>(l, 9, 0.8, V3::new(-5.0, 0.0, 0.0));
    s.run(steps).unwrap();
    s.want_virial = true;
    s.want_stats = true;
    s.run(1).unwrap();
    s
}

/// Everything a walled run carries between steps, for bitwise comparisons.
pub fn walled_state<F: Form>(s: &WalledGas<F>) -> (Vec<[f64; 9]>, Vec<f64>, u64) {
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

/// A rayon pool of `threads` threads (a test's runs for a thread count install into it).
pub fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
}
