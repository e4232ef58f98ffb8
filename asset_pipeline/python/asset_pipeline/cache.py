"""Content-addressed stage cache: a stage's output is stored under a hash of everything it depends
on (its inputs, its settings and the cooker's own code), so an unchanged input costs one file
read and a changed one can never return a stale result.

Entries hold IR values in the wire form (JSON + arrays) in one .npz, written to a temporary file
and renamed into place, so a crash never leaves a half entry. Each array is stored zstd-compressed
when that saves at least a tenth of it, else raw (`write_entry`).

The cache is bounded (`evict`): after each cook the least recently used entries go until the
cache is within its limit. An entry's mtime is its last use (a load touches it), and a cook never
removes what it used itself nor what a cook still running may be using: each running cook is
registered in `<root>/.cooks/` (`register`), and every entry used since the oldest of them
started is kept.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import importlib.metadata
import itertools
import json
import os
import re
import stat
import zipfile
from pathlib import Path

import numpy as np
import zstandard

import asset_pipeline

_COOKER_ID: str | None = None


def cooker_id() -> str:
    """Identity of the cooker's code: its Python sources and its native module. Any change to
    either invalidates every cache entry."""
    global _COOKER_ID
    if _COOKER_ID is None:
        h = hashlib.sha256(asset_pipeline._core.COOKER.encode())
        package = Path(asset_pipeline.__file__).parent
        for p in sorted(package.glob("*.py")):
            h.update(p.name.encode())
            h.update(p.read_bytes())
        for native in sorted(package.glob("_core*.so")) + sorted(package.glob("_core*.pyd")):
            st = native.stat()  # size + mtime: hashing tens of MB on every cook would cost more
            h.update(f"{native.name}:{st.st_size}:{st.st_mtime_ns}".encode())
        _COOKER_ID = h.hexdigest()[:16]
    return _COOKER_ID


def library_version(name: str) -> str:
    """The installed version of a Python distribution whose code shapes a stage's output
    (manifold3d, xatlas, fast-simplification, pyoidn): part of that stage's key, so upgrading
    it reruns the stage."""
    try:
        return f"{name} {importlib.metadata.version(name)}"
    except importlib.metadata.PackageNotFoundError:
        return f"{name} not installed"


class Hasher:
    """Builds a stage key from strings, settings, files and arrays."""

    def __init__(self, stage: str):
        self._h = hashlib.sha256(f"{stage}\0{cooker_id()}\0".encode())

    def text(self, s: str) -> "Hasher":
        self._h.update(s.encode())
        self._h.update(b"\0")
        return self

    def settings(self, obj) -> "Hasher":
        return self.text(json.dumps(obj, sort_keys=True, default=repr))

    def file(self, path: Path) -> "Hasher":
        self.text(os.fspath(path))
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                self._h.update(block)
        return self

    def array(self, a: np.ndarray | None) -> "Hasher":
        if a is None:
            return self.text("none")
        a = np.ascontiguousarray(a)
        self.text(f"{a.dtype.str}{a.shape}")
        self._h.update(memoryview(a).cast("B"))
        return self

    def key(self) -> str:
        return self._h.hexdigest()


def process_running(pid: int) -> bool:
    """Whether process `pid` exists (the writer of a temporary file named after it)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def write_atomic(path: Path, write) -> None:
    """Write `path` whole or not at all: `write(file)` fills a hidden temporary beside it named
    `.<name>.<pid>.tmp` (what the clean-ups of dead cooks' temporaries look for), which is then
    renamed into place. A reader sees the old file or the new one, never half of one."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as f:
            write(f)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


@contextlib.contextmanager
def file_lock(path: Path):
    """Hold an exclusive lock on `path` (created empty, and left: removing a lock file races with
    the next taker) until the block ends. Where there is no fcntl, no lock."""
    try:
        import fcntl
    except ImportError:
        yield
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


# ---- sizes ----------------------------------------------------------------------------------------

# The default bound of a stage cache: a few levels' bakes and mip chains at full quality.
DEFAULT_CACHE_MAX = 4 << 30
_SIZE = re.compile(r"^\s*(\d+(?:\.\d*)?|\.\d+)\s*(?:([kmgt])(i?)b?|b?)\s*$", re.IGNORECASE)
_UNIT = {"k": 1, "m": 2, "g": 3, "t": 4}


def parse_size(text: str) -> int:
    """Bytes from '4294967296', '500M', '4G', '1.5GiB', '200 MB': K, M, G and T are powers of
    1000, Ki, Mi, Gi and Ti of 1024 (a trailing B is allowed). ValueError says what is wrong."""
    m = _SIZE.match(text)
    if m is None:
        raise ValueError(f"'{text}' is not a size (bytes, or a number with K, M, G or T, e.g. 500M, 4G, 1.5GiB)")
    number, unit, binary = m.groups()
    scale = (1024 if binary else 1000) ** _UNIT[unit.lower()] if unit else 1
    return int(float(number) * scale)


def format_size(n: int) -> str:
    """'4 GiB' for whole MiB and GiB (as limits are usually given), else '52.8 MB'."""
    for unit, f in (("GiB", 1 << 30), ("MiB", 1 << 20)):
        if n >= f and n % f == 0:
            return f"{n // f} {unit}"
    for unit, f in (("TB", 10**12), ("GB", 10**9), ("MB", 10**6), ("kB", 10**3)):
        if n >= f:
            return f"{n / f:.3g} {unit}"
    return f"{n} bytes"


# ---- entries: .npz, each array raw or zstd-compressed ---------------------------------------------

# zstd level 1: on the demo level's bake (22 MB of float32 lightmap sums) level 3 saves 2% more
# and takes three times as long; its meshes and textures shrink 3x-50x at either.
ZSTD_LEVEL = 1
# An array is stored compressed only when that saves at least this fraction of it (data that
# looks random, as some block-compressed textures and noisy sums do, gains little: decompressing
# it would cost load time for nothing), and only from this size (below it the frame's header
# outweighs any gain).
MIN_SAVING = 0.10
MIN_COMPRESS_BYTES = 256


def _compressed(cctx: zstandard.ZstdCompressor, a: np.ndarray) -> bytes | None:
    """`a`'s bytes (C order) zstd-compressed, or None when storing it raw is as good."""
    if a.nbytes < MIN_COMPRESS_BYTES or a.dtype.hasobject or a.dtype.fields is not None or a.dtype.subdtype is not None:
        return None  # plain dtypes only: their .str names them exactly
    data = np.ascontiguousarray(a).reshape(-1).view(np.uint8)
    blob = cctx.compress(memoryview(data))
    return blob if len(blob) <= (1.0 - MIN_SAVING) * a.nbytes else None


