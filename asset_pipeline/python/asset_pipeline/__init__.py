"""The asset cooker: turns glTF 2.0 sources into cooked, checksummed packs.

Python orchestrates; the Rust extension ``asset_pipeline._core`` does the work and writes the
pack. Every failure on bad input raises :class:`CookError`, whose message is one line naming the
file, the object and the problem.
"""

from asset_pipeline._core import COOKER, CookError, read_pack_summary
from asset_pipeline.cook import cook

__all__ = ["COOKER", "CookError", "cook", "read_pack_summary"]
