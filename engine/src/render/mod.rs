//! Rendering. `renderer` owns a frame: it culls and picks LODs (`cull`, `lod_select`,
//! `visibility`), batches draws (`batches`) and runs the frame graph (`graph`), whose passes
//! (`passes/`, one file each) record with what `frame` gives them. What the passes draw with:
//! `mesh_draw` (the mesh pipelines, shared by the mesh passes), `shadow` (the sun's map),
//! `boids_draw`, `particles_draw`, `tonemap`, `sampled_input` (shared by the full-screen passes),
//! `samplers` and `shaders`. `scale`: the render scale the 3D passes draw at (adaptive), which
//! the `upscale` pass brings back to the output's size.

pub mod batches;
pub mod boids_draw;
pub mod cull;
pub mod frame;
pub mod fullscreen;
pub mod graph;
pub mod lod_select;
pub mod mesh_draw;
pub mod occlusion;
pub mod particles_draw;
pub mod passes;
pub mod renderer;
pub mod sampled_input;
pub mod scale;
pub mod samplers;
pub mod shaders;
pub mod shadow;
pub mod tonemap;
pub mod visibility;
