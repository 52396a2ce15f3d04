//! Step throughput on a state file, for profiling (`valgrind --tool=callgrind`) and quick timing:
//!     cargo bench --bench step -- FILE STEPS THREADS [mu]
//! File (f64 little-endian): kind (0 periodic packing, 1 channel), N, Lx, Ly, Lz, dt, then per
//! particle x y z vx vy vz wx wy wz d. A channel has walls at x = 0 and x = Lx (same law as the
//! pairs), periodic y and z, gravity -1 along y (000's channel). `benchmarks/kernel_state.py`
//! writes such files.
//! Knobs (environment): PRUNE=k prune interval, FUSE=n fused sweep from n particles,
//! NO_TEAM=1 steps through rayon only, NO_PRUNE_TEAM=1 prunes outside the team,
//! KN=k normal stiffness (default 1e6), SAMPLE=k the channel's bins and series every k steps,
//! AB=b runs two engines from the state in alternating blocks of b steps, A with the knobs
//! above, B also with SAMPLE, KINDS and CHECK=k (guard checks every k steps): B's time over A's.
//! PAD=b allocate b bytes first (shifts the heap layout), PIN=1 pins worker i to CPU i.
use granflow::components::{Body, Plane, Walls};
use granflow::contact::{Form, Friction, LawInput, LawSpec};
use granflow::domain::Domain;
use granflow::engine::Engine;
use granflow::particles::Particles;
use granflow::scene::{build_with, DomainSpec, EngineSink, FormKind, SceneSpec};
use granflow::V3;
use std::time::Instant;

/// Receives the engine `granflow::scene` composes, sets the knobs and runs it; with AB=b,
/// composes a second engine from `second` and runs the two side by side.
struct Bench {
    steps: u64,
    second: Option<SceneSpec>,
}

impl EngineSink for Bench {
    type Output = ();
    fn take<F: Form, T: Friction, D: Domain, W: Walls<F, T>, G: Body>(
        self,
        mut e: Engine<F, T, D, W, G>,
    ) {
        match self.second {
            None => {
                knobs(&mut e, true);
                go(e, self.steps)
            }
            Some(spec) => {
                knobs(&mut e, false);
                build_with(
                    spec,
                    Second {
                        a: e,
                        steps: self.steps,
                    },
                )
                .unwrap()
            }
        }
    }
}

/// AB=b: engine A (the shared knobs only) and engine B (also CHECK, SAMPLE, KINDS) from the
/// same state, run in alternating blocks of b steps (the order swapped every round), so that
/// the VM's drifting speed falls on both alike; prints B's time over A's.
struct Second<F: Form, T: Friction, D: Domain, W: Walls<F, T>, G: Body> {
    a: Engine<F, T, D, W, G>,
    steps: u64,
}

impl<F: Form, T: Friction, D: Domain, W: Walls<F, T>, G: Body> EngineSink
    for Second<F, T, D, W, G>
{
    type Output = ();
    fn take<F2: Form, T2: Friction, D2: Domain, W2: Walls<F2, T2>, G2: Body>(
        self,
        mut b: Engine<F2, T2, D2, W2, G2>,
    ) {
        knobs(&mut b, true);
        let mut a = self.a;
        let block: u64 = std::env::var("AB")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(500);
        a.run(10).unwrap();
        b.run(10).unwrap();
        b.timers = Default::default();
        let rounds = self.steps.div_ceil(block);
        let (mut ta, mut tb) = (0.0, 0.0);
        let mut ratios = Vec::new();
        for r in 0..rounds {
            let mut time_a = || {
                let t = Instant::now();
                a.run(block).unwrap();
                t.elapsed().as_secs_f64()
            };
            let mut time_b = || {
                let t = Instant::now();
                b.run(block).unwrap();
                t.elapsed().as_secs_f64()
            };
            let (x, y) = if r % 2 == 0 {
                let x = time_a();
                (x, time_b())
            } else {
                let y = time_b();
                (time_a(), y)
            };
            ta += x;
            tb += y;
            ratios.push(y / x);
        }
        ratios.sort_by(f64::total_cmp);
        let n = a.p.len() as f64 * (rounds * block) as f64;
        println!(
            "A {:.3e} B {:.3e} particle-steps/s; B/A time {:.4} (median of {} blocks {:.4}); B's samplers {:.1} us a step",
            n / ta,
            n / tb,
            tb / ta,
            rounds,
            ratios[ratios.len() / 2],
            b.timers.sampling / (rounds * block) as f64 * 1e6
        );
    }
}

