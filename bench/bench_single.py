"""Benchmark: the default single-scattering table (32 x 256 x 32, float64) through OpenCL and through
its NumPy twin, side by side in one run. Prints the table and writes it into README.md.

Each side is timed in wall time and process CPU time (every thread, PoCL's workers included), and the
ratio is given for both (issue 12: on a shared machine the wall-time ratio swings with the load, the
CPU-time ratio much less); the load average is recorded after each row.

Usage: python bench/bench_single.py [--repeat N] [--twin-repeat N] [--no-readme] [--smoke]

The kernel takes about 0.1 s, so a few runs swing with the shared machine: with the least of 3, four
runs in a row (2026-12-03, load average 0.9) gave the CPU-time ratio of the default row 12.7-18.9x;
the least of 10 kernel runs and of 2 twin runs is the default.

``--smoke``: an 8 x 32 x 8 table, one repetition, print only (bench/_report.py).
"""

from __future__ import annotations

import argparse
import datetime

from _report import description_of
from _report import (SMOKE, add_output_arguments, best_timing, load_average, load_note, machine,
                     parse_arguments, write_readme_section)
from _report import positive_integer

from clsky import TableSettings, preset, reference
from clsky._cl import describe_device
from clsky.single import SingleScatteringEngine


def main():
    parser = argparse.ArgumentParser(description=description_of(__doc__))
    parser.add_argument("--repeat", type=positive_integer, default=10,
                        help="OpenCL repetitions after a warm-up (default 10)")
    parser.add_argument("--twin-repeat", type=positive_integer, default=2, help="NumPy twin repetitions (default 2)")
    add_output_arguments(parser)
    args = parse_arguments(parser, sections=("single",))
    size = SMOKE.table if args.smoke else TableSettings().size
    if args.smoke:
        args.repeat = args.twin_repeat = SMOKE.repeat

    atmosphere = preset("atmosphere-plus")
    rows = []
    base = TableSettings(size=size)
    load_start = load_average()
    for label, settings in (("default (sun transmittance from the 2D table)", base),
                            ("sun rays re-marched (30 steps each)", base.replace(sun_transmittance="march")),
                            ("float32 kernels (NumPy twin in float64)", base.replace(dtype="float32"))):
        engine = SingleScatteringEngine(settings)
        engine.compute(atmosphere)                                  # warm-up: compile and first launch
        _, cl_wall, cl_cpu, _ = best_timing(lambda: engine.compute(atmosphere), args.repeat)
        _, numpy_wall, numpy_cpu, _ = best_timing(lambda: reference.single_scattering(atmosphere, settings),
                                                  args.twin_repeat)
        device = describe_device(engine.device)
        rows.append((label, cl_wall, cl_cpu, numpy_wall, numpy_cpu, load_average()))
        print(f"{label}: OpenCL {cl_wall:.3f} s ({cl_cpu:.3f} CPU-s), NumPy {numpy_wall:.2f} s ({numpy_cpu:.2f} "
              f"CPU-s), ratio {numpy_wall / cl_wall:.1f}x wall, {numpy_cpu / cl_cpu:.1f}x CPU", flush=True)

    highest = max(row[-1] for row in rows)
    lines = [f"Single-scattering table {' x '.join(map(str, size))}, 30 + 30 Keller & Bohn trapezoid steps, measured "
             f"{datetime.date.today()} on {machine()}, OpenCL device {device} (load average {load_start:.2f} at the "
             f"start); OpenCL: the least wall and the least process CPU time of {args.repeat} runs after a warm-up; "
             f"NumPy twin: the same of {args.twin_repeat}, same process. Process CPU time counts every thread (PoCL's workers); load: the "
             f"1-minute load average after the row.{load_note(highest)}", "",
             "| settings | OpenCL wall [s] | CPU [s] | NumPy twin wall [s] | CPU [s] | NumPy / OpenCL: wall | CPU "
             "| load |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
    lines += [f"| {label} | {cl_wall:.3f} | {cl_cpu:.3f} | {npy_wall:.2f} | {npy_cpu:.2f} | {npy_wall / cl_wall:.1f}x "
              f"| {npy_cpu / cl_cpu:.1f}x | {load:.2f} |"
              for label, cl_wall, cl_cpu, npy_wall, npy_cpu, load in rows]
    markdown = "\n".join(lines)
    print(markdown)
    if not args.no_readme:
        write_readme_section("single", markdown)


if __name__ == "__main__":
    main()
