"""Benchmark: speed versus accuracy of every numerical knob (anim/accuracy.py), in one run.

Builds the reference (the 'reference' quality level, anim/accuracy.py); then times each candidate (table build, frame render) and
measures its error on four fisheye frames (day, golden hour, sunset, civil twilight). Writes
docs/accuracy.csv, the Pareto plot docs/accuracy.png, the error against sun elevation
docs/accuracy_elevation.png (anim/accuracy_plot.py), and the table into README.md.

Usage: python bench/bench_accuracy.py [--size 128] [--reference-cache FILE] [--no-readme] [--docs DIR]
[--smoke] [--replot CSV]

``--reference-cache``: the reference frames saved by bench/bench_quality.py (same size), instead of
rendering them again (minutes). How far the reference converged: bench/bench_quality.py.

``--docs DIR``: where accuracy.csv and the two plots go. Default: docs/ when the run writes the README
(they belong together); with ``--no-readme``, nowhere (print only), so that a trial run never
overwrites the published data unless asked.

``--smoke``: 16 x 16 frames, the 'draft' quality level as the reference, four candidates (the default
table, a halved view axis, a 16-sample ray march, a 16 x 32 sky-view map) over an 8 x 32 x 8 table; the
CSV and the plots go to a temporary directory (or ``--docs DIR``); print only (bench/_report.py).

``--replot CSV``: measure nothing; draw the two plots again from a sweep's CSV into ``--docs DIR``
(default docs/; a temporary directory with --smoke), replacing them; ``--size`` must be that sweep's
(the CSV does not record it). The published plots came from a 64-pixel sweep:
``python bench/bench_accuracy.py --replot docs/accuracy.csv --size 64``.
"""

from __future__ import annotations

import argparse
import datetime
import pathlib
import tempfile


from _report import description_of
from _report import SMOKE, add_output_arguments, load_average, load_note, machine, parse_arguments, write_readme_section
from _report import integer_in, load_reference_cache, npz_file

import clsky
from clsky.anim import accuracy, accuracy_plot
from clsky._cl import default_device, describe_device

DOCS = pathlib.Path(__file__).resolve().parent.parent / "docs"
#: The candidates of a --smoke run (over an SMOKE.table base): one table, one table knob, one ray march,
#: one sky-view map.
SMOKE_CANDIDATES = ("default", "H / 2", "ray march 16 samples", "sky-view 16 x 32")


def main():
    parser = argparse.ArgumentParser(description=description_of(__doc__))
    parser.add_argument("--size", type=integer_in(16, 2048), default=128)
    parser.add_argument("--reference-cache", type=npz_file, metavar="FILE.npz")
    parser.add_argument("--docs", type=pathlib.Path, metavar="DIR",
                        help="write accuracy.csv and the two plots into DIR (default: docs/ when writing the "
                             "README; none with --no-readme; a temporary directory with --smoke)")
    parser.add_argument("--replot", type=pathlib.Path, metavar="CSV",
                        help="only draw the plots again from CSV, a sweep's accuracy.csv, into --docs DIR "
                             "(default docs/); --size: that sweep's frame size")
    add_output_arguments(parser)
    args = parse_arguments(parser, sections=("accuracy",))
    try:                       # the plots need matplotlib: refused before the sweep, as `clsky bench accuracy` does
        accuracy_plot.require_plotting()
    except ImportError as error:
        parser.error(str(error))
    candidates, level = accuracy.default_candidates(), "reference"
    if args.smoke:
        args.size, level = SMOKE.frame, SMOKE.reference_level
        base = clsky.TableSettings(mode="physical", size=SMOKE.table)
        candidates = [c for c in accuracy.default_candidates(base) if c.label in SMOKE_CANDIDATES]
    with tempfile.TemporaryDirectory() as temporary:
        if args.replot is not None:
            try:               # the CSV's own errors name it, its line and column: one line, not a traceback
                replot(args.replot, args.docs or (pathlib.Path(temporary) if args.smoke else DOCS), args.size)
            except OSError as error:
                raise SystemExit(f"--replot: {args.replot}: cannot read it ({error.strerror or error})") from None
            except ValueError as error:
                raise SystemExit(f"--replot: {error}") from None
            return
        if args.docs is None and args.smoke:
            args.docs = pathlib.Path(temporary)
        elif args.docs is None and not args.no_readme:
            args.docs = DOCS
        run(args, candidates, level)


def replot(csv_path, docs, size):
    """Draw the two plots of a sweep's CSV into ``docs`` (created if needed), replacing them."""
    docs.mkdir(parents=True, exist_ok=True)
    written = accuracy_plot.plot_csv(csv_path, docs / "accuracy.png", docs / "accuracy_elevation.png", size=size,
                                     force=True)
    print("wrote " + ", ".join(map(str, written)), flush=True)


def run(args, candidates, level):

    if args.reference_cache:
        cached = load_reference_cache(args.reference_cache, level, args.size, accuracy.SUN_ELEVATIONS)
        reference, valid = {name: cached[name] for name in accuracy.SUN_ELEVATIONS}, cached["valid"]
    else:
        reference, valid = accuracy.render_reference(args.size, level=level)
    load_start = load_average()
    rows = accuracy.measure(candidates, reference, valid)
    load_end = load_average()
    if args.docs is not None:
        # the CSV and its plots land together (a failed plot left a new CSV beside the old plots)
        args.docs.mkdir(parents=True, exist_ok=True)
        written = accuracy_plot.write_sweep(rows, *(args.docs / name for name in ("accuracy.csv", "accuracy.png",
                                                                               "accuracy_elevation.png")),
                                            args.size, level, force=True)
        print("wrote " + ", ".join(map(str, written)), flush=True)
    front = {r["candidate"] for r in accuracy.pareto_front(rows)}
    names = list(accuracy.SUN_ELEVATIONS)
    lines = [f"Measured {datetime.date.today()} on {machine()}, {describe_device(default_device())} (load average "
             f"{load_start:.2f} before the candidates, {load_end:.2f} after): "
             f"{args.size} x {args.size} fisheye frames from the ground, sun at elevations "
             + ", ".join(f"{e:g} deg ({n})" for n, e in accuracy.SUN_ELEVATIONS.items())
             + ". Error: 95th percentile of the relative HDR luminance error against the reference "
             f"(the '{level}' quality level, `anim/accuracy.py`; how far it converged: \"Quality levels\" "
             "below). Build: table "
             "(single + orders); render: one frame; each in wall and process CPU time (every thread, PoCL's "
             "workers included). * = on the Pareto front (render time vs worst error). "
             "Raw numbers: `docs/accuracy.csv`." + load_note(max(load_start, load_end)), "",
             "| candidate | knob | build [s] | CPU [s] | render [ms] | CPU [ms] | "
             + " | ".join(f"p95 {n} [%]" for n in names) + " | worst mean Delta E |",
             "|---|---|---:|---:|---:|---:|" + "---:|" * len(names) + "---:|"]
    for r in rows:
        mark = " *" if r["candidate"] in front else ""
        lines.append(f"| {r['candidate']}{mark} | {r['knob']} | {r['build_s']:.2f} | {r['build_cpu_s']:.2f} | "
                     f"{1e3 * r['render_s']:.1f} | {1e3 * r['render_cpu_s']:.1f} | "
                     + " | ".join(f"{100 * r[f'p95_rel {n}']:.2f}" for n in names)
                     + f" | {r['mean_delta_e']:.2f} |")
    markdown = "\n".join(lines)
    print(markdown)
    if not args.no_readme:
        write_readme_section("accuracy", markdown)


if __name__ == "__main__":
    main()
