//! What the overlay shows. Every section is a `Panel`: the renderer's own (frame-time graph,
//! counters, switches) and whatever a caller adds for the frame (simulation parameters later),
//! so a new panel is one trait impl handed to `Overlay::build`, not a change to the overlay.

use super::history::{FrameHistory, Ring};
use super::FrameStats;
use crate::render::scale::{RenderScale, Upscaler};
use crate::render::renderer::{AntiAliasing, Renderer};
use crate::render::visibility::LOD_BUCKETS;
use egui::{Color32, Pos2, Rect, Sense, Shape, Stroke, Vec2};

/// One collapsible section of the overlay window.
pub trait Panel {
    fn title(&self) -> &str;
    fn ui(&mut self, ui: &mut egui::Ui);
    /// Whether the section starts open (egui remembers the user's choice after that).
    fn default_open(&self) -> bool {
        false
    }
}

/// Where each labelled control was laid out last frame (points), so scripted input (tests, the
/// headless demo) can press it like a user would.
pub type ControlRects = Vec<(&'static str, Rect)>;

pub const CPU_COLOR: Color32 = Color32::from_rgb(255, 190, 60);
pub const GPU_COLOR: Color32 = Color32::from_rgb(90, 200, 255);

/// The renderer's section: reads its counters and flips its real switches.
pub struct RendererPanel<'a> {
    pub renderer: &'a mut Renderer,
    pub history: &'a FrameHistory,
    pub last: &'a FrameStats,
    pub controls: &'a mut ControlRects,
}

impl Panel for RendererPanel<'_> {
    fn title(&self) -> &str {
        "renderer"
    }

    fn ui(&mut self, ui: &mut egui::Ui) {
        frame_time_graph(ui, self.history);
        ui.separator();
        counters(ui, self.renderer, self.last);
        ui.separator();
        self.switches(ui);
    }
}

impl RendererPanel<'_> {
    fn switches(&mut self, ui: &mut egui::Ui) {
        let r = &mut *self.renderer;
        let mut control = |name: &'static str, response: egui::Response| {
            self.controls.push((name, response.rect));
        };
        control("depth pre-pass", ui.checkbox(&mut r.prepass, "depth pre-pass"));
        control("frustum culling", ui.checkbox(&mut r.visibility.culling, "frustum culling"));
        control("occlusion culling", ui.checkbox(&mut r.visibility.occlusion, "occlusion culling (CPU depth buffer of the largest static occluders)"));
        control("LOD selection", ui.checkbox(&mut r.visibility.lod_selection, "LOD selection (off: LOD 0 everywhere)"));
        control("freeze LOD", ui.checkbox(&mut r.visibility.freeze_lod, "freeze LODs (keep the last choice per instance)"));
        control("count shaded fragments", ui.checkbox(&mut r.count_fragments, "count shaded fragments (an atomic per fragment)"));
        control("depth view", ui.checkbox(&mut r.depth_view, "depth view (the depth buffer instead of the frame)"));
        control("sky", ui.checkbox(&mut r.sky, "sky (the baked level's sky and sun disc as the background)"));
        control("material maps", ui.checkbox(&mut r.material_maps, "material maps (normal, metallic-roughness, occlusion, emissive)"));
        control("specular", ui.checkbox(&mut r.specular, "specular (off: diffuse only)"));
        control("transparency", ui.checkbox(&mut r.transparency, "transparency (BLEND materials; off: not drawn)"));
        control("bicubic lightmaps", ui.checkbox(&mut r.bicubic_lightmaps, "bicubic lightmaps (a cubic B-spline; off: bilinear)"));
        control("reflection probes", ui.checkbox(&mut r.reflections, "reflection probes (off: the lightmap's light as the environment)"));
        // Adaptive render scale on and off (off: every pass at the output's size); the target
        // is kept from the command line, or 60 fps.
        let mut adaptive = matches!(r.render_scale.mode, RenderScale::Adaptive { .. });
        let was = adaptive;
        control("adaptive resolution", ui.checkbox(&mut adaptive, "adaptive render scale (off: every pass at the output's size)"));
        if adaptive != was {
            r.render_scale.mode = if adaptive { RenderScale::Adaptive { target_ms: r.render_scale.target_ms() } } else { RenderScale::Fixed(1.0) };
        }
        ui.horizontal(|ui| {
            ui.label("upscaler:");
            for u in Upscaler::ALL {
                let label = match u {
                    Upscaler::Easu => "FSR 1 EASU",
                    Upscaler::Cubic => "Catmull-Rom",
                };
                control(u.name(), ui.radio_value(&mut r.upscaler, u, label));
            }
        });
        // Each mode's cost shows in the pass list above: MSAA's in every camera pass and the
        // resolve pass, FXAA's as the fxaa pass.
        ui.horizontal(|ui| {
            ui.label("anti-aliasing:");
            for aa in AntiAliasing::ALL {
                let label = match aa {
                    AntiAliasing::Off => "off",
                    AntiAliasing::Msaa => "MSAA 4x",
                    AntiAliasing::Fxaa => "FXAA",
                };
                control(aa.name(), ui.radio_value(&mut r.aa, aa, label));
            }
        });
        let policy = &mut r.visibility.policy;
        control(
            "LOD threshold",
            ui.add(egui::Slider::new(&mut policy.threshold_px, 0.1..=32.0).logarithmic(true).text("LOD pixel error")),
        );
        control("LOD hysteresis", ui.add(egui::Slider::new(&mut policy.band, 0.0..=0.5).text("LOD hysteresis band")));
    }
}

