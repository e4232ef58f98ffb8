//! Walking on the level (the demo's walk mode): the feet stay on the highest floor under them,
//! climbing ledges no higher than a step and dropping down any height, while walls, pillars and
//! ledges too high to climb stop the body, which slides along them. Collision is against the
//! pack's static instances' triangles (LOD 0, world space), bucketed in a grid over x and z so that a move
//! looks only at the triangles near the player.

use glam::{Mat4, Vec2, Vec3, Vec3Swizzles};

/// The tallest ledge a step climbs: stairs rise 15 to 20 cm, a high step or a curb up to 40.
pub const MAX_STEP_M: f32 = 0.45;
/// How close the body's centre comes to a wall.
pub const BODY_RADIUS_M: f32 = 0.3;
/// The body's height: anything in the way between a step's height and this stops it.
pub const BODY_HEIGHT_M: f32 = 1.8;
/// Surfaces steeper than this (about 60 degrees) are walls, not floors.
const MIN_FLOOR_NORMAL_Y: f32 = 0.5;
/// A move is taken in sub-steps no longer than this, so a long frame does not pass through a
/// wall thinner than the body.
const MAX_SUBSTEP_M: f32 = BODY_RADIUS_M * 0.5;

/// The static level's triangles in a uniform grid of cells over x and z.
pub struct WalkMesh {
    triangles: Vec<[Vec3; 3]>,
    /// x and z of the grid's corner, the cell side, and the cells per axis.
    origin: Vec2,
    cell: f32,
    counts: [usize; 2],
    /// Triangles of cell c: `ids[start[c]..start[c + 1]]`. A triangle is in every cell its
    /// x/z bounds, widened by the body's radius, overlap.
    start: Vec<u32>,
    ids: Vec<u32>,
}

impl WalkMesh {
    /// The LOD 0 triangles of `pack`'s static instances (`Node::is_static`), placed by their nodes.
    pub fn from_pack(pack: &pack::Pack) -> WalkMesh {
        let m = &pack.manifest;
        let world = crate::scene::world_transforms(&m.nodes);
        let mut triangles = Vec::new();
        for (node, w) in m.nodes.iter().zip(&world) {
            let Some(mesh) = node.mesh.filter(|_| node.is_static).and_then(|i| m.meshes.get(i as usize)) else { continue };
            let Some(lod) = mesh.lods.first() else { continue };
            triangles.extend(lod_triangles(pack.bytes(lod.vertices), &pack.indices(lod), *w));
        }
        WalkMesh::new(triangles)
    }

    pub fn new(triangles: Vec<[Vec3; 3]>) -> WalkMesh {
        let (lo, hi) = triangles.iter().flatten().fold((Vec2::splat(f32::MAX), Vec2::splat(f32::MIN)), |(lo, hi), p| (lo.min(p.xz()), hi.max(p.xz())));
        let (lo, hi) = if triangles.is_empty() { (Vec2::ZERO, Vec2::ONE) } else { (lo - BODY_RADIUS_M, hi + BODY_RADIUS_M) };
        // Cells of about 2 m, at most 512 a side: a few dozen triangles per query in a level.
        let extent = (hi - lo).max(Vec2::splat(1e-3));
        let cell = (extent.max_element() / 512.0).max(2.0);
        let counts = [(extent.x / cell).ceil() as usize, (extent.y / cell).ceil() as usize].map(|n| n.max(1));
        let mut mesh = WalkMesh { triangles, origin: lo, cell, counts, start: Vec::new(), ids: Vec::new() };
        let mut per_cell: Vec<Vec<u32>> = vec![Vec::new(); counts[0] * counts[1]];
        for (i, t) in mesh.triangles.iter().enumerate() {
            let (a, b) = t.iter().fold((Vec2::splat(f32::MAX), Vec2::splat(f32::MIN)), |(a, b), p| (a.min(p.xz()), b.max(p.xz())));
            let ([x0, z0], [x1, z1]) = (mesh.cell_of(a - BODY_RADIUS_M), mesh.cell_of(b + BODY_RADIUS_M));
            for z in z0..=z1 {
                for x in x0..=x1 {
                    per_cell[z * counts[0] + x].push(i as u32);
                }
            }
        }
        mesh.start.push(0);
        for c in per_cell {
            mesh.ids.extend(c);
            mesh.start.push(mesh.ids.len() as u32);
        }
        mesh
    }

