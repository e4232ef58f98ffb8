//! What a game gives the window (`app::run`): it reacts to keys, advances its world and camera
//! each frame, feeds the renderer its particles and birds, and may add overlay panels. The
//! window owns the device, the swapchain, the renderer and the scene; the game owns everything
//! else (the demo's is `src/bin/demo/game.rs`).

use crate::scene::camera::Camera;
use crate::gpu::Gpu;
use crate::ui::Panel;
use crate::render::renderer::{Lighting, Renderer};
use crate::scene::GpuScene;
use anyhow::Result;
use std::collections::HashSet;
use winit::keyboard::KeyCode;

/// The player's input this frame.
#[derive(Debug, Default)]
pub struct Input {
    /// Keys held down (not taken by the overlay).
    pub keys: HashSet<KeyCode>,
    /// Pointer movement while dragging with a mouse button, in pixels since the last frame.
    pub look: (f64, f64),
}

impl Input {
    pub fn held(&self, k: KeyCode) -> bool {
        self.keys.contains(&k)
    }
}

/// What the window lends a game.
pub struct Cx<'a> {
    pub gpu: &'a Gpu,
    pub renderer: &'a mut Renderer,
    pub scene: &'a mut GpuScene,
    pub(super) frames_in_flight: usize,
}

impl Cx<'_> {
    /// Replace the scene with `pack`'s meshes and animated characters (`assets::reload`): on an
    /// error the old scene stays, whole.
    pub fn frames_in_flight(&self) -> usize {
        self.frames_in_flight
    }

    pub fn load(&mut self, pack: &pack::Pack) -> Result<()> {
        crate::assets::reload::replace_scene(self.gpu, self.renderer, self.scene, pack, self.frames_in_flight)
    }
}

pub trait Game {
    /// The window's first scene was loaded from `pack`: set up from it.
    fn start(&mut self, cx: &mut Cx, pack: &pack::Pack) -> Result<()>;
    /// A key was pressed (not a repeat): what changed, for the log (the window logs it, and logs
    /// it again as "shown" once it is on screen). Loading another scene is `cx.load`.
    fn key(&mut self, cx: &mut Cx, key: KeyCode) -> Result<Option<String>>;
    /// Advance by `dt` seconds (at most 0.1) with `input`, before the frame is prepared; the
    /// renderer's particles and birds are filled here.
    fn update(&mut self, cx: &mut Cx, input: &Input, dt: f32);
    /// The view to render.
    fn camera(&self) -> Camera;
    fn lighting(&self) -> Lighting;
    /// The pack the scene on show was loaded from, when it is not the window's first one
    /// (`cx.load` since): after a device loss the scene is made again from it.
    fn pack(&self) -> Option<&pack::Pack> {
        None
    }
    /// Show the overlay with the game's panels: call `show` once with them.
    fn panels(&mut self, show: &mut dyn FnMut(&mut [&mut dyn Panel])) {
        show(&mut []);
    }
}