/// CPU frame time and GPU time over the history, with the last value, median and p99.
fn frame_time_graph(ui: &mut egui::Ui, h: &FrameHistory) {
    let line = |ui: &mut egui::Ui, name: &str, ring: &Ring, color: Color32| {
        let text = match (ring.last(), ring.median(), ring.p99()) {
            (Some(last), Some(median), Some(p99)) => format!("{name} ms: {last:6.2}  median {median:6.2}  p99 {p99:6.2}"),
            _ => format!("{name} ms: (no samples yet)"),
        };
        ui.colored_label(color, egui::RichText::new(text).monospace());
    };
    line(ui, "CPU frame", &h.cpu_ms, CPU_COLOR);
    line(ui, "GPU      ", &h.gpu_ms, GPU_COLOR);
    let (rect, _) = ui.allocate_exact_size(Vec2::new(ui.available_width().max(240.0), 70.0), Sense::hover());
    let painter = ui.painter_at(rect);
    painter.rect_filled(rect, 2.0, Color32::from_black_alpha(120));
    // Scale to the p99 of either series (with headroom) so one hitch does not flatten the rest.
    let top = [h.cpu_ms.p99(), h.gpu_ms.p99()].into_iter().flatten().fold(1.0f64, f64::max) * 1.25;
    painter.text(
        rect.left_top() + Vec2::new(3.0, 1.0),
        egui::Align2::LEFT_TOP,
        format!("{top:.1} ms"),
        egui::FontId::monospace(10.0),
        Color32::GRAY,
    );
    let capacity = super::history::HISTORY_FRAMES as f32;
    for (ring, color) in [(&h.cpu_ms, CPU_COLOR), (&h.gpu_ms, GPU_COLOR)] {
        // Newest sample at the right edge.
        let start = capacity - ring.len() as f32;
        let points: Vec<Pos2> = ring
            .iter()
            .enumerate()
            .map(|(i, ms)| {
                let x = rect.left() + rect.width() * (start + i as f32) / (capacity - 1.0).max(1.0);
                let y = rect.bottom() - rect.height() * (ms / top).min(1.0) as f32;
                Pos2::new(x, y)
            })
            .collect();
        if points.len() >= 2 {
            painter.add(Shape::line(points, Stroke::new(1.5, color)));
        }
    }
}

