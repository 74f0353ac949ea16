"""Benchmark: speed versus accuracy of every numerical knob (anim/accuracy.py), in one run.

Builds the reference (the 'reference' quality level, anim/accuracy.py); then times each candidate (table build, frame render) and
measures its error on four fisheye frames (day, golden hour, sunset, civil twilight). Writes
docs/accuracy.csv, the Pareto plot docs/accuracy.png, and the table into README.md.

Usage: python bench/bench_accuracy.py [--size 128] [--reference-cache FILE] [--no-readme]

``--reference-cache``: the reference frames saved by bench/bench_quality.py (same size), instead of
rendering them again (minutes). How far the reference converged: bench/bench_quality.py.
"""

from __future__ import annotations

import argparse
import datetime
import pathlib

import numpy as np

from _report import machine, write_readme_section

from anim import accuracy, writers
from clsky._cl import default_device, describe_device

DOCS = pathlib.Path(__file__).resolve().parent.parent / "docs"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--reference-cache", type=pathlib.Path)
    parser.add_argument("--no-readme", action="store_true")
    args = parser.parse_args()

    if args.reference_cache:
        cached = np.load(args.reference_cache)
        reference, valid = {name: cached[name] for name in accuracy.SUN_ELEVATIONS}, cached["valid"]
        if valid.shape != (args.size, args.size):
            raise SystemExit(f"{args.reference_cache} holds {valid.shape} frames, not {args.size} x {args.size}")
    else:
        reference, valid = accuracy.render_reference(args.size)
    rows = accuracy.measure(accuracy.default_candidates(), reference, valid)
    writers.write_csv(DOCS / "accuracy.csv", rows, force=True)
    accuracy.pareto_plot(rows, DOCS / "accuracy.png", force=True, size=args.size)
    front = {r["candidate"] for r in accuracy.pareto_front(rows)}
    names = list(accuracy.SUN_ELEVATIONS)
    lines = [f"Measured {datetime.date.today()} on {machine()}, {describe_device(default_device())}: "
             f"{args.size} x {args.size} fisheye frames from the ground, sun at elevations "
             + ", ".join(f"{e:g} deg ({n})" for n, e in accuracy.SUN_ELEVATIONS.items())
             + ". Error: 95th percentile of the relative HDR luminance error against the reference "
             "(the 'reference' quality level, `anim/accuracy.py`; how far it converged: \"Quality levels\" "
             "below). Build: table "
             "(single + orders); render: one frame. * = on the Pareto front (render time vs worst error). "
             "Raw numbers: `docs/accuracy.csv`.", "",
             "| candidate | knob | build [s] | render [ms] | " + " | ".join(f"p95 {n} [%]" for n in names)
             + " | worst mean Delta E |",
             "|---|---|---:|---:|" + "---:|" * len(names) + "---:|"]
    for r in rows:
        mark = " *" if r["candidate"] in front else ""
        lines.append(f"| {r['candidate']}{mark} | {r['knob']} | {r['build_s']:.2f} | {1e3 * r['render_s']:.1f} | "
                     + " | ".join(f"{100 * r[f'p95_rel {n}']:.2f}" for n in names)
                     + f" | {r['mean_delta_e']:.2f} |")
    markdown = "\n".join(lines)
    print(markdown)
    if not args.no_readme:
        write_readme_section("accuracy", markdown)


if __name__ == "__main__":
    main()
