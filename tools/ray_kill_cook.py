"""A Ray cook with a worker killed (issue 27, `make check-long`): cooks a level with
`cook --executor ray` on a two-node loopback cluster this script starts (a head and one more node,
one CPU each, as tests/test_ray.py's), SIGKILLs a worker process of the second node while it is
inside a lightmap tile, and compares the pack and its EXR pages byte for byte with a local cook of
the same level and settings.

    .venv/bin/python tools/ray_kill_cook.py [--level content/levels/temple.toml] [--json OUT]
                                            [-- extra cook arguments]

The local cook is the one `make cook` leaves in build/ (build/<level>.pack, the cook's default
settings): `cook` is run on it first, which only says it is up to date when it is. With extra cook
arguments the local cook is made in build/ray-kill/local/ instead. The Ray cook goes to
build/ray-kill/ray/ with a cache of its own, so it does all the work.

The kill waits on the cook's own progress: its stderr is a terminal (a pty), so it draws the
`bake tiles` bar, and each redraw of the bar (a tile came back) is the moment to look for a worker
of the second node titled `ray::bake_tile` (busy in a tile) and kill it; the first redraw after
two tiles, before the last, that finds one kills it. Prints `identical` or `differs`; exit status
0 when the files are identical and a worker was killed mid-bake, 1 otherwise, 2 on a setup error.
"""

from __future__ import annotations

import argparse
import fcntl
import json
import os
import pty
import re
import shutil
import signal
import struct
import subprocess
import sys
import termios
import time
from pathlib import Path

# Before Ray is imported (and inherited by the cook): no usage reporting, and 127.0.0.1 stays
# 127.0.0.1 (see tests/test_ray.py).
os.environ["RAY_USAGE_STATS_ENABLED"] = "0"
os.environ["RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"] = "0"

ROOT = Path(__file__).resolve().parent.parent
COOK = ROOT / ".venv" / "bin" / "cook"
NODE = {"num_cpus": 1, "node_ip_address": "127.0.0.1", "object_store_memory": 200 * 1024 * 1024}
# tqdm's bar on the terminal: "bake tiles:  25%|##5       | 4/16 [00:02<00:06, 1.9item/s]".
BAR = re.compile(r"bake tiles:\s*\d+%\|[^|]*\|\s*(\d+)/(\d+)")


def outputs(pack: Path) -> dict[str, bytes]:
    """The pack and its EXR pages, by name."""
    return {p.name: p.read_bytes() for p in sorted(pack.parent.glob(f"{pack.stem}.*")) if p.suffix in (".pack", ".exr")}


def busy_workers(raylet_pid: int, task: str) -> list[int]:
    """Worker processes of one raylet that are running `task` (Ray titles a busy worker
    `ray::<task>`, an idle one `ray::IDLE`)."""
    pids = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
            title = (d / "cmdline").read_bytes().split(b"\0")[0].decode(errors="replace")
        except (OSError, IndexError, ValueError):
            continue
        if ppid == raylet_pid and title.startswith(f"ray::{task}"):
            pids.append(int(d.name))
    return pids


def run_cook(args: list[str]) -> subprocess.CompletedProcess:
    r = subprocess.run([str(COOK), *args], capture_output=True, text=True, cwd=ROOT)
    if r.returncode != 0:
        raise SystemExit(f"ray_kill_cook: the local cook failed:\n{r.stderr}")
    return r


