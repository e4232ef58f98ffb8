"""The bounded stage cache (cache.py): compressed entries read back exactly, LRU eviction to the
limit after every cook (never what this cook or another running one uses), `cook --cache-info`,
`cook --cache-prune`, `--cache-max`, and concurrent cooks into one cache.

Order of use is set with os.utime where it matters, never by sleeping: these tests do not depend
on timing.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from asset_pipeline import cache as cache_mod
from asset_pipeline.bake import BakeSettings
from asset_pipeline.cache import StageCache, evict, info, parse_size
from asset_pipeline.cook import cook_detailed
from asset_pipeline.pipeline import CookSettings
from conftest import COOK

QUICK_BAKE = BakeSettings(preset="draft", samples=1, probe_samples=4)
QUICK_CLI = ("-q", "--quality", "draft", "--samples", "1", "--probe-samples", "4")
S = 1_000_000_000  # ns per second

# A small level (CSG, lightmap UVs, a bake, a procedural texture with mips); `size` and `color`
# make levels whose entries differ.
LEVEL = """
[level]
name = "cache"
texels_per_metre = 6

[[materials]]
name = "stone"
texture = {{ procedural = "bricks", size = 64, seed = 3 }}

[[materials]]
name = "plaster"
base_color = {color}

[[brushes]]
name = "floor"
kind = "box"
size = [{size}, 0.5, 8]
material = "stone"

[[brushes]]
name = "hut"
kind = "box"
size = [3, 3, 3]
translation = [0, 1.7, 0]
material = "plaster"

[[brushes]]
name = "room"
kind = "box"
size = [2.4, 2.4, 2.4]
translation = [0, 1.7, 0]
material = "plaster"

[[objects]]
name = "ground"
op = "union"
operands = ["floor"]

[[objects]]
name = "house"
op = "difference"
operands = ["hut", "room"]

[[lights]]
name = "sun"
kind = "sun"
intensity = 50000
direction = [-0.4, -1, -0.3]
"""


def level(folder: Path, name: str, size: float = 8, color: str = "[0.8, 0.78, 0.7]") -> Path:
    path = folder / f"{name}.toml"
    path.write_text(LEVEL.format(size=size, color=color))
    return path


def run(*args, env=None) -> subprocess.CompletedProcess:
    return subprocess.run([str(COOK), *map(str, args)], capture_output=True, text=True, timeout=300, env=env)


def entry_key(n: int) -> str:
    return f"{n:064x}"


def age(path: Path, seconds: int) -> None:
    """Set `path`'s last use (mtime) to `seconds` after the epoch."""
    os.utime(path, ns=(seconds * S, seconds * S))


# ---- entries ----------------------------------------------------------------------------------


def test_entries_round_trip_exactly_compressed_or_raw(tmp_path):
    rng = np.random.default_rng(7)
    arrays = [
        np.zeros(0, np.float32),  # empty
        np.zeros((0, 3), np.uint8),
        np.linspace(0, 1, 5000).astype(np.float16),  # compressible half floats
        rng.standard_normal((300, 3)).astype(np.float16),  # noise: stays raw
        np.tile(np.arange(12, dtype=np.float32), 400).reshape(-1, 3),
        rng.integers(0, 1 << 32, (64, 64, 4), dtype=np.uint32).view(np.float32),  # random bits (NaNs too)
        np.zeros((64, 64, 4), np.uint8),  # compresses to nothing
        rng.integers(0, 255, (128, 128, 4), dtype=np.uint8),  # noise
        np.arange(6000, dtype=">i4").reshape(60, 100),  # big-endian
        np.asfortranarray(np.arange(2000, dtype=np.int64).reshape(40, 50)),  # Fortran order
        np.array(2.5),  # 0-d
        np.array([True, False] * 300),
        np.array(["ab", "cdef"] * 100),
    ]
    meta = {"name": "x", "list": [1, 2.5, None], "nested": {"a": "b"}}
    cache = StageCache(tmp_path / "cache")
    cache.store("stage", entry_key(1), meta, arrays)
    path = tmp_path / "cache" / "stage" / f"{entry_key(1)}.npz"

    # Both ways of storing are exercised: what compresses by a tenth or more is compressed.
    members = set(zipfile.ZipFile(path).namelist())
    compressed = {i for i in range(len(arrays)) if f"z{i}.npy" in members}
    assert {2, 4, 6, 8, 9, 12} <= compressed, members
    assert not compressed & {0, 1, 3, 5, 7, 10}, members
    assert len(members) == len(arrays) + 1

    got_meta, got = StageCache(tmp_path / "cache").load("stage", entry_key(1))
    assert got_meta == meta
    assert len(got) == len(arrays)
    for i, (a, b) in enumerate(zip(arrays, got)):
        assert b.dtype == a.dtype and b.shape == a.shape, (i, a.dtype, b.dtype, a.shape, b.shape)
        assert b.tobytes() == a.tobytes(), i
        assert b.flags.writeable, i  # stages may work in place on what they load
    raw = sum(a.nbytes for i, a in enumerate(arrays) if i not in compressed)
    packed = sum(a.nbytes for i, a in enumerate(arrays) if i in compressed)
    assert path.stat().st_size < raw + packed / 2 + 4096, (path.stat().st_size, raw, packed)


