//! The skinning compute pass against the CPU reference, on the real Vulkan device (lavapipe in
//! CI) with validation on. Sample models are cooked in-process with cook_core, so these tests
//! need the Khronos samples ($GLTF_SAMPLES_DIR, default ../shared/gltf-samples) but no Python.

use engine::anim::skin_cpu::{skin_cpu, DeformData};
use engine::anim::skin_gpu::{JobSpec, Owner, SkinBatch, SkinPipeline};
use engine::anim::{joint_count, node_joint_matrices, Rig};
use glam::{Mat4, Quat, Vec3};
use pack::Vertex;

mod common;
use common::{assert_clean, cook, gpu, samples};

/// Largest position difference over the model's size (bounding box diagonal of `a`).
fn relative_error(a: &[Vertex], b: &[Vertex]) -> f32 {
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for v in a {
        lo = lo.min(Vec3::from(v.position));
        hi = hi.max(Vec3::from(v.position));
    }
    let size = (hi - lo).length().max(1e-6);
    a.iter().zip(b).map(|(x, y)| (Vec3::from(x.position) - Vec3::from(y.position)).length()).fold(0.0, f32::max) / size
}

#[test]
fn gpu_skinning_equals_the_cpu_reference_on_the_sample_models() {
    let Some(dir) = samples() else { return };
    let gpu = gpu();
    let mut pipe = SkinPipeline::new(&gpu).unwrap();
    // Every deforming node of the four models, each a job of one batch with its own pose (owner)
    // and data (source), skinned in one dispatch as the renderer does: each job's range of the
    // output must match the CPU reference for that node alone.
    struct Case {
        label: String,
        data: DeformData,
        joints: Vec<Mat4>,
        weights: Vec<f32>,
        cpu: Vec<Vertex>,
    }
    let mut cases = Vec::new();
    // (model, time in seconds): times inside each model's clip, away from its keys.
    for (name, time) in [("SimpleSkin", 1.3f32), ("RiggedSimple", 0.9), ("BoxAnimated", 1.7), ("SimpleMorph", 0.7)] {
        let pack = cook(&dir, name);
        let rig = Rig::from_pack(&pack);
        assert!(!rig.clips.is_empty(), "{name}: no clip was cooked");
        let mut pose = rig.new_pose();
        rig.sample(0, time, false, &mut pose);
        rig.update_globals(&mut pose);
        let mut moved = 0.0f32;
        let mut deformed_meshes = 0;
        for node in 0..pack.manifest.nodes.len() {
            let Some(data) = DeformData::for_node(&pack, node, 0) else { continue };
            let mut joints = vec![Mat4::IDENTITY; joint_count(&pack, node)];
            node_joint_matrices(&pack, &rig, node, &pose, &mut joints);
            let weights = rig.node_weights(node, &pose).to_vec();
            let mut cpu = data.vertices.clone();
            skin_cpu(&data, &weights, &joints, &mut cpu);
            moved = moved.max(relative_error(&cpu, &data.vertices));
            deformed_meshes += 1;
            cases.push(Case { label: format!("{name} node {node}"), data, joints, weights, cpu });
        }
        assert!(deformed_meshes > 0, "{name}: no mesh node");
        // The pose at `time` must actually deform something, or the comparison proves little.
        assert!(moved > 1e-3, "{name}: the pose at {time} s leaves every vertex in place");
    }
    let sources: Vec<&DeformData> = cases.iter().map(|c| &c.data).collect();
    let owners: Vec<Owner> = cases.iter().map(|c| Owner { joints: c.joints.len(), targets: c.data.targets }).collect();
    let jobs: Vec<JobSpec> = (0..cases.len()).map(|k| JobSpec { owner: k, source: k }).collect();
    let mut batch = SkinBatch::new(&gpu, &pipe, &sources, &owners, &jobs, 1).unwrap();
    for (k, c) in cases.iter().enumerate() {
        batch.update(0, k, &c.joints, &c.weights);
    }
    let outputs = batch.run_and_read_back(&gpu, &pipe).unwrap();
    batch.destroy(&gpu);
    assert_eq!(outputs.len(), cases.len());
    for (c, gpu_out) in cases.iter().zip(&outputs) {
        let err = relative_error(&c.cpu, gpu_out);
        println!(
            "{}: {} vertices, {} joints, {} morph targets, GPU vs CPU relative error {err:.2e}",
            c.label,
            c.cpu.len(),
            c.joints.len(),
            c.data.targets
        );
        assert!(err <= 1e-4, "{}: GPU differs from the CPU reference by {err:e} of the model size", c.label);
        let normals_ok = c.cpu.iter().zip(gpu_out).all(|(a, b)| (Vec3::from(a.normal) - Vec3::from(b.normal)).length() < 1e-4);
        assert!(normals_ok, "{}: skinned normals differ", c.label);
    }
    pipe.destroy(&gpu);
    assert_clean(&gpu);
}

