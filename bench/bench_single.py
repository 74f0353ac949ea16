"""Benchmark: the default single-scattering table (32 x 256 x 32, float64) through OpenCL and through
its NumPy twin, side by side in one run. Prints the table and writes it into README.md.

Usage: python bench/bench_single.py [--repeat N] [--no-readme] [--smoke]

``--smoke``: an 8 x 32 x 8 table, one repetition, print only (bench/_report.py).
"""

from __future__ import annotations

import argparse
import datetime

import numpy as np

from _report import SMOKE, add_output_arguments, best_of, machine, parse_arguments, write_readme_section

from clsky import TableSettings, preset, reference
from clsky._cl import describe_device
from clsky.single import SingleScatteringEngine


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="OpenCL repetitions (NumPy runs once)")
    add_output_arguments(parser)
    args = parse_arguments(parser)
    size = SMOKE.table if args.smoke else TableSettings().size
    if args.smoke:
        args.repeat = SMOKE.repeat

    atmosphere = preset("atmosphere-plus")
    rows = []
    base = TableSettings(size=size)
    for label, settings in (("default (sun transmittance from the 2D table)", base),
                            ("sun rays re-marched (30 steps each)", base.replace(sun_transmittance="march")),
                            ("float32 kernels (NumPy twin in float64)", base.replace(dtype="float32"))):
        engine = SingleScatteringEngine(settings)
        engine.compute(atmosphere)                                  # warm-up: compile and first launch
        cl_best, _ = best_of(lambda: engine.compute(atmosphere), args.repeat)
        numpy_best, _ = best_of(lambda: reference.single_scattering(atmosphere, settings), 1)
        device = describe_device(engine.device)
        check = np.abs(engine.compute(atmosphere) - reference.single_scattering(atmosphere, settings)).max()
        rows.append((label, cl_best, numpy_best, numpy_best / cl_best, check))
        print(f"{label}: OpenCL {cl_best:.3f} s, NumPy {numpy_best:.2f} s, ratio {numpy_best / cl_best:.1f}x",
              flush=True)

    lines = [f"Single-scattering table {' x '.join(map(str, size))}, 30 + 30 Keller & Bohn trapezoid steps, measured "
             f"{datetime.date.today()} on {machine()}, OpenCL device {device}; OpenCL: best of "
             f"{args.repeat} after a warm-up, NumPy twin: one run, same process.", "",
             "| settings | OpenCL [s] | NumPy twin [s] | NumPy / OpenCL |", "|---|---:|---:|---:|"]
    lines += [f"| {label} | {cl:.3f} | {npy:.2f} | {ratio:.1f}x |" for label, cl, npy, ratio, _ in rows]
    markdown = "\n".join(lines)
    print(markdown)
    if not args.no_readme:
        write_readme_section("single", markdown)


if __name__ == "__main__":
    main()
