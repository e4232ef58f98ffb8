//! The runtime: Vulkan 1.3 (ash) renderer for cooked packs, headless or in a window.

pub mod anim;
pub mod app;
pub mod animated;
pub mod batches;
pub mod boids_draw;
pub mod camera;
pub mod cull;
pub mod gpu;
pub mod headless;
pub mod instances;
pub mod lod_select;
pub mod overlay;
pub mod particles_pass;
pub mod render;
pub mod renderer;
pub mod samplers;
pub mod scene;
pub mod shaders;
pub mod shadow;
pub mod sim;
pub mod sim_level;
pub mod stats;
pub mod tonemap;
pub mod visibility;
pub mod walk;

pub use pack;
