//! Run-time guards: an unstable integration stops with a clear error instead of writing NaN.

mod common;

use common::gas;
use granflow::components::{NoBody, NoWalls};
use granflow::contact::{Frictionless, Hooke, LawSpec};
use granflow::domain::OrthoBox;
use granflow::engine::Engine;
use granflow::insert::SizeDist;

#[test]
fn unstable_integration_stops_with_a_clear_error() {
    let l = 8.0;
    let p = gas(0.3, l, 4, SizeDist::Uniform(0.9, 1.1));
    let law = LawSpec::new(1e4, 1.0, 0.0);
    let mut s: Engine<Hooke, Frictionless, OrthoBox, NoWalls, NoBody> = Engine::new(
        p,
        law,
        OrthoBox::periodic_cube(l).unwrap(),
        NoWalls,
        NoBody,
        None,
        0.3,
    )
    .unwrap();
    // bypass the constructor's dt check: omega dt > 2 makes velocity Verlet unstable
    s.dt = 0.9 * s.contact_time();
    s.guards.check_every = 5;
    let err = s.run(100_000).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, granflow::Error::Instability { .. }), "{msg}");
    assert!(msg.contains("step") && msg.contains("t_c"), "{msg}");
    assert!(s.p.x.iter().all(|x| x.iter().all(|c| c.is_finite())) || msg.contains("NaN"));
}
