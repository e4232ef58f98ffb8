#!/usr/bin/env python3
"""Report on `bench` results (build/bench/<scenario>.json): a plot per scenario and a summary.

    tools/bench_report.py [DIR]              plots DIR/<scenario>.svg, writes DIR/summary.md, prints it
    tools/bench_report.py compare DIR_A DIR_B  per-scenario ratios B/A of the frame-time percentiles

The plots are SVG written by hand, so the report needs nothing beyond the standard library (it
runs in CI and on a fresh clone before any pip install).

Exit status: 0 ok, 1 a result file is unreadable, 2 bad arguments (a missing directory, no
results, or no scenario in common to compare).
"""

from __future__ import annotations

import json
import sys
from html import escape
from pathlib import Path

DEFAULT_DIR = Path("build/bench")
# Counters shown in the summary table, when the scenario has them (all are in the JSON).
# fragments_shaded, not the pipeline statistics' fragment invocations: lavapipe counts those
# before the depth test, so they cannot show what the pre-pass saves.
TABLE_COUNTERS = ("drawn", "culled", "triangles", "particles", "boids_drawn", "skinned_vertices", "fragments_shaded")
# The order `bench --all` runs them in; other names follow, alphabetically.
SCENARIO_ORDER = ("demo-flythrough", "culling-100k", "boids-10k", "particles-100k", "skinned-64", "prepass-overdraw")


class ReportError(Exception):
    """A problem with the inputs; `status` is the exit status to leave with."""

    def __init__(self, message: str, status: int = 2):
        super().__init__(message)
        self.status = status


def load_results(directory: Path) -> dict[str, dict]:
    """Every scenario result in `directory`, by scenario name."""
    if not directory.is_dir():
        raise ReportError(f"{directory}: no such directory (run `make bench` or `bench --all` first)")
    results = {}
    for path in sorted(directory.glob("*.json")):
        try:
            doc = json.loads(path.read_text())
        except (OSError, ValueError) as e:
            raise ReportError(f"{path}: not a readable JSON file: {e}", status=1) from e
        if not isinstance(doc, dict) or "scenario" not in doc or "cpu_frame_ms" not in doc:
            raise ReportError(f"{path}: not a bench result (no 'scenario' or 'cpu_frame_ms')", status=1)
        results[doc["scenario"]] = doc
    if not results:
        raise ReportError(f"{directory}: no bench results (*.json) in it")
    rank = {name: i for i, name in enumerate(SCENARIO_ORDER)}
    return dict(sorted(results.items(), key=lambda kv: (rank.get(kv[0], len(rank)), kv[0])))


def fmt(v, digits: int = 2) -> str:
    return "n/a" if v is None else f"{v:.{digits}f}"


# ---- plots ---------------------------------------------------------------------------------------

WIDTH, HEIGHT, MARGIN = 720, 300, 56
# One per series; a scenario with more series than colours reuses them in order.
COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf", "#bcbd22")


def polyline(values: list[float], y_max: float, colour: str) -> str:
    """One series as an SVG polyline in the plot area (frame index on x, ms on y)."""
    n = max(len(values) - 1, 1)
    inner_w, inner_h = WIDTH - 2 * MARGIN, HEIGHT - 2 * MARGIN
    points = " ".join(f"{MARGIN + inner_w * i / n:.1f},{HEIGHT - MARGIN - inner_h * v / y_max:.1f}" for i, v in enumerate(values))
    return f'<polyline fill="none" stroke="{colour}" stroke-width="1.5" points="{points}"/>'


def axes(title: str, y_max: float, frames: int) -> list[str]:
    """Frame, labels and horizontal grid lines at quarters of `y_max`."""
    inner_h = HEIGHT - 2 * MARGIN
    parts = [
        f'<rect x="0" y="0" width="{WIDTH}" height="{HEIGHT}" fill="white"/>',
        f'<text x="{WIDTH / 2}" y="22" text-anchor="middle" font-size="15">{escape(title)}</text>',
        f'<text x="{WIDTH / 2}" y="{HEIGHT - 12}" text-anchor="middle" font-size="12">measured frame (of {frames})</text>',
        f'<text x="16" y="{HEIGHT / 2}" font-size="12" transform="rotate(-90 16 {HEIGHT / 2})" text-anchor="middle">frame time (ms)</text>',
    ]
    for q in range(5):
        y = HEIGHT - MARGIN - inner_h * q / 4
        parts.append(f'<line x1="{MARGIN}" y1="{y:.1f}" x2="{WIDTH - MARGIN}" y2="{y:.1f}" stroke="#ddd"/>')
        parts.append(f'<text x="{MARGIN - 6}" y="{y + 4:.1f}" text-anchor="end" font-size="11">{y_max * q / 4:.1f}</text>')
    return parts


def plot_svg(doc: dict) -> str:
    """Frame time over the run: CPU frame time (and each variant's: pre-pass off, MSAA...), with
    the floor."""
    variants = doc.get("variants", {})
    series = [("CPU frame, default" if variants else "CPU frame (wall, fence wait included)", doc["samples"]["cpu_frame_ms"])]
    for key, v in variants.items():
        series.append((f"CPU frame, {v.get('label', key.replace('_', ' '))}", v["samples"]["cpu_frame_ms"]))
    floor = doc.get("floor_ms", {}).get("p50") or 0.0
    y_max = max([floor] + [max(v) for _, v in series if v]) * 1.1 or 1.0
    parts = axes(f"{doc['scenario']} ({doc['width']}x{doc['height']}, {doc['device']})", y_max, doc["frames"])
    for i, (label, values) in enumerate(series):
        parts.append(polyline(values, y_max, COLOURS[i % len(COLOURS)]))
    if floor:
        y = HEIGHT - MARGIN - (HEIGHT - 2 * MARGIN) * floor / y_max
        parts.append(f'<line x1="{MARGIN}" y1="{y:.1f}" x2="{WIDTH - MARGIN}" y2="{y:.1f}" stroke="#777" stroke-dasharray="5,4"/>')
        series.append((f"floor p50 {floor:.2f} ms (clear + wait)", None))
    for i, (label, values) in enumerate(series):
        colour = COLOURS[i % len(COLOURS)] if values is not None else "#777"
        parts.append(f'<text x="{MARGIN + 8}" y="{MARGIN - 16 + 14 * i}" font-size="11" fill="{colour}">{escape(label)}</text>')
    body = "\n".join(parts)
    return f'<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{HEIGHT}" viewBox="0 0 {WIDTH} {HEIGHT}">\n{body}\n</svg>\n'


