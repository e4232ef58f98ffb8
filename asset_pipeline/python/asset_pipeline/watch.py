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
atomically); the next save cooks again. Ctrl-C stops watching, and stops a cook in progress
without writing anything.

An edit made while a cook runs is not lost: the files' (size, mtime) are noted before each cook
and compared once the watcher for the next wait is running, so a change made before the watcher
started cooks again at once, and one made after it is an event.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from asset_pipeline import CookError
from asset_pipeline.cook import cook_detailed
from asset_pipeline.pipeline import CookResult, CookSettings

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


def stage_summary(result: CookResult) -> str:
    """'ran: level, bake, write; cached: uv2, lod' from the cook's stage records."""
    ran = [r.name for r in result.stages if r.cached < r.items]
    cached = [r.name for r in result.stages if r.items > 0 and r.cached >= r.items]
    parts = [f"ran: {', '.join(ran) or 'nothing'}"]
    if cached:
        parts.append(f"cached: {', '.join(cached)}")
    return "; ".join(parts)


def wait_for_change(files: list[str], before: Fingerprint, debounce_ms: int = DEBOUNCE_MS,
                    stop: Callable[[], bool] | None = None) -> list[str] | None:
    """Block until one of `files` changes; return the changed ones (None if `stop()` says so).
    `before`: their stat when the last cook started; a file already different is returned at
    once, once the watcher runs (so no change slips between the cook and the watch)."""
    import watchfiles

    wanted = {os.fspath(Path(f)) for f in files}
    dirs = sorted({os.fspath(Path(f).parent) for f in wanted if Path(f).parent.is_dir()})
    if not dirs:
        raise CookError("cook --watch: none of the files the cook read is in a directory that exists")
    first = True
    for changes in watchfiles.watch(*dirs, watch_filter=lambda _change, path: path in wanted, debounce=debounce_ms, step=50,
                                    rust_timeout=WAKE_MS, yield_on_timeout=True, recursive=False, raise_interrupt=True):
        if changes:
            return sorted({path for _, path in changes})
        if first:
            # The watcher is running now: anything that changed since the cook started was
            # missed by it, and the stat says so.
            first = False
            missed = changed_files(before)
            if missed:
                return missed
        if stop is not None and stop():
            return None
    return None


def run(source: str | os.PathLike, out: str | os.PathLike, settings: CookSettings | None = None, progress: bool = True,
        say: Callable[[str], None] | None = None, warn: Callable[[str], None] | None = None,
        stop: Callable[[], bool] | None = None, debounce_ms: int = DEBOUNCE_MS) -> int:
    """The watch loop: returns 0 when stopped (Ctrl-C, or `stop()` true between cooks).
    `say` prints progress lines (stdout), `warn` the errors (stderr)."""
    say = say or (lambda line: print(line, flush=True))
    warn = warn or (lambda line: print(line, file=sys.stderr, flush=True))
    source, out = Path(source), Path(out)
    settings = settings or CookSettings()
    # What no edit of the source can fix is an error now, as for a single cook.
    for problem in ([f"{source}: no such file"] if not source.is_file() else []) + (
            [f"{out}: output directory '{out.parent}' does not exist"] if not out.parent.is_dir() else []):
        warn(f"cook: error: {problem}")
        return 2
    files = [os.fspath(source.resolve())]
    try:
        while True:
            before = fingerprint(files)
            outcome = cook_once(source, out, settings, progress)
            if outcome.result is not None:
                result = outcome.result
                # The files of the last good cook, and the source however it fails next.
                files = list(dict.fromkeys([os.fspath(source.resolve()), *result.files]))
                before.update({f: v for f, v in fingerprint(f for f in files if f not in before).items()})
                if result.up_to_date:
                    say(f"cook: {out} is up to date ({outcome.seconds:.2f} s)")
                else:
                    say(f"cook: wrote {out} in {outcome.seconds:.2f} s ({stage_summary(result)})")
            else:
                warn(f"cook: error: {outcome.error}")
                say(f"cook: {out} left as it was; save a fix to cook again")
            say(f"cook: watching {len(files)} file{'s' if len(files) != 1 else ''} (Ctrl-C to stop)")
            changed = wait_for_change(files, before, debounce_ms, stop)
            if changed is None:
                return 0
            say(f"cook: changed: {', '.join(_short(f, source) for f in changed)}")
    except KeyboardInterrupt:
        say("cook: stopped watching")
        return 0


def cook_once(source: Path, out: Path, settings: CookSettings, progress: bool) -> Outcome:
    """One cook; a user's mistake becomes the outcome's error (the pack is left as it was)."""
    t0 = time.perf_counter()
    try:
        result = cook_detailed(source, out, progress=progress, settings=settings)
    except CookError as e:
        return Outcome(None, str(e), time.perf_counter() - t0)
    return Outcome(result, None, time.perf_counter() - t0)


def _short(path: str, source: Path) -> str:
    """`path` relative to the source's folder when inside it (the way the user named it)."""
    try:
        return os.fspath(Path(path).relative_to(source.resolve().parent))
    except ValueError:
        return path