#[test]
fn gpu_skinning_handles_300_joints_and_four_influences() {
    let gpu = gpu();
    let mut pipe = SkinPipeline::new(&gpu).unwrap();
    let joints_n = 300usize;
    let n = 1000usize;
    let vertices: Vec<Vertex> = (0..n)
        .map(|i| {
            let f = i as f32;
            Vertex {
                position: [f.sin(), (f * 0.37).cos(), f * 0.01],
                normal: Vec3::new(1.0, f.cos(), 0.5).normalize().to_array(),
                tangent: [1.0, 0.0, 0.0, -1.0],
                uv0: [f * 0.5, -f],
                uv1: [f * 0.25, 1.0 - f],
                color: [i as u8, (i >> 8) as u8, 7, 255],
                ..Default::default()
            }
        })
        .collect();
    let joints: Vec<[u16; 4]> = (0..n).map(|i| std::array::from_fn(|k| ((i * 7 + k * 101) % joints_n) as u16)).collect();
    let weights: Vec<[f32; 4]> = (0..n).map(|_| [0.4, 0.3, 0.2, 0.1]).collect();
    let data = DeformData {
        uv_ranges: pack::UvRanges::fit(&vertices),
        vertices,
        joints: Some(joints),
        weights: Some(weights),
        targets: 0,
        morph_positions: vec![],
        morph_normals: vec![],
    };
    // `mirror` -1 reflects every joint in x: the normal matrix's determinant is then negative,
    // and a shader taking the cofactor matrix without its sign would turn normals inside out.
    for mirror in [1.0f32, -1.0] {
        let mats: Vec<Mat4> = (0..joints_n)
            .map(|j| {
                let a = j as f32 * 0.05;
                let scale = Vec3::new(mirror, 1.0, 1.0) * (1.0 + 0.001 * j as f32);
                Mat4::from_scale_rotation_translation(scale, Quat::from_rotation_y(a) * Quat::from_rotation_x(0.3 * a), Vec3::new(a, -a, 0.5))
            })
            .collect();
        let mut cpu = data.vertices.clone();
        skin_cpu(&data, &[], &mats, &mut cpu);
        let mut skinned = SkinBatch::single(&gpu, &pipe, &data, joints_n).unwrap();
        skinned.update(0, 0, &mats, &[]);
        let out = skinned.run_and_read_back(&gpu, &pipe).unwrap().remove(0);
        skinned.destroy(&gpu);
        let err = relative_error(&cpu, &out);
        assert!(err <= 1e-5, "mirror {mirror}: relative error {err:e}");
        // The output is stored quantised: 16-bit octahedral normals and tangents (<= 0.01°,
        // 1.7e-4 of a unit vector; engine/pack/src/vertex.rs).
        let close = |a: [f32; 3], b: [f32; 3]| (Vec3::from(a) - Vec3::from(b)).length() < 4e-4;
        let bad_normals = cpu.iter().zip(&out).filter(|(c, g)| !close(c.normal, g.normal)).count();
        assert_eq!(bad_normals, 0, "mirror {mirror}: skinned normals differ from the CPU reference's");
        let bad_tangents = cpu
            .iter()
            .zip(&out)
            .filter(|(c, g)| !close([c.tangent[0], c.tangent[1], c.tangent[2]], [g.tangent[0], g.tangent[1], g.tangent[2]]))
            .count();
        assert_eq!(bad_tangents, 0, "mirror {mirror}: skinned tangents differ from the CPU reference's");
        // Everything after the tangent's xyz passes through bit for bit: the codes the input was
        // stored as.
        let stored = pack::decode_vertices(&pack::encode_vertices_with(&data.vertices, &data.uv_ranges), &data.uv_ranges);
        assert!(out
            .iter()
            .zip(&stored)
            .all(|(o, v)| o.uv0 == v.uv0 && o.uv1 == v.uv1 && o.color == v.color && o.tangent[3] == v.tangent[3]));
    }
    pipe.destroy(&gpu);
    // Joint 299 is in use, so the joint buffer really holds all 300.
    assert!(data.joints.as_ref().unwrap().iter().flatten().any(|&j| j as usize == joints_n - 1));
    assert_clean(&gpu);
}

