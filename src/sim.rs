//! An object-safe view of any composed engine, so front ends (Python bindings, CLI) can hold
//! "a simulation" without naming its type parameters. The hot loop stays monomorphised: dynamic
//! dispatch happens once per `run` call, never per particle or pair.

use crate::components::{Body, Walls};
use crate::contact::{Form, Friction, LawSpec};
use crate::domain::Domain;
use crate::engine::{Engine, StepDiag};
use crate::error::Result;
use crate::particles::Particles;
use crate::table::Table;

pub trait Simulation: Send + Sync {
    /// Advance `n` steps (samplers, if any, run on their triggers).
    fn run(&mut self, n: u64) -> Result<()>;
    fn particles(&self) -> &Particles;
    /// Mutable access; call [`Simulation::invalidate`] after changing positions or velocities.
    fn particles_mut(&mut self) -> &mut Particles;
    fn invalidate(&mut self);
    fn step(&self) -> u64;
    fn time(&self) -> f64;
    fn dt(&self) -> f64;
    fn contact_time(&self) -> f64;
    /// The particle–particle law in use (resolved: every default filled).
    fn law(&self) -> LawSpec;
    /// The particle–wall law in use (None without walls).
    fn wall_law(&self) -> Option<LawSpec>;
    fn diag(&self) -> StepDiag;
    /// Neighbour-list builds and prunes since the start (counters, for benchmarks and tuning).
    fn list_counts(&self) -> (u64, u64);
    /// The parts this simulation is composed of (e.g. "contact: hooke/coulomb", "walls: 2 planes").
    fn components(&self) -> Vec<String>;
    /// Bytes held by each part (capacity of its arrays).
    fn memory(&self) -> Vec<(String, usize)>;
    /// Ask the next force evaluation for per-particle contact sums (see `Engine::pstats`).
    fn request_stats(&mut self);
    /// Per-particle contact sums of the last evaluation that was asked for them (internal
    /// order; empty if none).
    fn particle_stats(&self) -> &[[f64; 10]];
    /// Total force exerted by the particles on each wall at the last evaluation.
    fn wall_forces(&self) -> Vec<crate::V3> {
        Vec::new()
    }
    /// Named scalar observables of the domain (empty for a static box).
    fn domain_observables(&self) -> Vec<(String, f64)>;
    /// Change the imposed stress of a stress-controlled domain (an error for any other).
    fn set_stress(&mut self, p_ext: f64, tau_ext: f64) -> Result<()>;
    /// Drive a cell at an imposed xy shear rate, its normal stress (sigma_yy if `gradient`,
    /// else the pressure) held at `p_ext` (an error for any other domain).
    fn set_rate(&mut self, rate: f64, gradient: bool, p_ext: f64) -> Result<()>;
    /// Pair contacts of the last force evaluation: (id_i, id_j, r_ij = x_i - x_j (minimum
    /// image), force on i), in list order.
    fn contacts(&self) -> Vec<(u32, u32, crate::V3, crate::V3)>;
    /// Time integral of `wall_forces` since the start (trapezoid rule, as the integrator).
    fn wall_impulse(&self) -> Vec<crate::V3> {
        Vec::new()
    }
    /// Add a sampler (`crate::sampling::make`: kind, trigger, window, bins, columns).
    fn add_sampler(&mut self, kind: &str, spec: crate::sampling::SamplerSpec) -> Result<()>;
    /// The kinds and tables of the samplers configured, in order.
    fn samplers(&self) -> Vec<(String, String)>;
    /// Tables closed by the samplers since the last call (table name, table), oldest first.
    fn take_tables(&mut self) -> Vec<(String, Table)>;
    /// Volume of the domain.
    fn volume(&self) -> f64;
    /// Cell matrix (columns = cell vectors) and origin.
    fn cell(&self) -> (crate::M3, crate::V3);
    /// A position mapped into the primary cell (the kernel wraps only at list builds, so
    /// stored positions may lie up to half a skin outside).
    fn wrapped(&self, x: crate::V3) -> crate::V3;
    /// Write the complete dynamic state (see `checkpoint`).
    fn save_checkpoint(&self, w: &mut crate::checkpoint::Writer);
    /// Restore a state written by `save_checkpoint` from a simulation built with the same
    /// parameters.
    fn load_checkpoint(&mut self, r: &crate::checkpoint::Reader) -> Result<()>;
    /// Total elastic energy stored in the contacts: normal springs (linear law: kn delta^2/2;
    /// Hertz: 2/5 kn delta^(5/2)/sqrt(d)) and tangential springs (s kt |u|^2/2); used for
    /// energy balances.
    fn elastic_energy(&self) -> f64;
}