def write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    tmp.replace(path)


# ---- summary table -------------------------------------------------------------------------------


def counters_cell(doc: dict) -> str:
    c = doc.get("counters", {})
    return ", ".join(f"{k} {c[k]}" for k in TABLE_COUNTERS if c.get(k) not in (None, 0))


def summary_rows(doc: dict) -> list[list[str]]:
    """The scenario's row (and one for each of its variants)."""
    rows = []
    variants = [("", doc)] + [(f" ({name.replace('_', ' ')})", v) for name, v in doc.get("variants", {}).items()]
    for suffix, v in variants:
        cpu, ratio, gpu = v["cpu_frame_ms"], v.get("floor_ratio", {}), v.get("gpu_frame_ms", {})
        rows.append([
            doc["scenario"] + suffix,
            str(cpu.get("count", doc["frames"])),
            fmt(cpu["p50"]), fmt(cpu["p95"]), fmt(cpu["p99"]), fmt(cpu["max"]),
            fmt(ratio.get("p50"), 1), fmt(ratio.get("p95"), 1),
            fmt(gpu.get("p50")),
            counters_cell(v),
        ])
    return rows


def markdown_table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def summary_markdown(results: dict[str, dict]) -> str:
    first = next(iter(results.values()))
    floor = first.get("floor_ms", {})
    header = ["scenario", "frames", "CPU p50 ms", "p95", "p99", "max", "p50 / floor", "p95 / floor", "GPU ts p50 ms", "counters (last frame)"]
    rows = [row for doc in results.values() for row in summary_rows(doc)]
    return "\n".join([
        f"# Frame times: {first['device']}, {first.get('cores', '?')} cores, {first['width']}x{first['height']}",
        "",
        f"Floor (clear + wait for an empty {first['width']}x{first['height']} frame): p50 {fmt(floor.get('p50'), 3)} ms, "
        f"p95 {fmt(floor.get('p95'), 3)} ms. CPU times are the wall time of whole frames, fence wait included; "
        "GPU timestamps (lavapipe) understate compute work.",
        "",
        markdown_table(header, rows),
        "",
    ])


def report(directory: Path) -> str:
    results = load_results(directory)
    for name, doc in results.items():
        write_atomic(directory / f"{name}.svg", plot_svg(doc))
    text = summary_markdown(results)
    write_atomic(directory / "summary.md", text)
    return text


# ---- compare -------------------------------------------------------------------------------------


def ratio(b, a) -> str:
    return "n/a" if not a or b is None else f"{b / a:.2f}x"


def compare(dir_a: Path, dir_b: Path) -> str:
    a, b = load_results(dir_a), load_results(dir_b)
    common = [name for name in a if name in b]
    if not common:
        raise ReportError(f"{dir_a} and {dir_b} have no scenario in common")
    rows = []
    for name in common:
        ca, cb = a[name]["cpu_frame_ms"], b[name]["cpu_frame_ms"]
        # Counters are exact: a difference means the two runs did different work.
        changed = sorted(k for k in set(a[name].get("counters", {})) | set(b[name].get("counters", {}))
                         if a[name].get("counters", {}).get(k) != b[name].get("counters", {}).get(k))
        rows.append([name, fmt(ca["p50"]), fmt(cb["p50"]), ratio(cb["p50"], ca["p50"]), fmt(ca["p95"]), fmt(cb["p95"]),
                     ratio(cb["p95"], ca["p95"]), ", ".join(changed) or "same"])
    only = sorted(set(a) ^ set(b))
    header = ["scenario", "A p50 ms", "B p50 ms", "B/A p50", "A p95 ms", "B p95 ms", "B/A p95", "counters that differ"]
    text = f"A = {dir_a}, B = {dir_b} (ratios below 1 mean B is faster)\n\n" + markdown_table(header, rows) + "\n"
    if only:
        text += f"\nin one set only (not compared): {', '.join(only)}\n"
    return text


USAGE = __doc__.split("\n\n")[1]


def main(argv: list[str]) -> int:
    try:
        if argv and argv[0] in ("-h", "--help"):
            print(__doc__)
            return 0
        if argv and argv[0] == "compare":
            if len(argv) != 3:
                raise ReportError("compare needs two result directories: compare DIR_A DIR_B")
            print(compare(Path(argv[1]), Path(argv[2])), end="")
            return 0
        if len(argv) > 1 or (argv and argv[0].startswith("-")):
            raise ReportError(f"unexpected arguments: {' '.join(argv)}")
        directory = Path(argv[0]) if argv else DEFAULT_DIR
        print(report(directory), end="")
        print(f"wrote {directory / 'summary.md'} and a plot per scenario ({directory}/<scenario>.svg)")
        return 0
    except ReportError as e:
        print(f"bench_report: {e}\n{USAGE}", file=sys.stderr)
        return e.status


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
