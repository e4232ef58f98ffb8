//! The scenarios' setups: the scene, world, camera and variant switches each one measures.

use super::*;

pub(super) fn setup(gpu: &Gpu, o: &Options, name: &str, renderer: &mut Renderer) -> anyhow::Result<Setup> {
    match name {
        "demo-flythrough" => demo_flythrough(gpu, o, renderer),
        "culling-100k" => culling(gpu, renderer, 100_000),
        "boids-10k" => boids(gpu, renderer, 10_000),
        "particles-100k" => particles(gpu, renderer, 100_000),
        "skinned-64" => skinned(gpu, o, renderer, 64),
        "prepass-overdraw" => overdraw(gpu, renderer, 16),
        other => anyhow::bail!("unknown scenario '{other}'"),
    }
}

fn empty_world() -> World {
    World::new(FixedClock::new(ClockParams::default()))
}

fn read_pack(path: &Path) -> anyhow::Result<Pack> {
    Pack::read_file(path).map_err(|e| match e {
        pack::PackError::Io(io) => anyhow::anyhow!("{}: {io} (run `make cook` to cook the project's content)", path.display()),
        other => anyhow::anyhow!("{}: {other}", path.display()),
    })
}

/// The demo level as `demo` shows it headless (animation, spawned boids and particles warmed up),
/// seen along the headless demo's camera flight (`src/bin/demo/flight.rs`): the measured frames are
/// spread over the whole loop (a time-lapse of the camera; the simulation still steps 1/60 s per
/// frame), so the percentiles cover every view, ground level and above the roofs.
fn demo_flythrough(gpu: &Gpu, o: &Options, renderer: &mut Renderer) -> anyhow::Result<Setup> {
    let pack = read_pack(&o.level)?;
    let scene = GpuScene::upload(gpu, &pack, renderer.layouts())?;
    renderer.animation = AnimatedScene::new(gpu, &pack, &scene, 1)?;
    let (min, max) = scene.bounds();
    let mut world = level::world_from_spawns(&pack.manifest.spawns, &pack.manifest.pillars, min, max);
    level::warm_up(&mut world);
    let flight = Flight::for_pack(&pack.manifest, min, max, flight::DEFAULT_SECONDS);
    let (warmup, frames) = (o.warmup, o.frames.max(1));
    let camera = move |k: usize| flight.camera(k.saturating_sub(warmup) as f32 / frames as f32 * flight.seconds);
    let mut content = Map::new();
    content.insert("level".into(), json!(o.level.display().to_string()));
    content.insert("spawns".into(), json!(pack.manifest.spawns.len()));
    Ok(Setup {
        scene,
        world,
        camera: Box::new(camera),
        lighting: Lighting::for_pack(&pack.manifest),
        // The look's features, each off (or, for anti-aliasing, on) in a variant of its own.
        variants: vec![Switch::Msaa, Switch::Fxaa, Switch::SkyOff, Switch::MaterialMapsOff, Switch::SpecularOff, Switch::TransparencyOff, Switch::BicubicLightmaps, Switch::ReflectionsOff],
        content,
    })
}

fn looking_at(position: Vec3, target: Vec3) -> Camera {
    let f = (target - position).normalize_or(Vec3::NEG_Z);
    Camera {
        position,
        yaw: (-f.x).atan2(-f.z),
        pitch: f.y.clamp(-1.0, 1.0).asin(),
        fov_y: 60f32.to_radians(),
        near: 0.1,
    }
}

/// `n` cubes on a grid, the camera fixed in the middle looking along it (the older default
/// bench's scene): about a quarter in view, most of them far away.
fn culling(gpu: &Gpu, renderer: &mut Renderer, n: usize) -> anyhow::Result<Setup> {
    let scene = GpuScene::upload(gpu, &boxes_pack(cube_grid(n)), renderer.layouts())?;
    let side = (n as f64).sqrt().ceil() as f32 * 3.0;
    let camera = Camera {
        position: Vec3::new(0.5 * side, 6.0, -0.5 * side),
        yaw: -90f32.to_radians(),
        pitch: -8f32.to_radians(),
        fov_y: 60f32.to_radians(),
        near: 0.1,
    };
    let mut content = Map::new();
    content.insert("cubes".into(), json!(n));
    Ok(Setup {
        scene,
        world: empty_world(),
        camera: Box::new(move |_| camera),
        lighting: Lighting::default(),
        variants: vec![Switch::InstancingOff],
        content,
    })
}

/// Half the size of the boids' box.
const FLOCK_HALF_M: f32 = 40.0;

/// A flock of `n` in a box, drawn to its centre, over one ground slab; the camera frames the box.
fn boids(gpu: &Gpu, renderer: &mut Renderer, n: usize) -> anyhow::Result<Setup> {
    let h = Vec3::splat(FLOCK_HALF_M);
    let mut world = empty_world();
    let params = BoidParams {
        goal: Some([0.0; 3]),
        bounds: Some(Aabb {
            min: (-h).to_array(),
            max: h.to_array(),
        }),
        seed: 9,
        ..BoidParams::default()
    };
    world.flocks.push(Flock::new(params, FlockState::random(n, -h * 0.5, h * 0.5, 5.0, 9)));
    let mut pack = ground_pack(FLOCK_HALF_M);
    world.flock_meshes.push(Some(bird::push_bird(&mut pack)));
    let scene = GpuScene::upload(gpu, &pack.finish(), renderer.layouts())?;
    let camera = Camera::framing(-h, h);
    let mut content = Map::new();
    content.insert("boids".into(), json!(n));
    Ok(Setup {
        scene,
        world,
        camera: Box::new(move |_| camera),
        lighting: Lighting::default(),
        variants: Vec::new(),
        content,
    })
}

