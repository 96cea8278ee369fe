"""Timing helpers shared by the benchmark scripts (not part of the package)."""

from __future__ import annotations

import os
import platform
import time
from collections.abc import Callable
from dataclasses import dataclass


def best_time(f: Callable[[], object], repeat: int = 5, min_time: float = 0.2) -> float:
    """Best wall time of one call of ``f`` over ``repeat`` rounds of at least ``min_time`` s."""
    f()  # warm up (compilation, caches)
    best = float("inf")
    for _ in range(repeat):
        calls = 0
        start = time.perf_counter()
        while True:
            f()
            calls += 1
            elapsed = time.perf_counter() - start
            if elapsed >= min_time:
                break
        best = min(best, elapsed / calls)
    return best


@dataclass
class Row:
    """One benchmark figure: what, the measured time, its unit count, and its baseline."""

    name: str
    seconds: float
    per: str
    count: int
    baseline_name: str
    baseline_seconds: float
    target: str = ""

    def line(self) -> str:
        each = self.seconds / self.count
        ratio = self.baseline_seconds / self.seconds
        return (
            f"| {self.name} | {_fmt(each)} per {self.per} | {self.count / self.seconds:,.0f} {self.per}/s | "
            f"{self.baseline_name}: {_fmt(self.baseline_seconds / self.count)} | {ratio:,.1f}x | {self.target} |"
        )


def _fmt(seconds: float) -> str:
    if seconds < 1e-6:
        return f"{seconds * 1e9:.0f} ns"
    if seconds < 1e-3:
        return f"{seconds * 1e6:.2f} us"
    if seconds < 1:
        return f"{seconds * 1e3:.2f} ms"
    return f"{seconds:.2f} s"


def machine() -> str:
    """One line about this machine."""
    return (
        f"{platform.node()} | {platform.processor() or platform.machine()} | {os.cpu_count()} cores | "
        f"Python {platform.python_version()} | {time.strftime('%Y-%m-%d')}"
    )


def print_table(title: str, rows: list[Row]) -> None:
    print(f"\n### {title}\n")
    print("| what | time | throughput | baseline (same run) | speed-up | target |")
    print("| --- | --- | --- | --- | --- | --- |")
    for row in rows:
        print(row.line())
