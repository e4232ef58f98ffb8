"""The validation soak (issues 11 and 27): the demo headless for many frames with the Vulkan
validation layer on and every pass of the renderer running. Passes when there are no validation
messages at all and the memory allocated, on the heap and on the device, at the end is within 1%
of what it was after frame 1,000 (a leak of a few KiB per frame would show as megabytes by then).

What is compared: the demo's `--rss-at` reports, every 50 frames here, the bytes allocated on the
heap and not yet freed (glibc's own count, over all its arenas: our Rust code's memory, lavapipe's
and the validation layer's) and the device memory held by live buffers and images (our allocator's
count: a buffer leaked per frame would grow it while still fitting in a block already allocated,
so neither the heap nor the resident memory would show it). For each, the soak compares the
median of the samples in the 500 frames from the baseline with the median of the last 500 frames'.

The resident memory is reported beside it, not judged: it is a high-water mark. lavapipe
allocates and frees ~6 MB of scratch in every frame; when two frames' scratch overlap under load,
glibc keeps the larger, fragmented heap it grew. Under heaptrack, in 3,000 frames, the live heap's
low point between frames stayed within 10 KB while the resident memory rose by one 3 MiB step at
the moment the live heap reached a new peak; over 50,000 frames the steps came rarer and the
resident memory levelled off. Handing glibc's free pages back before each sample (malloc_trim)
does not cure it: trimming returns only whole free pages. Single heap samples vary by ~1 MB with
where lavapipe is in its frame, hence the medians.

    .venv/bin/python tools/soak.py [--frames 10000] [--pack build/temple.pack] [--width 320 --height 180]
                                   [--aa fxaa,msaa] [--baseline 1000] [--json OUT]

Every pass: the demo's defaults leave some off, so each run adds `--overlay` (the debug overlay,
egui, drawn into every frame), `--render-scale 0.75` (the 3D passes at 3/4 size, then the
upscale pass) and an anti-aliasing mode. The two modes exclude each other (MSAA's resolve pass, or
the FXAA pass), so there is one run per mode in --aa, each of --frames frames; the flight (the
default 24 s loop over the level) keeps culling, LODs, the characters, doves and particles
changing. Each run lists the passes that ran (the demo's `pass gpu_ms` line) and fails if one
of the renderer's passes is missing, but for the two that cannot run here: the other AA mode's
pass, and `depth view` (a debug view that replaces the frame, switched only from the overlay).
The sun's static shadow map is drawn once and then copied each frame (`shadow static` runs when
the static casters change, i.e. at the first frame).

Run by `make soak` and `make check-long`, outside `make test` (it takes a while on lavapipe).
Exit status 0 pass, 1 fail, 2 bad arguments or no demo binary.
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DEMO = ROOT / "target" / "release" / "demo"
# The renderer's passes (engine/src/render/passes/mod.rs, in frame order) that every frame of a
# soak run must have run in some frame; per AA mode the one pass of the mode is added.
PASSES = ["skinning", "shadow static", "shadow copy", "shadow", "prepass", "shading", "boids", "transparent", "particles",
          "tonemap", "upscale"]
MODE_PASS = {"msaa": "resolve", "fxaa": "fxaa"}
RENDER_SCALE = "0.75"
# Memory samples: one every EVERY frames; each end of the comparison is the median of WINDOW frames' samples.
EVERY = 50
WINDOW = 500


def soak(args, aa: str) -> dict:
    shot = ROOT / "build" / f"soak-{aa}.png"
    cmd = [str(DEMO), str(args.pack), "--headless", "--validation", "--frames", str(args.frames), "--width", str(args.width),
           "--height", str(args.height), "--overlay", "--aa", aa, "--render-scale", RENDER_SCALE,
           "--rss-at", ",".join(str(f) for f in sample_frames(args)), "--screenshot", str(shot)]
    print("soak:", " ".join(cmd), flush=True)
    start = time.monotonic()
    r = subprocess.run(cmd, capture_output=True, text=True)
    minutes = (time.monotonic() - start) / 60
    mem = memory_samples(r.stdout)
    messages = [line for line in r.stderr.splitlines() if line.startswith("[vulkan validation")]
    errors = re.search(r"validation errors: (\d+)", r.stdout)
    ran = re.search(r"pass gpu_ms \(median\): (.*?) \(\d+ shadow casters", r.stdout)
    passes = [re.sub(r" [\d.]+$", "", p) for p in ran.group(1).split(", ")] if ran else []
    missing = [p for p in PASSES + [MODE_PASS[aa]] if p not in passes]
    out = {"aa": aa, "frames": args.frames, "minutes": round(minutes, 1), "exit": r.returncode, "messages": len(messages),
           "errors": int(errors.group(1)) if errors else None, "passes": passes, "missing_passes": missing}
    print(f"soak [{aa}]: {args.frames} frames at {args.width}x{args.height} in {minutes:.1f} min, exit {r.returncode}")
    print(f"soak [{aa}]: validation messages (errors and warnings): {len(messages)}; errors counted by the demo: {out['errors'] if errors else '?'}")
    for line in messages[:10]:
        print(f"  {line}")
    print(f"soak [{aa}]: passes that ran: {', '.join(passes) or '?'}" + (f"; MISSING: {', '.join(missing)}" if missing else ""))
    # Warnings count too: the soak's promise is zero messages.
    ok = r.returncode == 0 and errors is not None and errors.group(1) == "0" and not messages and not missing
    first, last = windows(args)
    if all(f in mem for f in first + last):
        def drift(i):
            x = statistics.median(mem[f][i] for f in first)
            y = statistics.median(mem[f][i] for f in last)
            return x, y, (y - x) / x
        a, b, change = drift(0)
        da, db, device_change = drift(1)
        ra, rb = mem[args.baseline][2], mem[args.frames][2]
        heaps = [m[0] for m in mem.values()]
        devices = [m[1] for m in mem.values()]
        out.update(heap_baseline_kib=a, heap_last_kib=b, heap_drift_percent=round(100 * change, 3), heap_min_kib=min(heaps),
                   heap_max_kib=max(heaps), device_baseline_kib=da, device_last_kib=db,
                   device_drift_percent=round(100 * device_change, 3), device_min_kib=min(devices), device_max_kib=max(devices),
                   resident_baseline_kib=ra, resident_last_kib=rb,
                   resident_drift_percent=round(100 * (rb - ra) / ra, 3),
                   samples={f: list(m) for f, m in sorted(mem.items())})
        print(f"soak [{aa}]: heap allocated, median of frames {first[0]}-{first[-1]}: {a / 1024:.1f} MiB, of frames "
              f"{last[0]}-{last[-1]}: {b / 1024:.1f} MiB ({change:+.2%}); every {EVERY} frames it ranged "
              f"{min(heaps) / 1024:.1f}-{max(heaps) / 1024:.1f} MiB")
        print(f"soak [{aa}]: device memory allocated, medians {da / 1024:.1f} -> {db / 1024:.1f} MiB ({device_change:+.2%}); "
              f"it ranged {min(devices) / 1024:.1f}-{max(devices) / 1024:.1f} MiB")
        print(f"soak [{aa}]: resident memory (not judged): after frame {args.baseline} {ra / 1024:.1f} MiB, after frame "
              f"{args.frames} {rb / 1024:.1f} MiB ({(rb - ra) / ra:+.2%})")
        ok = ok and abs(change) <= 0.01 and abs(device_change) <= 0.01
    else:
        print(f"soak [{aa}]: the demo did not report its memory", file=sys.stderr)
        print(r.stdout[-2000:], r.stderr[-2000:], file=sys.stderr)
        ok = False
    out["ok"] = ok
    print(f"soak [{aa}]: PASS" if ok else f"soak [{aa}]: FAIL", flush=True)
    return out


def memory_samples(stdout: str) -> dict[int, tuple[int, int, int]]:
    """The demo's `--rss-at` lines: frame -> (KiB allocated on the heap, on the device, KiB resident)."""
    pattern = r"memory after frame (\d+): heap (\d+) KiB allocated, device (\d+) KiB allocated \(of \d+ KiB in blocks\), (\d+) KiB resident"
    return {int(f): (int(h), int(d), int(r)) for f, h, d, r in re.findall(pattern, stdout)}


