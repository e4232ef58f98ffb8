//! The lightmap baker: ray queries ([`bvh`]), samplers ([`sampling`]), analytic lights in
//! physical units ([`lights`]), materials evaluated where rays hit ([`material`], reading
//! [`textures`]), the traced scene ([`scene`]: geometry, materials, emitters, lights, sky) and the
//! path-tracing integrator ([`integrator`]), which computes B = H/pi per surface point;
//! irradiance probes for dynamic objects ([`probes`]) reuse it.

pub mod bvh;
pub mod integrator;
pub mod light_set;
pub mod lights;
pub mod material;
pub mod probes;
pub mod reflection;
pub mod sampling;
pub mod scene;
pub mod textures;

/// Run `f` on a rayon pool of `threads` workers (None or 0: one per core), so callers (the
/// bindings) need not depend on rayon themselves.
pub fn with_threads<R: Send>(threads: Option<usize>, f: impl FnOnce() -> R + Send) -> Result<R, String> {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads.unwrap_or(0)).build().map_err(|e| format!("thread pool: {e}"))?;
    Ok(pool.install(f))
}

#[cfg(test)]
mod tests;
