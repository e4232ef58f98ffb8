//! The scene's placed meshes behind handles: spawn, move and despawn them while rendering, and
//! the culling spheres, the static/dynamic split and the scene's bounds stay right by
//! themselves. Instances live in dense arrays (what culling and drawing walk, by index); an
//! `InstanceId` finds its instance through a slot with a generation, so a despawned handle is
//! refused rather than aliasing whatever took its place.
//!
//! Cost: nothing per frame for static instances. A static change (spawn, move or despawn of a
//! static instance) bumps `static_version`, which is what caches of static data key on (the
//! shadow map's static casters); the static bounds are recomputed once, lazily. Moving a dynamic
//! instance costs its own sphere; the dynamic part of the bounds is derived from the dynamic
//! instances' spheres (skinned characters' come from their pose), O(dynamic) when asked.

use crate::render::cull::{world_sphere, Spheres};
use glam::{Mat4, Vec3};
use std::cell::Cell;

/// One placed mesh.
#[derive(Debug, Clone, Copy)]
pub struct Instance {
    pub mesh: u32,
    pub world: Mat4,
    /// Largest axis scale of `world` (object-space errors and radii to world metres).
    pub scale: f32,
    /// A static placement (`pack::Node::is_static`): its shadow is cached, and moving it redraws
    /// that cache; the sun's shadow map is not drawn for static instances alone.
    pub is_static: bool,
    /// Where its lightmap lies in the atlas (`pack::Node::lightmap`): with baked pages it is lit
    /// by them rather than by the probes and the sun.
    pub lightmap: Option<pack::LightmapRegion>,
    /// A material drawn instead of every submesh's own (None: the mesh's materials).
    pub material: Option<u32>,
}

/// A spawned instance, valid until it is despawned.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct InstanceId {
    slot: u32,
    generation: u32,
}

/// What is wrong with a call (a caller's mistake, reported, never a panic).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum InstanceError {
    #[error("instance handle {0:?} was despawned (or never spawned here)")]
    Stale(InstanceId),
    #[error("mesh {mesh} does not exist (the scene has {meshes})")]
    NoMesh { mesh: u32, meshes: usize },
    #[error("material {material} does not exist (the scene has {materials})")]
    NoMaterial { material: u32, materials: usize },
}

/// A mesh's bounds in its own space: the box and the sphere around it.
#[derive(Debug, Clone, Copy)]
pub struct LocalBounds {
    pub min: Vec3,
    pub max: Vec3,
}

impl LocalBounds {
    fn sphere(&self, world: Mat4) -> (Vec3, f32) {
        world_sphere(world, (self.min + self.max) * 0.5, (self.max - self.min).length() * 0.5)
    }
}

/// A world-space box (min, max).
type Bounds = (Vec3, Vec3);

#[derive(Debug, Clone, Copy)]
struct Slot {
    generation: u32,
    /// Index into the dense arrays while alive.
    dense: Option<u32>,
}

#[derive(Debug, Default)]
pub struct Instances {
    dense: Vec<Instance>,
    spheres: Spheres,
    /// The slot of each dense instance (to fix a moved one's slot on despawn).
    owner: Vec<u32>,
    /// Whether each dense instance's sphere was set from a pose (`set_sphere`) rather than
    /// derived from its transform: the bounds then use the sphere, not the transformed box.
    posed: Vec<bool>,
    slots: Vec<Slot>,
    free: Vec<u32>,
    /// Dense indices of the dynamic instances, kept up to date by spawn and despawn.
    dynamic: Vec<u32>,
    static_version: u64,
    /// World bounds of the static instances (transformed boxes), for `static_version`.
    static_bounds: Cell<Option<(u64, Option<Bounds>)>>,
}

impl Instances {
    pub fn len(&self) -> usize {
        self.dense.len()
    }

    pub fn is_empty(&self) -> bool {
        self.dense.is_empty()
    }

