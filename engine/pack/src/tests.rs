use super::*;

/// A small but complete pack: one textured quad with a node, a material and a 2-level texture.
fn sample() -> Pack {
    let mut b = PackBuilder::new("test.gltf", "test");
    let verts: Vec<Vertex> = (0..4)
        .map(|i| Vertex {
            position: [(i & 1) as f32, (i >> 1) as f32, 0.0],
            normal: [0.0, 0.0, 1.0],
            tangent: [1.0, 0.0, 0.0, 1.0],
            uv0: [(i & 1) as f32, (i >> 1) as f32],
            color: [255, 128, 0, 255],
            texcoord1: [0.25, 0.75],
            ..Default::default()
        })
        .collect();
    let idx: Vec<u8> = [0u32, 1, 2, 2, 1, 3].iter().flat_map(|i| i.to_le_bytes()).collect();
    let (vertices, uv_ranges) = b.push_vertices(&verts);
    let indices = b.push_bytes(&idx);
    let mip0 = b.push_bytes(&[7u8; 2 * 2 * 4]);
    let mip1 = b.push_bytes(&[9u8; 4]);
    b.manifest.textures.push(Texture {
        name: "t".into(),
        width: 2,
        height: 2,
        format: TextureFormat::Rgba8Srgb,
        mips: vec![mip0, mip1],
        sampler: Sampler { wrap_s: Wrap::Clamp, wrap_t: Wrap::Mirror, mag_filter: Filter::Nearest, ..Default::default() },
    });
    let uv = TextureTransform { tex_coord: 1, offset: [0.5, 0.0], rotation: 0.3, scale: [2.0, 1.0] };
    b.manifest.materials.push(Material { base_color_texture: Some(0), base_color_uv: uv, ..Default::default() });
    let lod1 = b.push_bytes(&IndexFormat::U16.encode(&[0, 1, 2]));
    b.manifest.meshes.push(Mesh {
        name: "quad".into(),
        lods: vec![
            MeshLod {
                vertices,
                vertex_count: 4,
                uv_ranges,
                indices,
                index_count: 6,
                index_format: IndexFormat::U32,
                submeshes: vec![Submesh { first_index: 0, index_count: 6, material: 0, lightmap_block: Some(0) }],
                error: 0.0,
            },
            MeshLod {
                vertices,
                vertex_count: 4,
                uv_ranges,
                indices: lod1,
                index_count: 3,
                index_format: IndexFormat::U16,
                submeshes: vec![Submesh { first_index: 0, index_count: 3, material: 0, lightmap_block: Some(0) }],
                error: 0.5,
            },
        ],
        bounds_min: [0.0; 3],
        bounds_max: [1.0, 1.0, 0.0],
    });
    b.manifest.lights.push(Light {
        name: "sun".into(),
        kind: LightKind::Sun,
        color: [1.0, 0.95, 0.9],
        intensity: 100_000.0,
        position: [0.0; 3],
        direction: [0.0, -1.0, 0.0],
        range: None,
        inner_cone: 0.0,
        outer_cone: 0.0,
        size: [0.0; 2],
        angular_radius: 0.00465,
    });
    b.manifest.spawns.push(Spawn {
        name: "player".into(),
        kind: "player".into(),
        position: [0.0, 1.7, 0.0],
        rotation: [0.0, 0.0, 0.0, 1.0],
        params: serde_json::json!({"speed": 4.0}),
    });
    b.manifest.pillars.push(Pillar { name: "columns[1]".into(), centre: [-6.0, 3.6], radius: 0.45, y_min: 0.5, y_max: 7.3 });
    b.manifest.sky = Some(Sky { color: [0.5, 0.7, 1.0], intensity: 8000.0 });
    // A baked 4x4 lightmap page (half floats) and a 2x1x1 probe grid.
    let lm = b.push_bytes(&[0x3cu8; 4 * 4 * 8]);
    b.manifest.textures.push(Texture { name: "lightmap0".into(), width: 4, height: 4, format: TextureFormat::Rgba16Float, mips: vec![lm], sampler: Sampler::default() });
    b.manifest.lightmap = Some(LightmapLayout { texels_per_metre: 16.0, pages: vec![[4, 4]], padding: 2, textures: vec![1], directions: vec![], log_average: None, samples: None });
    let sh = b.push_bytes(&[0u8; 2 * 27 * 4]);
    let sun = b.push_bytes(&[0u8; 2 * 4]);
    b.manifest.probes = Some(ProbeGrid { origin: [0.0; 3], spacing: [2.0; 3], counts: [2, 1, 1], sh, sun_visibility: sun });
    let region = LightmapRegion { page: 0, scale: [0.5, 0.25], offset: [0.125, 0.5] };
    b.manifest.nodes.push(Node { name: "root".into(), parent: None, local: IDENTITY, mesh: Some(0), is_static: true, lightmap: Some(region) });
    b.finish()
}

const IDENTITY: [f32; 16] = [1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1.];

#[test]
fn round_trip_is_exact() {
    let p = sample();
    let bytes = p.to_bytes().unwrap();
    let q = Pack::from_bytes(&bytes).unwrap();
    assert_eq!(p, q);
    assert_eq!(q.to_bytes().unwrap(), bytes, "encoding is deterministic");
    assert_eq!(Pack::from_vec(bytes.clone()).unwrap(), q, "a file read whole keeps its data in place, the same pack");
    assert!(matches!(Pack::from_vec(bytes[..bytes.len() - 1].to_vec()), Err(PackError::Truncated { .. })));
    let lod = &q.manifest.meshes[0].lods[0];
    let v = &q.bytes(lod.vertices)[..VERTEX_STRIDE];
    assert_eq!(&v[0..4], &0.0f32.to_le_bytes());
    assert_eq!(lod.uv_ranges.texcoord1, [0.0, 0.0, 0.25, 0.75], "texcoord1: constant");
    assert_eq!(&v[32..36], &[255, 128, 0, 255], "colour");
    let decoded = decode_vertices(q.bytes(lod.vertices), &lod.uv_ranges);
    assert_eq!(decoded[3].uv0, [1.0, 1.0]);
    assert_eq!(decoded[3].texcoord1, [0.25, 0.75]);
    // The offsets the runtime binds are the codec's.
    let at = |loc: u32| VERTEX_ATTRIBUTES.iter().find(|a| a.0 == loc).unwrap().1 as usize;
    assert_eq!((at(13), at(5)), (28, 32));
}

