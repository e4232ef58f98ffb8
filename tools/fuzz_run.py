"""Run fuzz targets, each for a fixed time, and report executions and crashes per target (`make
fuzz`, `make check-long`).

    .venv/bin/python tools/fuzz_run.py TARGET=SECONDS [TARGET=SECONDS ...] [--json OUT]

Targets: the cargo-fuzz crate's (fuzz/fuzz_targets/*.rs: pack_from_bytes, pack_manifest,
gltf_import; libFuzzer through `cargo +$FUZZ_TOOLCHAIN fuzz run`, cargo-fuzz from build/tools/bin)
and the Python ones (fuzz/python/*.py: level_toml; atheris, libFuzzer's engine in the venv). Each
runs one job from fuzz/corpus/<target>/ (seeded by tools/fuzz_seed.sh; what it finds is added
there) with libFuzzer's -max_total_time; a crash stops the target with its input in
fuzz/artifacts/<target>/ and the log in build/fuzz-<target>.log. The numbers are libFuzzer's
final stats (-print_final_stats=1). Every target runs even after one crashed; exit status 1 if any
crashed or did not run.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PYTHON_TARGETS = {p.stem: p for p in (ROOT / "fuzz" / "python").glob("*.py")}
# libFuzzer's options for every target: no input may take 10 s or 2 GB (a hang or a blow-up is a
# crash). Python inputs are kept to 4 KiB: longer ones only slow the interpreter down (the
# project's levels are longer, but their sections are each in a short seed too).
COMMON = ["-timeout=10", "-rss_limit_mb=2048", "-print_final_stats=1"]
RUST_ONLY = ["-malloc_limit_mb=1024"]
PYTHON_ONLY = ["-max_len=4096"]


def command(target: str, seconds: int) -> list[str]:
    corpus = ROOT / "fuzz" / "corpus" / target
    artifacts = ROOT / "fuzz" / "artifacts" / target
    corpus.mkdir(parents=True, exist_ok=True)
    artifacts.mkdir(parents=True, exist_ok=True)
    limits = [f"-max_total_time={seconds}", *COMMON]
    if target in PYTHON_TARGETS:
        return [str(ROOT / ".venv" / "bin" / "python"), str(PYTHON_TARGETS[target]), str(corpus), f"-artifact_prefix={artifacts}/",
                *limits, *PYTHON_ONLY]
    toolchain = os.environ.get("FUZZ_TOOLCHAIN", "nightly")
    return [os.environ.get("CARGO", "cargo"), f"+{toolchain}", "fuzz", "run", "--fuzz-dir", "fuzz", "-O", target, "--", *limits, *RUST_ONLY]


def run(target: str, seconds: int) -> dict:
    log = ROOT / "build" / f"fuzz-{target}.log"
    log.parent.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "PATH": f"{ROOT / 'build' / 'tools' / 'bin'}:{os.environ.get('PATH', '')}"}
    print(f"== fuzz {target} for {seconds} s", flush=True)
    t0 = time.monotonic()
    with open(log, "w") as f:
        code = subprocess.run(command(target, seconds), cwd=ROOT, env=env, stdout=f, stderr=subprocess.STDOUT).returncode
    wall = time.monotonic() - t0
    text = log.read_text(errors="replace")
    stat = dict(re.findall(r"^stat::(\w+):\s+(\d+)", text, re.M))
    written = re.findall(r"Test unit written to (\S+)", text)
    crashes = [w for w in written if Path(w).name.split("-")[0] in ("crash", "timeout", "oom", "leak")]
    # A slow unit (libFuzzer's -report_slow_units, 10 s) that finished is not a failure: on a loaded
    # machine one input once took 15 s and 0.07 s when run again. A real hang is a timeout-* above.
    slow = [w for w in written if Path(w).name.startswith("slow-unit")]
    summary = re.findall(r"^(SUMMARY: .*|Uncaught Python exception:.*|==\d+== ERROR: .*)$", text, re.M)
    out = {"target": target, "seconds": seconds, "wall_s": round(wall, 1), "exit": code,
           "executions": int(stat.get("number_of_executed_units", 0)), "exec_per_s": int(stat.get("average_exec_per_sec", 0)),
           "new_units": int(stat.get("new_units_added", 0)), "peak_rss_mb": int(stat.get("peak_rss_mb", 0)),
           "crashes": len(crashes) if crashes or code == 0 else 1, "artifacts": crashes, "slow_units": slow, "log": str(log.relative_to(ROOT))}
    out["ok"] = code == 0 and not crashes and out["executions"] > 0
    print(f"fuzz {target}: {out['executions']:,} executions in {seconds} s ({out['exec_per_s']:,}/s), {out['new_units']} new corpus "
          f"units, peak {out['peak_rss_mb']} MB, crashes {out['crashes']}"
          + (f", {len(slow)} slow unit(s) kept to look at" if slow else "") + ("" if out["ok"] else f", exit {code}; see {out['log']}"), flush=True)
    for line in summary[:3] + crashes + slow:
        print(f"  {line}")
    return out


def main(argv: list[str]) -> int:
    json_out = None
    if "--json" in argv:
        i = argv.index("--json")
        json_out = Path(argv[i + 1])
        argv = argv[:i] + argv[i + 2:]
    if not argv or any(not re.fullmatch(r"[\w-]+=\d+", a) for a in argv):
        print(__doc__, file=sys.stderr)
        return 2
    results = [run(t, int(s)) for t, s in (a.split("=") for a in argv)]
    if json_out:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        json_out.write_text(json.dumps(results, indent=2) + "\n")
    return 0 if all(r["ok"] for r in results) else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