def test_a_truncated_damaged_or_missing_entry_is_a_miss(tmp_path):
    cache = StageCache(tmp_path)
    data = [np.arange(100_000, dtype=np.float32), np.ones(1000, np.uint8)]
    for k in range(4):
        cache.store("s", entry_key(k), {"k": k}, data)
    paths = [tmp_path / "s" / f"{entry_key(k)}.npz" for k in range(4)]
    whole = paths[0].read_bytes()
    paths[0].write_bytes(whole[: len(whole) // 2])  # cut short
    paths[1].write_bytes(whole[:-30])  # cut in the zip's directory
    damaged = bytearray(whole)
    damaged[len(damaged) // 3] ^= 0xFF  # a flipped byte inside the compressed array
    paths[2].write_bytes(bytes(damaged))
    paths[3].unlink()  # evicted by another cook

    reader = StageCache(tmp_path)
    for k in range(4):
        assert reader.load("s", entry_key(k)) is None, k
    assert (reader.hits, reader.misses) == (0, 4)
    assert reader.used == set(), "a miss is not a use"


# ---- eviction -----------------------------------------------------------------------------------


def fill(root: Path, names: dict[str, int], size: int = 50_000) -> dict[str, Path]:
    """Entries of about `size` bytes (incompressible) named a, b, c..., last used at the given
    seconds."""
    rng = np.random.default_rng(1)
    cache, paths = StageCache(root), {}
    for n, (name, used) in enumerate(names.items()):
        cache.store("stage", entry_key(n), {"name": name}, [rng.integers(0, 255, size, dtype=np.uint8)])
        paths[name] = root / "stage" / f"{entry_key(n)}.npz"
        age(paths[name], used)
    return paths


def test_eviction_order_follows_loads_not_stores(tmp_path):
    paths = fill(tmp_path, {"a": 1000, "b": 2000, "c": 3000})
    size = paths["a"].stat().st_size
    # A cook loads the oldest entry: that is a use.
    cook = StageCache(tmp_path)
    cook.begin()
    assert cook.load("stage", entry_key(0))[0] == {"name": "a"}
    cook.end()
    assert paths["a"].stat().st_mtime_ns > 3000 * S

    e = evict(tmp_path, 2 * size + 100)
    assert (e.removed, e.freed) == (1, size)
    assert not paths["b"].exists(), "the least recently used entry (b) should go"
    assert paths["a"].exists() and paths["c"].exists()
    assert info(tmp_path).total == e.total <= 2 * size + 100


def test_a_cook_that_finds_its_output_up_to_date_touches_nothing(tmp_path):
    """Loads before `begin` (the up-to-date check) do not move an entry's last use."""
    paths = fill(tmp_path, {"a": 1000})
    cache = StageCache(tmp_path)
    assert cache.load("stage", entry_key(0)) is not None
    assert paths["a"].stat().st_mtime_ns == 1000 * S
    assert cache.used == {paths["a"]}  # but it is kept from this cook's own eviction
    e = evict(tmp_path, 0, keep=cache.used)
    assert paths["a"].exists() and e.removed == 0 and e.total > e.limit


def test_eviction_keeps_what_this_cook_used_even_over_the_limit(tmp_path):
    paths = fill(tmp_path, {"a": 1000, "b": 2000, "c": 3000})
    e = evict(tmp_path, 0, keep={paths["a"]})
    assert paths["a"].exists() and not paths["b"].exists() and not paths["c"].exists()
    assert e.removed == 2 and e.total == e.in_use == paths["a"].stat().st_size > e.limit


def test_entries_of_a_running_cook_are_kept_and_a_dead_cooks_registration_goes(tmp_path):
    """Another cook is running (a `sleep` standing in for it, registered as cook.register
    registers): every entry used since it started is kept; once it is gone, they may go too."""
    paths = fill(tmp_path, {"old": 1000, "older": 900, "its": 5001, "also": 5000})
    other = subprocess.Popen(["sleep", "300"])
    try:
        registry = tmp_path / ".cooks"
        registry.mkdir()
        live = registry / f"{other.pid}-0"
        live.write_text(f"{other.pid} {cache_mod._process_start(other.pid) or ''}\n")
        age(live, 5000)  # it started at 5000 s: "its" and "also" are its uses
        # A registration left by an earlier process that had the same pid (another start time).
        assert cache_mod._process_start(other.pid) not in (None, "1")  # Linux: /proc/<pid>/stat
        reused = registry / f"{other.pid}-1"
        reused.write_text(f"{other.pid} 1\n")
        age(reused, 10)
        assert cache_mod.running_cooks(tmp_path) == [5000 * S]

        e = evict(tmp_path, 0)
        assert sorted(p for p in paths if paths[p].exists()) == ["also", "its"]
        assert e.cooks == 1 and e.removed == 2 and e.total == e.in_use > 0
        assert live.exists()
        assert not reused.exists(), "a registration of an earlier process of the same pid is dead, and removed"
    finally:
        other.kill()
        other.wait()
    assert cache_mod.running_cooks(tmp_path) == []
    e = evict(tmp_path, 0)
    assert e.total == 0 and e.removed == 2 and e.cooks == 0
    assert not live.exists(), "a dead cook's registration is removed"


def test_this_process_registered_cook_counts_as_running_for_another(tmp_path):
    """Two cooks in one process (threads) each see the other's registration as running."""
    paths = fill(tmp_path, {"old": 1000, "new": 4000})
    cook = StageCache(tmp_path)
    cook.begin()
    try:
        age(cook.registration, 3000)
        e = evict(tmp_path, 0)  # a second cook (or cook --cache-prune): not registered here
        assert not paths["old"].exists() and paths["new"].exists() and e.cooks == 1
        e = evict(tmp_path, 0, own=cook.registration)  # the registered cook itself: nothing else runs
        assert not paths["new"].exists() and e.cooks == 0
    finally:
        cook.end()
    assert list((tmp_path / ".cooks").glob("[0-9]*")) == []


def test_only_entries_count_not_live_temporaries_the_registry_or_other_files(tmp_path):
    paths = fill(tmp_path, {"a": 1000})
    size = paths["a"].stat().st_size
    stage = tmp_path / "stage"
    dead_pid = subprocess.Popen(["true"])  # a writer that is no longer running
    dead_pid.wait()
    live_tmp = stage / f".{entry_key(8)}.npz.{os.getpid()}.tmp"
    dead_tmp = stage / f".{entry_key(9)}.npz.{dead_pid.pid}.tmp"
    for f in (live_tmp, dead_tmp):
        f.write_bytes(b"x" * 10_000)
    (stage / "notes.txt").write_text("not an entry: a folder given as --cache by mistake loses nothing")
    registration = cache_mod.register(tmp_path)  # this process, as a running cook
    registration.write_text(f"{os.getpid()} {cache_mod._process_start(os.getpid())} " + "x" * 10_000)  # not counted
    age(registration, 500)  # started before "a" was last used... 
    i = info(tmp_path)
    assert (i.total, i.entries, i.stages) == (size, 1, {"stage": (1, size)})
    assert i.cooks == 1
    e = evict(tmp_path, 0, own=registration)  # ...but it is this cook's own registration
    assert e.removed == 1 and not paths["a"].exists()
    assert live_tmp.exists() and (stage / "notes.txt").exists() and registration.exists()
    assert not dead_tmp.exists(), "a dead writer's temporary is removed"
    registration.unlink()


@pytest.mark.parametrize("text, size", [
    ("0", 0), ("1234", 1234), ("500M", 500_000_000), ("500MB", 500_000_000), ("4G", 4_000_000_000),
    ("1.5GiB", 1_610_612_736), ("2Ki", 2048), ("3 mib", 3 << 20), ("1T", 10**12), ("100B", 100), (".5K", 500),
])
def test_sizes(text, size):
    assert parse_size(text) == size


@pytest.mark.parametrize("text", ["", "M", "-5M", "5X", "1e9", "5iB", "nan", "4 G B"])
def test_bad_sizes(text):
    with pytest.raises(ValueError, match="is not a size"):
        parse_size(text)


# ---- cooks fill the cache past its limit -------------------------------------------------------


def test_cooks_keep_the_cache_under_its_limit_and_an_evicted_level_rebuilds(tmp_path):
    cache_dir = tmp_path / "cache"
    # Largest first: every later cook's entries fit the limit set from the first one's.
    levels = [level(tmp_path, f"l{k}", size=9.5 - 0.5 * k, color=f"[0.{k + 2}, 0.5, 0.5]") for k in range(4)]
    outs = [tmp_path / f"l{k}.pack" for k in range(4)]
    first = cook_detailed(levels[0], outs[0], progress=False, settings=CookSettings(bake=QUICK_BAKE, cache_dir=cache_dir))
    one_cook = info(cache_dir).total
    assert set(first.cache_entries) == {os.fspath(e.path) for e in cache_mod.scan(cache_dir)[0]}
    limit = int(one_cook * 1.6)
    settings = CookSettings(bake=QUICK_BAKE, cache_dir=cache_dir, cache_max=limit)
    packs = [outs[0].read_bytes()]
    for k in range(1, 4):
        result = cook_detailed(levels[k], outs[k], progress=False, settings=settings)
        assert not result.up_to_date
        packs.append(outs[k].read_bytes())
        assert info(cache_dir).total <= limit, f"cook {k}: {info(cache_dir).total} bytes over the limit {limit}"
        missing = [e for e in result.cache_entries if not Path(e).exists()]
        assert missing == [], f"cook {k} lost entries it used: {missing}"
    assert len(set(packs)) == 4, "the levels should differ"

    # The first level's own bake and import went (least recently used)...
    gone = [e for e in first.cache_entries if not Path(e).exists()]
    assert any("/bake/" in e for e in gone) and any("/source/" in e for e in gone), gone
    # ... so cooking it again runs them, and gives its pack to the byte.
    again = cook_detailed(levels[0], outs[0], progress=False, settings=settings)
    table = {s.name: (s.items, s.cached) for s in again.stages}
    assert not again.up_to_date and table["level"] == (1, 0) and table["bake"][1] == 0 < table["bake"][0], table
    assert outs[0].read_bytes() == packs[0]
    assert info(cache_dir).total <= limit


# ---- concurrent cooks ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def solo(tmp_path_factory):
    """Two levels, each cooked alone with a cache of its own: {name: (level, pack bytes)}."""
    folder = tmp_path_factory.mktemp("solo")
    refs = {}
    for name, size, color in (("a", 8, "[0.8, 0.2, 0.2]"), ("b", 7, "[0.2, 0.2, 0.8]")):
        src = level(folder, name, size=size, color=color)
        out = folder / name / f"{name}.pack"
        out.parent.mkdir()
        r = run(src, "-o", out, *QUICK_CLI)
        assert r.returncode == 0, r.stderr
        refs[name] = (src, out.read_bytes())
    assert refs["a"][1] != refs["b"][1]
    return refs


def cook_together(*jobs: tuple) -> list[subprocess.CompletedProcess]:
    """Start every cook (source, out, extra args) at once, then wait for all of them."""
    procs = [subprocess.Popen([str(COOK), str(src), "-o", str(out), *QUICK_CLI, *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True) for src, out, *extra in jobs]
    results = []
    for p in procs:
        stdout, stderr = p.communicate(timeout=300)
        results.append(subprocess.CompletedProcess(p.args, p.returncode, stdout, stderr))
    return results


def test_concurrent_cooks_of_two_levels_into_one_cache(solo, tmp_path):
    shared = tmp_path / "cache"
    (tmp_path / "a").mkdir(), (tmp_path / "b").mkdir()
    outs = {n: tmp_path / n / f"{n}.pack" for n in "ab"}
    for r in cook_together(*((solo[n][0], outs[n], "--cache", shared) for n in "ab")):
        assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    for n in "ab":
        assert outs[n].read_bytes() == solo[n][1], f"level {n} cooked beside another differs from its solo cook"
    assert list((shared / ".cooks").glob("[0-9]*")) == [], "both cooks unregistered"


def test_concurrent_cooks_of_one_level_to_two_outputs_with_a_cache_of_no_room(solo, tmp_path):
    """With --cache-max 0 each cook evicts all it may at its end: never what the other, still
    running, uses; either way both packs are the solo one."""
    shared = tmp_path / "cache"
    outs = [tmp_path / "one.pack", tmp_path / "two.pack"]
    for r in cook_together(*((solo["a"][0], out, "--cache", shared, "--cache-max", "0") for out in outs)):
        assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
        assert "more than its limit" in r.stderr  # what it used itself is kept, and said
    for out in outs:
        assert out.read_bytes() == solo["a"][1]
    # Nothing runs now: a prune to 0 empties it.
    r = run("--cache-prune", "--cache", shared, "--cache-max", "0")
    assert r.returncode == 0, r.stderr
    assert info(shared).entries == 0


def test_concurrent_cooks_of_one_level_to_one_output(solo, tmp_path):
    out = tmp_path / "a.pack"
    for r in cook_together((solo["a"][0], out), (solo["a"][0], out)):
        assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    assert out.read_bytes() == solo["a"][1]
    assert sorted(f.name for f in tmp_path.iterdir() if f.name.startswith(".") and f.name != ".cook-cache") == []
    # The stamp is the last writer's, of the files it wrote: the output is up to date.
    r = run(solo["a"][0], "-o", out, *QUICK_CLI)
    assert r.returncode == 0 and "is up to date" in r.stdout, (r.stdout, r.stderr)


# ---- the command line -----------------------------------------------------------------------------


def test_cache_info_prints_size_limit_stages_and_uses(tmp_path):
    root = tmp_path / ".cook-cache"
    rng = np.random.default_rng(3)
    cache = StageCache(root)
    for k, stage in enumerate(["bake", "bake", "lod"]):
        cache.store(stage, entry_key(k), {}, [rng.integers(0, 255, 20_000, dtype=np.uint8)])
    entries = {e.path.name: e for e in cache_mod.scan(root)[0]}
    for k, when in enumerate([1_700_000_000, 1_700_000_100, 1_700_003_600]):
        age(root / ("bake" if k < 2 else "lod") / f"{entry_key(k)}.npz", when)
    bake = sum(e.size for e in entries.values() if e.stage == "bake")
    total = sum(e.size for e in entries.values())

    r = run("--cache-info", "-o", tmp_path / "level.pack", "--cache-max", "1.5GiB")
    assert r.returncode == 0 and r.stderr == "", r.stderr
    lines = r.stdout.splitlines()
    stamp = lambda s: time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(s))
    assert lines[0] == f"stage cache: {root}"
    assert lines[1] == f"size: {cache_mod.format_size(total)} in 3 entries (limit 1536 MiB)"
    assert re.fullmatch(rf"  bake +2 entries +{re.escape(cache_mod.format_size(bake))}", lines[2]), lines[2]
    assert re.fullmatch(r"  lod +1 entry +\S+ kB", lines[3]), lines[3]
    assert lines[4:] == [f"oldest use: {stamp(1_700_000_000)}", f"newest use: {stamp(1_700_003_600)}", "running cooks: 0"]

    # The limit comes from $COOK_CACHE_MAX when --cache-max is not given, else 4 GiB.
    r = run("--cache-info", "--cache", root, env={**os.environ, "COOK_CACHE_MAX": "2G"})
    assert r.returncode == 0 and "(limit 2 GB)" in r.stdout, r.stdout
    r = run("--cache-info", "--cache", root, env={k: v for k, v in os.environ.items() if k != "COOK_CACHE_MAX"})
    assert "(limit 4 GiB)" in r.stdout


def test_cache_prune_trims_to_the_limit_oldest_first(tmp_path):
    paths = fill(tmp_path / "c", {"a": 1000, "b": 2000, "c": 3000})
    size = paths["a"].stat().st_size
    r = run("--cache-prune", "--cache", tmp_path / "c", "--cache-max", str(2 * size))
    assert r.returncode == 0 and r.stderr == "", r.stderr
    assert r.stdout == (f"cook: pruned {tmp_path / 'c'}: removed 1 entry ({cache_mod.format_size(size)}); "
                        f"{cache_mod.format_size(2 * size)} in 2 entries left, limit {cache_mod.format_size(2 * size)}\n")
    assert [p for p in paths if paths[p].exists()] == ["b", "c"]


@pytest.mark.parametrize("args, message", [
    (("--cache-info", "--cache", "{tmp}/nothing"), "cook: error: --cache-info: no stage cache at '{tmp}/nothing' (no such directory)"),
    (("--cache-prune", "-o", "{tmp}/x/level.pack"), "cook: error: --cache-prune: no stage cache at '{tmp}/x/.cook-cache' (no such directory)"),
])
def test_a_missing_cache_is_one_line(tmp_path, args, message):
    r = run(*(a.format(tmp=tmp_path) for a in args))
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.splitlines() == [message.format(tmp=tmp_path)]


@pytest.mark.parametrize("args, fragment", [
    (("--cache-max", "5X"), "argument --cache-max: '5X' is not a size"),
    (("--cache-max", "-1"), "argument --cache-max: '-1' is not a size"),
    (("--cache-prune",), "--cache-prune needs the cache: --cache DIR, or -o OUT.pack"),
    (("--cache-info", "--cache-prune", "--cache", "{tmp}"), "argument --cache-prune: not allowed with argument --cache-info"),
    (("--cache-info", "level.toml", "--cache", "{tmp}"), "--cache-info cooks nothing: drop SOURCE"),
    (("level.toml",), "the following arguments are required: -o/--out"),
    ((), "the following arguments are required: source, -o/--out"),
])
def test_bad_cache_arguments_are_one_line_usage_errors(tmp_path, args, fragment):
    args = [a.format(tmp=tmp_path) for a in args]
    if args and args[0] == "--cache-max":  # for a cook
        args = [tmp_path / "level.toml", "-o", tmp_path / "level.pack", *args]
    r = run(*args)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    errors = [l for l in r.stderr.splitlines() if l.startswith("cook: error:")]
    assert len(errors) == 1 and fragment in errors[0], r.stderr
    assert all(l.startswith(("usage:", " ", "cook: error:")) for l in r.stderr.splitlines()), r.stderr
    assert list(tmp_path.iterdir()) == []


def test_a_bad_cook_cache_max_is_one_line(tmp_path):
    src = level(tmp_path, "l")
    r = run(src, "-o", tmp_path / "l.pack", env={**os.environ, "COOK_CACHE_MAX": "lots"})
    assert r.returncode == 2
    assert r.stderr.splitlines() == ["cook: error: COOK_CACHE_MAX: 'lots' is not a size (bytes, or a number with K, M, G or T, e.g. 500M, 4G, 1.5GiB)"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["l.toml"]


def test_help_names_the_cache_options():
    r = run("--help")
    assert r.returncode == 0
    text = " ".join(r.stdout.split())
    for option in ("--cache DIR", "--cache-max SIZE", "--cache-info", "--cache-prune", "COOK_CACHE_MAX"):
        assert option in text, option
    assert text.startswith("usage: cook SOURCE -o OUT.pack [options] cook --cache-info | --cache-prune")