#[test]
fn data_is_aligned_in_the_file() {
    let bytes = sample().to_bytes().unwrap();
    let data_off = u64::from_le_bytes(bytes[40..48].try_into().unwrap());
    assert_eq!(data_off % DATA_ALIGN as u64, 0);
}

#[test]
fn truncated_pack_is_reported_as_truncated() {
    let bytes = sample().to_bytes().unwrap();
    for cut in [bytes.len() - 1, bytes.len() / 2, HEADER_LEN + 1, HEADER_LEN - 1, 20] {
        match Pack::from_bytes(&bytes[..cut]) {
            Err(PackError::Truncated { actual, .. }) => assert_eq!(actual, cut as u64),
            other => panic!("cut at {cut}: expected Truncated, got {other:?}"),
        }
    }
}

#[test]
fn every_flipped_byte_after_the_header_is_caught() {
    let bytes = sample().to_bytes().unwrap();
    for i in HEADER_LEN..bytes.len() {
        let mut b = bytes.clone();
        b[i] ^= 0x40;
        assert!(
            matches!(Pack::from_bytes(&b), Err(PackError::ChecksumMismatch { .. })),
            "flip at {i} not caught"
        );
    }
}

#[test]
fn flipped_header_bytes_never_pass() {
    let bytes = sample().to_bytes().unwrap();
    for i in 0..HEADER_LEN {
        let mut b = bytes.clone();
        b[i] ^= 0x01;
        assert!(Pack::from_bytes(&b).is_err(), "header flip at {i} accepted");
    }
}

#[test]
fn wrong_version_is_reported_with_both_versions() {
    let mut bytes = sample().to_bytes().unwrap();
    bytes[8..12].copy_from_slice(&(FORMAT_VERSION + 1).to_le_bytes());
    let e = Pack::from_bytes(&bytes).unwrap_err();
    assert_eq!(e, PackError::WrongVersion { found: FORMAT_VERSION + 1, supported: FORMAT_VERSION });
    assert!(e.to_string().contains("re-cook"));
}

#[test]
fn non_pack_files_are_reported_as_such() {
    for junk in [&b""[..], b"GAME", b"{\"asset\": {\"version\": \"2.0\"}}", b"\x89PNG\r\n\x1a\n0000000000"] {
        assert_eq!(Pack::from_bytes(junk), Err(PackError::NotAPack));
    }
}

#[test]
fn trailing_garbage_is_corrupt() {
    let mut bytes = sample().to_bytes().unwrap();
    bytes.extend_from_slice(b"xx");
    assert!(matches!(Pack::from_bytes(&bytes), Err(PackError::Corrupt(_))));
}

