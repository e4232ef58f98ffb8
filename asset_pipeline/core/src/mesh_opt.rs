//! GPU-friendly triangle and vertex order for one LOD, with meshoptimizer (the library Godot
//! runs on import): within each draw group (the pack's submesh: material and lightmap block),
//! triangles ordered for the post-transform vertex cache and then, within that order's
//! clusters, front to back from the outside in (overdraw); then the vertices renumbered in the
//! order the triangles first use them (vertex fetch locality), dropping any no triangle uses.
//!
//! The stage changes order only, never geometry: the same triangles (each keeping its winding),
//! the same vertex values. Callers carry every per-vertex stream through `vertices` and every
//! per-triangle value through `triangle_order`.

use meshopt::{VertexCacheStatistics, VertexDataAdapter};

/// The FIFO size ACMR is reported at: meshoptimizer's default model of a post-transform cache.
pub const CACHE_SIZE: u32 = 16;
/// How much the overdraw pass may worsen the cache order to reduce overdraw (meshoptimizer's
/// recommended 1.05: up to 5 % more vertex shader invocations).
pub const OVERDRAW_THRESHOLD: f32 = 1.05;

#[derive(Debug, Clone, PartialEq)]
pub struct Optimized {
    /// New triangles, indexing the new vertex order.
    pub triangles: Vec<[u32; 3]>,
    /// For each new triangle, the input triangle it is (a permutation of 0..m).
    pub triangle_order: Vec<u32>,
    /// For each new vertex, the input vertex it is (used vertices only, each once).
    pub vertices: Vec<u32>,
}

/// Reorder one LOD. `keys[t]`: triangle t's draw group; groups come out in ascending key order
/// (the order the pack writer lays submeshes in), each group's triangles contiguous.
/// `positions`: the vertices' positions (for the overdraw order). Errors name the problem.
pub fn optimize(triangles: &[[u32; 3]], keys: &[u64], positions: &[[f32; 3]]) -> Result<Optimized, String> {
    let n = positions.len();
    if keys.len() != triangles.len() {
        return Err(format!("{} group keys for {} triangles", keys.len(), triangles.len()));
    }
    if let Some(i) = triangles.iter().flatten().find(|&&i| i as usize >= n) {
        return Err(format!("triangle index {i} is out of range for {n} vertices"));
    }
    let mut order: Vec<u32> = (0..triangles.len() as u32).collect();
    order.sort_by_key(|&t| keys[t as usize]); // stable: deterministic for equal keys
    let position_bytes: Vec<u8> = positions.iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
    let adapter = VertexDataAdapter::new(&position_bytes, 12, 0).map_err(|e| e.to_string())?;

    let mut new_order = Vec::with_capacity(order.len());
    let mut indices: Vec<u32> = Vec::with_capacity(order.len() * 3);
    let mut start = 0;
    while start < order.len() {
        let key = keys[order[start] as usize];
        let end = start + order[start..].iter().take_while(|&&t| keys[t as usize] == key).count();
        let group = &order[start..end];
        let mut ix: Vec<u32> = group.iter().flat_map(|&t| triangles[t as usize]).collect();
        ix = meshopt::optimize_vertex_cache(&ix, n);
        meshopt::optimize_overdraw_in_place(&mut ix, &adapter, OVERDRAW_THRESHOLD);
        // meshoptimizer returns triangles, not which input triangle each is: find them again
        // (a triangle keeps its corners' cyclic order, so its rotation to the smallest index
        // first names it; duplicates of one triangle are interchangeable).
        new_order.extend(match_triangles(group, triangles, &ix)?);
        indices.extend_from_slice(&ix);
        start = end;
    }

    // Vertex fetch order: vertices numbered by first use (meshopt_optimizeVertexFetchRemap's
    // rule; the crate's wrapper truncates its old -> new table to the used count, so it is
    // unusable when any vertex is unused).
    let mut remap = vec![u32::MAX; n];
    let mut vertices: Vec<u32> = Vec::with_capacity(n);
    for &i in &indices {
        if remap[i as usize] == u32::MAX {
            remap[i as usize] = vertices.len() as u32;
            vertices.push(i);
        }
    }
    let triangles = indices.chunks_exact(3).map(|t| [remap[t[0] as usize], remap[t[1] as usize], remap[t[2] as usize]]).collect();
    Ok(Optimized { triangles, triangle_order: new_order, vertices })
}