def ray_cook_with_a_kill(cmd: list[str], raylet_pid: int) -> dict:
    """Run the Ray cook with its stderr on a pty; kill a busy bake_tile worker of `raylet_pid` at a
    redraw of the tile bar. Returns what happened."""
    primary, secondary = pty.openpty()
    fcntl.ioctl(secondary, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 160, 0, 0))
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=secondary, stdin=subprocess.DEVNULL, cwd=ROOT)
    os.close(secondary)
    killed: dict = {}
    shown = b""
    tail = ""
    try:
        while True:
            try:
                chunk = os.read(primary, 65536)  # blocks until the cook writes (or exits: EIO)
            except OSError:
                break
            if not chunk:
                break
            shown += chunk
            tail = (tail + chunk.decode(errors="replace"))[-4096:]
            if killed:
                continue
            bars = BAR.findall(tail)
            if not bars:
                continue
            done, total = map(int, bars[-1])
            if 2 <= done < total:
                for pid in busy_workers(raylet_pid, "bake_tile")[:1]:
                    os.kill(pid, signal.SIGKILL)
                    killed = {"pid": pid, "tiles_done": done, "tiles": total, "after_s": round(time.monotonic() - t0, 2)}
                    print(f"ray_kill_cook: killed worker {pid} (busy in a tile) with {done} of {total} tiles back", flush=True)
    finally:
        os.close(primary)
        stdout = proc.stdout.read().decode(errors="replace")
        code = proc.wait()
    text = shown.decode(errors="replace")
    # The terminal's stage lines, without the bars' redraws.
    lines = [l.split("\r")[-1].strip() for l in text.replace("\r\n", "\n").split("\n")]
    return {"code": code, "stdout": stdout, "stderr_lines": [l for l in lines if l], "killed": killed, "seconds": round(time.monotonic() - t0, 1)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--level", type=Path, default=ROOT / "content" / "levels" / "temple.toml")
    ap.add_argument("--work", type=Path, default=ROOT / "build" / "ray-kill", help="where the Ray cook (and a local one, if needed) go")
    ap.add_argument("--json", type=Path, help="also write the result here")
    ap.add_argument("cook_args", nargs="*", help="extra cook arguments, the same for both cooks (after --)")
    args = ap.parse_args()
    if not COOK.exists():
        print(f"ray_kill_cook: {COOK} is missing (run `make cooker`)", file=sys.stderr)
        return 2
    # The pack records its source as the cook was given it: both cooks name it as `make cook`
    # does, relative to the project's root (and run there).
    level = args.level.resolve()
    if level.is_relative_to(ROOT):
        level = level.relative_to(ROOT)
    name = f"{level.stem}.pack"

    # The local cook: build/'s when the settings are the default ones (`make cook`), made fresh if
    # it is not up to date; else one of our own.
    local = ROOT / "build" / name if not args.cook_args else args.work / "local" / name
    local.parent.mkdir(parents=True, exist_ok=True)
    r = run_cook([str(level), "-o", str(local), *args.cook_args])
    print(f"ray_kill_cook: local cook {local.relative_to(ROOT)}: {r.stdout.strip().splitlines()[-1] if r.stdout.strip() else 'done'}", flush=True)

    out = args.work / "ray" / name
    shutil.rmtree(out.parent, ignore_errors=True)
    out.parent.mkdir(parents=True)

    from ray.cluster_utils import Cluster

    cluster = Cluster(initialize_head=True, head_node_args={**NODE, "include_dashboard": False})
    try:
        worker_node = cluster.add_node(**NODE)
        cluster.wait_for_nodes()
        raylet_pid = worker_node.all_processes["raylet"][0].process.pid
        print(f"ray_kill_cook: cluster at {cluster.address} (2 nodes, 1 CPU each)", flush=True)
        cmd = [str(COOK), str(level), "-o", str(out), "--cache", str(out.parent / "cache"), "--executor", "ray",
               "--ray-address", cluster.address, *args.cook_args]
        run = ray_cook_with_a_kill(cmd, raylet_pid)
    finally:
        cluster.shutdown()

    result = {"level": str(level), "local": str(local),
              "ray": str(out), "cook_exit": run["code"], "killed": run["killed"], "seconds": run["seconds"]}
    if run["code"] != 0:
        print("\n".join(run["stderr_lines"][-20:]), file=sys.stderr)
        result.update(identical=False, verdict=f"the Ray cook failed (exit {run['code']})")
    else:
        a, b = outputs(local), outputs(out)
        differ = sorted(k for k in a.keys() | b.keys() if a.get(k) != b.get(k))
        result.update(identical=not differ and bool(a), files=sorted(a), differ=differ)
        tasks = re.search(r"\((\d+) Ray tasks?\)", run["stdout"])
        result["ray_tasks"] = int(tasks[1]) if tasks else None
        result["verdict"] = "identical" if result["identical"] else f"differs ({', '.join(differ) or 'no files'})"
    if result.get("identical") and not run["killed"]:
        result["verdict"] += "; but no worker was killed (none was busy in a tile at a redraw of the bar)"
    ok = bool(result.get("identical")) and bool(run["killed"])
    result["ok"] = ok
    print(f"ray_kill_cook: {result['verdict']}: {', '.join(result.get('files', []))} "
          f"(Ray cook {run['seconds']} s, {result.get('ray_tasks')} Ray tasks)")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=2) + "\n")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
