"""Progress for the cook: one bar per stage (count, rate, ETA) on a terminal; plain log lines
otherwise (CI, pipes, files), so logs stay readable."""

from __future__ import annotations

import sys
import time
from contextlib import contextmanager

from tqdm import tqdm


class _Bar:
    def __init__(self, bar: tqdm | None, notify=None):
        self._bar = bar
        self._notify = notify
        self.done = 0
        self.text = ""

    def note(self, text: str) -> None:
        """A short status after the counts (a rate, say); the plain log line ends with the last one."""
        self.text = text
        if self._bar is not None:
            self._bar.set_postfix_str(text, refresh=False)

    def advance(self, n: int = 1) -> None:
        self.done += n
        if self._bar is not None:
            self._bar.update(n)
        if self._notify is not None:
            self._notify(self.done)


class Progress:
    """`callback(stage, done, total)`, when given, replaces all output (for callers that show
    progress their own way); an exception it raises aborts the cook before anything is written."""

    def __init__(self, enabled: bool = True, stream=None, callback=None):
        self.stream = stream or sys.stderr
        self.callback = callback
        self.enabled = enabled and callback is None
        self.tty = self.enabled and hasattr(self.stream, "isatty") and self.stream.isatty()

    def line(self, message: str) -> None:
        if self.enabled:
            print(f"cook: {message}", file=self.stream, flush=True)

    def warning(self, message: str) -> None:
        """A problem the cook fixed on its own: shown even when progress is off (not with a
        callback, whose caller reads `scene.warnings` itself)."""
        if self.callback is None:
            print(f"cook: warning: {message}", file=self.stream, flush=True)

    @contextmanager
    def stage(self, name: str, total: int):
        start = time.perf_counter()
        if self.callback is not None:
            self.callback(name, 0, total)
            yield _Bar(None, lambda done: self.callback(name, done, total))
            return
        if self.tty:
            with tqdm(total=total, desc=f"{name:>6}", file=self.stream, unit="item", leave=True, dynamic_ncols=True) as bar:
                yield _Bar(bar)
            return
        b = _Bar(None)
        yield b
        self.line(f"{name}: {b.done}/{total} in {time.perf_counter() - start:.2f} s" + (f", {b.text}" if b.text else ""))
