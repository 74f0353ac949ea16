"""Benchmark: every OpenCL device at hand with fp64, side by side: PoCL, Intel's CPU runtime, a GPU.

The devices are those the OpenCL loader lists with double precision: through ``--vendors`` (an OpenCL
vendors directory; by default ``.intel-opencl/vendors`` when ``scripts/intel_opencl.sh`` has written it,
which lists Intel's CPU runtime beside the drivers already registered), else through the system's
registry. Every measurement runs in a fresh process that picks one device with
``PYOPENCL_CTX=<platform>:<device>``, and, with ``--vector-widths 8 1``, also the kernels' scalar form
(``clsky._cl.VECTOR_WIDTH``, clsky's default on GPUs; tests/test_vector_width.py). The width is always
explicit here: 8 unless ``--vector-widths`` says otherwise, also on a GPU. Per device and width:

- renders of the default physical table (32 x 256 x 32): the 3D table lookup and the sky-view map on a
  1024 x 1024 fisheye, the ray march (48 samples) on 512 x 512, as bench_render.py frames them: best wall
  time and mean process CPU time of ``--repeat`` frames after a warm-up;
- the default animation's planned table (bench_orders.py's second row: 32 x 256 x 208, M = 2), one build
  after a warm-up build at the smoke size (kernels compiled);
- the default ``clsky animate`` end to end: wall time, CPU time of the process and ffmpeg;
- whether the animations are the same as the first configuration's (PoCL's, when it is there): the 8-bit
  values of every PNG frame compared, and the largest difference of any number in the metrics CSV.
The configurations alternate over ``--rounds`` rounds (in order, then reversed, ...), so that a drift of
the machine's load shows as a difference between rounds. Prints the table and writes it into README.md
(section "Speed", ``bench:runtimes``).

Usage: python bench/bench_runtimes.py [--vendors DIR] [--vector-widths W ...] [--rounds N] [--repeat N]
[--keep-outputs DIR] [--no-readme] [--smoke]

``--keep-outputs DIR``: keep each configuration's first-round animation (``DIR/<configuration>/``, numbered
as the table's rows of round 1), to compare with another machine's (a GPU session brings back its own).

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
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

from _report import description_of
from _report import SMOKE, add_output_arguments, best_of, children_cpu, load_average, load_note, machine, \
    parse_arguments, write_readme_section
from _report import positive_integer

from clsky._cl import VECTOR_WIDTHS
from clsky._files import temporary_prefix

ROOT = pathlib.Path(__file__).resolve().parent.parent
#: where scripts/intel_opencl.sh writes its OpenCL vendors directory
DEFAULT_VENDORS = ROOT / ".intel-opencl" / "vendors"

#: Run by a fresh interpreter: the devices with fp64 the loader lists, as JSON.
LIST_DEVICES = """
import json, pyopencl as cl
from clsky._cl import describe_device, has_fp64
print(json.dumps([{"selector": f"{p}:{d}", "name": describe_device(device), "platform": platform.name}
                  for p, platform in enumerate(cl.get_platforms())
                  for d, device in enumerate(platform.get_devices()) if has_fp64(device)]))
"""

#: Run by a fresh interpreter: ``clsky animate`` with the kernels' vector width given first.
ANIMATE = """
import sys
import clsky._cl, clsky.anim.cli
clsky._cl.VECTOR_WIDTH = int(sys.argv[1])
sys.argv = ["clsky", *sys.argv[2:]]
sys.exit(clsky.anim.cli.main())
"""


def short_name(device: dict) -> str:
    """'PoCL', 'Intel' (its CPU runtime), or the device's own name for anything else (a GPU)."""
    if "PoCL" in device["name"]:
        return "PoCL"
    if device["platform"].startswith("Intel(R) OpenCL") and "Graphics" not in device["platform"]:
        return "Intel"
    return device["name"]


def worker(smoke: bool, repeat: int, vector_width: int) -> dict:
    """The in-process measurements of one device and width (run with ``--worker`` in a fresh process)."""
    import clsky
    import clsky._cl
    from bench_orders import build_cases
    from clsky.anim.cameras import FisheyeCamera, sun_direction
    from clsky.render import SkyRenderer

    clsky._cl.VECTOR_WIDTH = vector_width
    result = {}
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
    renders = (("lookup", sizes[0], renderer.render_table), ("skyview", sizes[0], renderer.render_skyview),
               ("raymarch", sizes[1], renderer.render_raymarch))
    for name, size, method in renders:
        prepared = renderer.prepare(*FisheyeCamera(size).directions())
        method(prepared, sun, 0.0)                                                 # warm-up
        cpu = time.process_time()
        best, _ = best_of(lambda: method(prepared, sun, 0.0), repeat)
        result[name] = {"wall": best, "cpu": (time.process_time() - cpu) / repeat}
    return result