#[test]
fn dangling_references_are_rejected_before_writing() {
    let mut p = sample();
    p.manifest.meshes[0].lods[0].submeshes[0].material = 5;
    let e = p.to_bytes().unwrap_err().to_string();
    assert!(e.contains("material 5 does not exist"), "{e}");

    let mut p = sample();
    p.manifest.textures[0].mips[1].len = 8;
    let e = p.to_bytes().unwrap_err().to_string();
    assert!(e.contains("mip 1") && e.contains("4 expected"), "{e}");

    let mut p = sample();
    p.manifest.meshes[0].lods[1].submeshes[0].lightmap_block = Some(3);
    let e = p.to_bytes().unwrap_err().to_string();
    assert!(e.contains("lightmap block 3 cannot lie on one of the 1 pages"), "{e}");

    // A static instance's lightmap region must lie on the pages, with a positive scale.
    let mut p = sample();
    p.manifest.nodes[0].lightmap = Some(LightmapRegion { page: 1, scale: [1.0, 1.0], offset: [0.0, 0.0] });
    let e = p.to_bytes().unwrap_err().to_string();
    assert!(e.contains("node 0 'root': lightmap pages 1..2 do not exist (1 pages)"), "{e}");
    let mut p = sample();
    p.manifest.nodes[0].lightmap = Some(LightmapRegion { page: 0, scale: [0.0, 1.0], offset: [0.0, 0.0] });
    let e = p.to_bytes().unwrap_err().to_string();
    assert!(e.contains("bad lightmap region"), "{e}");
    // Pages share one size (the runtime's array texture).
    let mut p = sample();
    p.manifest.lightmap.as_mut().unwrap().pages.push([8, 4]);
    let e = p.to_bytes().unwrap_err().to_string();
    assert!(e.contains("lightmap: pages of different sizes (4x4 and 8x4)"), "{e}");
    // A slot reads TEXCOORD_0 or _1 only.
    let mut p = sample();
    p.manifest.materials[0].emissive_uv.tex_coord = 2;
    let e = p.to_bytes().unwrap_err().to_string();
    assert!(e.contains("emissive reads TEXCOORD_2"), "{e}");

    // Every material texture slot is checked: it must exist and hold what the slot reads.
    let mut p = sample();
    p.manifest.materials[0].occlusion_texture = Some(4);
    let e = p.to_bytes().unwrap_err().to_string();
    assert!(e.contains("material 0 'default': occlusion texture 4 does not exist"), "{e}");
    let mut p = sample();
    p.manifest.materials[0].normal_texture = Some(0);
    let e = p.to_bytes().unwrap_err().to_string();
    assert!(e.contains("normal texture 0 't' is Rgba8Srgb, expected one of [Rgba16Unorm, Rgba8Unorm, Bc5Unorm]"), "{e}");

    let mut p = sample();
    p.manifest.meshes[0].lods[1].error = -1.0;
    let e = p.to_bytes().unwrap_err().to_string();
    assert!(e.contains("non-decreasing"), "{e}");

    let mut p = sample();
    p.manifest.nodes.push(Node { name: "loop".into(), parent: Some(1), local: IDENTITY, mesh: None, ..Default::default() });
    assert!(p.to_bytes().is_err());

    // Lightmap pages must be baked into Rgba16Float textures of the page's size.
    let mut p = sample();
    p.manifest.lightmap.as_mut().unwrap().textures = vec![0];
    let e = p.to_bytes().unwrap_err().to_string();
    assert!(e.contains("lightmap page 0: texture 0 't' is 2x2 Rgba8Srgb (2 levels), not 4x4 Rgba16Float or Bc6hUfloat (one level, page 0's format)"), "{e}");
    let mut p = sample();
    p.manifest.lightmap.as_mut().unwrap().textures = vec![1, 1];
    let e = p.to_bytes().unwrap_err().to_string();
    assert!(e.contains("2 baked textures for 1 pages"), "{e}");
    // A BC6H page of the page's size is a page too (one 4x4 block).
    let p = sample();
    let mut b = PackBuilder::new("test", "test");
    b.manifest = p.manifest.clone();
    b.push_bytes(&p.data);
    let blocks = b.push_bytes(&[0u8; 16]);
    b.manifest.textures.push(Texture { name: "lightmap0 bc6h".into(), width: 4, height: 4, format: TextureFormat::Bc6hUfloat, mips: vec![blocks], sampler: Sampler::default() });
    b.manifest.lightmap.as_mut().unwrap().textures = vec![2];
    let q = Pack::from_bytes(&b.finish().to_bytes().unwrap()).unwrap();
    assert_eq!(q.manifest.textures[2].format, TextureFormat::Bc6hUfloat);
    // Directional pages: one Rgba8Unorm (or Bc7Unorm) direction texture of the page's size per page.
    let mut p = sample();
    p.manifest.lightmap.as_mut().unwrap().directions = vec![1];
    let e = p.to_bytes().unwrap_err().to_string();
    assert!(e.contains("lightmap page 0: direction texture 1 'lightmap0' is 4x4 Rgba16Float (1 levels), not 4x4 Rgba8Unorm or Bc7Unorm (one level, page 0's format)"), "{e}");
    p.manifest.lightmap.as_mut().unwrap().directions = vec![1, 1];
    let e = p.to_bytes().unwrap_err().to_string();
    assert!(e.contains("2 direction textures and 1 baked textures for 1 pages"), "{e}");
    let p = sample();
    let mut b = PackBuilder::new("test", "test");
    b.manifest = p.manifest.clone();
    b.push_bytes(&p.data);
    let d = b.push_bytes(&[128u8; 4 * 4 * 4]);
    b.manifest.textures.push(Texture { name: "lightmap0 direction".into(), width: 4, height: 4, format: TextureFormat::Rgba8Unorm, mips: vec![d], sampler: Sampler::default() });
    b.manifest.lightmap.as_mut().unwrap().directions = vec![2];
    let q = Pack::from_bytes(&b.finish().to_bytes().unwrap()).unwrap();
    assert_eq!(q.manifest.lightmap.unwrap().directions, vec![2]);

    // Probe data must hold 27 floats and a visibility per probe.
    let mut p = sample();
    p.manifest.probes.as_mut().unwrap().counts = [2, 2, 1];
    let e = p.to_bytes().unwrap_err().to_string();
    assert!(e.contains("probes sh") && e.contains("432 expected"), "{e}");
    let mut p = sample();
    p.manifest.probes.as_mut().unwrap().spacing[1] = 0.0;
    let e = p.to_bytes().unwrap_err().to_string();
    assert!(e.contains("probes: bad grid"), "{e}");
}

#[test]
fn bad_pillars_are_rejected_by_name_and_old_manifests_have_none() {
    for (edit, want) in [
        ((|p: &mut Pillar| p.radius = 0.0) as fn(&mut Pillar), "pillar 0 'columns[1]': radius 0 is not positive"),
        (|p: &mut Pillar| p.y_max = p.y_min, "pillar 0 'columns[1]': y range 0.5..0.5 is empty"),
        (|p: &mut Pillar| p.centre[1] = f32::NAN, "pillar 0 'columns[1]': non-finite numbers"),
    ] {
        let mut p = sample();
        edit(&mut p.manifest.pillars[0]);
        let e = p.to_bytes().unwrap_err().to_string();
        assert!(e.contains(want), "{e}");
    }
    // A manifest written before pillars were recorded has no `pillars` key: it reads as none.
    let mut json = serde_json::to_value(&sample().manifest).unwrap();
    json.as_object_mut().unwrap().remove("pillars").expect("the sample has pillars");
    let m: Manifest = serde_json::from_value(json).unwrap();
    assert!(m.pillars.is_empty());
}

