"""Benchmark: per-frame rendering speed and the default animation's wall time, in one run.

- table-lookup render of a 1024 x 1024 fisheye (frames per second, HDR frame on the host);
- per-pixel ray march of a 512 x 512 fisheye at the default samples;
- the default `clsky animate` (120 frames, 512 x 512, both renderers, comparison, files), wall time.
Prints the table and writes it into README.md.

Usage: python bench/bench_render.py [--repeat N] [--no-readme] [--skip-animation]
"""

from __future__ import annotations

import argparse
import datetime
import subprocess
import sys
import tempfile
import time

from _report import best_of, machine, write_readme_section

import clsky
from anim.cameras import FisheyeCamera, sun_direction
from clsky._cl import describe_device
from clsky.render import RAYMARCH_DEFAULTS, SkyRenderer


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--no-readme", action="store_true")
    parser.add_argument("--skip-animation", action="store_true")
    args = parser.parse_args()

    table = clsky.ScatteringTable.build("physical", clsky.TableSettings(mode="physical"))
    renderer = SkyRenderer(table)
    sun = sun_direction(50.0, 160.0)
    rows = []
    for size, method, label in ((1024, renderer.render_table, "table lookup, fisheye 1024 x 1024"),
                                (512, renderer.render_raymarch,
                                 f"ray march ({RAYMARCH_DEFAULTS.view_steps} samples), fisheye 512 x 512")):
        directions, valid = FisheyeCamera(size).directions()
        prepared = renderer.prepare(directions, valid)
        method(prepared, sun, 0.0)                                     # warm-up
        best, median = best_of(lambda: method(prepared, sun, 0.0), args.repeat)
        rows.append(f"| {label} | {1000 * best:.0f} ms | {1000 * median:.0f} ms | {1 / best:.1f} |")
        print(rows[-1], flush=True)
    animation = "not measured (--skip-animation)"
    if not args.skip_animation:
        with tempfile.TemporaryDirectory() as directory:
            start = time.perf_counter()
            subprocess.run([sys.executable, "-m", "anim", "animate", "--progress", "none"], cwd=directory, check=True)
            animation = f"{time.perf_counter() - start:.0f} s"
        print("default animate:", animation, flush=True)
    lines = [f"Rendering, measured {datetime.date.today()} on {machine()}, OpenCL device "
             f"{describe_device(renderer.engine.device)}; best and median of {args.repeat} frames after a warm-up "
             f"(HDR float64 frame copied to the host).", "",
             "| render | best | median | frames/s (best) |", "|---|---:|---:|---:|", *rows, "",
             f"Default `clsky animate` (120 frames, 512 x 512 fisheye, table build, both renderers, comparison, "
             f"PNG + MP4 + metrics), wall time of the whole command: **{animation}**."]
    markdown = "\n".join(lines)
    print(markdown)
    if not args.no_readme:
        write_readme_section("render", markdown)


if __name__ == "__main__":
    main()