/// This frame's culling and LOD counters, and the last finished frame's GPU measurements.
fn counters(ui: &mut egui::Ui, renderer: &Renderer, last: &FrameStats) {
    let c = &renderer.visibility.counts;
    egui::Grid::new("counters").num_columns(2).striped(true).show(ui, |ui| {
        let mut row = |name: &str, value: String| {
            ui.label(name);
            ui.monospace(value);
            ui.end_row();
        };
        row("instances tested", c.cull.tested.to_string());
        row("instances culled", c.cull.culled.to_string());
        let o = &renderer.visibility.occlusion_culler.stats;
        row("occlusion tested / culled", format!("{} / {}", c.cull.occlusion_tested, c.cull.occlusion_culled));
        row("occluders / triangles", format!("{} / {}", o.occluders, o.occluder_triangles));
        row("instances drawn", c.cull.visible.to_string());
        row("triangles / draw calls", format!("{} / {}", c.triangles, renderer.draw_calls));
        let buckets: Vec<String> = c
            .lod_histogram
            .iter()
            .enumerate()
            .map(|(i, n)| if i + 1 == LOD_BUCKETS { format!("{i}+:{n}") } else { format!("{i}:{n}") })
            .collect();
        row("LOD histogram", buckets.join(" "));
        // The overlay itself is drawn after the upscaler, at the output's size.
        let e = renderer.render_extent();
        row("render scale", format!("{:.2} ({}x{}, {})", renderer.frame_scale(), e.width, e.height, renderer.render_scale.mode.describe()));
        row("fragments shaded (counter)", last.fragments_shaded.map_or_else(|| "off".to_string(), |n| n.to_string()));
    });
}

/// Every pass of the renderer's frame graph (a fixed list, so rows do not come and go): the
/// last finished frame's GPU ms and vertex / fragment shader invocations; "off" for a pass that
/// frame did not run. The graph measures every pass, so a new one shows up here by itself.
pub struct PassesPanel<'a> {
    pub renderer: &'a Renderer,
    pub last: &'a FrameStats,
}

impl Panel for PassesPanel<'_> {
    fn title(&self) -> &str {
        "passes"
    }

    fn ui(&mut self, ui: &mut egui::Ui) {
        egui::Grid::new("passes").num_columns(3).striped(true).show(ui, |ui| {
            for name in self.renderer.pass_names() {
                ui.label(name);
                let p = self.last.passes.as_ref().map(|p| p.get(name));
                let (ms, inv) = match p {
                    None => ("n/a".to_string(), String::new()),
                    Some(None) => ("off".to_string(), String::new()),
                    Some(Some(p)) => (
                        p.gpu_ms.map_or_else(|| "n/a".to_string(), |ms| format!("{ms:.3} ms")),
                        p.invocations.map_or_else(String::new, |s| format!("VS {} / FS {}", s.vertex, s.fragment)),
                    ),
                };
                ui.monospace(ms);
                ui.monospace(inv);
                ui.end_row();
            }
        });
    }
}

/// The pack on show (`assets::reload::PackInfo`): its file, when it was cooked, its bake's
/// samples per texel (growing while `cook --watch` refines it) and a refused reload's error.
pub struct PackPanel<'a> {
    pub info: &'a crate::assets::reload::PackInfo,
}

impl Panel for PackPanel<'_> {
    fn title(&self) -> &str {
        "pack"
    }

    fn default_open(&self) -> bool {
        true
    }

    fn ui(&mut self, ui: &mut egui::Ui) {
        egui::Grid::new("pack").num_columns(2).striped(true).show(ui, |ui| {
            for (name, value) in self.info.rows(std::time::SystemTime::now()) {
                ui.label(name);
                if name.ends_with("refused") {
                    ui.colored_label(egui::Color32::from_rgb(255, 96, 96), value);
                } else {
                    ui.monospace(value);
                }
                ui.end_row();
            }
        });
    }
}
