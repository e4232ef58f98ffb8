"""``cook SOURCE -o OUT.pack``: the command-line front of :func:`asset_pipeline.cook`.

Exit status: 0 on success, 2 on bad arguments or bad input (as argparse), 130 when interrupted.
Errors are one line on stderr, ``cook: error: <message>``, never a traceback.
"""

from __future__ import annotations

import argparse
import sys

from asset_pipeline import CookError, cook


def _count(n: int, one: str, many: str) -> str:
    return f"{n} {one if n == 1 else many}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="cook", description="Cook a glTF 2.0 file (.gltf or .glb) into a pack.")
    parser.add_argument("source", help="the .gltf or .glb file to cook")
    parser.add_argument("-o", "--out", required=True, metavar="OUT.pack",
                        help="where to write the pack (its directory must exist)")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    try:
        s = cook(args.source, args.out, progress=not args.quiet)
    except CookError as e:
        print(f"cook: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("cook: interrupted; nothing written", file=sys.stderr)
        return 130
    print(f"cook: wrote {args.out}: {_count(s['meshes'], 'mesh', 'meshes')}, {_count(s['triangles'], 'triangle', 'triangles')}, "
          f"{_count(s['textures'], 'texture', 'textures')}, {s['bytes']} bytes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