/// The knobs from the environment (`b`: also those only engine B of an A/B run takes).
fn knobs<F: Form, T: Friction, D: Domain, W: Walls<F, T>, G: Body>(
    e: &mut Engine<F, T, D, W, G>,
    b: bool,
) {
    if let Some(k) = std::env::var("PRUNE").ok().and_then(|s| s.parse().ok()) {
        e.tuning.prune_steps = k;
    }
    if let Some(k) = std::env::var("FUSE").ok().and_then(|s| s.parse().ok()) {
        e.tuning.fuse_from = k;
    }
    if std::env::var_os("NO_PRUNE_TEAM").is_some() {
        e.tuning.prune_in_team = false;
    }
    if std::env::var_os("NO_TEAM").is_some() {
        e.tuning.team = false;
    }
    if !b {
        return;
    }
    if let Some(k) = std::env::var("CHECK").ok().and_then(|s| s.parse().ok()) {
        e.guards.check_every = k;
    }
    // SAMPLE=k: the channel's bins (1 wide) and series every k steps, windows of 50
    if let Some(k) = std::env::var("SAMPLE")
        .ok()
        .and_then(|s| s.parse::<u64>().ok())
    {
        let w = e.domain.widths().x;
        let edges: Vec<f64> = (0..=w.round() as usize)
            .map(|i| i as f64 * w / w.round())
            .collect();
        let kinds = std::env::var("KINDS").unwrap_or("channel_bins,channel_series".into());
        for kind in kinds.split(',') {
            let spec = granflow::sampling::SamplerSpec {
                every: k,
                window: 50,
                edges: edges.clone(),
                columns: None,
            };
            e.add_sampler(kind, spec).unwrap();
        }
    }
}

fn go<F: Form, T: Friction, D: Domain, W: Walls<F, T>, G: Body>(
    mut e: Engine<F, T, D, W, G>,
    steps: u64,
) {
    e.run(10).unwrap();
    e.timers = Default::default();
    let b0 = e.nl.builds;
    let q0 = e.nl.prunes;
    let t0 = Instant::now();
    let c0 = cpu_seconds();
    e.run(steps).unwrap();
    let el = t0.elapsed().as_secs_f64();
    let cpu = cpu_seconds() - c0;
    let n = e.p.len();
    println!(
        "{:?}\npairs/particle {:.2} inner {:.2} (prunes {}) cross {:.2} contacts/particle {:.2} builds {} kernel B/particle {:.0}",
        e.timers,
        e.nl.len() as f64 / n as f64,
        e.nl.inner_len() as f64 / n as f64,
        e.nl.prunes - q0,
        e.nl.n_cross() as f64 / e.nl.inner_len() as f64,
        e.diag.contacts as f64 / n as f64,
        e.nl.builds - b0,
        e.memory_list().iter().map(|(_, b)| *b as f64).sum::<f64>() / n as f64
    );
    let mut by_id = vec![V3::zeros(); n];
    for i in 0..n {
        by_id[e.p.id[i] as usize] = e.p.x[i] + e.p.v[i];
    }
    let sum: f64 = by_id.iter().map(|x| x.x + 2.0 * x.y + 3.0 * x.z).sum();
    println!("checksum (x + v by id) {sum:.17e}");
    for (name, b) in e.memory_list() {
        println!("  {name}: {:.1} B/particle", b as f64 / n as f64);
    }
    if e.timers.sampling > 0.0 {
        println!(
            "samplers {:.1} us a step",
            e.timers.sampling / steps as f64 * 1e6
        );
    }
    println!(
        "N={n} steps={steps} {}: {:.3e} particle-steps/s wall, {:.3e} per CPU-second",
        F::NAME,
        n as f64 * steps as f64 / el,
        n as f64 * steps as f64 / cpu
    );
}