#[test]
fn an_index_past_the_vertices_is_rejected_on_write_and_on_read() {
    let mut p = sample();
    let at = p.manifest.meshes[0].lods[0].indices.offset as usize + 8;
    p.data[at..at + 4].copy_from_slice(&4u32.to_le_bytes());
    let e = p.to_bytes().unwrap_err().to_string();
    assert!(e.contains("mesh 0 'quad' LOD 0: index 2 is 4, but the LOD has 4 vertices"), "{e}");
    // A pack written without the check (as by an older or foreign writer) is refused on read.
    let mut bytes = sample().to_bytes_with(DataEncoding::Raw).unwrap();
    let data_off = u64_at(&bytes, 40) as usize;
    bytes[data_off + at..data_off + at + 4].copy_from_slice(&4u32.to_le_bytes());
    bytes[CHECKSUM_AT..CHECKSUM_AT + 4].copy_from_slice(&[0; 4]);
    let crc = checksum(&bytes);
    bytes[CHECKSUM_AT..CHECKSUM_AT + 4].copy_from_slice(&crc.to_le_bytes());
    let e = Pack::from_bytes(&bytes).unwrap_err().to_string();
    assert!(e.starts_with("malformed pack: mesh 0 'quad' LOD 0: index 2 is 4"), "{e}");
}

#[test]
fn the_data_blob_is_stored_zstd_compressed_and_read_back_exactly() {
    let p = sample();
    let raw = p.to_bytes_with(DataEncoding::Raw).unwrap();
    let z = p.to_bytes().unwrap();
    assert_eq!(u32_at(&raw, 60), 0);
    assert_eq!(u32_at(&z, 60), 1, "the cooker's packs are compressed");
    assert_eq!(Pack::from_bytes(&raw).unwrap(), p);
    assert_eq!(Pack::from_bytes(&z).unwrap(), p);
    assert_eq!(Pack::from_vec(z.clone()).unwrap(), p);
    // A blob that compresses (a repeated vertex) is smaller stored.
    let mut big = sample();
    big.data.extend(std::iter::repeat_n([1u8, 2, 3, 4], 4096).flatten());
    assert!(big.to_bytes().unwrap().len() < big.to_bytes_with(DataEncoding::Raw).unwrap().len() - 15_000);
}

/// A blob's frame is the same bytes whatever the number of compressing threads (the cook's
/// output must not depend on the machine), and a big blob is stored at the faster level.
#[test]
fn the_compressed_blob_does_not_depend_on_the_worker_count_and_big_blobs_use_the_fast_level() {
    let data_off = |b: &[u8]| u64_at(b, 40) as usize;
    // Vertex-like data: a slowly varying sequence with noise, so every level finds matches.
    let mut big = sample();
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let n = ZSTD_BEST_MAX + (1 << 20);
    big.data.reserve(n);
    for i in 0..n / 4 {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        big.data.extend_from_slice(&(((i / 64) as u32).wrapping_mul(2_654_435_761) ^ (state as u32 & 0xff)).to_le_bytes());
    }
    assert!(big.data.len() > ZSTD_BEST_MAX);
    let one = big.encode(DataEncoding::Zstd, 1).unwrap();
    assert_eq!(big.encode(DataEncoding::Zstd, 3).unwrap(), one, "3 workers, other bytes");
    assert_eq!(Pack::from_bytes(&one).unwrap(), big);
    // The frame is level 9's, made by zstd's multithreaded encoder.
    let mut c = zstd::bulk::Compressor::new(ZSTD_LEVEL_LARGE).unwrap();
    c.set_parameter(zstd::zstd_safe::CParameter::NbWorkers(2)).unwrap();
    assert_eq!(&one[data_off(&one)..], &c.compress(&big.data).unwrap()[..]);
    // A small blob: level 19, the same bytes on any number of workers too.
    let small = sample();
    let a = small.encode(DataEncoding::Zstd, 1).unwrap();
    assert_eq!(small.encode(DataEncoding::Zstd, 4).unwrap(), a);
    assert_eq!(small.to_bytes().unwrap(), a);
    let mut c = zstd::bulk::Compressor::new(ZSTD_LEVEL).unwrap();
    c.set_parameter(zstd::zstd_safe::CParameter::NbWorkers(1)).unwrap();
    assert_eq!(&a[data_off(&a)..], &c.compress(&small.data).unwrap()[..]);
    assert_eq!((zstd_level(ZSTD_BEST_MAX), zstd_level(ZSTD_BEST_MAX + 1)), (19, 9));
}

#[test]
fn a_bad_data_encoding_or_frame_is_malformed_not_a_panic() {
    // Rewrite the stored blob and the encoding word, with a valid checksum (a foreign writer).
    let forge = |encoding: u32, blob: &[u8]| {
        let mut b = sample().to_bytes_with(DataEncoding::Raw).unwrap();
        let data_off = u64_at(&b, 40) as usize;
        b.truncate(data_off);
        b.extend_from_slice(blob);
        let len = b.len() as u64;
        b[16..24].copy_from_slice(&len.to_le_bytes());
        b[48..56].copy_from_slice(&(blob.len() as u64).to_le_bytes());
        b[60..64].copy_from_slice(&encoding.to_le_bytes());
        b[CHECKSUM_AT..CHECKSUM_AT + 4].copy_from_slice(&[0; 4]);
        let crc = checksum(&b);
        b[CHECKSUM_AT..CHECKSUM_AT + 4].copy_from_slice(&crc.to_le_bytes());
        Pack::from_bytes(&b).unwrap_err().to_string()
    };
    let data = sample().data;
    assert!(forge(7, &data).contains("data encoding 7 is unknown"));
    assert!(forge(1, &data).contains("data: not a zstd frame"));
    let frame = zstd::bulk::compress(&data, 3).unwrap();
    assert!(forge(1, &frame[..frame.len() - 3]).starts_with("malformed pack: data:"), "a frame cut short");
    let short = zstd::bulk::compress(&data[..data.len() - 16], 3).unwrap();
    assert!(forge(1, &short).starts_with("malformed pack:"), "a frame of fewer bytes than the ranges need");
    // A frame that claims 60 GiB (under MAX_DATA_BYTES) and holds one 128 KiB run: the claim was
    // allocated up front and the process aborted when that failed (found by the pack_manifest
    // fuzzer). Now the output grows with what the frame decodes to.
    // Magic; an 8-byte content size and a window descriptor (128 KiB); the size; one block.
    let mut bomb = vec![0x28, 0xB5, 0x2F, 0xFD, 0xC0, (17 - 10) << 3];
    bomb.extend_from_slice(&(60u64 << 30).to_le_bytes());
    let block: u32 = 1 | (1 << 1) | ((128 << 10) << 3); // last block, RLE, 128 KiB
    bomb.extend_from_slice(&block.to_le_bytes()[..3]);
    bomb.push(0);
    // zstd finds the frame ends short of its claim; before, this test aborted on the allocation.
    let said = forge(1, &bomb);
    assert!(said.starts_with("malformed pack: data: zstd:"), "{said}");
    // The same as one segment (its window is the whole claimed size): zstd refuses the window.
    let mut single = vec![0x28, 0xB5, 0x2F, 0xFD, 0xE0];
    single.extend_from_slice(&bomb[6..]);
    assert!(forge(1, &single).starts_with("malformed pack: data: zstd:"), "{}", forge(1, &single));
}

