"""Benchmark: the CPU OpenCL runtimes at hand, side by side: PoCL and Intel's CPU runtime.

Intel's runtime is an opt-in: ``scripts/intel_opencl.sh`` installs it under ``.intel-opencl`` and writes
an OpenCL vendors directory listing it beside the drivers already registered. Every measurement runs in
a fresh process that sees that directory (``OCL_ICD_VENDORS``) and picks one runtime with
``PYOPENCL_CTX`` (``portable`` for PoCL, ``intel``); without the directory, PoCL alone is measured.
Per runtime:

- renders of the default physical table (32 x 256 x 32): the 3D table lookup and the sky-view map on a
  1024 x 1024 fisheye, the ray march (48 samples) on 512 x 512, as bench_render.py frames them: best wall
  time and mean process CPU time of ``--repeat`` frames after a warm-up;
- the default animation's planned table (bench_orders.py's second row: 32 x 256 x 208, M = 2), one build
  after a warm-up build at the smoke size (kernels compiled);
- the default ``clsky animate`` end to end: wall time, CPU time of the process and ffmpeg;
- whether the two runtimes' animations are the same: the 8-bit values of every PNG frame compared, and
  the largest relative difference of any number in the metrics CSV.
The runtimes alternate over ``--rounds`` rounds (A B, then B A, ...), so that a drift of the machine's
load shows as a difference between rounds. Prints the table and writes it into README.md (section
"Speed", ``bench:runtimes``).

Usage: python bench/bench_runtimes.py [--vendors DIR] [--rounds N] [--repeat N] [--no-readme] [--smoke]

``--smoke``: 8 x 32 x 8 tables, 16 x 16 frames, a 2-frame animation, one round; print only
(bench/_report.py).
"""

from __future__ import annotations

import argparse
import csv
import datetime
import json
import os
import pathlib
import resource
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

from _report import SMOKE, add_output_arguments, load_average, load_note, machine, parse_arguments, \
    write_readme_section

ROOT = pathlib.Path(__file__).resolve().parent.parent
#: where scripts/intel_opencl.sh writes its OpenCL vendors directory
DEFAULT_VENDORS = ROOT / ".intel-opencl" / "vendors"
#: runtime label: the PYOPENCL_CTX that picks it (a substring of its platform's name)
RUNTIMES = {"PoCL": "portable", "Intel": "intel"}


def worker(smoke: bool, repeat: int) -> dict:
    """The in-process measurements of one runtime (run with ``--worker`` in a fresh process)."""
    import clsky
    from bench_orders import build_cases
    from clsky._cl import describe_device, make_context
    from clsky.anim.cameras import FisheyeCamera, sun_direction
    from clsky.render import SkyRenderer

    result = {"device": describe_device(make_context().devices[0])}
    label, atmosphere, planned = build_cases(smoke)[1]
    clsky.ScatteringTable.build(atmosphere, planned.replace(size=SMOKE.table))       # warm-up: kernels compiled
    wall, cpu = time.perf_counter(), time.process_time()
    clsky.ScatteringTable.build(atmosphere, planned)
    result["table"] = {"wall": time.perf_counter() - wall, "cpu": time.process_time() - cpu}
    settings = clsky.TableSettings(mode="physical")
    if smoke:
        settings = settings.replace(size=SMOKE.table)
    renderer = SkyRenderer(clsky.ScatteringTable.build("physical", settings))
    sizes = (SMOKE.frame, SMOKE.frame) if smoke else (1024, 512)
    sun = sun_direction(50.0, 160.0)
    for name, size, method in (("lookup", sizes[0], renderer.render_table), ("skyview", sizes[0], renderer.render_skyview),
                               ("raymarch", sizes[1], renderer.render_raymarch)):
        prepared = renderer.prepare(*FisheyeCamera(size).directions())
        method(prepared, sun, 0.0)                                                 # warm-up
        walls, cpu = [], time.process_time()
        for _ in range(repeat):
            start = time.perf_counter()
            method(prepared, sun, 0.0)
            walls.append(time.perf_counter() - start)
        result[name] = {"wall": min(walls), "cpu": (time.process_time() - cpu) / repeat}
    return result