#[test]
fn sample_models_cook_with_their_skins_clips_and_morph_targets() {
    let Some(dir) = samples() else { return };
    let skin = cook(&dir, "SimpleSkin");
    let a = &skin.manifest.animation;
    assert_eq!((a.skins.len(), a.skins[0].joints.len(), a.clips.len()), (1, 2, 1));
    let d = DeformData::from_pack(&skin, 0, 0);
    let w = d.weights.as_ref().unwrap();
    assert!(w.iter().all(|w| (w.iter().sum::<f32>() - 1.0).abs() < 1e-6), "weights sum to 1 after cooking");
    let morph = cook(&dir, "SimpleMorph");
    let m = &morph.manifest.animation;
    assert_eq!(m.meshes[0].morph_weights, vec![0.5, 0.5]);
    assert_eq!(m.clips[0].channels[0].path, pack::ChannelPath::Weights);
    let boxes = cook(&dir, "BoxAnimated");
    assert_eq!(boxes.manifest.animation.clips.len(), 2, "BoxAnimated has two animations");
}

/// The benchmark shape, measured rather than asserted (run with `--ignored`): 64
/// characters of 10k vertices and 64 joints, skinned in one command buffer, and the CPU time to
/// sample 64 animators of a cooked rig.
#[test]
#[ignore]
fn measure_skinning_64_characters_of_10k_vertices() {
    let gpu = gpu();
    let mut pipe = SkinPipeline::new(&gpu).unwrap();
    let (n, joints_n) = (10_000usize, 64usize);
    let vertices: Vec<Vertex> = (0..n)
        .map(|i| Vertex {
            position: [(i % 100) as f32 * 0.01, (i / 100) as f32 * 0.01, 0.0],
            normal: [0.0, 0.0, 1.0],
            tangent: [1.0, 0.0, 0.0, 1.0],
            ..Default::default()
        })
        .collect();
    let data = DeformData {
        uv_ranges: pack::UvRanges::fit(&vertices),
        vertices,
        joints: Some((0..n).map(|i| std::array::from_fn(|k| ((i / 160 + k) % joints_n) as u16)).collect()),
        weights: Some(vec![[0.4, 0.3, 0.2, 0.1]; n]),
        targets: 0,
        morph_positions: vec![],
        morph_normals: vec![],
    };
    let mats: Vec<Mat4> = (0..joints_n).map(|j| Mat4::from_rotation_z(j as f32 * 0.01)).collect();
    // 64 characters of one mesh: one source, 64 owners, skinned in one dispatch.
    let owners = vec![Owner { joints: joints_n, targets: 0 }; 64];
    let jobs: Vec<JobSpec> = (0..64).map(|k| JobSpec { owner: k, source: 0 }).collect();
    let mut batch = SkinBatch::new(&gpu, &pipe, &[&data], &owners, &jobs, 1).unwrap();
    for k in 0..64 {
        batch.update(0, k, &mats, &[]);
    }
    let mut times = Vec::new();
    for _ in 0..5 {
        let t = std::time::Instant::now();
        gpu.one_shot(|cb| batch.record(&gpu, &pipe, cb)).unwrap();
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    println!(
        "skinning 64 x {n} vertices ({joints_n} joints) on {}: median {:.2} ms per frame (submit + wait)",
        gpu.caps.device_name, times[2]
    );
    batch.destroy(&gpu);
    pipe.destroy(&gpu);
    if let Some(dir) = samples() {
        let pack = cook(&dir, "RiggedSimple");
        let rig = Rig::from_pack(&pack);
        let mut animators: Vec<engine::anim::Animator> = (0..64)
            .map(|i| {
                let mut a = engine::anim::Animator::new(&rig, 0);
                a.time = i as f32 * 0.05;
                a
            })
            .collect();
        let mut jm = vec![Mat4::IDENTITY; rig.skins[0].joints.len()];
        let t = std::time::Instant::now();
        for _ in 0..100 {
            for a in &mut animators {
                a.advance(&rig, 1.0 / 60.0);
                rig.joint_matrices(0, &a.pose, &mut jm);
            }
        }
        println!("CPU sampling of 64 RiggedSimple animators: {:.4} ms per frame", t.elapsed().as_secs_f64() * 1e3 / 100.0);
    }
}