fn vec_bytes<T>(v: &Vec<T>) -> usize {
    v.capacity() * std::mem::size_of::<T>()
}

/// Bytes held by the particle arrays.
/// Bytes held by the per-chunk history lists and their next-step copies.
fn list_bytes<H: Copy + Default>(
    a: &[crate::history::HistList<H>],
    b: &[crate::history::HistList<H>],
) -> usize {
    a.iter().chain(b).map(|l| l.bytes()).sum()
}

pub fn particle_bytes(p: &Particles) -> usize {
    vec_bytes(&p.x)
        + vec_bytes(&p.v)
        + vec_bytes(&p.omega)
        + vec_bytes(&p.force)
        + vec_bytes(&p.torque)
        + vec_bytes(&p.radius)
        + vec_bytes(&p.mass)
        + vec_bytes(&p.inv_mass)
        + vec_bytes(&p.inv_inertia)
        + vec_bytes(&p.image)
        + vec_bytes(&p.id)
}

impl<F: Form, T: Friction, D: Domain, W: Walls<F, T>, G: Body> Engine<F, T, D, W, G> {
    pub fn component_list(&self) -> Vec<String> {
        let mut c = vec![
            format!("contact: {}", crate::contact::Law::<F, T>::name()),
            format!(
                "tangential history: {}",
                if T::FRICTIONAL { "per contact" } else { "none" }
            ),
            format!("domain: {}", D::NAME),
            "integrator: velocity Verlet (translation + rotation)".to_string(),
            if D::PLAIN_NVE {
                "neighbours: cell list + Verlet list with skin, pruned to the pairs near contact \
                 every few steps (the lists' lifetimes from the largest speed relative to a \
                 moving frame)"
                    .to_string()
            } else {
                "neighbours: cell list + Verlet list with skin".to_string()
            },
        ];
        if W::ON {
            c.push(format!("walls: {} planes", self.walls.planes().len()));
        }
        if G::ON {
            let g = self.body.g();
            c.push(format!("body force: gravity ({}, {}, {})", g.x, g.y, g.z));
        }
        c
    }

    pub fn memory_list(&self) -> Vec<(String, usize)> {
        let nl = &self.nl;
        vec![
            ("particles".to_string(), particle_bytes(&self.p)),
            (
                "pair list".to_string(),
                vec_bytes(&nl.pair_j)
                    + vec_bytes(&nl.own_start)
                    + vec_bytes(&nl.cross_off)
                    + vec_bytes(&nl.cross_start)
                    + vec_bytes(&nl.cross_slot)
                    + vec_bytes(&nl.cross_src)
                    + vec_bytes(&nl.pair_img)
                    + vec_bytes(&nl.x_build),
            ),
            (
                "inner (pruned) pair list".to_string(),
                nl.inner.iter().map(|c| c.bytes()).sum::<usize>()
                    + nl.inner.capacity() * std::mem::size_of::<crate::neighbor::InnerChunk>(),
            ),
            (
                "cross-chunk contact forces".to_string(),
                self.cross.iter().map(vec_bytes).sum::<usize>()
                    + self.cross_idx.capacity() * 4
                    + self.cross.capacity() * std::mem::size_of::<Vec<crate::engine::PairOut>>(),
            ),
            (
                "packed step records".to_string(),
                vec_bytes(&self.xr) + vec_bytes(&self.kin),
            ),
            (
                "tangential history".to_string(),
                list_bytes(&self.hist, &self.hist_next),
            ),
            (
                "wall history".to_string(),
                list_bytes(&self.whist, &self.whist_next),
            ),
            (
                "contact records for samplers".to_string(),
                self.crecs.iter().map(vec_bytes).sum(),
            ),
            (
                "samplers".to_string(),
                self.samplers.iter().map(|s| s.bytes()).sum(),
            ),
        ]
    }

