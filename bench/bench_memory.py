"""Benchmark: peak memory (maximum resident set size) of the default animation and of the table of each
quality level, measured against :mod:`clsky.resources`' estimate. Prints the table and writes it into
README.md (section ``memory``).

Each case runs the command line in a fresh process, one at a time, after a warm-up run that fills
PyOpenCL's program cache (a first compile adds up to ~150 MiB of LLVM memory); the peak is that
process' ``ru_maxrss``, read by a wrapper process of its own.

Usage: python bench/bench_memory.py [--reference] [--no-readme] [--only NAME ...] [--smoke]
                                    [--ground-albedo A] [--ozone-column DU]

``--ground-albedo`` / ``--ozone-column`` (clsky.cli.add_atmosphere_overrides) reach every measured
command and its estimate, as they reach ``clsky table`` and ``clsky animate``.

``--smoke``: one table and one animation at bench/_report.py's SMOKE sizes, outputs in a temporary
directory, the table printed only.
"""

from __future__ import annotations

import argparse
import datetime
import os
import subprocess
import sys
import tempfile
import time

from _report import description_of
from _report import SMOKE, add_output_arguments, machine, parse_arguments, write_readme_section

from clsky.atmosphere import OVERRIDE_RANGES
from clsky.cli import add_atmosphere_overrides
from clsky.resources import BASE_PROCESS_BYTES, device_of, estimate_table_memory, format_bytes

#: Runs the command in argv[1:] and prints its peak RSS [KiB] (ru_maxrss of the only child).
_WRAPPER = ("import resource, subprocess, sys; code = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL, "
            "stderr=subprocess.DEVNULL).returncode; "
            "print(code, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)")

#: The tables' command line: the default animation's sun path on the physical preset.
TABLE_ARGS = ["table", "--preset", "physical", "--mode", "physical", "--sun-elevations", "-6", "60"]
#: What every measured command line gets beyond the row's (which a reader types without them).
QUIET = ["--progress", "none", "--force"]


def typed(arguments, words=""):
    """A row's description: its command line as a reader types it, then ``words``."""
    return f"`clsky {' '.join(arguments)}`" + (f" ({words})" if words else "")


def smoke_cases():
    """The cases of a ``--smoke`` run: one small table, one small animation (bench/_report.py)."""
    size = [str(n) for n in SMOKE.table]
    table = TABLE_ARGS + ["--quality", "draft", "--size", *size]
    frames = ["animate", "--frames", "2", "--size", str(SMOKE.frame), "--quality", "draft", "--table-size", *size]
    return [("table smoke", typed(table), table), ("frames smoke", typed(frames), frames)]


def cases(reference=False):
    """(name, description, clsky arguments without the output and :data:`QUIET`) of each measurement."""
    levels = ["draft", "default", "high"] + (["reference"] if reference else [])
    rows = [("animation", typed(["animate"], "defaults: 120 frames 512 x 512, compare, default quality"),
             ["animate"])]
    rows += [(f"table {level}", typed(TABLE_ARGS + ["--quality", level]), TABLE_ARGS + ["--quality", level])
             for level in levels]
    for size in (256, 1024):
        frames = ["animate", "--frames", "2", "--size", str(size), "--quality", "draft", "--table-size", "16", "64",
                  "16"]
        rows.append((f"frames {size}", typed(frames), frames))
    return rows


def with_overrides(arguments, args):
    """``arguments`` followed by the --ground-albedo / --ozone-column options given to the benchmark."""
    options = {"ground_albedo": "--ground-albedo", "ozone_column_du": "--ozone-column"}
    assert set(options) == set(OVERRIDE_RANGES)
    extra = [item for field, option in options.items() if getattr(args, field, None) is not None
             for item in (option, repr(float(getattr(args, field))))]
    return list(arguments) + extra


def peak_rss(arguments, output):
    """(exit status, peak RSS [bytes], seconds) of ``clsky ARGUMENTS -o OUTPUT`` in a fresh process."""
    command = [sys.executable, "-c", _WRAPPER, sys.executable, "-m", "clsky.anim", *arguments, "-o", output]
    start = time.perf_counter()
    result = subprocess.run(command, capture_output=True, text=True, check=True)
    seconds = time.perf_counter() - start
    code, kib = result.stdout.split()
    return int(code), int(kib) * 1024, seconds


