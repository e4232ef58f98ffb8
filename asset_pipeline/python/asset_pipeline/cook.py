"""The cook entry point shared by the CLI and Python callers."""

from __future__ import annotations

import os
from collections.abc import Callable

from asset_pipeline.pipeline import CookResult, CookSettings
from asset_pipeline.pipeline import cook as run_pipeline
from asset_pipeline.progress import Progress

ProgressCallback = Callable[[str, int, int], object]


def cook(source: str | os.PathLike, out: str | os.PathLike, progress: bool | ProgressCallback = True,
         settings: CookSettings | None = None) -> dict:
    """Cook ``source`` (.gltf, .glb or a level .toml) into the pack ``out``; return its summary.

    ``progress``: True shows a bar per stage on a terminal and one line per stage otherwise (on
    stderr); False shows nothing; a callable ``(stage, done, total)`` is called instead.
    The pack is written atomically: on any error nothing appears at ``out`` and an existing file
    there is left as it was. A report ``<out stem>.report.md`` and a stage cache (``.cook-cache``
    beside the output unless ``settings.cache_dir`` says otherwise) are written too.
    Raises :class:`asset_pipeline.CookError` on bad input.
    """
    return cook_detailed(source, out, progress, settings).summary


def cook_detailed(source, out, progress: bool | ProgressCallback = True, settings: CookSettings | None = None) -> CookResult:
    """As :func:`cook`, returning stage times, cache hits and whether anything ran."""
    if callable(progress):
        p = Progress(callback=progress)
    else:
        p = Progress(enabled=bool(progress))
    return run_pipeline(source, out, settings, p)