    pub fn elastic_energy_sum(&self) -> f64 {
        let kn = self.law.params.kn;
        let mut u = 0.0;
        let pair_i = self.nl.pair_i();
        for (&i, &j) in pair_i.iter().zip(&self.nl.pair_j) {
            let (i, j) = (i as usize, j as usize);
            let rs = self.p.radius[i] + self.p.radius[j];
            let r = self.domain.delta(&self.p.x[i], &self.p.x[j]).norm();
            let delta = rs - r;
            if delta > 0.0 {
                u += F::elastic_energy(kn, delta, rs);
            }
        }
        if let Some(wl) = self.walls.law() {
            let kw = wl.params.kn;
            for i in 0..self.p.len() {
                let ri = self.p.radius[i];
                for pl in self.walls.planes() {
                    let gap = pl.sign * (self.p.x[i][pl.axis] - pl.pos);
                    if gap < ri {
                        u += F::elastic_energy(kw, ri - gap, 2.0 * ri);
                    }
                }
            }
        }
        u + self.tangential_energy()
    }

    /// Energy in the tangential springs of the closed contacts, s k_t |u|^2 / 2 (A2; s the
    /// form's spring factor), pairs and walls.
    pub fn tangential_energy(&self) -> f64 {
        let p = &self.p;
        let u2 = |h: &T::History| {
            let a = T::to_array(h);
            a[0] * a[0] + a[1] * a[1] + a[2] * a[2]
        };
        let mut e = 0.0;
        let kt = self.law.params.kt;
        let ktw = self.walls.law().map_or(0.0, |wl| wl.params.kt);
        let planes = self.walls.planes();
        let mut wall_e = 0.0;
        self.for_each_history(
            |i, j, h| {
                let rs = p.radius[i] + p.radius[j];
                let delta = rs - self.domain.delta(&p.x[i], &p.x[j]).norm();
                let (sf, _) = F::factors(delta.max(0.0), rs, false);
                e += 0.5 * sf * kt * u2(h);
            },
            |i, w, h| {
                let pl = planes[w];
                let ri = p.radius[i];
                let delta = ri - pl.sign * (p.x[i][pl.axis] - pl.pos);
                let (sf, _) = F::factors(delta.max(0.0), 2.0 * ri, false);
                wall_e += 0.5 * sf * ktw * u2(h);
            },
        );
        e + wall_e
    }
}