/// One flat slab under everything (the mesh passes need something to draw), unfinished.
fn ground_pack(half: f32) -> PackBuilder {
    boxes_builder(std::iter::once(Mat4::from_scale_rotation_translation(
        Vec3::new(2.0 * half, 0.2, 2.0 * half),
        glam::Quat::IDENTITY,
        Vec3::new(0.0, -half - 0.1, 0.0),
    )))
}

/// A fountain in steady state with about `n` live particles (rate × mean life = n), warmed up
/// for 2.5 s of simulated time at load, seen from the side.
fn particles(gpu: &Gpu, renderer: &mut Renderer, n: usize) -> anyhow::Result<Setup> {
    let params = EmitterParams {
        rate_per_s: n as f32 / 2.0,
        life_min_s: 1.5,
        life_max_s: 2.5,
        capacity: (n + n / 4) as u32,
        size: engine::sim::curve::Curve::constant(0.03),
        ground_y: Some(0.0),
        ..EmitterParams::preset(Preset::Fountain)
    };
    let mut world = empty_world();
    world.emitters.push(ParticleSystem::new(params));
    for _ in 0..(2.5 / FRAME_S).round() as usize {
        world.update(FRAME_S);
    }
    let scene = GpuScene::upload(gpu, &ground_pack(10.0).finish(), renderer.layouts())?;
    let camera = looking_at(Vec3::new(0.0, 3.0, 14.0), Vec3::new(0.0, 2.0, 0.0));
    let mut content = Map::new();
    content.insert("particles_target".into(), json!(n));
    Ok(Setup {
        scene,
        world,
        camera: Box::new(move |_| camera),
        lighting: Lighting::default(),
        variants: Vec::new(),
        content,
    })
}

/// `n` copies of the character pack on a grid, each playing its first clip at its own phase,
/// every one in view, so the skinning pass skins them all every frame: at the LOD their size on
/// screen picks (morphing meshes have LOD chains too), and in the variant `lod_off` all at full
/// detail (the skinning pass's worst case).
fn skinned(gpu: &Gpu, o: &Options, renderer: &mut Renderer, n: usize) -> anyhow::Result<Setup> {
    let single = read_pack(&o.character)?;
    if single.manifest.animation.skins.is_empty() || single.manifest.animation.clips.is_empty() {
        anyhow::bail!("{} has no skin or no clip", o.character.display());
    }
    let pack = skinned_bench::replicate(&single, n);
    let mut scene = GpuScene::upload(gpu, &pack, renderer.layouts())?;
    let mut anim = AnimatedScene::new(gpu, &pack, &scene, 1)?.ok_or_else(|| anyhow::anyhow!("nothing in {} deforms", o.character.display()))?;
    let per_copy = single.manifest.animation.clips.len();
    for i in 0..anim.instances.len() {
        let clip = (i % n) * per_copy;
        let phase = (i as f32 * 0.618_034).fract() * anim.rig.clips[clip].duration;
        anim.play(i, clip, phase, 1.0);
    }
    renderer.animation = Some(anim);
    // Framed on the characters' placements (their meshes' boxes), before a pose moves the
    // bounds: the same view whatever the clips do.
    let (lo, hi) = scene.bounds();
    renderer.animate(&mut scene, 0.0);
    let camera = Camera::framing(lo - Vec3::splat(1.0), hi + Vec3::splat(1.0));
    let mut content = Map::new();
    content.insert("characters".into(), json!(n));
    content.insert("character".into(), json!(o.character.display().to_string()));
    Ok(Setup {
        scene,
        world: empty_world(),
        camera: Box::new(move |_| camera),
        lighting: Lighting::default(),
        variants: vec![Switch::LodOff],
        content,
    })
}

/// `layers` thin slabs facing the camera, each covering about half the view, drawn farthest
/// first (instance order is draw order): without the pre-pass every layer shades every pixel it
/// covers; with it, only the nearest does. (Not more layers or a full screen: with the pre-pass
/// off, lavapipe takes seconds a frame.)
fn overdraw(gpu: &Gpu, renderer: &mut Renderer, layers: usize) -> anyhow::Result<Setup> {
    let slabs = (0..layers).map(|i| {
        let z = -0.25 * (layers - 1 - i) as f32;
        Mat4::from_scale_rotation_translation(Vec3::new(14.0, 8.0, 0.05), glam::Quat::IDENTITY, Vec3::new(0.0, 0.0, z))
    });
    let scene = GpuScene::upload(gpu, &boxes_pack(slabs), renderer.layouts())?;
    // No LOD to pick (one level) and nothing out of view: the work is the overdraw alone.
    let camera = looking_at(Vec3::new(0.0, 0.0, 10.0), Vec3::ZERO);
    let mut content = Map::new();
    content.insert("layers".into(), json!(layers));
    Ok(Setup {
        scene,
        world: empty_world(),
        camera: Box::new(move |_| camera),
        lighting: Lighting::default(),
        variants: vec![Switch::PrepassOff],
        content,
    })
}
