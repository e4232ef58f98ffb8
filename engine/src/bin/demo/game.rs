//! The demo's game on the engine's window (`engine::app`): fly or walk the level, the feature
//! switches on the function keys, Tab to the next pack, and the level's particles and flocks
//! stepped each frame (with their overlay panel).

use anyhow::Result;
use engine::app::{Cx, Game, Input};
use engine::assets::reload::{reload_shaders, PackInfo, PackWatch, ShaderReload};
use engine::render::shaders::{self, SourceWatch};
use engine::scene::camera::{Camera, EYE_HEIGHT_M};
use engine::ui::{PackPanel, Panel, SimPanel};
use engine::render::renderer::Lighting;
use engine::sim::clock::{ClockParams, FixedClock};
use engine::sim::World;
use engine::sim::level;
use engine::scene::walk::WalkMesh;
use glam::{Vec2, Vec3};
use winit::keyboard::KeyCode;

/// The keys, as `demo --help` and the README list them.
pub const KEYS: &str = "WASD move, Q/E down/up, Shift faster, drag with a mouse button to look, Esc quits;
F1 overlay, F2 depth pre-pass, F3 frustum culling, F4 LOD selection, F5 lightmaps (off: probes
and sun light the static geometry too), F6 walk mode (on the level's floors at eye height, up
steps, stopped by walls, at the player spawn's speed), Tab next scene (when several packs were given).";

pub struct DemoGame<'a> {
    packs: &'a [pack::Pack],
    /// The pack on screen.
    current: usize,
    camera: Camera,
    lighting: Lighting,
    /// Walk mode: the eye's height above the feet (None: flying).
    walk: Option<f32>,
    /// What walking stands on and bumps into: the level's static triangles.
    walk_mesh: WalkMesh,
    /// Where the feet go where no floor is under the camera, and the walking speed: from the
    /// player spawn.
    ground: f32,
    walk_speed: f32,
    /// The level's particles and flocks, stepped on the fixed clock by each frame's duration.
    world: World,
    /// `--watch`: the first pack's file, watched for replacement, and what the overlay says of it.
    watch: Option<(PackWatch, PackInfo)>,
    /// The first pack as last reloaded (what Tab comes back to instead of `packs[0]`).
    reloaded: Option<pack::Pack>,
    /// `--watch` with the shader sources present: they, watched.
    shader_watch: Option<SourceWatch>,
}

impl<'a> DemoGame<'a> {
    /// A game over `packs` (at least one), showing the first.
    pub fn new(packs: &'a [pack::Pack]) -> DemoGame<'a> {
        DemoGame {
            packs,
            current: 0,
            camera: Camera::framing(Vec3::splat(-1.0), Vec3::splat(1.0)),
            lighting: Lighting::default(),
            walk: None,
            walk_mesh: WalkMesh::from_pack(&packs[0]),
            ground: 0.0,
            walk_speed: 1.5,
            world: World::new(FixedClock::new(ClockParams::default())),
            watch: None,
            reloaded: None,
            shader_watch: None,
        }
    }

    /// Reload the first pack whenever its file (`path`) is replaced (`demo --watch`).
    pub fn watching(mut self, path: &std::path::Path) -> Self {
        self.watch = Some((PackWatch::new(path), PackInfo::new(path, &self.packs[0])));
        self.shader_watch = shaders::sources().map(|d| SourceWatch::new(&d));
        self
    }

    /// `--watch`: if the first pack's file was replaced and it is on screen, show the new one,
    /// keeping the camera, walk mode and world; a pack that cannot be read or loaded leaves the
    /// old one on screen and its error in the overlay (and on stderr).
    fn reload_if_replaced(&mut self, cx: &mut Cx) {
        let Some((watch, info)) = self.watch.as_mut() else { return };
        if let Some(sw) = self.shader_watch.as_mut() {
            match reload_shaders(sw, cx.gpu, cx.renderer, cx.frames_in_flight()) {
                Ok(ShaderReload::Unchanged) => {}
                Ok(ShaderReload::Reloaded(changed)) => {
                    println!("reloaded shaders ({} modules changed: {})", changed.len(), changed.join(", "));
                    info.shader_reloads += 1;
                    info.shader_error = None;
                }
                Ok(ShaderReload::Refused(messages)) => {
                    eprintln!("demo: shader error: {messages}\ndemo: the pipelines are as they were");
                    info.shader_error = messages.lines().next().map(str::to_string);
                }
                Err(e) => eprintln!("demo: error: remaking the pipelines: {e:#}"),
            }
        }
        if self.current != 0 || !watch.changed() {
            return;
        }
        let path = watch.path().to_path_buf();
        match pack::Pack::read_file(&path).map_err(anyhow::Error::from).and_then(|p| cx.load(&p).map(|()| p)) {
            Ok(p) => {
                self.lighting = Lighting::for_pack(&p.manifest);
                self.walk_mesh = WalkMesh::from_pack(&p);
                info.shown(&p);
                info.reloads += 1;
                println!("reloaded {}", path.display());
                self.reloaded = Some(p);
            }
            Err(e) => {
                eprintln!("demo: error: {}: {e:#}; still showing the last good pack", path.display());
                info.error = Some(format!("{e:#}"));
            }
        }
    }

    /// Set up from the scene just loaded from `pack`: its camera, light, floors and world. The
    /// switches and walk mode stay as they are.
    fn set_up(&mut self, cx: &mut Cx, pack: &pack::Pack) {
        let (min, max) = cx.scene.bounds();
        self.world = level::world_from_spawns(&pack.manifest.spawns, &pack.manifest.pillars, min, max);
        level::warm_up(&mut self.world);
        self.camera = Camera::for_pack(&pack.manifest, min, max);
        self.lighting = Lighting::for_pack(&pack.manifest);
        self.walk_mesh = WalkMesh::from_pack(pack);
        self.ground = pack.manifest.spawns.iter().find(|s| s.kind == "player").map_or(min.y, |s| s.position[1]);
        let player = pack.manifest.spawns.iter().find(|s| s.kind == "player");
        self.walk_speed = player.and_then(|s| s.params.get("speed")).and_then(|v| v.as_f64()).map_or(1.5, |v| v as f32);
        self.land();
    }

    /// Walking, put the feet on the floor under the camera (the spawn's height where there is
    /// none) and the eye above them.
    fn land(&mut self) {
        if let Some(eye) = self.walk {
            let p = self.camera.position;
            let floor = self.walk_mesh.floor(Vec2::new(p.x, p.z), p.y).unwrap_or(self.ground);
            self.camera.position.y = floor + eye;
        }
    }

    /// WASD to move, Q/E down/up, Shift to go faster; drag to look. Walking, the feet follow the
    /// level's floors (up steps, down drops), walls stop them, the eye stays at its height above
    /// them and Q/E do nothing.
    fn move_camera(&mut self, cx: &Cx, input: &Input, dt: f32) {
        let sensitivity = 0.004;
        self.camera.rotate(-input.look.0 as f32 * sensitivity, -input.look.1 as f32 * sensitivity);
        let (min, max) = cx.scene.bounds();
        let mut speed = if self.walk.is_some() { self.walk_speed } else { ((max - min).length() * 0.4).max(1.0) };
        if input.held(KeyCode::ShiftLeft) || input.held(KeyCode::ShiftRight) {
            speed *= if self.walk.is_some() { 2.0 } else { 4.0 };
        }
        let axis = |pos: KeyCode, neg: KeyCode| (input.held(pos) as i32 - input.held(neg) as i32) as f32;
        let local = Vec3::new(axis(KeyCode::KeyD, KeyCode::KeyA), axis(KeyCode::KeyE, KeyCode::KeyQ), axis(KeyCode::KeyW, KeyCode::KeyS));
        match self.walk {
            Some(eye) => {
                let feet = self.walk_mesh.step(self.camera.position - Vec3::Y * eye, self.camera.walk_delta(local * speed * dt));
                self.camera.position = feet + Vec3::Y * eye;
            }
            None => self.camera.translate_local(local * speed * dt),
        }
    }
}

impl Game for DemoGame<'_> {
    fn start(&mut self, cx: &mut Cx, pack: &pack::Pack) -> Result<()> {
        self.set_up(cx, pack);
        Ok(())
    }