def _decompressed(dctx: zstandard.ZstdDecompressor, blob: np.ndarray, dtype: str, shape: list[int]) -> np.ndarray:
    """The array `_compressed` made `blob` from: decompressed straight into a new (writable)
    array; a blob that does not fill it exactly is damaged (ValueError)."""
    out = np.empty(tuple(shape), np.dtype(dtype))
    buf = memoryview(out.reshape(-1).view(np.uint8))
    done = 0
    with dctx.stream_reader(blob) as reader:
        while done < len(buf):
            n = reader.readinto(buf[done:])
            if n == 0:
                break
            done += n
        if done != len(buf) or reader.read(1):
            raise ValueError("compressed array of the wrong size")
    return out


def write_entry(f, meta: dict, arrays: list[np.ndarray]) -> None:
    """An entry into the open file `f`: an .npz of `meta` as JSON and the arrays, array i as
    `a<i>` (raw) or `z<i>` (its zstd-compressed bytes; its dtype and shape in the JSON)."""
    cctx = zstandard.ZstdCompressor(level=ZSTD_LEVEL)
    payload: dict[str, np.ndarray] = {}
    packed: dict[str, list] = {}
    for i, a in enumerate(arrays):
        a = np.asarray(a)
        blob = _compressed(cctx, a)
        if blob is None:
            payload[f"a{i}"] = a
        else:
            payload[f"z{i}"] = np.frombuffer(blob, np.uint8)
            packed[str(i)] = [a.dtype.str, list(a.shape)]
    payload["meta"] = np.array(json.dumps({**meta, "_arrays": len(arrays), "_zstd": packed}))
    np.savez(f, **payload)


