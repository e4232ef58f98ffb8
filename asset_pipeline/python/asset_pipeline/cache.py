"""Content-addressed stage cache: a stage's output is stored under a hash of everything it depends
on (its inputs, its settings and the cooker's own code), so an unchanged input costs one file
read and a changed one can never return a stale result.

Entries hold IR values in the wire form (JSON + arrays) in one uncompressed .npz, written to a
temporary file and renamed into place, so a crash never leaves a half entry.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import json
import os
import zipfile
from pathlib import Path

import numpy as np

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


class StageCache:
    def __init__(self, root: Path, enabled: bool = True):
        self.root = Path(root)
        self.enabled = enabled
        self.hits = 0
        self.misses = 0

    def _path(self, stage: str, key: str) -> Path:
        return self.root / stage / f"{key}.npz"

    def load(self, stage: str, key: str) -> tuple[dict, list[np.ndarray]] | None:
        """The stored (metadata, arrays) or None. A damaged entry counts as a miss."""
        path = self._path(stage, key)
        if not self.enabled or not path.exists():
            self.misses += 1
            return None
        try:
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z["meta"]))
                arrays = [z[f"a{i}"] for i in range(meta.pop("_arrays"))]
        except (OSError, ValueError, KeyError, zipfile.BadZipFile, json.JSONDecodeError):
            self.misses += 1
            return None
        self.hits += 1
        return meta, arrays

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
        payload = {"meta": np.array(json.dumps({**meta, "_arrays": len(arrays)})), **{f"a{i}": a for i, a in enumerate(arrays)}}
        write_atomic(path, lambda f: np.savez(f, **payload))
