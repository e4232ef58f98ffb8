//! The renderer's frame: a frame graph (`graph`) running passes (`passes/`, one file each) that
//! record with what `frame` gives them; `mesh_draw` is what the mesh passes share and
//! `sampled_input` what the full-screen passes share.

pub mod frame;
pub mod graph;
pub mod mesh_draw;
pub mod passes;
pub mod sampled_input;