def read_entry(path: Path) -> tuple[dict, list[np.ndarray]]:
    """(metadata, arrays) as `write_entry` was given them. Raises one of DAMAGED when the file is
    gone, cut short or not an entry."""
    with np.load(path, allow_pickle=False) as z:
        meta = json.loads(str(z["meta"]))
        count, packed = meta.pop("_arrays"), meta.pop("_zstd", {})
        dctx = zstandard.ZstdDecompressor()
        arrays = [_decompressed(dctx, z[f"z{i}"], *packed[str(i)]) if str(i) in packed else z[f"a{i}"] for i in range(count)]
    return meta, arrays


# What reading a missing, truncated or foreign file raises (FileNotFoundError included: an entry
# another cook evicted between our lookup and our open is a miss like any other).
DAMAGED = (OSError, EOFError, ValueError, KeyError, TypeError, zipfile.BadZipFile, zstandard.ZstdError)


# ---- what a cache holds ---------------------------------------------------------------------------

# The files of a cache root that count: stage entries (`<stage>/<sha256>.npz`, whatever their
# format: entries of an older cooker age out like any other) and output stamps
# (`outputs/<hash>.json`). Nothing else in a folder given as --cache is ever counted or removed.
_ENTRY = re.compile(r"^[0-9a-f]{16,64}\.(npz|json)$")
_TEMPORARY = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)\.tmp$")
COOKS = ".cooks"  # the registry of running cooks (not counted)


@dataclasses.dataclass
class Entry:
    path: Path
    stage: str
    size: int
    mtime_ns: int  # its last use


def _writer_running(pid: int) -> bool:
    return pid == os.getpid() or process_running(pid)


def scan(root: Path) -> tuple[list[Entry], list[Path]]:
    """Every entry under `root`'s stage folders, and the temporaries of writers that are gone
    (those of running writers are neither: they are about to become entries, or to vanish)."""
    entries: list[Entry] = []
    dead: list[Path] = []
    try:
        stages = [d for d in os.scandir(root) if d.name != COOKS and d.is_dir(follow_symlinks=False)]
    except (FileNotFoundError, NotADirectoryError):
        return entries, dead
    for d in stages:
        try:
            files = list(os.scandir(d.path))
        except OSError:
            continue  # removed meanwhile
        for f in files:
            t = _TEMPORARY.match(f.name)
            if t is not None:
                if _ENTRY.match(t["name"]) and not _writer_running(int(t["pid"])):
                    dead.append(Path(f.path))
                continue
            if not _ENTRY.match(f.name):
                continue
            try:
                st = f.stat(follow_symlinks=False)
            except FileNotFoundError:
                continue  # evicted by another cook meanwhile
            if stat.S_ISREG(st.st_mode):
                entries.append(Entry(Path(f.path), d.name, st.st_size, st.st_mtime_ns))
    return entries, dead


# ---- running cooks --------------------------------------------------------------------------------

_SERIAL = itertools.count()  # cooks of this process (threads may cook at once)


def _process_start(pid: int) -> str | None:
    """When process `pid` started (clock ticks since boot, /proc/<pid>/stat field 22), to tell it
    from an earlier process of the same pid; None where /proc does not say."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
        return text[text.rindex(")") + 2:].split()[19]
    except (OSError, ValueError, IndexError):
        return None


def register(root: Path) -> Path:
    """Register a running cook: `<root>/.cooks/<pid>-<n>`, holding its pid and process start. The
    file's mtime is when the cook started: every entry it uses is touched after that."""
    folder = Path(root) / COOKS
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{os.getpid()}-{next(_SERIAL)}"
    path.write_text(f"{os.getpid()} {_process_start(os.getpid()) or ''}\n")
    return path