def estimate(arguments):
    """The estimated peak [bytes] of a case (arrays + :data:`BASE_PROCESS_BYTES`), and its table size: for an
    animation the estimate `clsky animate` checks on this machine's device (its suns a ray-march launch,
    packed reads)."""
    from clsky.anim import cli as anim_cli
    from clsky.anim.animate import memory_estimate, sun_positions
    from clsky import cli

    parser, _ = cli.build_parser(extensions=(anim_cli.register,))
    args = parser.parse_args(arguments + ["-o", "x.mp4" if arguments[0] == "animate" else "x.npz"])
    if arguments[0] == "table":
        settings = cli.table_settings(args, cli.table_atmosphere(args))
        result = estimate_table_memory(settings, saving=True)
        size = settings.size
    else:
        config = anim_cli._config(args)          # every field from the parsed options, as `clsky animate` does
        result = memory_estimate(config, sun_positions(config), device=device_of())
        size = result.what.rsplit("table ", 1)[1].rstrip(")")
    return result.peak_bytes() + BASE_PROCESS_BYTES, size


def main():
    parser = argparse.ArgumentParser(description=description_of(__doc__))
    parser.add_argument("--reference", action="store_true", help="also the reference level (~6 min)")
    parser.add_argument("--only", nargs="+", help="run only these cases (names as printed)")
    parser.add_argument("--directory", default="/tmp/clsky_bench_memory", help="where outputs go")
    add_atmosphere_overrides(parser.add_argument_group("atmosphere (every case)"))
    add_output_arguments(parser)
    args = parse_arguments(parser, sections=("memory",))
    if args.smoke:                               # a temporary directory, removed afterwards
        with tempfile.TemporaryDirectory(prefix="clsky_bench_memory_") as directory:
            measure(args, directory)
    else:
        os.makedirs(args.directory, exist_ok=True)
        measure(args, args.directory)


def measure(args, directory):
    """Run the selected cases with their outputs in ``directory``; print (and write) the table."""
    selected = [(name, description, with_overrides(arguments, args) + QUIET)
                for name, description, arguments in (smoke_cases() if args.smoke else cases(args.reference))
                if not args.only or name in args.only]
    overridden = with_overrides([], args)
    peak_rss(with_overrides(["table", "--size", "8", "16", "8"], args) + QUIET,
             os.path.join(directory, "warm.npz"))
    lines = [f"Peak resident memory (`ru_maxrss` of the whole process) measured {datetime.date.today()} on "
             f"{machine()}, load average {os.getloadavg()[0]:.1f} at the start (a machine shared with other "
             f"work: the times are not benchmarks), PyOpenCL's program cache warm. Estimate: "
             f"`clsky.resources` (the arrays' peak, host and OpenCL buffers, one memory on a CPU device) + "
             f"{format_bytes(BASE_PROCESS_BYTES)} for the process itself."
             + (f" Every run with `{' '.join(overridden)}`." if overridden else ""), "",
             "| run | table (W x H x D) | measured peak | estimate | estimate / measured | wall time [s] |",
             "|---|---|---:|---:|---:|---:|"]
    for name, description, arguments in selected:
        suffix = ".mp4" if arguments[0] == "animate" else ".npz"
        code, measured, seconds = peak_rss(arguments, os.path.join(directory, name.replace(" ", "_") + suffix))
        if code != 0:
            raise SystemExit(f"{name}: exit status {code}")
        estimated, size = estimate(arguments)
        size_text = " x ".join(str(n) for n in size) if isinstance(size, tuple) else size
        lines.append(f"| {description} | {size_text} | {format_bytes(measured)} | {format_bytes(estimated)} | "
                     f"{estimated / measured:.2f} | {seconds:.0f} |")
        print(lines[-1], flush=True)
    print("\n".join(lines))
    if not args.no_readme:
        write_readme_section("memory", "\n".join(lines))


if __name__ == "__main__":
    main()
