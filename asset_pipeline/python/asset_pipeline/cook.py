"""The cook entry point shared by the CLI and Python callers."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from pathlib import Path

from tqdm import tqdm

from asset_pipeline import _core

Progress = Callable[[str, float], object]


def cook(source: str | os.PathLike, out: str | os.PathLike, progress: bool | Progress = True) -> dict:
    """Cook ``source`` (.gltf or .glb) into the pack ``out`` and return its summary.

    ``progress``: True shows a bar on stderr when stderr is a terminal (and nothing otherwise),
    False shows nothing, a callable ``(what, fraction)`` is called instead.
    The pack is written atomically: on any error nothing appears at ``out`` and an existing file
    there is left as it was. Raises :class:`asset_pipeline.CookError` on bad input.
    """
    source, out = os.fspath(source), os.fspath(out)
    if callable(progress) or not progress:
        return _core.cook_gltf(source, out, progress or None)
    # disable=None: tqdm turns itself off when stderr is not a TTY (logs, CI, pipes).
    with tqdm(total=100, desc=Path(source).name, file=sys.stderr, disable=None, leave=False,
              bar_format="{desc}: {percentage:3.0f}%|{bar}| {postfix}") as bar:

        def update(what: str, fraction: float) -> None:
            bar.set_postfix_str(what, refresh=False)
            bar.update(round(fraction * 100) - bar.n)

        return _core.cook_gltf(source, out, update)
