"""The long checks (issue 27), run by `make check-long` after its setup (build, cook, cargo-fuzz,
atheris), in order:

1. the validation soak (tools/soak.py): --frames frames per anti-aliasing mode with every pass
   running; validation messages must be 0 and the memory allocated on the heap and on the device
   within 1% from frame 1,000 on (medians of the samples in the 500 frames from there and in the
   last 500; the resident memory is reported, not judged: soak.py says why);
2. the fuzzers (tools/fuzz_seed.sh, then tools/fuzz_run.py), each for its fixed time: the pack
   reader (pack_from_bytes, pack_manifest), glTF import (gltf_import, with seeds that use the
   glTF extensions the importer supports) and the level TOML loader (level_toml); each must end
   with 0 crashes (and is expected to reach 1,000,000 executions in its time);
3. a Ray cook of the demo level with a worker SIGKILLed mid-bake (tools/ray_kill_cook.py), which
   must give the local cook's pack and EXR byte for byte.

    .venv/bin/python tools/check_long.py [--frames 10000] [--fuzz "pack_from_bytes=240 ..."]

Every step runs even if one before it failed; the summary table is printed at the end and written
to build/check-long.txt (the steps' details: build/check-long/*.json and the fuzz logs). Exit
status 0 when every check holds.
"""

from __future__ import annotations

import argparse
import datetime
import json
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PY = str(ROOT / ".venv" / "bin" / "python")
OUT = ROOT / "build" / "check-long"
MIN_EXECUTIONS = 1_000_000


def step(title: str, cmd: list[str]) -> tuple[int, float]:
    print(f"\n==== check-long: {title}\n$ {' '.join(cmd)}", flush=True)
    t0 = time.monotonic()
    code = subprocess.run(cmd, cwd=ROOT).returncode
    return code, time.monotonic() - t0


def load(path: Path):
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=10_000)
    ap.add_argument("--fuzz", default="pack_from_bytes=240 pack_manifest=360 gltf_import=900 level_toml=480",
                    help="TARGET=SECONDS ..., the fuzz targets and their fixed times")
    args = ap.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    for f in OUT.glob("*.json"):
        f.unlink()
    started = datetime.datetime.now(datetime.timezone.utc)

    soak_code, soak_s = step("soak", [PY, "tools/soak.py", "--frames", str(args.frames), "--json", str(OUT / "soak.json")])
    seed_code, _ = step("fuzz seeds", ["bash", "tools/fuzz_seed.sh"])
    fuzz_code, fuzz_s = step("fuzz", [PY, "tools/fuzz_run.py", *args.fuzz.split(), "--json", str(OUT / "fuzz.json")])
    ray_code, ray_s = step("Ray cook with a worker killed", [PY, "tools/ray_kill_cook.py", "--json", str(OUT / "ray-kill.json")])

    rows: list[tuple[str, str, str]] = []  # (check, result, verdict)
    ok = True
    soak = load(OUT / "soak.json") or []
    if not soak:
        rows.append(("soak", f"did not report (exit {soak_code})", "FAIL"))
        ok = False
    for r in soak:
        heap = f"{r['heap_drift_percent']:+.2f}%" if "heap_drift_percent" in r else "?"
        device = f"{r['device_drift_percent']:+.2f}%" if "device_drift_percent" in r else "?"
        resident = f"{r['resident_drift_percent']:+.2f}%" if "resident_drift_percent" in r else "?"
        missing = f"; passes missing: {', '.join(r['missing_passes'])}" if r["missing_passes"] else ""
        rows.append((f"soak, --aa {r['aa']} ({r['frames']:,} frames, {r['minutes']} min)",
                     f"validation messages {r['messages']}, memory allocated: heap {heap}, device {device} "
                     f"(frames 1,000-1,450 -> last 500; resident {resident}, not judged), "
                     f"{len(r['passes'])} passes{missing}", "pass" if r["ok"] else "FAIL"))
        ok = ok and r["ok"]
    fuzz = load(OUT / "fuzz.json") or []
    if not fuzz or seed_code != 0:
        rows.append(("fuzz", f"did not report (seeding exit {seed_code}, fuzz exit {fuzz_code})", "FAIL"))
        ok = False
    for r in fuzz:
        enough = r["executions"] >= MIN_EXECUTIONS
        good = r["ok"] and enough
        rows.append((f"fuzz {r['target']} ({r['seconds']} s)",
                     f"executions {r['executions']:,} ({r['exec_per_s']:,}/s), crashes {r['crashes']}"
                     + "".join(f" ({Path(a).name.split('-')[0]}: fuzz/artifacts/{r['target']}/{Path(a).name}, after {r['wall_s']:.0f} s)" for a in r["artifacts"])
                     + ("" if enough else f" (< {MIN_EXECUTIONS:,} executions)"), "pass" if good else "FAIL"))
        ok = ok and good
    ray = load(OUT / "ray-kill.json")
    if ray is None:
        rows.append(("Ray cook, a worker killed", f"did not report (exit {ray_code})", "FAIL"))
        ok = False
    else:
        k = ray.get("killed") or {}
        killed = f"worker {k['pid']} killed with {k['tiles_done']}/{k['tiles']} tiles back" if k else "no worker killed"
        rows.append((f"Ray cook, a worker killed ({ray.get('level')}, {ray_s:.0f} s)",
                     f"{ray.get('verdict')} to the local cook ({', '.join(ray.get('files', []))}); {killed}", "pass" if ray.get("ok") else "FAIL"))
        ok = ok and bool(ray.get("ok"))

    widths = [max(len(r[i]) for r in rows + [("check", "result", "verdict")]) for i in range(3)]
    line = lambda r: "| " + " | ".join(c.ljust(w) for c, w in zip(r, widths)) + " |"  # noqa: E731
    git = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    table = [f"make check-long at {git}{' (with uncommitted changes in the tree)' if dirty else ''}, "
             f"{started:%Y-%m-%d %H:%M}-{datetime.datetime.now(datetime.timezone.utc):%H:%M} UTC "
             f"(soak {soak_s / 60:.0f} min, fuzz {fuzz_s / 60:.0f} min, Ray {ray_s / 60:.1f} min)", "",
             line(("check", "result", "verdict")), "|" + "|".join("-" * (w + 2) for w in widths) + "|", *map(line, rows), "",
             f"check-long: {'PASS' if ok else 'FAIL'}"]
    text = "\n".join(table) + "\n"
    (ROOT / "build" / "check-long.txt").write_text(text)
    print("\n" + text, end="")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