    fn cell_of(&self, p: Vec2) -> [usize; 2] {
        let c = ((p - self.origin) / self.cell).floor();
        [(c.x.max(0.0) as usize).min(self.counts[0] - 1), (c.y.max(0.0) as usize).min(self.counts[1] - 1)]
    }

    /// The triangles that may touch a body at x/z `p` (none outside the grid).
    fn near(&self, p: Vec2) -> &[u32] {
        let c = (p - self.origin) / self.cell;
        if c.x < 0.0 || c.y < 0.0 || c.x >= self.counts[0] as f32 || c.y >= self.counts[1] as f32 {
            return &[];
        }
        let i = c.y as usize * self.counts[0] + c.x as usize;
        &self.ids[self.start[i] as usize..self.start[i + 1] as usize]
    }

    /// The height of the highest floor under x/z `p` at or below `top`, if any.
    pub fn floor(&self, p: Vec2, top: f32) -> Option<f32> {
        self.near(p)
            .iter()
            .filter_map(|&i| {
                let [a, b, c] = self.triangles[i as usize];
                let n = (b - a).cross(c - a);
                // Floors face up; a wall or an underside is not stood on.
                if n.y <= MIN_FLOOR_NORMAL_Y * n.length() {
                    return None;
                }
                height_at(p, [a, b, c]).filter(|&y| y <= top + 1e-4)
            })
            .reduce(f32::max)
    }

    /// Whether a body standing at `feet` meets anything between a step above its feet and its
    /// head: a wall, a pillar, or a ledge too high to climb.
    pub fn blocked(&self, feet: Vec3) -> bool {
        let (y0, y1) = (feet.y + MAX_STEP_M, feet.y + BODY_HEIGHT_M);
        let p = feet.xz();
        self.near(p).iter().any(|&i| {
            let slab = clip_to_slab(&self.triangles[i as usize], y0, y1);
            slab.len() >= 3 && distance_to_polygon(p, &slab) < BODY_RADIUS_M
        })
    }

    /// Walk from `feet` by the horizontal `delta`: where the feet end up. Each sub-step goes as
    /// far as it can, sliding along x or z when a wall is in the way, and stops where neither
    /// axis is free or there is no floor (the edge of the level).
    pub fn step(&self, feet: Vec3, delta: Vec3) -> Vec3 {
        let delta = Vec3::new(delta.x, 0.0, delta.z);
        let n = (delta.length() / MAX_SUBSTEP_M).ceil().max(1.0) as usize;
        let d = delta / n as f32;
        let mut at = feet;
        for _ in 0..n {
            let moved = [d, Vec3::new(d.x, 0.0, 0.0), Vec3::new(0.0, 0.0, d.z)]
                .into_iter()
                .filter(|m| *m != Vec3::ZERO)
                .find_map(|m| self.stand(at + m, at.y));
            match moved {
                Some(p) => at = p,
                None => break,
            }
        }
        at
    }

    /// Where a body at x/z of `p` stands, coming from feet height `from_y`: on the highest floor
    /// a step up or less, if there is one and nothing is in the way there.
    fn stand(&self, p: Vec3, from_y: f32) -> Option<Vec3> {
        let y = self.floor(p.xz(), from_y + MAX_STEP_M)?;
        let at = Vec3::new(p.x, y, p.z);
        (!self.blocked(at)).then_some(at)
    }
}

/// World-space triangles of one LOD: `Vertex` records (position first) and its indices.
fn lod_triangles<'a>(vertices: &'a [u8], indices: &'a [u32], world: Mat4) -> impl Iterator<Item = [Vec3; 3]> + 'a {
    let position = move |i: u32| {
        let at = i as usize * pack::VERTEX_STRIDE;
        let f = |k: usize| vertices.get(at + 4 * k..at + 4 * k + 4).map_or(0.0, |b| f32::from_le_bytes(b.try_into().unwrap()));
        world.transform_point3(Vec3::new(f(0), f(1), f(2)))
    };
    indices.chunks_exact(3).map(move |c| [position(c[0]), position(c[1]), position(c[2])])
}

/// The height of triangle `t` above x/z `p`, if `p` is inside its projection.
fn height_at(p: Vec2, [a, b, c]: [Vec3; 3]) -> Option<f32> {
    let (a2, b2, c2) = (a.xz(), b.xz(), c.xz());
    let area = (b2 - a2).perp_dot(c2 - a2);
    if area.abs() < 1e-12 {
        return None;
    }
    let u = (c2 - b2).perp_dot(p - b2) / area;
    let v = (a2 - c2).perp_dot(p - c2) / area;
    let w = 1.0 - u - v;
    (u >= -1e-6 && v >= -1e-6 && w >= -1e-6).then_some(u * a.y + v * b.y + w * c.y)
}