impl<F: Form, T: Friction, D: Domain, W: Walls<F, T>, G: Body> Simulation
    for Engine<F, T, D, W, G>
{
    fn run(&mut self, n: u64) -> Result<()> {
        Engine::run(self, n)
    }
    fn particles(&self) -> &Particles {
        &self.p
    }
    fn particles_mut(&mut self) -> &mut Particles {
        &mut self.p
    }
    fn invalidate(&mut self) {
        Engine::invalidate(self)
    }
    fn step(&self) -> u64 {
        self.step
    }
    fn time(&self) -> f64 {
        self.time
    }
    fn dt(&self) -> f64 {
        self.dt
    }
    fn contact_time(&self) -> f64 {
        Engine::contact_time(self)
    }
    fn law(&self) -> LawSpec {
        self.law.params
    }
    fn wall_law(&self) -> Option<LawSpec> {
        self.walls.law().map(|l| l.params)
    }
    fn diag(&self) -> StepDiag {
        self.diag.clone()
    }
    fn list_counts(&self) -> (u64, u64) {
        (self.nl.builds, self.nl.prunes)
    }
    fn components(&self) -> Vec<String> {
        self.component_list()
    }
    fn memory(&self) -> Vec<(String, usize)> {
        self.memory_list()
    }
    fn volume(&self) -> f64 {
        self.domain.volume()
    }
    fn cell(&self) -> (crate::M3, crate::V3) {
        (self.domain.h(), self.domain.origin())
    }
    fn wrapped(&self, x: crate::V3) -> crate::V3 {
        let mut y = x;
        let mut im = [0i32; 3];
        self.domain.wrap(&mut y, &mut im);
        y
    }
    fn elastic_energy(&self) -> f64 {
        self.elastic_energy_sum()
    }
    fn save_checkpoint(&self, w: &mut crate::checkpoint::Writer) {
        self.save_state(w)
    }
    fn request_stats(&mut self) {
        self.want_stats = true;
    }
    fn domain_observables(&self) -> Vec<(String, f64)> {
        self.domain.observables()
    }
    fn set_stress(&mut self, p_ext: f64, tau_ext: f64) -> Result<()> {
        self.domain.set_stress(p_ext, tau_ext)
    }
    fn set_rate(&mut self, rate: f64, gradient: bool, p_ext: f64) -> Result<()> {
        self.domain.set_rate(rate, gradient, p_ext)
    }
    fn contacts(&self) -> Vec<(u32, u32, crate::V3, crate::V3)> {
        self.contact_list()
            .into_iter()
            .map(|(i, j, d, f)| (self.p.id[i], self.p.id[j], d, f))
            .collect()
    }
    fn particle_stats(&self) -> &[[f64; 10]] {
        &self.pstats
    }
    fn wall_forces(&self) -> Vec<crate::V3> {
        self.diag.wall_force[..self.walls.planes().len()].to_vec()
    }
    fn wall_impulse(&self) -> Vec<crate::V3> {
        self.wall_impulse[..self.walls.planes().len()].to_vec()
    }
    fn load_checkpoint(&mut self, r: &crate::checkpoint::Reader) -> Result<()> {
        self.load_state(r)
    }
    fn add_sampler(&mut self, kind: &str, spec: crate::sampling::SamplerSpec) -> Result<()> {
        Engine::add_sampler(self, kind, spec)
    }
    fn samplers(&self) -> Vec<(String, String)> {
        self.samplers
            .iter()
            .map(|s| (s.kind().to_string(), s.table().to_string()))
            .collect()
    }
    fn take_tables(&mut self) -> Vec<(String, Table)> {
        let mut out = Vec::new();
        for s in self.samplers.iter_mut() {
            let name = s.table();
            out.extend(s.take().into_iter().map(|t| (name.to_string(), t)));
        }
        out
    }
}

use crate::checkpoint::{flat_v3, unflat_v3, Reader, Writer};

