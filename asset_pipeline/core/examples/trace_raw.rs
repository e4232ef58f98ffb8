//! The BVH on a raw scene + rays file (the format `tools/bench_bvh.py --raw` and the anchor in
//! `../shared/bench` use), without Python in between: for profiling the tracer (`perf record`)
//! and quick A/B runs while working on it. The benchmark of record is `tools/bench_bvh.py`.
//!
//!     cargo run --release --example trace_raw -p cook_core -- build/anchor.raw [threads] [repeat]
//!
//! Prints the build time (best of `repeat`), then per pass Mrays/s and the hit fraction.

use cook_core::bake::bvh::Bvh;
use cook_core::bake::with_threads;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("usage: trace_raw FILE [threads] [repeat]");
    let threads: usize = args.get(2).map_or(1, |s| s.parse().expect("threads"));
    let repeat: usize = args.get(3).map_or(3, |s| s.parse().expect("repeat"));
    let bytes = std::fs::read(path).expect("read the raw file");
    let word = |i: usize| u32::from_le_bytes(bytes[4 * i..4 * i + 4].try_into().unwrap());
    let (nv, nt, nr) = (word(0) as usize, word(1) as usize, word(2) as usize);
    let f = |i: usize| f32::from_le_bytes(bytes[4 * i..4 * i + 4].try_into().unwrap());
    let rows = |at: usize, n: usize| (0..n).map(|i| [f(at + 3 * i), f(at + 3 * i + 1), f(at + 3 * i + 2)]).collect::<Vec<_>>();
    let pos = rows(3, nv);
    let tri: Vec<[u32; 3]> = (0..nt).map(|i| [word(3 + 3 * nv + 3 * i), word(4 + 3 * nv + 3 * i), word(5 + 3 * nv + 3 * i)]).collect();
    let org = rows(3 + 3 * nv + 3 * nt, nr);
    let dir = rows(3 + 3 * nv + 3 * nt + 3 * nr, nr);
    let mut build = f64::INFINITY;
    let mut bvh = None;
    for _ in 0..repeat {
        let t0 = Instant::now();
        let b = with_threads(Some(threads), || Bvh::build(&pos, &tri)).unwrap();
        build = build.min(t0.elapsed().as_secs_f64());
        bvh = Some(b);
    }
    let bvh = bvh.unwrap();
    println!("{nt} triangles, {nr} rays, {threads} thread(s): build {:.1} ms", build * 1e3);
    for _ in 0..repeat {
        let t0 = Instant::now();
        let (_, id) = with_threads(Some(threads), || bvh.closest_many(&org, &dir)).unwrap();
        let s = t0.elapsed().as_secs_f64();
        let hits = id.iter().filter(|&&i| i != u32::MAX).count();
        println!("{:.2} Mrays/s  hit {:.4}", nr as f64 / s / 1e6, hits as f64 / nr as f64);
    }
}