    pub fn iter(&self) -> std::slice::Iter<'_, Instance> {
        self.dense.iter()
    }

    /// The culling spheres, by dense index.
    pub fn spheres(&self) -> &Spheres {
        &self.spheres
    }

    /// Bumped by every change to a static instance: caches of static data key on it.
    pub fn static_version(&self) -> u64 {
        self.static_version
    }

    /// Dense indices of the dynamic instances (in no particular order).
    pub fn dynamic(&self) -> &[u32] {
        &self.dynamic
    }

    /// Add `instance` (its sphere from `bounds`, the mesh's local bounds).
    pub fn spawn(&mut self, instance: Instance, bounds: LocalBounds) -> InstanceId {
        let dense = self.dense.len() as u32;
        let slot = match self.free.pop() {
            Some(s) => {
                self.slots[s as usize].dense = Some(dense);
                s
            }
            None => {
                self.slots.push(Slot { generation: 0, dense: Some(dense) });
                self.slots.len() as u32 - 1
            }
        };
        let (c, r) = bounds.sphere(instance.world);
        self.spheres.push(c, r);
        self.dense.push(instance);
        self.owner.push(slot);
        self.posed.push(false);
        if instance.is_static {
            self.static_version += 1;
        } else {
            self.dynamic.push(dense);
        }
        InstanceId { slot, generation: self.slots[slot as usize].generation }
    }

    /// The dense index of `id` (what draw lists and culling use), if it is alive.
    pub fn index_of(&self, id: InstanceId) -> Result<u32, InstanceError> {
        self.slots.get(id.slot as usize).filter(|s| s.generation == id.generation).and_then(|s| s.dense).ok_or(InstanceError::Stale(id))
    }

    /// The handle of dense instance `i` (those a pack placed: `GpuScene::upload` spawns them
    /// in node order).
    pub fn id_at(&self, i: usize) -> InstanceId {
        let slot = self.owner[i];
        InstanceId { slot, generation: self.slots[slot as usize].generation }
    }

    pub fn get(&self, id: InstanceId) -> Result<&Instance, InstanceError> {
        Ok(&self.dense[self.index_of(id)? as usize])
    }

    /// Move `id` to `world` (its sphere and scale follow; `bounds` are its mesh's).
    pub fn set_transform(&mut self, id: InstanceId, world: Mat4, bounds: LocalBounds) -> Result<(), InstanceError> {
        let i = self.index_of(id)? as usize;
        let inst = &mut self.dense[i];
        if inst.world == world {
            // Nothing moved: static caches stay valid.
            return Ok(());
        }
        inst.world = world;
        inst.scale = crate::scene::max_scale(world);
        if inst.is_static {
            self.static_version += 1;
        }
        let (c, r) = bounds.sphere(world);
        self.set_sphere(i, c, r);
        self.posed[i] = false;
        Ok(())
    }

    /// Set dense instance `i`'s culling sphere from its pose (animation): the bounds follow it.
    pub fn set_sphere(&mut self, i: usize, centre: Vec3, radius: f32) {
        let s = &mut self.spheres;
        (s.x[i], s.y[i], s.z[i], s.r[i]) = (centre.x, centre.y, centre.z, radius);
        self.posed[i] = true;
    }

    /// Remove `id`: the last dense instance takes its place (its handle stays valid).
    pub fn despawn(&mut self, id: InstanceId) -> Result<(), InstanceError> {
        let i = self.index_of(id)? as usize;
        let last = self.dense.len() - 1;
        // O(dynamic): drop i from the dynamic list, and the last instance moves to i.
        self.dynamic.retain(|&d| d as usize != i);
        for d in &mut self.dynamic {
            if *d as usize == last {
                *d = i as u32;
            }
        }
        self.dense.swap_remove(i);
        self.owner.swap_remove(i);
        self.posed.swap_remove(i);
        for v in [&mut self.spheres.x, &mut self.spheres.y, &mut self.spheres.z, &mut self.spheres.r] {
            v.swap_remove(i);
        }
        if i != last {
            self.slots[self.owner[i] as usize].dense = Some(i as u32);
        }
        let slot = &mut self.slots[id.slot as usize];
        slot.dense = None;
        slot.generation = slot.generation.wrapping_add(1);
        self.free.push(id.slot);
        // Dense indices moved: every cache keyed on them is stale.
        self.static_version += 1;
        Ok(())
    }

    /// World bounds of every instance: their transformed boxes (the static ones cached until a
    /// static change), except where a pose set the sphere (a walking, skinned character): that
    /// sphere. None without instances. `bounds(mesh)` gives a mesh's local bounds.
    pub fn world_bounds(&self, bounds: impl Fn(u32) -> LocalBounds) -> Option<(Vec3, Vec3)> {
        let statics = match self.static_bounds.get() {
            Some((version, b)) if version == self.static_version => b,
            _ => {
                let b = union(self.dense.iter().filter(|i| i.is_static).map(|i| {
                    let l = bounds(i.mesh);
                    crate::scene::transform_bounds(i.world, l.min, l.max)
                }));
                self.static_bounds.set(Some((self.static_version, b)));
                b
            }
        };
        let s = &self.spheres;
        let dynamic = union(self.dynamic.iter().map(|&i| {
            let (i, inst) = (i as usize, &self.dense[i as usize]);
            if self.posed[i] {
                let (c, r) = (Vec3::new(s.x[i], s.y[i], s.z[i]), s.r[i]);
                (c - Vec3::splat(r), c + Vec3::splat(r))
            } else {
                let l = bounds(inst.mesh);
                crate::scene::transform_bounds(inst.world, l.min, l.max)
            }
        }));
        union(statics.into_iter().chain(dynamic))
    }
}

