"""``cook --watch SOURCE -o PACK``: cook, then cook again whenever a file the cook read changes.

The files watched are the ones the last cook read (``CookResult.files``: the level or glTF file,
then the props, buffers, images and textures it names), so an edit that names a new file is
followed by watching that file too. Their directories are watched for events (``watchfiles``:
inotify on Linux), not the files themselves, so an editor that saves by writing a new file and
renaming it over the old one is seen too; events on other files in those directories (editor
swap files, the pack itself when it is written beside the source) are ignored.

Each cook goes through the stage cache, so only the stages whose inputs changed run again; the
line after each cook names the stages that ran and those that came from the cache. A cook that
fails prints its one-line error and leaves the last good pack as it was (the pipeline writes
atomically); the next save cooks again. Ctrl-C (or SIGTERM) stops watching, and stops a cook
in progress without writing anything.

An edit made while a cook runs is not lost: the files' (size, mtime) are noted before each cook
and compared once the watcher for the next wait is running, so a change made before the watcher
started cooks again at once, and one made after it is an event.
"""

from __future__ import annotations

import dataclasses
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from asset_pipeline import CookError
from asset_pipeline.bake import BakeSettings, Refinement, Superseded, preset_samples
from asset_pipeline.cook import cook_detailed
from asset_pipeline.pipeline import CookResult, CookSettings, is_up_to_date

# Quiet time after the last event before cooking (an editor's save can be several events).
DEBOUNCE_MS = 150
# How often the wait wakes up without events, to look at the files' stat (changes made before
# the watcher started) and to notice a stop request.
WAKE_MS = 200

Fingerprint = dict[str, tuple[int, int] | None]


def fingerprint(files: Iterable[str]) -> Fingerprint:
    """Each file's (size, mtime in ns), None where it cannot be read (gone, being replaced)."""
    out: Fingerprint = {}
    for f in files:
        try:
            st = os.stat(f)
            out[f] = (st.st_size, st.st_mtime_ns)
        except OSError:
            out[f] = None
    return out


def changed_files(before: Fingerprint) -> list[str]:
    """The files of `before` whose stat differs now."""
    now = fingerprint(before)
    return [f for f in before if now[f] != before[f]]


@dataclass
class Outcome:
    """One cook of the watch loop: its result, or the error it stopped with."""

    result: CookResult | None
    error: str | None
    seconds: float
    superseded: bool = False  # a refining bake step given up for an edit that arrived


def stage_summary(result: CookResult) -> str:
    """'ran: level, bake, write; cached: uv2, lod' from the cook's stage records."""
    ran = [r.name for r in result.stages if r.cached < r.items]
    cached = [r.name for r in result.stages if r.items > 0 and r.cached >= r.items]
    parts = [f"ran: {', '.join(ran) or 'nothing'}"]
    if cached:
        parts.append(f"cached: {', '.join(cached)}")
    return "; ".join(parts)


class FileWatch:
    """Changes to a set of files, collected on a thread (``watchfiles`` over their folders), so a
    refining bake can ask between batches whether an edit arrived (`pending`)."""

    def __init__(self, debounce_ms: int = DEBOUNCE_MS):
        self.debounce_ms = debounce_ms
        self._wanted: frozenset[str] = frozenset()
        self._dirs: tuple[str, ...] = ()
        self._changes: set[str] = set()
        self._lock = threading.Lock()
        self._event = threading.Event()
        self._thread: threading.Thread | None = None
        self._stop: threading.Event | None = None
        self._ready = threading.Event()

    def follow(self, files: Iterable[str]) -> bool:
        """Watch these files from now on; True when the watcher (re)started, so changes made
        before this call were not seen by it."""
        self._wanted = frozenset(os.fspath(Path(f)) for f in files)
        dirs = tuple(sorted({os.fspath(Path(f).parent) for f in self._wanted if Path(f).parent.is_dir()}))
        if dirs == self._dirs and self._thread is not None and self._thread.is_alive():
            return False
        self.close()
        if not dirs:
            raise CookError("cook --watch: none of the files the cook read is in a folder that exists")
        self._dirs, self._stop, self._ready = dirs, threading.Event(), threading.Event()
        self._thread = threading.Thread(target=self._run, args=(dirs, self._stop, self._ready), name="cook-watch", daemon=True)
        self._thread.start()
        self._ready.wait()
        return True

    def _run(self, dirs, stop: threading.Event, ready: threading.Event) -> None:
        import watchfiles

        # The first (empty) yield comes once the watcher runs: `follow` waits for it.
        for changes in watchfiles.watch(*dirs, watch_filter=lambda _c, path: path in self._wanted, debounce=self.debounce_ms, step=50,
                                        stop_event=stop, rust_timeout=50, yield_on_timeout=True, recursive=False, raise_interrupt=False):
            ready.set()
            if changes:
                self.add(path for _, path in changes)
        ready.set()

    def add(self, paths: Iterable[str]) -> None:
        with self._lock:
            self._changes.update(paths)
            if self._changes:
                self._event.set()

    def pending(self) -> bool:
        return self._event.is_set()

    def take(self, stop: Callable[[], bool] | None = None) -> list[str] | None:
        """Wait for changes and return them (None when `stop()` says so first)."""
        while not self._event.wait(WAKE_MS / 1000):
            if stop is not None and stop():
                return None
        with self._lock:
            out, self._changes = sorted(self._changes), set()
            self._event.clear()
        return out

    def close(self) -> None:
        if self._stop is not None:
            self._stop.set()
        if self._thread is not None:
            self._thread.join()
        self._thread, self._stop, self._dirs = None, None, ()