/// The part of triangle `t` with y in [y0, y1], as a polygon (empty when it misses the slab).
fn clip_to_slab(t: &[Vec3; 3], y0: f32, y1: f32) -> Vec<Vec3> {
    let clip = |poly: Vec<Vec3>, keep: &dyn Fn(Vec3) -> f32| -> Vec<Vec3> {
        // Sutherland-Hodgman against one plane; keep(p) >= 0 inside.
        let mut out = Vec::with_capacity(poly.len() + 1);
        for (i, &p) in poly.iter().enumerate() {
            let q = poly[(i + 1) % poly.len()];
            let (dp, dq) = (keep(p), keep(q));
            if dp >= 0.0 {
                out.push(p);
            }
            if (dp >= 0.0) != (dq >= 0.0) {
                out.push(p + (q - p) * (dp / (dp - dq)));
            }
        }
        out
    };
    let above = clip(t.to_vec(), &|p| p.y - y0);
    if above.is_empty() {
        return above;
    }
    clip(above, &|p| y1 - p.y)
}

/// Distance in x/z from `p` to the projection of the convex polygon `poly` (0 inside).
fn distance_to_polygon(p: Vec2, poly: &[Vec3]) -> f32 {
    let pts: Vec<Vec2> = poly.iter().map(|v| v.xz()).collect();
    let n = pts.len();
    let mut sign = 0.0f32;
    let mut inside = true;
    let mut best = f32::MAX;
    for i in 0..n {
        let (a, b) = (pts[i], pts[(i + 1) % n]);
        let ab = b - a;
        let t = if ab.length_squared() > 0.0 { ((p - a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0) } else { 0.0 };
        best = best.min((a + ab * t - p).length());
        let s = ab.perp_dot(p - a);
        if s != 0.0 {
            if sign == 0.0 {
                sign = s.signum();
            } else if s.signum() != sign {
                inside = false;
            }
        }
    }
    // A wall seen edge-on projects to a segment: only the distance to it counts.
    if inside && sign != 0.0 {
        0.0
    } else {
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two triangles: the axis-aligned rectangle `lo`..`hi` (x/z) at height y, facing up.
    fn floor(lo: Vec2, hi: Vec2, y: f32) -> [[Vec3; 3]; 2] {
        let v = |x: f32, z: f32| Vec3::new(x, y, z);
        [[v(lo.x, lo.y), v(lo.x, hi.y), v(hi.x, hi.y)], [v(lo.x, lo.y), v(hi.x, hi.y), v(hi.x, lo.y)]]
    }

    /// A closed box from `lo` to `hi`: top, bottom and four sides.
    fn block(lo: Vec3, hi: Vec3) -> Vec<[Vec3; 3]> {
        let c = |i: usize| Vec3::new(if i & 1 == 0 { lo.x } else { hi.x }, if i & 2 == 0 { lo.y } else { hi.y }, if i & 4 == 0 { lo.z } else { hi.z });
        // Quads by corner index, wound so that their normals face out.
        let quads = [[2, 6, 7, 3], [0, 1, 5, 4], [0, 2, 3, 1], [4, 5, 7, 6], [0, 4, 6, 2], [1, 3, 7, 5]];
        quads.iter().flat_map(|q| [[c(q[0]), c(q[1]), c(q[2])], [c(q[0]), c(q[2]), c(q[3])]]).collect()
    }

    /// A 20 m floor at y = 0 with a 0.3 m step (x 2..4), a 1 m ledge (x 6..8) and a 3 m wall
    /// (x 10..10.2), each across z -5..5; a 2 m deep pit floor at x 12..20.
    fn course() -> WalkMesh {
        let mut t: Vec<[Vec3; 3]> = floor(Vec2::new(-5.0, -5.0), Vec2::new(12.0, 5.0), 0.0).to_vec();
        t.extend(floor(Vec2::new(12.0, -5.0), Vec2::new(20.0, 5.0), -2.0));
        t.extend(block(Vec3::new(2.0, 0.0, -5.0), Vec3::new(4.0, 0.3, 5.0)));
        t.extend(block(Vec3::new(6.0, 0.0, -5.0), Vec3::new(8.0, 1.0, 5.0)));
        t.extend(block(Vec3::new(10.0, 0.0, -5.0), Vec3::new(10.2, 3.0, 5.0)));
        WalkMesh::new(t)
    }

    fn walk_x(m: &WalkMesh, from: Vec3, to_x: f32) -> Vec3 {
        m.step(from, Vec3::new(to_x - from.x, 0.0, 0.0))
    }

    #[test]
    fn the_feet_climb_a_step_and_come_down_from_it() {
        let m = course();
        let on_step = walk_x(&m, Vec3::ZERO, 3.0);
        assert!((on_step - Vec3::new(3.0, 0.3, 0.0)).length() < 1e-4, "{on_step}");
        let past = walk_x(&m, on_step, 5.0);
        assert!((past - Vec3::new(5.0, 0.0, 0.0)).length() < 1e-4, "{past}");
    }

    #[test]
    fn a_ledge_higher_than_a_step_stops_the_body_a_radius_short() {
        let m = course();
        let stopped = walk_x(&m, Vec3::new(5.0, 0.0, 0.0), 7.0);
        assert_eq!(stopped.y, 0.0);
        assert!(stopped.x < 6.0 - BODY_RADIUS_M + 1e-3 && stopped.x > 6.0 - BODY_RADIUS_M - MAX_SUBSTEP_M, "{stopped}");
    }

    #[test]
    fn a_wall_stops_the_body_and_it_slides_along_it() {
        let m = course();
        // Towards the wall at 45 degrees: x stops a radius short, z keeps going.
        let slid = m.step(Vec3::new(9.0, 0.0, 0.0), Vec3::new(2.0, 0.0, 2.0));
        assert!(slid.x < 10.0 - BODY_RADIUS_M + 1e-3, "{slid}");
        assert!((slid.z - 2.0).abs() < 1e-4, "{slid}");
        // Never through it, however long the frame.
        assert!(walk_x(&m, Vec3::new(9.0, 0.0, 0.0), 15.0).x < 10.0);
    }

    #[test]
    fn the_feet_drop_into_a_pit_and_stop_at_the_edge_of_the_level() {
        let m = course();
        // From the far side of the wall (x 10.5) into the pit: down 2 m.
        let down = walk_x(&m, Vec3::new(10.6, 0.0, 0.0), 14.0);
        assert!((down - Vec3::new(14.0, -2.0, 0.0)).length() < 1e-4, "{down}");
        // The pit's far end is the end of the floor: no floor, no move.
        let end = walk_x(&m, down, 25.0);
        assert!(end.x <= 20.0 && end.x > 19.8, "{end}");
    }

    #[test]
    fn a_pack_level_is_walked_on_its_world_space_triangles() {
        // A floor mesh placed 1 m up by its node: the floor query sees it there.
        let mut b = pack::PackBuilder::new("generated", "test");
        let tris = floor(Vec2::new(-2.0, -2.0), Vec2::new(2.0, 2.0), 0.0);
        let verts: Vec<pack::Vertex> = tris.iter().flatten().map(|p| pack::Vertex { position: p.to_array(), ..Default::default() }).collect();
        let (vertices, uv_ranges) = b.push_vertices(&verts);
        let indices = b.push_bytes(&(0u32..6).flat_map(|i| i.to_le_bytes()).collect::<Vec<u8>>());
        b.manifest.meshes.push(pack::Mesh {
            name: "floor".into(),
            lods: vec![pack::MeshLod { vertices, uv_ranges, vertex_count: 6, indices, index_count: 6, index_format: pack::IndexFormat::U32, submeshes: vec![], error: 0.0 }],
            bounds_min: [-2.0, 0.0, -2.0],
            bounds_max: [2.0, 0.0, 2.0],
        });
        let floor_node = |name: &str, y: f32, is_static| pack::Node { name: name.into(), local: Mat4::from_translation(Vec3::Y * y).to_cols_array(), mesh: Some(0), is_static, ..Default::default() };
        b.manifest.nodes.push(floor_node("floor", 1.0, true));
        // The same mesh placed again as a dynamic instance (a prop that may move): not walked on.
        b.manifest.nodes.push(floor_node("raft", 3.0, false));
        let m = WalkMesh::from_pack(&b.finish());
        assert_eq!(m.floor(Vec2::ZERO, 5.0), Some(1.0));
        assert_eq!(m.floor(Vec2::ZERO, 0.5), None, "a floor above `top` is not under the feet");
        assert_eq!(m.floor(Vec2::new(3.0, 0.0), 5.0), None);
    }
}