def sample_frames(args) -> list[int]:
    """The frames after which the demo reports its memory: every EVERY frames, and the two the
    comparison is named by."""
    return sorted(set(range(EVERY, args.frames + 1, EVERY)) | {args.baseline, args.frames})


def windows(args) -> tuple[list[int], list[int]]:
    """The samples compared: those in WINDOW frames from the baseline, and those in the last WINDOW frames."""
    frames = sample_frames(args)
    return ([f for f in frames if args.baseline <= f < args.baseline + WINDOW],
            [f for f in frames if f > args.frames - WINDOW])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=10_000)
    ap.add_argument("--baseline", type=int, default=1_000, help="frame whose memory is the baseline (default 1000)")
    ap.add_argument("--pack", type=Path, default=ROOT / "build" / "temple.pack")
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=180)
    ap.add_argument("--aa", default="fxaa,msaa", help="anti-aliasing modes, one run each (default fxaa,msaa)")
    ap.add_argument("--json", type=Path, help="also write the runs' results here")
    args = ap.parse_args()
    if not DEMO.exists():
        print(f"soak: {DEMO} is missing (run `make build`)", file=sys.stderr)
        return 2
    if not 0 < args.baseline <= args.frames - 2 * WINDOW:
        ap.error(f"--baseline must be above 0 and at least {2 * WINDOW} frames before --frames (the two windows compared)")
    modes = [m for m in args.aa.split(",") if m]
    if not modes or any(m not in MODE_PASS for m in modes):
        ap.error(f"--aa: a comma-separated list of {', '.join(MODE_PASS)}")
    runs = [soak(args, m) for m in modes]
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(runs, indent=2) + "\n")
    ok = all(r["ok"] for r in runs)
    print("soak: PASS" if ok else "soak: FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
