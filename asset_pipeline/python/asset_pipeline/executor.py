"""Where the cook's independent work runs: ``local`` (this process; the default, needs no Ray) or
``ray`` (tasks on a Ray cluster, ``cook --executor ray [--ray-address ADDR]``).

What goes to Ray: lightmap texel tiles, probe batches and reflection probes (the bake), LOD
chains per mesh and mip chains per texture. The source import and the lightmap UV atlas stay in the driver: each is one
item (the atlas packs every mesh's charts together).

The bake's scene (``bake.StaticScene.baker_args``, the arguments of ``_core.Baker``: triangles,
per-vertex attributes, materials and their textures, lights, sky; exactly what a local bake
builds its Baker from) is put into Ray's object store once per bake (``ray.put``); each task
carries only a reference to it, boxed in a list so Ray does not fetch it per task. A worker process builds the ``_core.Baker`` (the BVH) the first time it sees that
reference and keeps it for the following tiles (``_WORKER_BAKER``), so the BVH is built once per
worker process, not per task.

Results do not depend on where or in which order tiles run: the baker keys every texel's random
streams by (seed, page, texel index), every probe's by its grid index and every reflection
probe's by its index in the scene, so the pack is the same bytes as a local cook. A task whose
worker dies is resubmitted (``max_retries``); Ctrl-C cancels every submitted task that has not
finished.

This module imports ``ray`` only when a Ray executor connects.
"""

from __future__ import annotations

import ipaddress
import os
import socket
import time

from asset_pipeline._core import CookError

EXECUTORS = ("local", "ray")

# Per worker process: (scene key, Baker) of the last scene seen; one entry, so a long-lived worker
# serving many cooks holds one BVH, not all of them.
_WORKER_BAKER: dict = {}


def _worker_baker(key: str, boxed_ref: list):
    """The Baker for `key` in this worker process, built from the object store on first use.
    Returns (baker, built now)."""
    hit = _WORKER_BAKER.get(key)
    if hit is not None:
        return hit, False
    import ray

    from asset_pipeline import _core

    # bake.StaticScene.baker_args: the very arguments the local bake builds its Baker from.
    baker = _core.Baker(*ray.get(boxed_ref[0]))
    _WORKER_BAKER.clear()
    _WORKER_BAKER[key] = baker
    return baker, True


def bake_tile(key: str, boxed_ref: list, points, normals, ids, kw: dict):
    """One tile of lightmap texels (B (k, 3), or (k, 13) with kw's directional): (texels, rays,
    worker pid, built the BVH here, seconds)."""
    t0 = time.perf_counter()
    baker, built = _worker_baker(key, boxed_ref)
    out, rays = baker.bake_points(points, normals, ids, **kw)
    return out, rays, os.getpid(), built, time.perf_counter() - t0


def bake_probe_batch(key: str, boxed_ref: list, points, ids, kw: dict):
    """One batch of probes: (sh, sun visibility, backface, rays, worker pid, built here, seconds)."""
    t0 = time.perf_counter()
    baker, built = _worker_baker(key, boxed_ref)
    sh, sun, back, rays = baker.bake_probes(points, ids, **kw)
    return sh, sun, back, rays, os.getpid(), built, time.perf_counter() - t0


def bake_reflection_probe(key: str, boxed_ref: list, position, index: int, kw: dict):
    """One reflection probe (Baker.bake_reflection_probe, `id` its index in the scene): (radiance
    float32 (T, 3), rays, worker pid, built the BVH here, seconds)."""
    t0 = time.perf_counter()
    baker, built = _worker_baker(key, boxed_ref)
    rgb, rays = baker.bake_reflection_probe(position, id=index, **kw)
    return rgb, rays, os.getpid(), built, time.perf_counter() - t0


def lod_chain(base, lod_settings):
    from asset_pipeline.lod import build_lods

    return build_lods(base, lod_settings)


def texture_levels(level0, usage: str, normal: bool, job: dict):
    """The mip levels of one texture (see pipeline._textures_stage); a ValueError comes back as
    ("error", message) so the driver can name the texture."""
    from asset_pipeline._core import mip_chain, normal_chain

    try:
        if normal:
            return "ok", normal_chain(level0, filter=job["filter"], edge=job["edge"])
        return "ok", mip_chain(level0, usage, filter=job["filter"], edge=job["edge"], alpha_cutoff=job["alpha_cutoff"])
    except ValueError as e:
        return "error", str(e)


def _is_loopback(address: str) -> bool:
    host = address.rpartition(":")[0].strip("[]")
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


def _check_reachable(address: str) -> None:
    """A clear error now for an address nobody listens on, instead of Ray's long connect retries."""
    if address == "auto" or address.startswith("ray://"):
        return
    host, sep, port = address.rpartition(":")
    if not sep or not port.isdigit():
        raise CookError(f"--ray-address '{address}': expected HOST:PORT (the head's GCS address, as `ray start --head` prints)")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=5).close()
    except OSError as e:
        raise CookError(f"ray: cannot reach a cluster at {address}: {e.strerror or e}") from None