def environment(vendors: pathlib.Path | None, selector: str | None = None) -> dict:
    env = {key: value for key, value in os.environ.items() if key != "PYOPENCL_CTX"}
    if selector is not None:
        env["PYOPENCL_CTX"] = selector
    if vendors is not None:
        env["OCL_ICD_VENDORS"] = str(vendors)
    return env


def devices_at_hand(vendors) -> list[dict]:
    """The devices with fp64 the loader lists, PoCL's first (the reference of the comparisons)."""
    output = subprocess.run([sys.executable, "-c", LIST_DEVICES], env=environment(vendors), check=True,
                            capture_output=True, text=True)
    devices = json.loads(output.stdout.strip().splitlines()[-1])
    if not devices:
        raise SystemExit("no OpenCL device with fp64: nothing to measure")
    return sorted(devices, key=lambda device: short_name(device) != "PoCL")


def measure(device, width, vendors, smoke, repeat, animate_arguments, directory: pathlib.Path) -> dict:
    """The worker's measurements and the end-to-end animation (written in ``directory``) of one
    configuration."""
    env = environment(vendors, device["selector"])
    command = [sys.executable, __file__, "--worker", "--repeat", str(repeat), "--vector-widths", str(width)]
    output = subprocess.run(command + (["--smoke"] if smoke else []), env=env, check=True, capture_output=True,
                            text=True)
    result = json.loads(output.stdout.strip().splitlines()[-1])
    directory.mkdir(parents=True)
    load_before, cpu, wall = load_average(), children_cpu(), time.perf_counter()
    subprocess.run([sys.executable, "-c", ANIMATE, str(width), "animate", "--progress", "none", *animate_arguments],
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


def keep_outputs(scratch: pathlib.Path, count: int, target: pathlib.Path):
    """Copy the first round's animations of ``count`` configurations into ``target/<index>/``: staged in
    a directory of a unique name beside ``target``, then renamed onto it, so that an interrupted run
    leaves no half copy under that name."""
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = pathlib.Path(tempfile.mkdtemp(prefix=temporary_prefix(target, ""), dir=target.parent))
    try:
        for index in range(count):
            shutil.copytree(scratch / f"{index}-0", staging / str(index))
        os.rename(staging, target)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


def main():
    parser = argparse.ArgumentParser(description=description_of(__doc__))
    parser.add_argument("--vendors", type=pathlib.Path, default=None,
                        help="OpenCL vendors directory listing the devices (default .intel-opencl/vendors when "
                             "scripts/intel_opencl.sh wrote it, else the system's registry)")
    parser.add_argument("--vector-widths", type=int, choices=VECTOR_WIDTHS, nargs="+", default=[8], metavar="W",
                        help="the kernels' vector widths to measure on each device (1 and/or 8; default 8)")
    parser.add_argument("--rounds", type=positive_integer, default=2,
                        help="rounds of the configurations, alternating (default 2)")
    parser.add_argument("--repeat", type=positive_integer, default=5, help="timed frames per render (default 5)")
    parser.add_argument("--keep-outputs", type=pathlib.Path, default=None, metavar="DIR",
                        help="keep each configuration's first-round animation in DIR/<configuration index>/")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    add_output_arguments(parser)
    args = parse_arguments(parser, sections=("runtimes",))
    if not set(args.vector_widths) <= {1, 8}:
        parser.error(f"--vector-widths {' '.join(map(str, args.vector_widths))}: each must be 1 or 8")
    if args.smoke:
        args.rounds, args.repeat = 1, SMOKE.repeat
    if args.worker:
        print(json.dumps(worker(args.smoke, args.repeat, args.vector_widths[0])))
        return
    vendors = args.vendors or (DEFAULT_VENDORS if DEFAULT_VENDORS.is_dir() else None)
    if vendors is not None and not vendors.is_dir():
        parser.error(f"--vendors {vendors}: no such directory")
    if args.keep_outputs is not None and args.keep_outputs.exists():
        parser.error(f"--keep-outputs {args.keep_outputs}: exists already (nothing is overwritten)")
    devices = devices_at_hand(vendors)
    configurations = [(device, width) for device in devices for width in dict.fromkeys(args.vector_widths)]
    label = {index: short_name(device) + (f", width {width}" if len(args.vector_widths) > 1 else "")
             for index, (device, width) in enumerate(configurations)}
    animate_arguments = []
    if args.smoke:
        animate_arguments = ["--frames", str(SMOKE.animation_frames), "--size", str(SMOKE.frame),
                             "--table-size", *map(str, SMOKE.table)]
    results, highest = [], load_average()
    with tempfile.TemporaryDirectory() as scratch:
        scratch = pathlib.Path(scratch)
        for round_index in range(args.rounds):
            order = range(len(configurations))
            for index in (order if round_index % 2 == 0 else reversed(order)):
                device, width = configurations[index]
                directory = scratch / f"{index}-{round_index}"
                result = measure(device, width, vendors, args.smoke, args.repeat, animate_arguments, directory)
                results.append((round_index + 1, index, result))
                highest = max(highest, result["load"])
                print(f"round {round_index + 1}, {label[index]} ({device['name']}): ray march "
                      f"{result['raymarch']['cpu'] * 1e3:.0f} CPU-ms, table {result['table']['wall']:.1f} s, animate "
                      f"{result['animate']['wall']:.1f} s wall", flush=True)
                if round_index > 0:
                    shutil.rmtree(directory)            # the first round's outputs are compared below
        comparisons = {index: same_outputs(scratch / "0-0", scratch / f"{index}-0")
                       for index in range(1, len(configurations))}
        if args.keep_outputs is not None:
            keep_outputs(scratch, len(configurations), args.keep_outputs)

    shown = "clsky animate " + " ".join(animate_arguments) if animate_arguments else "clsky animate"
    names = "; ".join(f"{short_name(device)}: {device['name']}" for device in devices)
    lines = [f"Measured {datetime.date.today()} on {machine()} ({names}), {args.rounds} round(s), the "
             f"configurations alternating. Renders of the default physical table: best wall time and mean process "
             f"CPU time of {args.repeat} frames after a warm-up [ms] (3D lookup and sky-view map on a 1024 x 1024 "
             f"fisheye, ray march on 512 x 512); the default animation's planned table, one build after a warm-up "
             f"[s]; `{shown}` end to end in a fresh process [s] (CPU: the process and ffmpeg); width: the kernels' "
             f"vector width; load: the highest 1-minute load average seen.{load_note(highest)}", "",
             "| round | device | width | 3D lookup: wall | CPU | sky-view: wall | CPU | ray march: wall | CPU | "
             "planned table: wall | CPU | animate: wall | CPU | load |",
             "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for round_number, index, r in results:
        lines.append(f"| {round_number} | {short_name(configurations[index][0])} | {configurations[index][1]} | "
                     f"{r['lookup']['wall'] * 1e3:.0f} | {r['lookup']['cpu'] * 1e3:.0f} | "
                     f"{r['skyview']['wall'] * 1e3:.0f} | {r['skyview']['cpu'] * 1e3:.0f} | "
                     f"{r['raymarch']['wall'] * 1e3:.0f} | {r['raymarch']['cpu'] * 1e3:.0f} | "
                     f"{r['table']['wall']:.1f} | {r['table']['cpu']:.1f} | {r['animate']['wall']:.1f} | "
                     f"{r['animate']['cpu']:.1f} | {r['load']:.1f} |")
    if len(configurations) == 1:
        lines += ["", f"One configuration only: Intel's CPU runtime is not installed here (no "
                      f"{DEFAULT_VENDORS.relative_to(ROOT)}: scripts/intel_opencl.sh) and no other device lists fp64."]
    else:
        lines += ["", f"{label[0]} / each other configuration, per round (CPU time; wall time in brackets):", ""]
        for index in range(1, len(configurations)):
            for round_number in range(1, args.rounds + 1):
                first, other = (next(r for n, i, r in results if n == round_number and i == wanted)
                                for wanted in (0, index))
                ratios = ", ".join(f"{what} {first[key]['cpu'] / other[key]['cpu']:.2f}x "
                                   f"({first[key]['wall'] / other[key]['wall']:.2f}x)"
                                   for key, what in (("lookup", "3D lookup"), ("skyview", "sky-view"),
                                                     ("raymarch", "ray march"), ("table", "planned table"),
                                                     ("animate", "animate")))
                lines.append(f"- {label[0]} / {label[index]}, round {round_number}: {ratios}")
        lines.append("")
        for index, (differing, compared, largest, where) in comparisons.items():
            lines.append(f"- {label[index]} against {label[0]} (round 1): {differing} of {compared} 8-bit values "
                         f"of the PNG frames differ; the metrics' numbers by at most {largest:.1e} of their "
                         f"column's largest value ({where or 'none differs'}).")
    markdown = "\n".join(lines)
    print(markdown)
    if not args.no_readme:
        write_readme_section("runtimes", markdown)


if __name__ == "__main__":
    main()
