//! Load-time uploads through one staging ring (`gpu::Uploader`, issue 24): copies wait in the
//! ring and run together, a submit when it fills and one at the end; an upload larger than the
//! ring gets a staging buffer of its own. What lands in the device buffers is read back and
//! compared byte for byte; the demo level goes up in one submit.

use ash::vk;
use engine::gpu::{Buffer, Uploader};
use gpu_allocator::MemoryLocation;
use std::path::Path;

mod common;
use common::{assert_clean, gpu};

/// The bytes of a device-local buffer, through a copy into a host-visible one.
fn read_back(gpu: &engine::gpu::Gpu, b: &Buffer) -> Vec<u8> {
    let mut host = Buffer::new(gpu, "read back", b.size, vk::BufferUsageFlags::TRANSFER_DST, MemoryLocation::GpuToCpu).unwrap();
    gpu.one_shot(|cb| unsafe { gpu.device.cmd_copy_buffer(cb, b.buffer, host.buffer, &[vk::BufferCopy::default().size(b.size)]) }).unwrap();
    let bytes = host.mapped_ref().to_vec();
    host.destroy(gpu);
    bytes
}

#[test]
fn copies_wait_in_the_ring_and_run_in_few_submits() {
    let gpu = gpu();
    let mut up = Uploader::new(1000);
    let pattern = |n: usize, seed: u8| -> Vec<u8> { (0..n).map(|i| (i as u8).wrapping_mul(31).wrapping_add(seed)).collect() };
    let (a, b, c, big) = (pattern(300, 1), pattern(500, 2), pattern(400, 3), pattern(2500, 4));
    let usage = vk::BufferUsageFlags::TRANSFER_SRC;
    let mut made = Vec::new();
    made.push(up.buffer(&gpu, "a", &[&a], usage).unwrap());
    // Two parts, one buffer: laid out one after the other.
    made.push(up.buffer(&gpu, "b", &[&b[..123], &b[123..]], usage).unwrap());
    assert_eq!(up.submits, 0, "300 + 500 bytes fit the 1000-byte ring: nothing submitted yet");
    made.push(up.buffer(&gpu, "c", &[&c], usage).unwrap());
    assert_eq!(up.submits, 1, "400 more do not fit: the ring's copies ran first");
    made.push(up.buffer(&gpu, "big", &[&big], usage).unwrap());
    assert_eq!(up.submits, 1, "larger than the ring: a staging buffer of its own, no submit yet");
    let empty = up.buffer(&gpu, "empty", &[], usage).unwrap();
    up.flush(&gpu).unwrap();
    assert_eq!((up.submits, up.bytes), (2, 3700));
    for (buffer, want) in made.iter().zip([&a, &b, &c, &big]) {
        assert_eq!(&read_back(&gpu, buffer), want);
    }
    up.flush(&gpu).unwrap();
    assert_eq!(up.submits, 2, "nothing pending: no submit");
    up.destroy(&gpu);
    for mut b in made.into_iter().chain([empty]) {
        b.destroy(&gpu);
    }
    assert_clean(&gpu);
}

#[test]
fn the_demo_level_goes_up_in_one_submit() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../build/temple.pack");
    let pack = pack::Pack::read_file(&path).unwrap_or_else(|e| panic!("{}: {e} (`make cook` makes it; `make test` runs it first)", path.display()));
    let gpu = gpu();
    let renderer = engine::render::renderer::Renderer::new(&gpu, engine::app::headless::OFFSCREEN_FORMAT, 1).unwrap();
    let mut scene = engine::scene::GpuScene::upload(&gpu, &pack, renderer.layouts()).unwrap();
    // Every buffer, texture, mip level and lightmap page of the level (16.6 MB as stored, 20.0
    // MB once a CPU device's textures are decoded) in one submit.
    assert_eq!(scene.upload.submits, 1, "{:?}", scene.upload);
    assert!(scene.upload.bytes as f64 > 0.8 * pack.data.len() as f64, "{:?} of a pack of {} bytes", scene.upload, pack.data.len());
    scene.destroy(&gpu);
    let mut renderer = renderer;
    renderer.destroy(&gpu);
    assert_clean(&gpu);
}