def _alive(pid: int, text: str) -> bool:
    """Whether the cook that wrote registration `text` as process `pid` is still running (and
    not a later process that was given the same pid)."""
    if not process_running(pid):
        return False
    recorded = text.split()[1:2]
    now = _process_start(pid)
    return not recorded or now is None or recorded[0] == now


def running_cooks(root: Path, exclude: Path | None = None, clean: bool = False) -> list[int]:
    """The start times (ns) of the cooks registered under `root` that are still running, but
    `exclude` (the caller's own registration). `clean`: remove dead cooks' registrations."""
    starts = []
    try:
        files = list(os.scandir(Path(root) / COOKS))
    except (FileNotFoundError, NotADirectoryError):
        return starts
    for f in files:
        m = re.match(r"^(\d+)-\d+$", f.name)
        if m is None or (exclude is not None and Path(f.path) == exclude):
            continue
        try:
            text, start = Path(f.path).read_text(), f.stat().st_mtime_ns
        except OSError:
            continue  # it ended meanwhile
        if _alive(int(m[1]), text):
            starts.append(start)
        elif clean:
            Path(f.path).unlink(missing_ok=True)
    return starts


# ---- eviction -------------------------------------------------------------------------------------


@dataclasses.dataclass
class Eviction:
    limit: int
    total: int  # bytes of entries left
    entries: int  # entries left
    removed: int = 0
    freed: int = 0
    in_use: int = 0  # bytes of entries kept because a running cook (this one included) uses them
    cooks: int = 0  # other running cooks


def _remove_unused(e: Entry) -> bool:
    """Unlink entry `e` unless it was used since it was scanned (its mtime moved: a cook loaded
    it, or stored it again). A reader that already has it open still reads it whole; one that
    comes after finds it gone, a miss."""
    try:
        if os.stat(e.path).st_mtime_ns != e.mtime_ns:
            return False
        os.unlink(e.path)
    except FileNotFoundError:
        pass  # another cook removed it: gone all the same
    except OSError:
        return False
    return True


def evict(root: Path, limit: int, keep: frozenset | set = frozenset(), own: Path | None = None) -> Eviction:
    """Remove the least recently used entries under `root` until they total at most `limit`
    bytes, keeping those in `keep` (what this cook used) and every entry used since the oldest
    other running cook started (`own`: this cook's registration, not another's). Dead writers'
    temporaries go too. What must be kept may alone exceed `limit`: then it is all kept."""
    root = Path(root)
    entries, dead = scan(root)
    for t in dead:
        t.unlink(missing_ok=True)
    starts = running_cooks(root, exclude=own, clean=True)  # (and dead cooks' registrations go)
    total = sum(e.size for e in entries)
    if total <= limit:
        return Eviction(limit, total, len(entries), cooks=len(starts))
    # One evicter at a time, and it scans again: another may just have made room.
    with file_lock(root / COOKS / "evict.lock"):
        starts = running_cooks(root, exclude=own)
        cutoff = min(starts, default=None)
        entries, _ = scan(root)
        total = sum(e.size for e in entries)
        used = lambda e: e.path in keep or (cutoff is not None and e.mtime_ns >= cutoff)
        result = Eviction(limit, total, len(entries), in_use=sum(e.size for e in entries if used(e)), cooks=len(starts))
        for e in sorted((e for e in entries if not used(e)), key=lambda e: (e.mtime_ns, os.fspath(e.path))):
            if result.total <= limit:
                break
            if _remove_unused(e):
                result.total -= e.size
                result.entries -= 1
                result.removed += 1
                result.freed += e.size
    return result