impl<F: Form, T: Friction, D: Domain, W: Walls<F, T>, G: Body> Engine<F, T, D, W, G> {
    /// Everything needed to continue bitwise identically: internal particle order, the pair
    /// list as built (rebuild timing depends on the displacement bound or x_build), histories,
    /// last forces. The inner (pruned) list is not saved: it changes no result.
    pub fn save_state(&self, w: &mut Writer) {
        let p = &self.p;
        w.text("engine.kind", &self.kind_string());
        w.u64s("engine.step", &[self.step]);
        w.f64s("engine.time", &[self.time, self.dt]);
        w.f64s("p.x", &flat_v3(&p.x));
        w.f64s("p.v", &flat_v3(&p.v));
        w.f64s("p.omega", &flat_v3(&p.omega));
        w.f64s("p.force", &flat_v3(&p.force));
        w.f64s("p.torque", &flat_v3(&p.torque));
        w.f64s("p.radius", &p.radius);
        w.i32s(
            "p.image",
            &p.image.iter().flatten().cloned().collect::<Vec<_>>(),
        );
        w.u32s("p.id", &p.id);
        let nl = &self.nl;
        w.u32s("nl.pair_j", &nl.pair_j);
        w.u32s("nl.own_start", &nl.own_start);
        let xb: Vec<f64> = nl.x_build.iter().flatten().map(|&c| c as f64).collect();
        w.f64s("nl.x_build", &xb);
        // (the rounding of x_build in earlier versions; kept for their readers)
        w.f64s("nl.xb_eps", &[0.0]);
        w.u32s(
            "nl.pair_img",
            &nl.pair_img.iter().map(|&c| c as u32).collect::<Vec<_>>(),
        );
        let u = nl.frame_v;
        w.f64s("nl.moved", &[nl.moved, nl.drift_eps, u[0], u[1], u[2]]);
        w.u64s("nl.meta", &[nl.builds, nl.valid as u64]);
        // contact histories by particle ids (placed back into the list on loading)
        let (hp, hw) = self.carried_histories();
        w.u32s(
            "hist.pair_ids",
            &hp.iter().flat_map(|e| [e.0, e.1]).collect::<Vec<_>>(),
        );
        w.f64s(
            "hist.pairs",
            &hp.iter()
                .flat_map(|e| T::to_array(&e.2))
                .collect::<Vec<_>>(),
        );
        w.u32s(
            "hist.wall_ids",
            &hw.iter()
                .flat_map(|e| [e.0, e.1 as u32])
                .collect::<Vec<_>>(),
        );
        w.f64s(
            "hist.walls",
            &hw.iter()
                .flat_map(|e| T::to_array(&e.2))
                .collect::<Vec<_>>(),
        );
        w.f64s("domain", &self.domain.save_state());
        let imp: Vec<f64> = self
            .wall_impulse
            .iter()
            .flat_map(|v| [v.x, v.y, v.z])
            .collect();
        w.f64s("walls.impulse", &imp);
        let wf: Vec<f64> = self
            .diag
            .wall_force
            .iter()
            .flat_map(|v| [v.x, v.y, v.z])
            .collect();
        w.f64s("walls.force", &wf);
        // the samplers' open windows (closed ones are taken by the front end before saving)
        for s in &self.samplers {
            w.f64s(&format!("sampler.{}", s.kind()), &s.save());
        }
    }

    fn kind_string(&self) -> String {
        format!(
            "{}|{}|walls={}|gravity={}",
            crate::contact::Law::<F, T>::name(),
            D::NAME,
            W::ON,
            G::ON
        )
    }

