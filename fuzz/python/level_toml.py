"""Fuzz target for the level TOML loader (`asset_pipeline.level.parse_level`, the text half of
`load_level`), with atheris (libFuzzer for Python): coverage of `asset_pipeline.level` and the
standard library's `tomllib` guides the mutations; the bytes are the level file's contents.

The property: any input gives a LevelSpec or the cooker's CookError, whose message is one line
that starts with the level file's path. Any other exception (KeyError, TypeError, ValueError,
RecursionError, OverflowError, ...) is a crash, and so is a CookError of several lines or one that
does not name the file; a hang is libFuzzer's -timeout. Bytes that are not UTF-8 stop early, as
`load_level`'s read does (a CookError there).

    .venv/bin/python fuzz/python/level_toml.py fuzz/corpus/level_toml -max_total_time=600

(`make fuzz` / `make check-long` run it, with the corpus seeded by tools/fuzz_seed.sh.) The level
path is content/levels/fuzz.toml, so the files the project's levels name (textures, props) are
found beside it; nothing is read or written there.
"""

from __future__ import annotations

import sys
from pathlib import Path

import atheris

# The cooker's dependencies load uninstrumented (numpy is big and not under test); then the two
# modules under test are imported afresh with atheris' coverage instrumentation.
import numpy  # noqa: F401

from asset_pipeline import ir  # noqa: F401
from asset_pipeline._core import CookError

for name in [m for m in sys.modules if m == "tomllib" or m.startswith("tomllib.") or m == "asset_pipeline.level"]:
    del sys.modules[name]
with atheris.instrument_imports(include=["tomllib", "asset_pipeline.level"]):
    import tomllib  # noqa: F401
    from asset_pipeline import level

REPO = Path(__file__).resolve().parents[2]
PATH = REPO / "content" / "levels" / "fuzz.toml"


def test_one(data: bytes) -> None:
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        return  # load_level: "cannot read the level"
    try:
        spec = level.parse_level(text, PATH)
    except CookError as e:
        message = str(e)
        if len(message.splitlines()) != 1 or not message.startswith(f"{PATH}"):
            raise AssertionError(f"a CookError that is not one line naming the file: {message!r}") from None
        return
    if not isinstance(spec, level.LevelSpec):
        raise AssertionError(f"parse_level returned {type(spec).__name__}")


def main() -> None:
    atheris.Setup(sys.argv, test_one)
    atheris.Fuzz()


if __name__ == "__main__":
    main()
