//! The runtime: a Vulkan 1.3 (ash) renderer for cooked packs, headless or in a window, that a
//! game links.
//!
//! - `gpu`: the device, memory objects (owned while they are made: `gpu::Owned`), pipelines.
//! - `render`: the renderer (`render::renderer`), its frame graph (`render::graph`) and passes
//!   (`render::passes`, one file each), and what the passes draw with (meshes, shadow, boids,
//!   particles, tone map), culling and LOD selection.
//! - `scene`: the scene of instances behind handles (`scene::GpuScene`, `scene::instances`), the
//!   camera and walking on the level.
//! - `assets`: loading a cooked pack onto the device (`GpuScene::upload`).
//! - `anim`: sampling clips, posing, skinning and morphing (`anim::animated` runs them per frame).
//! - `sim`: particles and boids, and the level's world built from its spawns (`sim::level`).
//! - `ui`: the debug overlay (egui).
//! - `app`: the window, the frame loop and input (`app::Game`), and headless rendering.

pub mod anim;
pub mod app;
pub mod assets;
pub mod gpu;
pub mod render;
pub mod scene;
pub mod sim;
pub mod stats;
pub mod ui;

pub use pack;