#[test]
fn atomic_write_leaves_no_temporary_and_replaces_whole() {
    let dir = std::env::temp_dir().join(format!("pack-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("a.pack");
    std::fs::write(&path, b"old").unwrap();
    write_pack_atomic(&sample(), &path, 2).unwrap();
    assert_eq!(Pack::read_file(&path).unwrap(), sample());
    let names: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(names.len(), 1, "left behind: {names:?}");
    // A write into a directory that does not exist fails and creates nothing.
    let bad = dir.join("missing/b.pack");
    assert!(matches!(write_pack_atomic(&sample(), &bad, 1), Err(PackError::Io(_))));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn concurrent_writes_to_one_path_never_leave_a_broken_file() {
    let dir = std::env::temp_dir().join(format!("pack-race-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("a.pack");
    std::thread::scope(|s| {
        for _ in 0..8 {
            s.spawn(|| write_pack_atomic(&sample(), &path, 2).unwrap());
        }
    });
    assert_eq!(Pack::read_file(&path).unwrap(), sample());
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1, "temporary files left behind");
    std::fs::remove_dir_all(&dir).unwrap();
}

fn push(p: &mut Pack, bytes: &[u8]) -> BufferRange {
    let offset = align_up(p.data.len(), DATA_ALIGN);
    p.data.resize(offset, 0);
    p.data.extend_from_slice(bytes);
    BufferRange { offset: offset as u64, len: bytes.len() as u64 }
}

/// `sample()` with a skinned, morphing quad: a joint node, a skin, joints/weights and one morph
/// target on both LODs' 4 vertices, and a clip with a rotation and a weights channel.
fn animated() -> Pack {
    let mut p = sample();
    p.manifest.nodes.push(Node { name: "bone".into(), parent: Some(0), local: IDENTITY, mesh: None, ..Default::default() });
    let ibm = push(&mut p, &[0u8; 64]);
    p.manifest.animation.skins.push(Skin { name: "rig".into(), joints: vec![1], inverse_bind: ibm });
    let joints = push(&mut p, &[0u8; 4 * 8]);
    let weights = push(&mut p, &[0u8; 4 * 16]);
    let deltas = push(&mut p, &[0u8; 4 * 12]);
    let lod = DeformLod { skin: Some(SkinWeights { joints, weights }), morph: Some(MorphTargets { positions: deltas, normals: None }) };
    p.manifest.animation.meshes.push(DeformMesh { mesh: 0, morph_weights: vec![0.5], lods: vec![lod, lod] });
    p.manifest.animation.nodes.push(NodeBinding { node: 0, skin: Some(0), weights: Some(vec![1.0]) });
    let times = push(&mut p, &[0u8; 8]);
    let rotations = push(&mut p, &[0u8; 2 * 16]);
    let w = push(&mut p, &[0u8; 2 * 3 * 4]);
    p.manifest.animation.clips.push(Clip {
        name: "wave".into(),
        duration: 1.0,
        channels: vec![
            Channel { node: 1, path: ChannelPath::Rotation, interpolation: Interpolation::Linear, key_count: 2, components: 4, times, values: rotations },
            Channel { node: 0, path: ChannelPath::Weights, interpolation: Interpolation::Cubicspline, key_count: 2, components: 1, times, values: w },
        ],
    });
    p
}

#[test]
fn animation_section_round_trips_and_bad_references_are_rejected() {
    let p = animated();
    let q = Pack::from_bytes(&p.to_bytes().unwrap()).unwrap();
    assert_eq!(p, q);

    let bad = |edit: &dyn Fn(&mut Pack), want: &str| {
        let mut p = animated();
        edit(&mut p);
        let e = p.to_bytes().unwrap_err().to_string();
        assert!(e.contains(want), "expected '{want}' in: {e}");
    };
    bad(&|p| p.manifest.animation.clips[0].channels[0].key_count = 3, "clip 0 'wave' channel 0 (Rotation) times: 8 bytes stored but 12 expected");
    bad(&|p| p.manifest.animation.clips[0].channels[1].values.len = 8, "clip 0 'wave' channel 1 (Weights) values");
    bad(&|p| p.manifest.animation.clips[0].channels[0].node = 9, "clip 0 'wave' channel 0 (Rotation): node 9 does not exist");
    bad(&|p| p.manifest.animation.clips[0].channels[1].components = 2, "channel 1 (Weights): 2 components, node 0 needs 1");
    bad(&|p| p.manifest.animation.clips[0].channels[0].interpolation = Interpolation::Cubicspline, "channel 0 (Rotation) values");
    bad(&|p| p.manifest.animation.skins[0].joints = vec![7], "skin 0 'rig': joint node 7 does not exist");
    bad(&|p| p.manifest.animation.meshes[0].lods.pop().map(|_| ()).unwrap(), "deformation data for 1 LODs, the mesh has 2");
    bad(&|p| p.manifest.animation.nodes[0].weights = Some(vec![1.0, 2.0]), "node 0 'root': 2 morph weights for 1 morph targets");
    bad(&|p| p.manifest.animation.meshes[0].lods[1].skin = None, "node 0 'root': skin 0 does not exist or the node's mesh has no joints and weights");
    bad(&|p| p.manifest.animation.meshes[0].lods[0].skin.as_mut().unwrap().weights.len = 48, "mesh 0 'quad' LOD 0 weights");
}

/// `animated()` whose LOD 1 is a triangle of its own 3 vertices with its own skin and morph
/// deltas (positions and normals), as the cooker's LOD stage writes a morphing mesh's levels;
/// LOD 0 keeps 4 vertices with normal deltas too.
fn animated_lods() -> Pack {
    let mut p = animated();
    let f32s = |v: &[f32]| -> Vec<u8> { v.iter().flat_map(|x| x.to_le_bytes()).collect() };
    let verts: Vec<Vertex> = (0..3).map(|i| Vertex { position: [i as f32, 0.5, 0.0], normal: [0.0, 0.0, 1.0], ..Default::default() }).collect();
    let vertices = push(&mut p, &encode_vertices(&verts).0);
    let indices = push(&mut p, &[0u32, 1, 2].iter().flat_map(|i| i.to_le_bytes()).collect::<Vec<u8>>());
    let lod1 = &mut p.manifest.meshes[0].lods[1];
    (lod1.vertices, lod1.vertex_count, lod1.indices, lod1.index_count, lod1.index_format) = (vertices, 3, indices, 3, IndexFormat::U32);
    let joints = push(&mut p, &[0u8; 3 * 8]);
    let weights = push(&mut p, &f32s(&[1.0, 0.0, 0.0, 0.0].repeat(3)));
    let positions = push(&mut p, &f32s(&[0.0, 0.1, 0.0, 0.0, 0.2, 0.0, 0.0, 0.3, 0.0]));
    let normals = push(&mut p, &f32s(&[0.5; 9]));
    p.manifest.animation.meshes[0].lods[1] = DeformLod { skin: Some(SkinWeights { joints, weights }), morph: Some(MorphTargets { positions, normals: Some(normals) }) };
    let normals0 = push(&mut p, &f32s(&[0.25; 12]));
    p.manifest.animation.meshes[0].lods[0].morph.as_mut().unwrap().normals = Some(normals0);
    p
}

#[test]
fn each_lod_carries_its_own_morph_deltas_checked_against_its_own_vertices() {
    let p = animated_lods();
    let q = Pack::from_bytes(&p.to_bytes().unwrap()).unwrap();
    assert_eq!(p, q);
    let d = q.manifest.animation.deform(0).unwrap();
    let read = |r: BufferRange| -> Vec<f32> { q.bytes(r).chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().unwrap())).collect() };
    let (m0, m1) = (d.lods[0].morph.unwrap(), d.lods[1].morph.unwrap());
    assert_eq!(read(m1.positions), vec![0.0, 0.1, 0.0, 0.0, 0.2, 0.0, 0.0, 0.3, 0.0], "LOD 1's own deltas, one per its 3 vertices");
    assert_eq!(read(m1.normals.unwrap()), vec![0.5; 9]);
    assert_eq!((read(m0.positions).len(), read(m0.normals.unwrap()).len()), (12, 12), "LOD 0's: 4 vertices");

    let bad = |edit: &dyn Fn(&mut Pack), want: &str| {
        let mut p = animated_lods();
        edit(&mut p);
        let e = p.to_bytes().unwrap_err().to_string();
        assert!(e.contains(want) && !e.contains('\n'), "expected one line with '{want}': {e}");
    };
    // LOD 1's arrays are measured against LOD 1's 3 vertices, not LOD 0's 4.
    let lod1 = |p: &mut Pack| p.manifest.animation.meshes[0].lods[1].morph.unwrap();
    let four = |p: &mut Pack| push(p, &[0u8; 48]);
    bad(&|p| { let r = four(p); p.manifest.animation.meshes[0].lods[1].morph.as_mut().unwrap().positions = r; }, "mesh 0 'quad' LOD 1 morph positions: 48 bytes stored but 36 expected");
    bad(&|p| { let r = four(p); p.manifest.animation.meshes[0].lods[1].morph.as_mut().unwrap().normals = Some(r); }, "mesh 0 'quad' LOD 1 morph normals: 48 bytes stored but 36 expected");
    bad(&|p| { let r = lod1(p).positions; p.manifest.animation.meshes[0].lods[0].morph.as_mut().unwrap().positions = r; }, "mesh 0 'quad' LOD 0 morph positions: 36 bytes stored but 48 expected");
    bad(&|p| p.manifest.animation.meshes[0].lods[1].skin.as_mut().unwrap().weights.len = 64, "mesh 0 'quad' LOD 1 weights: 64 bytes stored but 48 expected");
    // Every LOD morphs alike: a level without the deltas (or without normal deltas) would drop
    // the morph at a distance.
    bad(&|p| p.manifest.animation.meshes[0].lods[1].morph = None, "mesh 0 'quad' LOD 1: morph deltas of none, LOD 0's of positions and normals (every LOD morphs alike)");
    bad(&|p| p.manifest.animation.meshes[0].lods[1].morph.as_mut().unwrap().normals = None, "mesh 0 'quad' LOD 1: morph deltas of positions, LOD 0's of positions and normals");
}

#[test]
fn texture_sizes_that_overflow_are_malformed_not_a_panic() {
    // Seen beside the fuzz targets: mip level 32 shifted the u32 width by 32 bits (a panic with
    // overflow checks, a wrapped size without), and a 2^32-1 square texture's byte count
    // overflowed u64.
    let mut p = sample();
    let one_texel = p.manifest.textures[0].mips[1];
    p.manifest.textures[0].mips = vec![one_texel; 40];
    let e = p.to_bytes().unwrap_err().to_string();
    assert!(e.contains("40 mips, more than the 2 of a full chain for 2x2"), "{e}");
    let mut p = sample();
    p.manifest.textures[0].width = u32::MAX;
    p.manifest.textures[0].height = u32::MAX;
    p.manifest.textures[0].format = TextureFormat::Rgba16Unorm;
    p.manifest.materials[0].base_color_texture = None;
    let e = p.to_bytes().unwrap_err().to_string();
    assert!(e.contains("4294967295x4294967295 is too large"), "{e}");
}

#[test]
fn non_finite_numbers_in_the_manifest_are_malformed() {
    // Infinity was written as JSON null, so the pack did not read back; and a number beyond f32
    // (1e39) read as infinity.
    let mut p = sample();
    p.manifest.lights[0].intensity = f32::INFINITY;
    let e = p.to_bytes().unwrap_err().to_string();
    assert!(e.contains("light 0 'sun': ") && e.contains("inf"), "{e}");
    let mut p = sample();
    p.manifest.materials[0].emissive[1] = f32::NAN;
    assert!(p.to_bytes().unwrap_err().to_string().contains("material 0 'default'"));

    let mut bytes = sample().to_bytes().unwrap();
    let at = bytes.windows(8).position(|w| w == b"100000.0").expect("the sun's intensity in the JSON");
    bytes[at..at + 8].copy_from_slice(b"1.000e39");
    bytes[CHECKSUM_AT..CHECKSUM_AT + 4].fill(0);
    let crc = checksum(&bytes);
    bytes[CHECKSUM_AT..CHECKSUM_AT + 4].copy_from_slice(&crc.to_le_bytes());
    let e = Pack::from_bytes(&bytes).unwrap_err().to_string();
    assert!(e.starts_with("malformed pack: light 0 'sun': ") && e.contains("inf"), "{e}");
}

#[test]
fn a_spawn_mesh_must_be_one_of_the_packs_meshes() {
    // A boids spawn names the mesh its flock is drawn with; the runtime indexes the scene's
    // meshes with it.
    let spawn = |mesh: serde_json::Value| Spawn { name: "doves".into(), kind: "boids".into(), position: [0.0; 3], rotation: [0.0, 0.0, 0.0, 1.0], params: serde_json::json!({ "mesh": mesh }) };
    let mut p = sample();
    p.manifest.spawns.push(spawn(serde_json::json!(0)));
    let bytes = p.to_bytes().unwrap();
    assert_eq!(Pack::from_bytes(&bytes).unwrap().manifest.spawns.last().unwrap().params["mesh"], 0);
    for bad in [serde_json::json!(1), serde_json::json!(-1), serde_json::json!("dove")] {
        let mut p = sample();
        p.manifest.spawns.push(spawn(bad.clone()));
        let e = p.to_bytes().unwrap_err().to_string();
        assert!(e.contains(&format!("spawn 1 'doves': mesh {bad} is not one of the 1 meshes")), "{e}");
    }
}

/// `sample()` with one 4-texel reflection probe of 3 levels (4, 2, 1 texels a face).
fn with_reflection_probe() -> Pack {
    let p = sample();
    let mut b = PackBuilder::new("test", "test");
    b.manifest = p.manifest.clone();
    b.push_bytes(&p.data);
    let texels = 6 * (16 + 4 + 1);
    let data = b.push_bytes(&vec![0x3cu8; texels * 8]);
    let probe = ReflectionProbe { name: "hall".into(), position: [0.0, 2.0, 0.0], box_min: [-5.0, 0.0, -5.0], box_max: [5.0, 4.0, 5.0], blend_distance: 1.0, data };
    b.manifest.reflection_probes = Some(ReflectionProbes { face_size: 4, levels: 3, format: TextureFormat::Rgba16Float, probes: vec![probe] });
    b.finish()
}

#[test]
fn reflection_probes_round_trip_and_bad_ones_are_rejected_by_name() {
    let p = with_reflection_probe();
    let q = Pack::from_bytes(&p.to_bytes().unwrap()).unwrap();
    assert_eq!(p, q);
    assert_eq!(q.manifest.reflection_probes.as_ref().unwrap().probe_bytes(), 6 * 21 * 8);
    for (edit, want) in [
        ((|r: &mut ReflectionProbes| r.levels = 4) as fn(&mut ReflectionProbes), "reflection probes: bad cube (4 texels a face, 4 levels)"),
        (|r| r.face_size = 6, "reflection probes: bad cube (6 texels a face"),
        (|r| r.levels = 2, "reflection probe 0 'hall': 1008 bytes stored but 960 expected"),
        (|r| r.probes[0].position[1] = 4.5, "reflection probe 0 'hall': position [0.0, 4.5, 0.0] is outside its box"),
        (|r| r.probes[0].box_max[0] = -5.0, "reflection probe 0 'hall': box [-5.0, 0.0, -5.0]..[-5.0, 4.0, 5.0] is empty"),
        (|r| r.probes[0].blend_distance = -1.0, "reflection probe 0 'hall': blend distance -1 is negative"),
        (|r| r.probes[0].box_min[2] = f32::NAN, "reflection probe 0 'hall': non-finite numbers"),
        // BC6H faces are whole blocks: 16 bytes a face at every level of a 4-texel cube.
        (|r| r.format = TextureFormat::Bc6hUfloat, "reflection probe 0 'hall': 1008 bytes stored but 288 expected"),
        (|r| r.format = TextureFormat::Bc7Unorm, "reflection probes: format Bc7Unorm is not Rgba16Float or Bc6hUfloat"),
    ] {
        let mut p = with_reflection_probe();
        edit(p.manifest.reflection_probes.as_mut().unwrap());
        let e = p.to_bytes().unwrap_err().to_string();
        assert!(e.contains(want), "want '{want}' in: {e}");
    }
}

#[test]
fn indices_of_either_width_read_back_and_are_checked() {
    let p = sample();
    assert_eq!(p.indices(&p.manifest.meshes[0].lods[0]), vec![0, 1, 2, 2, 1, 3]);
    assert_eq!(p.indices(&p.manifest.meshes[0].lods[1]), vec![0, 1, 2]);
    assert_eq!(IndexFormat::for_vertices(65_536), IndexFormat::U16);
    assert_eq!(IndexFormat::for_vertices(65_537), IndexFormat::U32);
    assert_eq!(IndexFormat::U16.decode(&IndexFormat::U16.encode(&[0, 65_535, 7])).collect::<Vec<_>>(), vec![0, 65_535, 7]);
    // A 16-bit index past the LOD's vertices.
    let mut bad = sample();
    let at = bad.manifest.meshes[0].lods[1].indices.offset as usize;
    bad.data[at + 2..at + 4].copy_from_slice(&4u16.to_le_bytes());
    let e = bad.to_bytes().unwrap_err();
    assert!(e.to_string().contains("mesh 0 'quad' LOD 1: index 1 is 4, but the LOD has 4 vertices"), "{e}");
    // The stored length must be the count times the width.
    let mut bad = sample();
    bad.manifest.meshes[0].lods[1].index_format = IndexFormat::U32;
    let e = bad.to_bytes().unwrap_err();
    assert!(e.to_string().contains("mesh 0 'quad' LOD 1 indices: 6 bytes stored but 12 expected"), "{e}");
}

/// A BC4 block whose every texel is `v` (both endpoints `v`, every index 0).
fn bc4_block(v: u8) -> [u8; 8] {
    [v, v, 0, 0, 0, 0, 0, 0]
}

#[test]
fn compressed_levels_are_whole_blocks_and_decode_cropped_to_the_level() {
    // 5x3: two blocks across (the second hangs 3 texels over), one down.
    let f = TextureFormat::Bc4Unorm;
    assert_eq!(f.level_bytes(5, 3), Some(16));
    assert_eq!(f.level_bytes(1, 1), Some(8));
    assert_eq!(TextureFormat::Bc7Srgb.level_bytes(8, 8), Some(64));
    assert_eq!(TextureFormat::Rgba8Srgb.level_bytes(5, 3), Some(60));
    let blocks: Vec<u8> = [bc4_block(10), bc4_block(20)].concat();
    let texels = bc::decode(f, 5, 3, &blocks).unwrap();
    assert_eq!(texels, [[10, 10, 10, 10, 20]; 3].concat());
    // BC5: x from the first half of a block, y from the second.
    let blocks: Vec<u8> = [bc4_block(10), bc4_block(30), bc4_block(50), bc4_block(70)].concat();
    let texels = bc::decode(TextureFormat::Bc5Unorm, 6, 2, &blocks).unwrap();
    assert_eq!(&texels[..12], &[10, 30, 10, 30, 10, 30, 10, 30, 50, 70, 50, 70]);
    assert_eq!(texels.len(), 6 * 2 * 2);
    // BC6H: RGBA half floats, alpha 1.0 (an all-zero block is mode 1 with black endpoints).
    let texels = bc::decode(TextureFormat::Bc6hUfloat, 5, 3, &[0u8; 32]).unwrap();
    assert_eq!(texels, [0u8, 0, 0, 0, 0, 0, 0x00, 0x3c].repeat(15));
    // Wrong lengths and plain formats decode to nothing.
    assert_eq!(bc::decode(f, 5, 3, &blocks[..8]), None);
    assert_eq!(bc::decode(TextureFormat::Rgba8Unorm, 1, 1, &[0; 4]), None);
}

#[test]
fn compressed_textures_round_trip_and_are_checked_by_block_size_and_slot() {
    let mut p = sample();
    let l0 = push(&mut p, &[bc4_block(1), bc4_block(2), bc4_block(3), bc4_block(4)].concat());
    let l1 = push(&mut p, &bc4_block(5));
    let l2 = push(&mut p, &bc4_block(6));
    let ao = p.manifest.textures.len();
    p.manifest.textures.push(Texture { name: "ao".into(), width: 6, height: 5, format: TextureFormat::Bc4Unorm, mips: vec![l0, l1, l2], sampler: Sampler::default() });
    p.manifest.materials[0].occlusion_texture = Some(ao as u32);
    let bytes = p.to_bytes().unwrap();
    assert_eq!(Pack::from_bytes(&bytes).unwrap(), p);
    // A level the size of plain texels (6x5 x 4 bytes) is not the size of its blocks.
    let mut q = p.clone();
    q.manifest.textures[ao].mips[0] = push(&mut q, &[0; 120]);
    let e = q.to_bytes().unwrap_err().to_string();
    assert!(e.contains(&format!("texture {ao} 'ao' mip 0")), "{e}");
    // BC4 holds one channel: not a base colour.
    let mut q = p.clone();
    q.manifest.materials[0].base_color_texture = Some(ao as u32);
    let e = q.to_bytes().unwrap_err().to_string();
    assert!(e.contains(&format!("base colour texture {ao} 'ao' is Bc4Unorm")), "{e}");
}
