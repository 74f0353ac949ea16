"""Shared by the benchmarks: machine description, timing, and writing a table into README.md.

A benchmark writes its Markdown table between ``<!-- bench:NAME -->`` and ``<!-- /bench:NAME -->`` in
the README, so the figures there are always those of the last run.
"""

from __future__ import annotations

import os
import pathlib
import platform
import re
import statistics
import time

README = pathlib.Path(__file__).resolve().parent.parent / "README.md"


def machine() -> str:
    """CPU model and core count, e.g. 'AMD EPYC ..., 2 cores'."""
    model = platform.processor() or platform.machine()
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{model}, {os.cpu_count()} cores"


def best_of(function, repeat):
    """(minimum, median) wall time [s] of ``repeat`` calls; the minimum is the least noisy figure."""
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return min(times), statistics.median(times)


def write_readme_section(name: str, markdown: str, readme: pathlib.Path = README):
    """Replace the README section between the bench markers of ``name`` (which must exist)."""
    text = readme.read_text()
    begin, end = f"<!-- bench:{name} -->", f"<!-- /bench:{name} -->"
    pattern = re.compile(re.escape(begin) + ".*?" + re.escape(end), re.S)
    if not pattern.search(text):
        raise SystemExit(f"README.md has no {begin} ... {end} section")
    readme.write_text(pattern.sub(lambda _: f"{begin}\n{markdown.strip()}\n{end}", text))