/// A triangle rotated so its smallest index comes first (same winding).
fn canonical(t: [u32; 3]) -> [u32; 3] {
    let k = (0..3).min_by_key(|&k| t[k]).unwrap();
    [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
}

/// For each triangle of `ix` (the group's triangles reordered), the input triangle it is.
fn match_triangles(group: &[u32], triangles: &[[u32; 3]], ix: &[u32]) -> Result<Vec<u32>, String> {
    let mut by_shape: std::collections::HashMap<[u32; 3], Vec<u32>> = std::collections::HashMap::with_capacity(group.len());
    // Reversed, so `pop` hands out duplicates in input order.
    for &t in group.iter().rev() {
        by_shape.entry(canonical(triangles[t as usize])).or_default().push(t);
    }
    ix.chunks_exact(3)
        .map(|t| {
            let c = canonical([t[0], t[1], t[2]]);
            by_shape.get_mut(&c).and_then(Vec::pop).ok_or_else(|| format!("meshoptimizer returned triangle {c:?}, which the input does not hold"))
        })
        .collect()
}

/// Post-transform vertex cache statistics of a triangle list (FIFO of `CACHE_SIZE`): ACMR
/// (vertices transformed per triangle; 0.5 is the ideal for a regular grid, 3 the worst) and
/// ATVR (per vertex; 1 is the ideal).
pub fn cache_stats(triangles: &[[u32; 3]], vertex_count: usize) -> VertexCacheStatistics {
    let ix: Vec<u32> = triangles.iter().flatten().copied().collect();
    meshopt::analyze_vertex_cache(&ix, vertex_count, CACHE_SIZE, 0, 0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A w x h grid of quads, each two triangles, with its triangles in a scattered order.
    fn grid(w: u32, h: u32) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
        let positions = (0..=h).flat_map(|y| (0..=w).map(move |x| [x as f32, y as f32, 0.0])).collect();
        let v = |x: u32, y: u32| y * (w + 1) + x;
        let mut tris = Vec::new();
        for y in 0..h {
            for x in 0..w {
                tris.push([v(x, y), v(x + 1, y), v(x + 1, y + 1)]);
                tris.push([v(x, y), v(x + 1, y + 1), v(x, y + 1)]);
            }
        }
        // A fixed scatter (a multiplicative permutation), so the input's cache order is poor.
        let m = tris.len();
        let step = (0..).map(|k| 7919 + k).find(|s| gcd(*s, m) == 1).unwrap();
        let scattered = (0..m).map(|i| tris[(i * step) % m]).collect();
        (positions, scattered)
    }

    fn gcd(a: usize, b: usize) -> usize {
        if b == 0 { a } else { gcd(b, a % b) }
    }

    fn canonical_set(tris: impl IntoIterator<Item = [u32; 3]>) -> Vec<[u32; 3]> {
        let mut v: Vec<_> = tris.into_iter().map(canonical).collect();
        v.sort();
        v
    }

    #[test]
    fn same_triangles_and_windings_in_a_better_order() {
        let (positions, tris) = grid(64, 64);
        // Two groups: the grid's left and right halves.
        let keys: Vec<u64> = tris.iter().map(|t| u64::from(positions[t[0] as usize][0] >= 32.0)).collect();
        let out = optimize(&tris, &keys, &positions).unwrap();
        // Every triangle is one input triangle, with its corners' positions in the same cyclic order.
        assert_eq!(out.triangle_order.len(), tris.len());
        let mut seen = out.triangle_order.clone();
        seen.sort();
        assert_eq!(seen, (0..tris.len() as u32).collect::<Vec<_>>());
        for (new, &old) in out.triangles.iter().zip(&out.triangle_order) {
            let back = new.map(|i| out.vertices[i as usize]);
            assert_eq!(canonical(back), canonical(tris[old as usize]));
        }
        // Groups contiguous, in ascending key order.
        let group_of: Vec<u64> = out.triangle_order.iter().map(|&t| keys[t as usize]).collect();
        assert!(group_of.windows(2).all(|w| w[0] <= w[1]));
        // Every vertex used, each once, first used in order (vertex fetch order).
        assert_eq!(out.vertices.len(), positions.len());
        let mut first = Vec::new();
        for &i in out.triangles.iter().flatten() {
            if !first.contains(&i) && first.len() < 64 {
                first.push(i);
            }
        }
        assert_eq!(first, (0..first.len() as u32).collect::<Vec<_>>());
        // The cache order: far fewer vertices transformed than the scattered input.
        let before = cache_stats(&tris, positions.len()).acmr;
        let after = cache_stats(&out.triangles, out.vertices.len()).acmr;
        assert!(before > 2.0 && after < 0.8, "ACMR {before} -> {after}");
        assert_eq!(canonical_set(out.triangles.iter().map(|t| t.map(|i| out.vertices[i as usize]))), canonical_set(tris));
    }

    #[test]
    fn unused_vertices_are_dropped_and_duplicates_kept() {
        let positions = vec![[0.0, 0.0, 0.0], [9.0, 9.0, 9.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let tris = vec![[0, 2, 3], [2, 3, 0], [0, 3, 2]];
        let out = optimize(&tris, &[0, 0, 1], &positions).unwrap();
        assert_eq!(out.vertices.len(), 3);
        assert!(!out.vertices.contains(&1));
        assert_eq!(out.triangle_order.len(), 3);
        assert_eq!(out.triangle_order[2], 2, "the key-1 triangle comes last");
    }

    #[test]
    fn bad_input_is_an_error() {
        assert!(optimize(&[[0, 1, 5]], &[0], &[[0.0; 3]; 3]).unwrap_err().contains("out of range"));
        assert!(optimize(&[[0, 1, 2]], &[], &[[0.0; 3]; 3]).unwrap_err().contains("group keys"));
    }
}