@dataclasses.dataclass
class CacheInfo:
    root: Path
    stages: dict[str, tuple[int, int]]  # stage -> (entries, bytes)
    total: int
    entries: int
    oldest_ns: int | None  # the least recent use
    newest_ns: int | None
    cooks: int  # running cooks


def info(root: Path) -> CacheInfo:
    """What the cache at `root` holds (read only)."""
    entries, _ = scan(root)
    stages: dict[str, tuple[int, int]] = {}
    for e in entries:
        n, size = stages.get(e.stage, (0, 0))
        stages[e.stage] = (n + 1, size + e.size)
    times = [e.mtime_ns for e in entries]
    return CacheInfo(Path(root), dict(sorted(stages.items())), sum(e.size for e in entries), len(entries),
                     min(times, default=None), max(times, default=None), len(running_cooks(root)))


# ---- the cache ------------------------------------------------------------------------------------


def _touch(path: Path) -> None:
    """Mark `path` used now (its mtime); a cache we may not write keeps its order."""
    try:
        os.utime(path)
    except OSError:
        pass


class StageCache:
    """One cook's view of a stage cache. `used`: every entry it loaded or stored (never evicted
    by it). Loads touch their entry only once the cook is registered (`begin`): a cook that finds
    its output up to date touches nothing."""

    def __init__(self, root: Path, enabled: bool = True, max_bytes: int = DEFAULT_CACHE_MAX):
        self.root = Path(root)
        self.enabled = enabled
        self.max_bytes = max_bytes
        self.hits = 0
        self.misses = 0
        self.used: set[Path] = set()
        self.registration: Path | None = None
        self._unregistered = False  # running, to be registered once the cache exists

    def _path(self, stage: str, key: str) -> Path:
        return self.root / stage / f"{key}.npz"

    def load(self, stage: str, key: str) -> tuple[dict, list[np.ndarray]] | None:
        """The stored (metadata, arrays) or None. A damaged entry counts as a miss, as does one
        that another cook evicted at this moment."""
        path = self._path(stage, key)
        if not self.enabled:
            self.misses += 1
            return None
        try:
            meta, arrays = read_entry(path)
        except DAMAGED:
            self.misses += 1
            return None
        self.hits += 1
        self.use(path)
        return meta, arrays

    def use(self, path: Path) -> None:
        """`path` (an entry or an output stamp) is used by this cook."""
        self.used.add(path)
        if self.registration is not None:
            _touch(path)

    def begin(self) -> None:
        """This cook is running: register it (its entries are kept from other cooks' eviction)
        and touch what it has read so far. Where there is no cache yet, at its first store: a
        cook that fails before storing anything leaves no cache behind."""
        if self.root.is_dir():
            self._register()
        else:
            self._unregistered = True

    def _register(self) -> None:
        self._unregistered = False
        try:
            self.registration = register(self.root)
        except OSError:
            return  # a cache that cannot be written: nothing will be stored either
        for path in self.used:
            _touch(path)

    def end(self) -> None:
        if self.registration is not None:
            self.registration.unlink(missing_ok=True)
            self.registration = None

    def trim(self) -> Eviction:
        """Evict down to `max_bytes`, keeping what this cook used."""
        return evict(self.root, self.max_bytes, keep=self.used, own=self.registration)

    def remove_stale_temporaries(self) -> None:
        """Remove entries' temporary files (`.<entry>.<pid>.tmp`) whose writer is no longer
        running: what a cook killed in the middle of `store` leaves behind."""
        for f in self.root.glob("*/.*.tmp"):
            pid = f.name.rsplit(".", 2)[-2]
            if pid.isdigit() and (int(pid) == os.getpid() or process_running(int(pid))):
                continue
            try:
                f.unlink()
            except OSError:
                pass

    def store(self, stage: str, key: str, meta: dict, arrays: list[np.ndarray]) -> None:
        path = self._path(stage, key)
        path.parent.mkdir(parents=True, exist_ok=True)
        if self._unregistered:
            self._register()
        write_atomic(path, lambda f: write_entry(f, meta, arrays))
        self.used.add(path)