def refine_steps(bake: BakeSettings) -> list[BakeSettings]:
    """The bakes a refining cook writes in turn: the target's settings with a sixteenth and a
    quarter of its lightmap and reflection samples, then the target itself (its one-shot bake,
    to the bit)."""
    samples, reflection = preset_samples(bake)
    steps = []
    for part in (16, 4):
        n, r = max(1, samples // part), max(1, reflection // part)
        if n < samples and (not steps or n > steps[-1].samples):
            steps.append(dataclasses.replace(bake, samples=n, reflection_samples=r))
    return [*steps, bake]


def run(source: str | os.PathLike, out: str | os.PathLike, settings: CookSettings | None = None, progress: bool = True,
        say: Callable[[str], None] | None = None, warn: Callable[[str], None] | None = None,
        stop: Callable[[], bool] | None = None, debounce_ms: int = DEBOUNCE_MS, refine: bool = True) -> int:
    """The watch loop: returns 0 when stopped (Ctrl-C, or `stop()` true while waiting), 2 when
    it cannot start. `say` prints progress lines (stdout), `warn` the errors (stderr). `refine`:
    bake in steps of growing sample counts (local bakes; see `refine_steps`)."""
    say = say or (lambda line: print(line, flush=True))
    warn = warn or (lambda line: print(line, file=sys.stderr, flush=True))
    source, out = Path(source), Path(out)
    settings = settings or CookSettings()
    # What no edit of the source can fix is an error now, as for a single cook.
    for problem in ([f"{source}: no such file"] if not source.is_file() else []) + (
            [f"{out}: output directory '{out.parent}' does not exist"] if not out.parent.is_dir() else []):
        warn(f"cook: error: {problem}")
        return 2
    watch = FileWatch(debounce_ms)
    # SIGTERM (a process manager, a test harness, a shell that started the cooker in the
    # background, where SIGINT is ignored) stops it as Ctrl-C does: cleanly, between writes.
    restore = _stop_on_sigterm()
    target = settings.bake or BakeSettings()
    local = settings.executor == "local" or settings.executor is None
    refinement = Refinement(stop=watch.pending) if refine and settings.baking and local else None
    steps = refine_steps(target) if refinement is not None else [target]
    files = [os.fspath(source.resolve())]
    try:
        while True:
            before = fingerprint(files)
            # A pack already cooked at the target is not replaced by a coarser one.
            todo = steps if refinement is not None and not is_up_to_date(source, out, settings) else [target]
            for bake in todo:
                outcome = cook_once(source, out, dataclasses.replace(settings, bake=bake, refine=refinement), progress)
                if outcome.superseded:
                    say("cook: an edit arrived; this bake step is dropped")
                    break
                if outcome.result is None:
                    warn(f"cook: error: {outcome.error}")
                    say(f"cook: {out} left as it was; save a fix to cook again")
                    break
                result = outcome.result
                # The files of the last good cook, and the source however it fails next.
                files = list(dict.fromkeys([os.fspath(source.resolve()), *result.files]))
                before.update({f: v for f, v in fingerprint(f for f in files if f not in before).items()})
                say(_cooked_line(out, outcome, bake is not target))
                if watch.follow(files):
                    # The watcher is new: what changed since the cook started was not seen by it.
                    watch.add(changed_files(before))
                if watch.pending():
                    break
            if not watch.pending():
                if watch.follow(files):
                    watch.add(changed_files(before))
                say(f"cook: watching {len(files)} file{'s' if len(files) != 1 else ''} (Ctrl-C to stop)")
            changed = watch.take(stop)
            if changed is None:
                return 0
            say(f"cook: changed: {', '.join(_short(f, source) for f in changed)}")
    except KeyboardInterrupt:
        say("cook: stopped watching")
        return 0
    finally:
        watch.close()
        restore()


def _stop_on_sigterm() -> Callable[[], None]:
    """Make SIGTERM raise KeyboardInterrupt in the main thread while watching; returns what puts
    the previous handler back. (Only the main thread can set handlers: elsewhere, nothing.)"""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None

    def interrupt(_signum, _frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    return lambda: signal.signal(signal.SIGTERM, previous)


def _cooked_line(out: Path, outcome: "Outcome", step: bool) -> str:
    """What a cook did, in one line: written or up to date, its bake's samples, its stages."""
    result = outcome.result
    if result.up_to_date:
        return f"cook: {out} is up to date ({outcome.seconds:.2f} s)"
    bake = result.bake.get("samples")
    refining = f"bake {bake} samples per texel{', refining' if step else ''}; " if bake else ""
    return f"cook: wrote {out} in {outcome.seconds:.2f} s ({refining}{stage_summary(result)})"


def cook_once(source: Path, out: Path, settings: CookSettings, progress: bool) -> Outcome:
    """One cook; a user's mistake becomes the outcome's error (the pack is left as it was), an
    edit arriving during a refining bake its `superseded`."""
    t0 = time.perf_counter()
    try:
        result = cook_detailed(source, out, progress=progress, settings=settings)
    except CookError as e:
        return Outcome(None, str(e), time.perf_counter() - t0)
    except Superseded:
        return Outcome(None, None, time.perf_counter() - t0, superseded=True)
    return Outcome(result, None, time.perf_counter() - t0)


def _short(path: str, source: Path) -> str:
    """`path` relative to the source's folder when inside it (the way the user named it)."""
    try:
        return os.fspath(Path(path).relative_to(source.resolve().parent))
    except ValueError:
        return path
