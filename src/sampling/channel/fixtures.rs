//! Random channel states: spheres and contact records shaped as the channel's (used by the
//! channel sampler's tests and by `benches/channel_sums.rs`; not part of the API).
use crate::particles::Particles;
use crate::sampling::{ContactRec, WALL};
use crate::V3;

/// Random spheres (d 0.8..1.2) in a 20 x 30 x 10 channel, and `per` random contacts for
/// each chunk of `ch` (a tenth on walls; branch vectors of a contact's length in any
/// direction, some along y: no length across x).
pub fn random_state(n: usize, ch: usize, per: usize) -> (Particles, Vec<Vec<ContactRec>>) {
    let mut rng = crate::rng::Rng::new(7);
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
