"""Seeds for the level TOML fuzz target (fuzz/python/level_toml.py): the project's levels
(content/levels/*.toml) and every level the tests write (the string constants and literals in
tests/*.py that parse as TOML and have a level's sections), one file each in OUT_DIR.

    python3 tools/fuzz_level_seeds.py OUT_DIR

Standard library only (run by tools/fuzz_seed.sh). Prints how many seeds it wrote.
"""

from __future__ import annotations

import ast
import hashlib
import sys
import textwrap
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SECTIONS = ("level", "materials", "brushes", "objects", "props", "lights", "spawns", "reflection_probes")


def levels_in(source: Path) -> list[str]:
    """The string literals of a test module that are level TOML (after dedenting)."""
    found = []
    for node in ast.walk(ast.parse(source.read_text(encoding="utf-8"))):
        if not (isinstance(node, ast.Constant) and isinstance(node.value, str)) or "[" not in node.value:
            continue
        text = textwrap.dedent(node.value)
        try:
            doc = tomllib.loads(text)
        except ValueError:
            continue
        if doc and any(k in doc for k in SECTIONS):
            found.append(text)
    return found


def main() -> int:
    if len(sys.argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    out = Path(sys.argv[1])
    out.mkdir(parents=True, exist_ok=True)
    texts = {p.stem: p.read_text(encoding="utf-8") for p in sorted((ROOT / "content" / "levels").glob("*.toml"))}
    for test in sorted((ROOT / "tests").glob("*.py")):
        for i, text in enumerate(levels_in(test)):
            texts[f"{test.stem}-{i}"] = text
    seen = set()
    for name, text in texts.items():
        digest = hashlib.sha1(text.encode()).hexdigest()
        if digest not in seen:
            seen.add(digest)
            (out / f"{name}.toml").write_text(text, encoding="utf-8")
    print(f"fuzz_level_seeds: {len(seen)} level seeds")
    return 0


if __name__ == "__main__":
    sys.exit(main())
