"""Shared by the benchmarks: machine description, timing, and writing a table into README.md.

A benchmark writes its Markdown table between ``<!-- bench:NAME -->`` and ``<!-- /bench:NAME -->`` in
the README, so the figures there are always those of the last run.

Every benchmark also takes ``--smoke`` (:func:`add_output_arguments`, :data:`SMOKE`): the same code
path at a tiny size, to prove that the script runs (tests/test_bench_smoke.py). A smoke run prints its
table and writes nothing into README.md or docs/: it implies ``--no-readme``, and any file it would
write goes to a temporary directory instead.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import pathlib
import platform
import re
import statistics
import time

README = pathlib.Path(__file__).resolve().parent.parent / "README.md"


@dataclasses.dataclass(frozen=True)
class SmokeSizes:
    """The sizes of a ``--smoke`` run: small enough that each benchmark runs in seconds to a minute on
    two cores, large enough that every code path (tables, orders, renders, plots) still runs."""

    #: table (W, H, D): altitude x view x sun nodes
    table: tuple = (8, 32, 8)
    #: Monte Carlo paths per channel and case
    photons: int = 300
    #: side of a rendered frame [px]
    frame: int = 16
    #: timing repetitions
    repeat: int = 1
    #: quality level standing in for the accuracy reference (anim/accuracy.py); 'draft' is the cheapest
    reference_level: str = "draft"
    #: frames of the animation run by bench_render.py
    animation_frames: int = 2


#: The one set of smoke sizes every benchmark uses.
SMOKE = SmokeSizes()


def add_output_arguments(parser: argparse.ArgumentParser):
    """Add the options every benchmark shares: ``--no-readme`` and ``--smoke``."""
    parser.add_argument("--no-readme", action="store_true", help="print only: leave README.md as it is")
    parser.add_argument("--smoke", action="store_true",
                        help="the same code path at a tiny size (bench/_report.py: SMOKE), to check that the "
                             "script runs; prints its table, writes nothing into README.md or docs/ "
                             "(implies --no-readme)")
    return parser


def parse_arguments(parser: argparse.ArgumentParser, argv=None):
    """``parser.parse_args(argv)``, with ``--smoke`` implying ``--no-readme``."""
    args = parser.parse_args(argv)
    if args.smoke:
        args.no_readme = True
    return args


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