/// User + system CPU time of this process (from /proc/self/stat, clock ticks of 10 ms): on a
/// loaded machine, the time the process actually ran.
fn cpu_seconds() -> f64 {
    let s = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let after = s.rsplit(')').next().unwrap_or("");
    let f: Vec<&str> = after.split_whitespace().collect();
    let t = |k: usize| f.get(k).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    (t(11) + t(12)) / 100.0
}

fn skin() -> f64 {
    std::env::var("SKIN")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0.2)
}

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let file = a
        .get(1)
        .cloned()
        .unwrap_or("/work/bench/channel.bin".into());
    let steps: u64 = a.get(2).and_then(|s| s.parse().ok()).unwrap_or(500);
    let threads: usize = a.get(3).and_then(|s| s.parse().ok()).unwrap_or(1);
    let mu: f64 = a.get(4).and_then(|s| s.parse().ok()).unwrap_or(0.5);
    let raw = std::fs::read(&file).expect("state file");
    let v: Vec<f64> = raw
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
        .collect();
    let kind = v[0] as usize;
    let n = v[1] as usize;
    let l = V3::new(v[2], v[3], v[4]);
    let dt = v[5];
    let rec = |i: usize| &v[6 + 10 * i..16 + 10 * i];
    let x: Vec<V3> = (0..n)
        .map(|i| V3::new(rec(i)[0], rec(i)[1], rec(i)[2]))
        .collect();
    let d: Vec<f64> = (0..n).map(|i| rec(i)[9]).collect();
    let mut p = Particles::new(x, &d, 1.0).unwrap();
    for i in 0..n {
        let r = rec(i);
        p.v[i] = V3::new(r[3], r[4], r[5]);
        p.omega[i] = V3::new(r[6], r[7], r[8]);
    }
    let law = LawSpec::resolve(
        &LawInput {
            kn: Some(
                std::env::var("KN")
                    .ok()
                    .and_then(|s| s.parse().ok())
                    .unwrap_or(1e6),
            ),
            e_n: Some(0.82),
            mu: Some(mu),
            ..LawInput::default()
        },
        "",
    )
    .unwrap();
    let mut spec = if kind == 1 {
        let bx = DomainSpec::Box {
            lo: V3::zeros(),
            length: l,
            periodic: [false, true, true],
        };
        let mut spec = SceneSpec::new(p, law, bx);
        spec.walls = Plane::pair_across(0, 0.0, l.x);
        spec.gravity = Some(V3::new(0.0, -1.0, 0.0));
        spec
    } else {
        let bx = DomainSpec::Box {
            lo: V3::zeros(),
            length: l,
            periodic: [true; 3],
        };
        SceneSpec::new(p, law, bx)
    };
    spec.form = FormKind::Hooke;
    spec.dt = Some(dt);
    spec.skin = skin();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .start_handler(|i| {
            if std::env::var_os("PIN").is_some() {
                // pinned for the worker's life: the guard is not dropped
                std::mem::forget(granflow::probe::pin::to(i));
            }
        })
        .build()
        .unwrap();
    println!("kind={kind} threads={threads} mu={mu}");
    pool.install(|| {
        // PAD bytes allocated first: shifts the heap layout (for layout-dependent effects)
        let _pad: Vec<u8> = vec![
            1;
            std::env::var("PAD")
                .ok()
                .and_then(|s| s.parse().ok())
                .unwrap_or(0)
        ];
        let second = std::env::var_os("AB").map(|_| spec.clone());
        build_with(spec, Bench { steps, second }).unwrap();
    });
}
