"""What long commands print while they work: a progress bar on stderr, and counted nouns."""
from __future__ import annotations

import sys
import time


class Progress:
    """A one-line progress bar on stderr (a line per 10 % when stderr is not a terminal)."""

    WIDTH = 30

    def __init__(self, label: str, stream=None):
        stream = sys.stderr if stream is None else stream  # (sys.stderr as it is now: the CLI guards it)
        self.label, self.stream = label, stream
        self.tty = stream.isatty()
        self._last_decile = -1
        self.t0 = time.perf_counter()

    def __call__(self, done: float, total: float, extra: str = "") -> None:
        frac = 0.0 if total <= 0 else min(1.0, done / total)
        if self.tty:
            bar = "#" * int(frac * self.WIDTH)
            self.stream.write(f"\r{self.label} [{bar:<{self.WIDTH}}] {100 * frac:5.1f}% {extra}")
            if frac >= 1.0:
                self.stream.write("\n")
            self.stream.flush()
        elif int(frac * 10) > self._last_decile:
            self._last_decile = int(frac * 10)
            self.stream.write(f"{self.label}: {100 * frac:.0f}% {extra}\n")
            self.stream.flush()


def plural(n: int, noun: str, nouns: str | None = None) -> str:
    """`n noun`, with the plural form unless n is 1: plural(1, "command") -> "1 command"."""
    return f"{n} {noun if n == 1 else (nouns or noun + 's')}"