    fn key(&mut self, cx: &mut Cx, key: KeyCode) -> Result<Option<String>> {
        let on_off = |b: bool| if b { "on" } else { "off" };
        let r = &mut *cx.renderer;
        Ok(Some(match key {
            KeyCode::F2 => {
                r.prepass = !r.prepass;
                format!("depth pre-pass {}", on_off(r.prepass))
            }
            KeyCode::F3 => {
                r.visibility.culling = !r.visibility.culling;
                format!("frustum culling {}", on_off(r.visibility.culling))
            }
            KeyCode::F4 => {
                r.visibility.lod_selection = !r.visibility.lod_selection;
                format!("LOD selection {}", on_off(r.visibility.lod_selection))
            }
            KeyCode::F5 => {
                r.lightmaps = !r.lightmaps;
                format!("lightmaps {}", on_off(r.lightmaps))
            }
            KeyCode::F6 => {
                self.walk = match self.walk {
                    Some(_) => None,
                    None => Some(EYE_HEIGHT_M),
                };
                self.land();
                format!("walk mode {}", on_off(self.walk.is_some()))
            }
            KeyCode::Tab if self.packs.len() > 1 => {
                self.current = (self.current + 1) % self.packs.len();
                let reloaded = if self.current == 0 { self.reloaded.take() } else { None };
                let packs = self.packs;
                let pack = reloaded.as_ref().unwrap_or(&packs[self.current]);
                cx.load(pack)?;
                self.set_up(cx, pack);
                if self.current == 0 {
                    self.reloaded = reloaded;
                }
                format!("scene {} of {}", self.current + 1, self.packs.len())
            }
            _ => return Ok(None),
        }))
    }

    fn update(&mut self, cx: &mut Cx, input: &Input, dt: f32) {
        self.reload_if_replaced(cx);
        self.move_camera(cx, input, dt);
        self.world.update(dt as f64);
        level::prepare_frame(&self.world, cx.renderer, cx.scene, &self.camera);
    }

    fn camera(&self) -> Camera {
        self.camera
    }

    fn lighting(&self) -> Lighting {
        self.lighting
    }

    fn pack(&self) -> Option<&pack::Pack> {
        Some(self.reloaded.as_ref().filter(|_| self.current == 0).unwrap_or(&self.packs[self.current]))
    }

    fn panels(&mut self, show: &mut dyn FnMut(&mut [&mut dyn Panel])) {
        let mut sim = SimPanel::new(&mut self.world);
        match &self.watch {
            Some((_, info)) => show(&mut [&mut PackPanel { info }, &mut sim]),
            None => show(&mut [&mut sim]),
        }
    }
}