def children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def environment(selector: str, vendors: pathlib.Path | None) -> dict:
    env = dict(os.environ, PYOPENCL_CTX=selector)
    if vendors is not None:
        env["OCL_ICD_VENDORS"] = str(vendors)
    return env


def measure(selector, vendors, smoke, repeat, animate_arguments, directory: pathlib.Path) -> dict:
    """The worker's measurements and the end-to-end animation (written in ``directory``) of one runtime."""
    env = environment(selector, vendors)
    command = [sys.executable, __file__, "--worker", "--repeat", str(repeat)] + (["--smoke"] if smoke else [])
    output = subprocess.run(command, env=env, check=True, capture_output=True, text=True)
    result = json.loads(output.stdout.strip().splitlines()[-1])
    directory.mkdir(parents=True)
    load_before, cpu, wall = load_average(), children_cpu(), time.perf_counter()
    subprocess.run([sys.executable, "-m", "clsky.anim", "animate", "--progress", "none", *animate_arguments],
                   cwd=directory, env=env, check=True, stdout=subprocess.DEVNULL)
    result["animate"] = {"wall": time.perf_counter() - wall, "cpu": children_cpu() - cpu}
    result["load"] = max(load_before, load_average())
    return result


def same_outputs(first: pathlib.Path, second: pathlib.Path) -> tuple[int, int, float, str]:
    """(8-bit values that differ, values compared, largest difference of a metrics number, its column) of
    two animations' outputs (sky_frames/*.png, sky_metrics.csv). A metric's difference is relative to the
    largest magnitude of its column over both runs: some columns hold zeros and values of 1e-16 (the
    temporal excess jumps), where a difference relative to the value itself would say nothing."""
    from PIL import Image

    frames = sorted((first / "sky_frames").glob("*.png"))
    if [p.name for p in frames] != sorted(p.name for p in (second / "sky_frames").glob("*.png")):
        raise SystemExit(f"the two runs wrote different frame files: {first} and {second}")
    differing = compared = 0
    for path in frames:
        a = np.asarray(Image.open(path))
        b = np.asarray(Image.open(second / "sky_frames" / path.name))
        differing += int((a != b).sum())
        compared += a.size
    rows = []
    for directory in (first, second):
        with open(directory / "sky_metrics.csv", newline="") as file:
            rows.append(list(csv.DictReader(file)))
    largest, where = 0.0, ""
    for key in rows[0][0]:
        try:
            values = np.array([[float(row[key]) for row in run] for run in rows])
        except ValueError:
            continue                                    # text: the lookup's name, the time
        scale = np.abs(values).max()
        difference = float(np.abs(values[0] - values[1]).max() / scale) if scale > 0 else 0.0
        if difference > largest:
            largest, where = difference, key
    return differing, compared, largest, where


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vendors", type=pathlib.Path, default=None,
                        help=f"OpenCL vendors directory listing the runtimes (default {DEFAULT_VENDORS.relative_to(ROOT)}, "
                             f"written by scripts/intel_opencl.sh)")
    parser.add_argument("--rounds", type=int, default=2, help="rounds of the runtimes in alternating order (default 2)")
    parser.add_argument("--repeat", type=int, default=5, help="timed frames per render (default 5)")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    add_output_arguments(parser)
    args = parse_arguments(parser)
    if args.smoke:
        args.rounds, args.repeat = 1, SMOKE.repeat
    if args.worker:
        print(json.dumps(worker(args.smoke, args.repeat)))
        return
    vendors = args.vendors or (DEFAULT_VENDORS if DEFAULT_VENDORS.is_dir() else None)
    if vendors is not None and not vendors.is_dir():
        parser.error(f"--vendors {vendors}: no such directory")
    runtimes = dict(RUNTIMES) if vendors is not None else {"PoCL": RUNTIMES["PoCL"]}
    animate_arguments = []
    if args.smoke:
        animate_arguments = ["--frames", str(SMOKE.animation_frames), "--size", str(SMOKE.frame),
                             "--table-size", *map(str, SMOKE.table)]
    results, highest = [], load_average()
    with tempfile.TemporaryDirectory() as scratch:
        scratch = pathlib.Path(scratch)
        for round_index in range(args.rounds):
            order = list(runtimes) if round_index % 2 == 0 else list(reversed(runtimes))
            for name in order:
                directory = scratch / f"{name}-{round_index}"
                result = measure(runtimes[name], vendors, args.smoke, args.repeat, animate_arguments, directory)
                results.append((round_index + 1, name, result))
                highest = max(highest, result["load"])
                print(f"round {round_index + 1}, {name} ({result['device']}): ray march {result['raymarch']['cpu'] * 1e3:.0f} "
                      f"CPU-ms, table {result['table']['wall']:.1f} s, animate {result['animate']['wall']:.1f} s wall",
                      flush=True)
                if round_index > 0:
                    shutil.rmtree(directory)            # the first round's outputs are compared below
        comparison = same_outputs(scratch / "PoCL-0", scratch / "Intel-0") if len(runtimes) == 2 else None

    shown = "clsky animate " + " ".join(animate_arguments) if animate_arguments else "clsky animate"
    devices = "; ".join(sorted({f"{name}: {result['device']}" for _, name, result in results}))
    lines = [f"Measured {datetime.date.today()} on {machine()} ({devices}), {args.rounds} round(s), the runtimes "
             f"alternating. Renders of the default physical table: best wall time and mean process CPU time of "
             f"{args.repeat} frames after a warm-up [ms] (3D lookup and sky-view map on a 1024 x 1024 fisheye, ray "
             f"march on 512 x 512); the default animation's planned table, one build after a warm-up [s]; "
             f"`{shown}` end to end in a fresh process [s] (CPU: the process and ffmpeg); load: the highest "
             f"1-minute load average seen.{load_note(highest)}", "",
             "| round | runtime | 3D lookup: wall | CPU | sky-view: wall | CPU | ray march: wall | CPU | "
             "planned table: wall | CPU | animate: wall | CPU | load |",
             "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for round_number, name, r in results:
        lines.append(f"| {round_number} | {name} | {r['lookup']['wall'] * 1e3:.0f} | {r['lookup']['cpu'] * 1e3:.0f} | "
                     f"{r['skyview']['wall'] * 1e3:.0f} | {r['skyview']['cpu'] * 1e3:.0f} | "
                     f"{r['raymarch']['wall'] * 1e3:.0f} | {r['raymarch']['cpu'] * 1e3:.0f} | "
                     f"{r['table']['wall']:.1f} | {r['table']['cpu']:.1f} | {r['animate']['wall']:.1f} | "
                     f"{r['animate']['cpu']:.1f} | {r['load']:.1f} |")
    if comparison is None:
        lines += ["", f"Intel's runtime is not installed here (no {DEFAULT_VENDORS.relative_to(ROOT)}: "
                      f"scripts/intel_opencl.sh): PoCL alone was measured."]
    else:
        lines += ["", "PoCL / Intel, per round (CPU time; wall time in brackets):", ""]
        for round_number in range(1, args.rounds + 1):
            pocl, intel = (next(r for n, name, r in results if n == round_number and name == runtime)
                           for runtime in ("PoCL", "Intel"))
            ratios = ", ".join(f"{label} {pocl[key]['cpu'] / intel[key]['cpu']:.2f}x "
                               f"({pocl[key]['wall'] / intel[key]['wall']:.2f}x)"
                               for key, label in (("lookup", "3D lookup"), ("skyview", "sky-view"),
                                                  ("raymarch", "ray march"), ("table", "planned table"),
                                                  ("animate", "animate")))
            lines.append(f"- round {round_number}: {ratios}")
        differing, compared, largest, where = comparison
        lines += ["", f"The two runtimes' animations (round 1): {differing} of {compared} 8-bit values of the PNG "
                      f"frames differ; the metrics' numbers by at most {largest:.1e} of their column's largest "
                      f"value ({where or 'none differs'})."]
    markdown = "\n".join(lines)
    print(markdown)
    if not args.no_readme:
        write_readme_section("runtimes", markdown)


if __name__ == "__main__":
    main()