    pub fn load_state(&mut self, r: &Reader) -> Result<()> {
        let bad = |m: String| crate::error::Error::Io {
            message: format!("checkpoint: {m}"),
        };
        let kind = r.text("engine.kind")?;
        if kind != self.kind_string() {
            return Err(bad(format!(
                "written by a '{kind}' simulation, this one is '{}'",
                self.kind_string()
            )));
        }
        let n = self.p.len();
        let id = r.u32s("p.id")?;
        if id.len() != n {
            return Err(bad(format!(
                "{} particles, this simulation has {n}",
                id.len()
            )));
        }
        // radii must match particle by particle (same parameters, same seed)
        let radius = r.f64s("p.radius")?;
        let mut mine = vec![0.0; n];
        for i in 0..n {
            mine[self.p.id[i] as usize] = self.p.radius[i];
        }
        for (k, &i) in id.iter().enumerate() {
            if (i as usize) >= n || mine[i as usize] != radius[k] {
                return Err(bad("particle sizes differ from this simulation's".into()));
            }
        }
        // re-order our particles into the checkpoint's internal order
        let mut where_id = vec![0usize; n];
        for i in 0..n {
            where_id[self.p.id[i] as usize] = i;
        }
        let perm: Vec<usize> = id.iter().map(|&k| where_id[k as usize]).collect();
        self.p.permute(&perm);
        self.p.x = unflat_v3(&r.f64s("p.x")?);
        self.p.v = unflat_v3(&r.f64s("p.v")?);
        self.p.omega = unflat_v3(&r.f64s("p.omega")?);
        self.p.force = unflat_v3(&r.f64s("p.force")?);
        self.p.torque = unflat_v3(&r.f64s("p.torque")?);
        self.p.image = r
            .i32s("p.image")?
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        let nl = &mut self.nl;
        nl.pair_j = r.u32s("nl.pair_j")?;
        nl.own_start = r.u32s("nl.own_start")?;
        if nl.own_start.len() != n + 1 {
            return Err(bad(
                "pair list offsets do not match the particle count".into()
            ));
        }
        nl.inner_valid = false;
        nl.x_build = r
            .f64s("nl.x_build")?
            .chunks_exact(3)
            .map(|c| [c[0] as f32, c[1] as f32, c[2] as f32])
            .collect();
        let meta = r.u64s("nl.meta")?;
        nl.builds = meta[0];
        nl.valid = meta[1] != 0;
        let ids = r.u32s("hist.pair_ids")?;
        let vals = r.f64s("hist.pairs")?;
        let pairs: Vec<(u32, u32, T::History)> = ids
            .chunks_exact(2)
            .zip(vals.chunks_exact(3))
            .map(|(a, v)| (a[0], a[1], T::from_array([v[0], v[1], v[2]])))
            .collect();
        let ids = r.u32s("hist.wall_ids")?;
        let vals = r.f64s("hist.walls")?;
        let walls: Vec<(u32, u8, T::History)> = ids
            .chunks_exact(2)
            .zip(vals.chunks_exact(3))
            .map(|(a, v)| (a[0], a[1] as u8, T::from_array([v[0], v[1], v[2]])))
            .collect();
        if pairs.iter().any(|e| e.0 as usize >= n || e.1 as usize >= n)
            || walls
                .iter()
                .any(|e| e.0 as usize >= n || e.1 as usize >= crate::components::MAX_WALLS)
        {
            return Err(bad("contact history refers to unknown particles".into()));
        }
        self.set_histories(&pairs, &walls);
        self.domain.load_state(&r.f64s("domain")?)?;
        // the pairs' periodic images follow from the positions at the last build
        if r.has("nl.pair_img") && r.has("nl.moved") {
            let img = r.u32s("nl.pair_img")?;
            if img.len() != self.nl.pair_j.len() || img.iter().any(|&c| c >= 27) {
                return Err(bad("pair image codes do not match the pair list".into()));
            }
            self.nl.pair_img = img.iter().map(|&c| c as u8).collect();
            let m = r.f64s("nl.moved")?;
            // (two values before the bound's frame velocity was kept: the frame at rest)
            if m.len() != 2 && m.len() != 5 {
                return Err(bad("list displacement bound has the wrong length".into()));
            }
            self.nl.moved = m[0];
            self.nl.drift_eps = m[1];
            self.nl.frame_v = if m.len() == 5 {
                [m[2], m[3], m[4]]
            } else {
                [0.0; 3]
            };
        } else {
            // an older checkpoint: the images follow from the positions at the last build;
            // the displacement since then is not known, so the list is rebuilt
            let hinv = self
                .domain
                .h()
                .try_inverse()
                .unwrap_or_else(crate::M3::zeros);
            let xb: Vec<crate::V3> = self.nl.x_build.iter().map(crate::neighbor::widen).collect();
            self.nl.set_images(&xb, &self.domain, &hinv);
            self.nl.valid = false;
        }
        if !self.nl.x_build.is_empty() {
            // a deforming cell's list from an earlier version, judged by these positions: its
            // displacement bound was not kept, so it is rebuilt
            self.nl.valid = false;
        }
        // (not saved: it follows from the radii and the skin)
        self.nl.cut = 2.0 * self.p.max_radius() + self.nl.skin;
        for (k, c) in r.f64s("walls.impulse")?.chunks_exact(3).enumerate() {
            self.wall_impulse[k] = crate::V3::new(c[0], c[1], c[2]);
        }
        for (k, c) in r.f64s("walls.force")?.chunks_exact(3).enumerate() {
            self.diag.wall_force[k] = crate::V3::new(c[0], c[1], c[2]);
        }
        // a sampler absent from the checkpoint starts a fresh window
        for s in self.samplers.iter_mut() {
            let key = format!("sampler.{}", s.kind());
            if r.has(&key) {
                s.load(&r.f64s(&key)?)?;
            }
        }
        let st = r.u64s("engine.step")?;
        let tt = r.f64s("engine.time")?;
        self.step = st[0];
        self.time = tt[0];
        self.dt = tt[1];
        self.mark_forces_valid();
        Ok(())
    }
}