impl std::ops::Index<usize> for Instances {
    type Output = Instance;
    fn index(&self, i: usize) -> &Instance {
        &self.dense[i]
    }
}

fn union(boxes: impl Iterator<Item = (Vec3, Vec3)>) -> Option<(Vec3, Vec3)> {
    boxes.reduce(|(a, b), (c, d)| (a.min(c), b.max(d)))
}

#[cfg(test)]
mod tests {
    use super::*;

    const UNIT: LocalBounds = LocalBounds { min: Vec3::splat(-1.0), max: Vec3::splat(1.0) };

    fn at(x: f32, is_static: bool) -> Instance {
        Instance { mesh: 0, world: Mat4::from_translation(Vec3::new(x, 0.0, 0.0)), scale: 1.0, is_static, lightmap: None, material: None }
    }

    #[test]
    fn handles_survive_a_despawn_that_moves_another_instance_and_stale_ones_are_refused() {
        let mut s = Instances::default();
        let a = s.spawn(at(0.0, true), UNIT);
        let b = s.spawn(at(10.0, false), UNIT);
        let c = s.spawn(at(20.0, false), UNIT);
        s.despawn(a).unwrap();
        // c moved into a's dense place; both live handles still find their own instance.
        assert_eq!((s.len(), s.index_of(c), s.index_of(b)), (2, Ok(0), Ok(1)));
        assert_eq!(s.spheres().x, vec![20.0, 10.0]);
        assert_eq!(s.get(a).unwrap_err(), InstanceError::Stale(a));
        assert_eq!(s.despawn(a), Err(InstanceError::Stale(a)));
        // A new spawn reuses a's slot with a new generation: a stays refused.
        let d = s.spawn(at(30.0, false), UNIT);
        assert_eq!(s.index_of(d), Ok(2));
        assert!(s.index_of(a).is_err());
        let mut dynamic = s.dynamic().to_vec();
        dynamic.sort();
        assert_eq!(dynamic, [0, 1, 2]);
    }

    #[test]
    fn only_static_changes_bump_the_static_version_and_bounds_follow_moves_and_poses() {
        let mut s = Instances::default();
        let wall = s.spawn(at(0.0, true), UNIT);
        let walker = s.spawn(at(0.0, false), UNIT);
        let v = s.static_version();
        s.set_transform(walker, Mat4::from_translation(Vec3::new(50.0, 0.0, 0.0)), UNIT).unwrap();
        assert_eq!(s.static_version(), v, "moving a dynamic instance leaves static caches valid");
        // The moved box at x = 50 widens the bounds.
        assert_eq!(s.world_bounds(|_| UNIT).unwrap(), (Vec3::splat(-1.0), Vec3::new(51.0, 1.0, 1.0)));
        // A pose's sphere (radius 2 at x = -10) counts as the sphere.
        s.set_sphere(s.index_of(walker).unwrap() as usize, Vec3::new(-10.0, 0.0, 0.0), 2.0);
        let (lo, hi) = s.world_bounds(|_| UNIT).unwrap();
        assert_eq!((lo, hi), (Vec3::new(-12.0, -2.0, -2.0), Vec3::new(1.0, 2.0, 2.0)));
        assert_eq!(s.static_version(), v, "a pose is not a static change");
        s.set_transform(wall, Mat4::from_translation(Vec3::new(-5.0, 0.0, 0.0)), UNIT).unwrap();
        assert!(s.static_version() > v);
        assert_eq!(s.world_bounds(|_| UNIT).unwrap().1.x, -4.0, "the wall's box moved to x = -5");
    }
}
