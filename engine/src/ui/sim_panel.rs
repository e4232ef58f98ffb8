//! The simulation's section of the overlay: a slider for every flock's and every emitter's
//! tunable numbers, written into the running `World` as they move, so the next fixed step
//! already uses them (issue 8: parameters live in the level and change live in the overlay).
//!
//! The knobs are tables of (name, range, get, set), and the sliders and `apply` (what tests and
//! scripts call) both go through `Knob::write`, so an edit made either way has the same effect:
//! the value is clamped to the knob's range, a min/max pair stays ordered (raising a minimum
//! past its maximum pushes the maximum along), and an emitter's capacity follows its rate and
//! longest life so a faster stream is not silently dropped at the old capacity.

use super::panels::Panel;
use crate::sim::boids::BoidParams;
use crate::sim::particles::{steady_state_capacity, Blend, EmitterParams};
use crate::sim::World;

/// One tunable number of a parameter struct `P`.
pub struct Knob<P> {
    pub name: &'static str,
    pub min: f32,
    pub max: f32,
    /// A logarithmic slider, for quantities that span decades (rates, weights).
    pub log: bool,
    pub get: fn(&P) -> f32,
    set: fn(&mut P, f32),
}

impl<P> Knob<P> {
    /// Sets the value, clamped to the knob's range; returns what was stored.
    pub fn write(&self, params: &mut P, value: f32) -> f32 {
        let v = if value.is_nan() { (self.get)(params) } else { value.clamp(self.min, self.max) };
        (self.set)(params, v);
        v
    }
}

const fn knob<P>(name: &'static str, min: f32, max: f32, log: bool, get: fn(&P) -> f32, set: fn(&mut P, f32)) -> Knob<P> {
    Knob { name, min, max, log, get, set }
}

/// The flock's knobs, in the order the rules are served (notes §8), then limits and radii.
pub const FLOCK_KNOBS: &[Knob<BoidParams>] = &[
    knob("obstacle weight", 0.0, 20.0, false, |p| p.obstacle_weight, |p, v| p.obstacle_weight = v),
    knob("avoid distance m", 0.1, 20.0, false, |p| p.avoid_distance, |p, v| p.avoid_distance = v),
    knob("separation weight", 0.0, 200.0, false, |p| p.separation_weight, |p, v| p.separation_weight = v),
    knob("alignment weight", 0.0, 20.0, false, |p| p.alignment_weight, |p, v| p.alignment_weight = v),
    knob("cohesion weight", 0.0, 20.0, false, |p| p.cohesion_weight, |p, v| p.cohesion_weight = v),
    knob("goal weight", 0.0, 20.0, false, |p| p.goal_weight, |p, v| p.goal_weight = v),
    knob("wander weight", 0.0, 20.0, false, |p| p.wander_weight, |p, v| p.wander_weight = v),
    knob(
        "speed min m/s",
        0.0,
        50.0,
        false,
        |p| p.speed_min,
        |p, v| {
            p.speed_min = v;
            p.speed_max = p.speed_max.max(v);
        },
    ),
    knob(
        "speed max m/s",
        0.1,
        50.0,
        false,
        |p| p.speed_max,
        |p, v| {
            p.speed_max = v;
            p.speed_min = p.speed_min.min(v);
        },
    ),
    knob("accel max m/s2", 0.1, 200.0, true, |p| p.accel_max, |p, v| p.accel_max = v),
    knob("separation radius m", 0.05, 20.0, false, |p| p.separation_radius, |p, v| p.separation_radius = v),
    knob("neighbour radius m", 0.1, 20.0, false, |p| p.neighbour_radius, |p, v| p.neighbour_radius = v),
    knob("max neighbours", 0.0, 128.0, false, |p| p.max_neighbours as f32, |p, v| p.max_neighbours = v.round() as u32),
    knob("bank max deg", 0.0, 90.0, false, |p| p.bank_max_deg, |p, v| p.bank_max_deg = v),
];

/// The emitter's knobs. Wind and gravity are per axis (gravity's x and z are rarely wanted).
pub const EMITTER_KNOBS: &[Knob<EmitterParams>] = &[
    knob("rate /s", 0.0, 20_000.0, true, |p| p.rate_per_s, |p, v| p.rate_per_s = v),
    knob(
        "life min s",
        0.05,
        20.0,
        true,
        |p| p.life_min_s,
        |p, v| {
            p.life_min_s = v;
            p.life_max_s = p.life_max_s.max(v);
        },
    ),
    knob(
        "life max s",
        0.05,
        20.0,
        true,
        |p| p.life_max_s,
        |p, v| {
            p.life_max_s = v;
            p.life_min_s = p.life_min_s.min(v);
        },
    ),
    knob(
        "speed min m/s",
        0.0,
        50.0,
        false,
        |p| p.speed_min,
        |p, v| {
            p.speed_min = v;
            p.speed_max = p.speed_max.max(v);
        },
    ),
    knob(
        "speed max m/s",
        0.0,
        50.0,
        false,
        |p| p.speed_max,
        |p, v| {
            p.speed_max = v;
            p.speed_min = p.speed_min.min(v);
        },
    ),
    knob("spread deg", 0.0, 180.0, false, |p| p.cone_half_angle_deg, |p, v| p.cone_half_angle_deg = v),
    knob("gravity y m/s2", -30.0, 30.0, false, |p| p.gravity[1], |p, v| p.gravity[1] = v),
    knob("drag /s", 0.0, 20.0, false, |p| p.drag_per_s, |p, v| p.drag_per_s = v),
    knob("wind x m/s", -20.0, 20.0, false, |p| p.wind[0], |p, v| p.wind[0] = v),
    knob("wind y m/s", -20.0, 20.0, false, |p| p.wind[1], |p, v| p.wind[1] = v),
    knob("wind z m/s", -20.0, 20.0, false, |p| p.wind[2], |p, v| p.wind[2] = v),
    knob("restitution", 0.0, 1.0, false, |p| p.restitution, |p, v| p.restitution = v),
    knob("friction", 0.0, 1.0, false, |p| p.friction, |p, v| p.friction = v),
    knob("spawn radius m", 0.0, 5.0, false, |p| p.spawn_radius, |p, v| p.spawn_radius = v),
];