class RayExecutor:
    """Submits work as Ray tasks on the cluster at `address` (the pipeline connects before the
    first stage of a cook that is not up to date).

    ``submitted`` counts the tasks submitted, ``cancelled`` those cancelled by an interrupt.
    ``cancel_on_interrupt=False`` (the CLI, which exits right after) leaves the tasks pending on
    Ctrl-C instead: the cluster drops a dead driver's tasks by itself, and cancelling them races
    Ray 2.60's core worker, which can abort the whole process when a cancelled task's reply
    arrives late ("Tried to complete task that was not pending"; a fresh-clone run hit it)."""

    name = "ray"

    def __init__(self, address: str | None = None, max_retries: int = 3, cancel_on_interrupt: bool = True):
        self.address = address
        self.max_retries = max_retries
        self.cancel_on_interrupt = cancel_on_interrupt
        self.submitted = 0
        self.cancelled = 0
        self._ray = None
        self._remote: dict = {}

    def connect(self):
        if self._ray is not None:
            return self._ray
        if self.address and _is_loopback(self.address):
            # Ray rewrites a loopback head address to this machine's IP before connecting
            # (services.resolve_ip_for_localhost), where nothing listens when the cluster was
            # started on 127.0.0.1: the cook would hang in Ray's connection retries. The switch
            # is read when Ray is imported; its name says Windows/OSX, but on Linux it only turns
            # that rewrite off.
            os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
        try:
            import ray
        except ImportError:
            raise CookError("--executor ray needs the ray package: pip install 'asset_pipeline[ray]'") from None
        if not ray.is_initialized():
            # Ray's anonymous usage reporting stays off unless the user turned it on.
            os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
            if self.address:
                _check_reachable(self.address)
            try:
                import logging

                ray.init(address=self.address, logging_level=logging.WARNING, log_to_driver=False,
                         **({} if self.address else {"include_dashboard": False}))
            except (ConnectionError, RuntimeError, ValueError) as e:
                raise CookError(f"ray: cannot connect to {self.address or 'a local Ray instance'}: {str(e).splitlines()[0] if str(e) else type(e).__name__}") from None
        self._ray = ray
        return ray

    def put(self, value):
        return self.connect().put(value)

    def _task(self, fn):
        r = self._remote.get(fn)
        if r is None:
            # One CPU per task: the Rust code then runs single-threaded in it, so Ray's scheduler
            # (not nested thread pools) spreads the cluster's cores over the tasks.
            r = self._remote[fn] = self.connect().remote(fn).options(num_cpus=1, max_retries=self.max_retries)
        return r

    def run(self, calls: list[tuple], on_done=None) -> list:
        """Submit fn(*args) for each (fn, args) in `calls`; return the results in call order.
        `on_done(index, result)` is called in the driver as each finishes (in any order). Any
        exception here, Ctrl-C included, cancels what is still pending and propagates."""
        if not calls:
            return []
        ray = self.connect()
        index: dict = {}
        pending: list = []
        try:
            for i, (fn, args) in enumerate(calls):
                ref = self._task(fn).remote(*args)
                self.submitted += 1
                index[ref] = i
                pending.append(ref)
            results: list = [None] * len(calls)
            while pending:
                ready, pending = ray.wait(pending, num_returns=1)
                for ref in ready:
                    i = index[ref]
                    results[i] = ray.get(ref)
                    if on_done is not None:
                        on_done(i, results[i])
            return results
        except BaseException as e:
            if isinstance(e, KeyboardInterrupt) and not self.cancel_on_interrupt:
                raise
            for ref in pending:
                try:
                    ray.cancel(ref)
                    self.cancelled += 1
                except Exception:  # noqa: BLE001 - already finished or gone: nothing to cancel
                    pass
            # A bad input found by a task is the same one-line error as in a local cook; a task
            # that failed for good (retries used up, cluster gone) is one line too, not Ray's trace.
            if isinstance(e, ray.exceptions.RayTaskError) and isinstance(e.cause, CookError):
                raise e.cause from None
            if isinstance(e, ray.exceptions.RayError) and not isinstance(e, ray.exceptions.RayTaskError):
                first = str(e).strip().splitlines()[0] if str(e).strip() else ""
                raise CookError(f"ray: {type(e).__name__}: {first}") from None
            raise


def make_executor(name, address: str | None = None):
    """None for the local executor (the pipeline runs everything in this process), else the
    Ray executor (`name` may be a RayExecutor already). Raises CookError for an unknown name."""
    if isinstance(name, RayExecutor):
        return name
    if name == "local":
        if address:
            raise CookError("--ray-address needs --executor ray")
        return None
    if name == "ray":
        return RayExecutor(address)
    raise CookError(f"unknown executor '{name}' ({', '.join(EXECUTORS)})")
