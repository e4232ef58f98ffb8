//! The overlay's simulation panel (engine/src/ui/sim_panel.rs): edits through its model
//! (`apply`) and through its sliders (scripted pointer input, no display) change the running
//! world's parameters at once, and the overlay with the panel open renders with validation clean.

use engine::app::headless::{Offscreen, OFFSCREEN_FORMAT};
use engine::ui::sim_panel::{apply, Target, EMITTER_KNOBS, FLOCK_KNOBS};
use engine::ui::{headless_input, FrameStats, Overlay, Panel, SimPanel};
use engine::render::renderer::{Lighting, Renderer};
use engine::scene::GpuScene;
use engine::sim::particles::Blend;
use engine::sim::World;
use engine::sim::level::world_from_spawns;
use glam::Vec3;
use pack::Material;

mod common;
use common::{assert_clean, gpu, spawn, square_pack};

/// A flock of doves and a fountain, as the temple authors them.
fn world() -> World {
    let spawns = [
        spawn("doves", "boids", [0.0, 9.0, 9.0], r#"{ "count": 32, "radius": 8.0, "speed": 3.0 }"#),
        spawn(
            "fountain_spray",
            "particles",
            [0.0, 1.95, 10.0],
            r#"{ "rate_per_s": 200, "lifetime_s": 1.2, "speed": 2.5, "blend": "alpha" }"#,
        ),
    ];
    world_from_spawns(&spawns, &[], Vec3::new(-20.0, 0.0, -20.0), Vec3::new(20.0, 12.0, 22.0))
}

#[test]
fn edits_through_the_panel_model_reach_the_running_simulation() {
    let mut w = world();
    assert_eq!(apply(&mut w, Target::Flock(0), "separation weight", 42.0), Ok(42.0));
    assert_eq!(w.flocks[0].params.separation_weight, 42.0);
    // A minimum raised past its maximum pushes the maximum along; the next step flies faster.
    assert_eq!(apply(&mut w, Target::Flock(0), "speed min m/s", 12.0), Ok(12.0));
    assert_eq!((w.flocks[0].params.speed_min, w.flocks[0].params.speed_max), (12.0, 12.0));
    w.update(1.0 / 60.0);
    let s = w.flocks[0].state();
    for i in 0..s.len() {
        let v = s.velocity(i).length();
        assert!((v - 12.0).abs() < 1e-3, "dove {i} flies at the new speed: {v}");
    }
    // Out of range values are clamped to the slider's range, as a slider would.
    assert_eq!(apply(&mut w, Target::Flock(0), "alignment weight", 1e9), Ok(20.0));

    // An emitter's rate: its capacity follows, so the faster stream is not dropped.
    let before = w.emitters[0].particles.capacity();
    assert_eq!(apply(&mut w, Target::Emitter(0), "rate /s", 2000.0), Ok(2000.0));
    let e = &w.emitters[0];
    assert_eq!(e.params.rate_per_s, 2000.0);
    assert!(e.particles.capacity() as f32 >= 2000.0 * e.params.life_max_s && e.particles.capacity() > before);
    assert_eq!(apply(&mut w, Target::Emitter(0), "wind x m/s", 5.0), Ok(5.0));
    assert_eq!(apply(&mut w, Target::Emitter(0), "gravity y m/s2", -3.0), Ok(-3.0));
    assert_eq!((w.emitters[0].params.wind, w.emitters[0].params.gravity), ([5.0, 0.0, 0.0], [0.0, -3.0, 0.0]));
    for _ in 0..60 {
        w.update(1.0 / 60.0);
    }
    let e = &w.emitters[0];
    assert!(e.particles.len() > before, "{} live after 1 s at 2000/s (capacity was {before})", e.particles.len());
    assert_eq!(e.counters.dropped, 0);

    // Mistakes name what was wrong.
    let err = apply(&mut w, Target::Flock(0), "colour", 1.0).unwrap_err();
    assert!(err.starts_with("unknown flock parameter 'colour' (expected one of: obstacle weight,"), "{err}");
    assert_eq!(apply(&mut w, Target::Emitter(3), "rate /s", 1.0).unwrap_err(), "no emitter 3 (the world has 1)");
}

#[test]
fn every_knob_reads_back_what_it_wrote() {
    let mut w = world();
    for k in FLOCK_KNOBS {
        let v = if k.name == "max neighbours" { 7.0 } else { k.min + 0.25 * (k.max - k.min) };
        let stored = apply(&mut w, Target::Flock(0), k.name, v).unwrap();
        assert_eq!((k.get)(&w.flocks[0].params), stored, "flock knob '{}'", k.name);
    }
    for k in EMITTER_KNOBS {
        let v = k.min + 0.25 * (k.max - k.min);
        let stored = apply(&mut w, Target::Emitter(0), k.name, v).unwrap();
        assert_eq!((k.get)(&w.emitters[0].params), stored, "emitter knob '{}'", k.name);
    }
}

/// Lay the panel out for one frame at `time_s` with `events`; returns its control rectangles.
fn frame(ctx: &egui::Context, w: &mut World, time_s: f64, events: Vec<egui::Event>) -> Vec<(String, egui::Rect)> {
    let mut panel = SimPanel::new(w);
    panel.open = true;
    let mut out = ctx.run_ui(headless_input(800, 2000, time_s, events), |ui| {
        egui::ScrollArea::vertical().show(ui, |ui| panel.ui(ui));
    });
    // Nothing is drawn here: drop the font atlas upload on purpose (epaint asserts otherwise).
    out.textures_delta.clear();
    panel.controls
}

fn click(at: egui::Pos2) -> [egui::Event; 3] {
    let button = |pressed| egui::Event::PointerButton {
        pos: at,
        button: egui::PointerButton::Primary,
        pressed,
        modifiers: egui::Modifiers::NONE,
    };
    [egui::Event::PointerMoved(at), button(true), button(false)]
}

#[test]
fn sliders_and_the_blend_box_edit_the_world_without_a_display() {
    let ctx = egui::Context::default();
    let mut w = world();
    let rect_of = |controls: &[(String, egui::Rect)], name: &str| controls.iter().find(|(n, _)| n == name).unwrap_or_else(|| panic!("no control '{name}'")).1;
    let controls = frame(&ctx, &mut w, 0.0, vec![]);
    assert_eq!(controls.len(), FLOCK_KNOBS.len() + EMITTER_KNOBS.len() + 1);
    // The slider's rail starts at the left of its row: a press at its left end is the minimum.
    let sep = rect_of(&controls, "flock 0/separation weight");
    assert!(w.flocks[0].params.separation_weight > 0.0);
    let [moved, down, up] = click(sep.left_center() + egui::vec2(1.0, 0.0));
    frame(&ctx, &mut w, 0.1, vec![moved, down]);
    frame(&ctx, &mut w, 0.2, vec![up]);
    assert_eq!(w.flocks[0].params.separation_weight, 0.0, "the slider's minimum reached the flock");
    // The emitter's blend box flips the running emitter to additive.
    assert_eq!(w.emitters[0].params.blend, Blend::Alpha);
    let blend = rect_of(&controls, "emitter 0/additive blend");
    let [moved, down, up] = click(blend.left_center() + egui::vec2(6.0, 0.0));
    frame(&ctx, &mut w, 0.3, vec![moved, down]);
    frame(&ctx, &mut w, 0.4, vec![up]);
    assert_eq!(w.emitters[0].params.blend, Blend::Additive);
}

#[test]
fn the_overlay_renders_the_open_simulation_panel_with_validation_clean() {
    let gpu = gpu();
    let (width, height) = (640u32, 900u32);
    let pack = square_pack("wall", 4.0, -6.0, Material::default());
    let mut target = Offscreen::new(&gpu, width, height).unwrap();
    let mut renderer = Renderer::new(&gpu, OFFSCREEN_FORMAT, 1).unwrap();
    let mut scene = GpuScene::upload(&gpu, &pack, renderer.layouts()).unwrap();
    let mut overlay = Overlay::new(&gpu, OFFSCREEN_FORMAT, 1).unwrap();
    let camera = engine::scene::camera::Camera {
        position: Vec3::ZERO,
        yaw: 0.0,
        pitch: 0.0,
        fov_y: 60f32.to_radians(),
        near: 0.1,
    };
    let mut w = world();
    let mut heights = Vec::new();
    for f in 0..3u32 {
        if f == 2 {
            apply(&mut w, Target::Emitter(0), "rate /s", 800.0).unwrap();
        }
        w.update(1.0 / 60.0);
        engine::sim::level::prepare_frame(&w, &mut renderer, &scene, &camera);
        let mut drawn = 0;
        let t = target
            .render_with(&gpu, &mut renderer, &scene, &camera, &Lighting::default(), true, &mut overlay, |overlay, renderer| {
                let mut panel = SimPanel::new(&mut w);
                panel.open = true;
                overlay.build(headless_input(width, height, f as f64 / 60.0, vec![]), renderer, &mut [&mut panel]);
                drawn = panel.controls.len();
            })
            .unwrap();
        overlay.push_frame(t.frame_ms, t.gpu_ms, FrameStats::read(&gpu, &renderer, 0));
        assert_eq!(drawn, FLOCK_KNOBS.len() + EMITTER_KNOBS.len() + 1, "frame {f}: the panel laid out every slider");
        let [_, y0, _, y1] = overlay.window_rect_px().expect("the overlay window is shown");
        heights.push(y1 - y0);
    }
    assert_eq!(w.emitters[0].params.rate_per_s, 800.0);
    assert!(heights[2] > 400.0, "the window holds the open panel: {heights:?}");
    overlay.destroy(&gpu);
    scene.destroy(&gpu);
    renderer.destroy(&gpu);
    target.destroy(&gpu);
    assert_clean(&gpu);
}