/// What an edit is aimed at: the world's flock or emitter number `n`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Target {
    Flock(usize),
    Emitter(usize),
}

fn find<'k, P>(knobs: &'k [Knob<P>], what: &str, name: &str) -> Result<&'k Knob<P>, String> {
    knobs.iter().find(|k| k.name == name).ok_or_else(|| {
        let names: Vec<&str> = knobs.iter().map(|k| k.name).collect();
        format!("unknown {what} parameter '{name}' (expected one of: {})", names.join(", "))
    })
}

/// Write one emitter's edited parameters into its system: the capacity follows rate and life
/// (`set_params` reallocates only when it changed).
fn commit_emitter(system: &mut crate::sim::particles::ParticleSystem, mut params: EmitterParams) {
    params.capacity = steady_state_capacity(params.rate_per_s, params.life_max_s);
    system.set_params(params);
}

/// Set parameter `name` (a knob's name) of `target` to `value`, as moving its slider does.
/// Returns the value stored (clamped to the knob's range); an unknown target or name is an
/// error naming it.
pub fn apply(world: &mut World, target: Target, name: &str, value: f32) -> Result<f32, String> {
    match target {
        Target::Flock(i) => {
            let count = world.flocks.len();
            let flock = world.flocks.get_mut(i).ok_or_else(|| format!("no flock {i} (the world has {count})"))?;
            Ok(find(FLOCK_KNOBS, "flock", name)?.write(&mut flock.params, value))
        }
        Target::Emitter(i) => {
            let count = world.emitters.len();
            let system = world.emitters.get_mut(i).ok_or_else(|| format!("no emitter {i} (the world has {count})"))?;
            let mut params = system.params.clone();
            let stored = find(EMITTER_KNOBS, "emitter", name)?.write(&mut params, value);
            commit_emitter(system, params);
            Ok(stored)
        }
    }
}

/// The overlay panel over a running world. `controls` gets each slider's rectangle, named
/// "<flock|emitter> <n>/<knob>", so scripted input (tests) can drag it like a user.
pub struct SimPanel<'a> {
    pub world: &'a mut World,
    pub controls: Vec<(String, egui::Rect)>,
    /// The panel and each flock's and emitter's section start open (egui remembers them after
    /// the first frame); closed in the demo, where the renderer's section comes first.
    pub open: bool,
}

impl<'a> SimPanel<'a> {
    pub fn new(world: &'a mut World) -> SimPanel<'a> {
        SimPanel {
            world,
            controls: Vec::new(),
            open: false,
        }
    }
}

fn slider<'v, P>(k: &Knob<P>, v: &'v mut f32) -> egui::Slider<'v> {
    egui::Slider::new(v, k.min..=k.max).logarithmic(k.log).text(k.name)
}

impl Panel for SimPanel<'_> {
    fn title(&self) -> &str {
        "simulation"
    }

    fn default_open(&self) -> bool {
        self.open
    }

    fn ui(&mut self, ui: &mut egui::Ui) {
        // A discarded egui pass lays out again: keep only the last pass's rectangles.
        self.controls.clear();
        let w = &mut *self.world;
        for (i, flock) in w.flocks.iter_mut().enumerate() {
            let label = w.flock_names.get(i).map_or_else(|| format!("flock {i}"), |n| format!("flock {i} '{n}'"));
            egui::CollapsingHeader::new(format!("{label}: {} boids", flock.len()))
                .id_salt(("flock", i))
                .default_open(self.open)
                .show(ui, |ui| {
                    for k in FLOCK_KNOBS {
                        let mut v = (k.get)(&flock.params);
                        let r = ui.add(slider(k, &mut v));
                        if r.changed() {
                            k.write(&mut flock.params, v);
                        }
                        self.controls.push((format!("flock {i}/{}", k.name), r.rect));
                    }
                });
        }
        for (i, system) in w.emitters.iter_mut().enumerate() {
            let label = w.emitter_names.get(i).map_or_else(|| format!("emitter {i}"), |n| format!("emitter {i} '{n}'"));
            let live = system.particles.len();
            egui::CollapsingHeader::new(format!("{label}: {live} live"))
                .id_salt(("emitter", i))
                .default_open(self.open)
                .show(ui, |ui| {
                    let mut params = system.params.clone();
                    let mut changed = false;
                    for k in EMITTER_KNOBS {
                        let mut v = (k.get)(&params);
                        let r = ui.add(slider(k, &mut v));
                        if r.changed() {
                            k.write(&mut params, v);
                            changed = true;
                        }
                        self.controls.push((format!("emitter {i}/{}", k.name), r.rect));
                    }
                    let mut additive = params.blend == Blend::Additive;
                    let r = ui.checkbox(&mut additive, "additive blend");
                    if r.changed() {
                        params.blend = if additive { Blend::Additive } else { Blend::Alpha };
                        changed = true;
                    }
                    self.controls.push((format!("emitter {i}/additive blend"), r.rect));
                    if changed {
                        commit_emitter(system, params);
                    }
                });
        }
        if w.flocks.is_empty() && w.emitters.is_empty() {
            ui.label("no flocks or emitters in this level");
        }
    }
}
