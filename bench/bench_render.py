"""Benchmark: per-frame rendering speed and the default animation's wall time, in one run.

- table-lookup render of a 1024 x 1024 fisheye (frames per second, HDR frame on the host), and the two
  renderers issue 11 added for dusk on the same frame: the per-frame sky-view map (its default 64 x 128
  map ray-marched, then read per pixel; clsky/skyview.py) and the 4D table's lookup (a table of the
  accuracy sweep's 4D size, 16 x 128 x 128 x 16, sun -14 to 60 deg, M = 2, whose build is timed too);
- per-pixel ray march of a 512 x 512 fisheye at the default samples, and its process CPU time per frame
  beside the exp() bound measured on this machine (bench/_bound.py) and their ratio (issue 12's goal: 2x),
  from frames each followed by a reading of the bound (:func:`march_beside_bound`); the same with the
  higher orders' source on every other node (``TableSettings.source_stride = 2``, the 'draft' and
  'default' quality levels' ray march), and that march for 4 suns a launch (``render_raymarch_suns``, what
  an animation does on CPUs: ``clsky.render.ray_march_suns``), per frame;
- each row's process CPU time per frame is the least and the median of its frames, each frame timed on
  its own: one disturbed frame moves a mean, not these; the rows take their frames in turn, round after
  round (:func:`frames_in_rounds`);
- the default `clsky animate` (120 frames, 512 x 512, both renderers, comparison, files), wall time.
Prints the table and writes it into README.md.

Usage: python bench/bench_render.py [--repeat N] [--no-readme] [--skip-animation] [--smoke]

``--smoke``: an 8 x 32 x 8 table, 16 x 16 frames, one repetition, and a 2-frame 16 x 16 animation over
the same table grid; print only (bench/_report.py).
"""

from __future__ import annotations

import argparse
import datetime
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

from _bound import EXPS_PER_NODE, march_exps
from _report import description_of
from _report import SMOKE, add_output_arguments, exp_reading, load_average, machine, parse_arguments, \
    positive_integer, timed_in_turn, timed_with_cpu, write_readme_section

import clsky
from clsky.anim.accuracy import LOOKUP4D_SUN_DEG, lookup4d_settings
from clsky.anim.cameras import FisheyeCamera, sun_direction
from clsky._cl import describe_device
from clsky import render
from clsky.render import RAYMARCH_DEFAULTS, SkyRenderer

#: Suns a launch of the batched ray march's rows (clsky.render.ray_march_suns on CPUs).
LAUNCH_SUNS = 4


#: Frames of the ray march, each followed by a reading of the exp() rate.
BOUND_PAIRS = 8
#: A pair is in the machine's fast state when its exp() reading is within this fraction of the fastest.
FAST_STATE = 0.15


def march_beside_bound(march, count):
    """[(process CPU time of one ``march`` [s], the exp() rate read right after it [1/s])] for
    ``count`` frames (:func:`_report.exp_reading`).

    Why pairs: on this virtual machine the CPU time of the same work is not steady. For seconds at a
    time the double8 exp() kernel runs at about 900 M per CPU-second instead of 1500-1700 on the AMD EPYC
    with AVX-512, about 330 instead of 540-618 on the one without (only while both of PoCL's workers run:
    with one, 30 readings of the first stayed within 1499-1596), and the ray march
    takes about a third more CPU then (README "Speed"). A frame and the reading just after it share
    the machine's state."""
    pairs = []
    for _ in range(count):
        cpu = time.process_time()
        march()
        cpu = time.process_time() - cpu
        pairs.append((cpu, 1e6 * exp_reading()))
    return pairs


def fast_state(pairs):
    """(the least march CPU time, the fastest exp() rate) among the ``pairs`` whose rate is within
    :data:`FAST_STATE` of the fastest: march and bound both in the machine's fast state."""
    fastest = max(rate for _, rate in pairs)
    return min(cpu for cpu, rate in pairs if rate >= (1.0 - FAST_STATE) * fastest), fastest


def frames_in_rounds(renders, rounds):
    """[(best wall, median wall, least CPU, median CPU) [s] of each of ``renders``] over ``rounds`` rounds
    in which each render is called once, in turn, after one warm-up call each (:func:`_report.timed_in_turn`:
    wall time and process CPU time of each call, PoCL's workers included)."""
    return [(min(w for w, _ in timed), statistics.median(w for w, _ in timed), min(c for _, c in timed),
             statistics.median(c for _, c in timed)) for timed in timed_in_turn(renders, rounds)]


def bound_sentence(label, pairs, exps, timed="frames"):
    """What ``pairs`` (:func:`march_beside_bound`, CPU per frame) of a march of ``exps`` exponentials a frame
    say against the exp() bound: (sentence, ratio); ``timed``: what each pair timed."""
    march_cpu, rate = fast_state(pairs)
    bound = exps / rate
    cpus, rates = [cpu for cpu, _ in pairs], [rate for _, rate in pairs]
    return (f"{label}: {1000 * march_cpu:.0f} CPU-ms per frame, its exponentials {1000 * bound:.0f} CPU-ms at "
            f"the {rate / 1e6:.0f} M double8 exp() per CPU-second read beside it: **{march_cpu / bound:.1f}x the "
            f"bound** ({len(pairs)} {timed}, each followed by a reading of exp(): {1000 * min(cpus):.0f}-"
            f"{1000 * max(cpus):.0f} CPU-ms, {min(rates) / 1e6:.0f}-{max(rates) / 1e6:.0f} M per CPU-second)",
            march_cpu / bound)


def main():
    parser = argparse.ArgumentParser(description=description_of(__doc__))
    parser.add_argument("--repeat", type=positive_integer, default=9)
    parser.add_argument("--skip-animation", action="store_true")
    add_output_arguments(parser)
    args = parse_arguments(parser, sections=("render",))
    sizes, animate = (1024, 512), [sys.executable, "-m", "clsky.anim", "animate", "--progress", "none"]
    settings = clsky.TableSettings(mode="physical")
    if args.smoke:
        args.repeat, sizes = SMOKE.repeat, (SMOKE.frame, SMOKE.frame)
        settings = settings.replace(size=SMOKE.table)
        animate += ["--size", str(SMOKE.frame), "--frames", str(SMOKE.animation_frames),
                    "--table-size", *map(str, SMOKE.table)]

    table = clsky.ScatteringTable.build("physical", settings)
    renderer = SkyRenderer(table)
    strided = SkyRenderer(table, RAYMARCH_DEFAULTS.replace(source_stride=2))
    settings4d = lookup4d_settings(clsky.TableSettings(mode="physical"))     # the accuracy sweep's 4D candidate
    if args.smoke:
        settings4d = settings4d.replace(size=SMOKE.table, azimuth_size=5)
    table4d, wall4d, cpu4d = timed_with_cpu(lambda: clsky.ScatteringTable.build("physical", settings4d))
    renderer4d = SkyRenderer(table4d)
    sun = sun_direction(50.0, 160.0)
    suns = [sun_direction(50.0 + 0.5 * k, 160.0) for k in range(LAUNCH_SUNS)]    # an animation's next suns

    render.RAY_MARCH_SUNS = LAUNCH_SUNS         # on any device (GPUs march one sun a launch by default)

    def strided_suns(prepared, _sun, altitude):
        """The strided march of LAUNCH_SUNS suns in one launch (a row's times are then divided by them)."""
        return strided.render_raymarch_suns(prepared, suns, altitude)

    side = f"fisheye {sizes[0]} x {sizes[0]}"
    four = " x ".join(map(str, settings4d.size + (settings4d.azimuth_size,)))
    measured = ((sizes[0], renderer.render_table, f"table lookup, {side}"),
                (sizes[0], renderer.render_skyview, f"sky-view map 64 x 128 (map and read), {side}"),
                (sizes[0], renderer4d.render_lut4d, f"4D table lookup ({four}), {side}"),
                (sizes[1], renderer.render_raymarch,
                 f"ray march ({RAYMARCH_DEFAULTS.view_steps} samples), fisheye {sizes[1]} x {sizes[1]}"),
                (sizes[1], strided.render_raymarch,
                 f"ray march ({RAYMARCH_DEFAULTS.view_steps} samples, the higher orders' source on "
                 f"every other node), fisheye {sizes[1]} x {sizes[1]}"),
                (sizes[1], strided_suns, f"the same, {LAUNCH_SUNS} suns a launch (an animation's on CPUs), per frame"))
    prepared, marched = {}, {}
    for size in sizes:
        directions, valid = FisheyeCamera(size).directions()
        prepared[size], marched[size] = renderer.prepare(directions, valid), int(np.count_nonzero(valid))
    renders = [(lambda method=method, size=size: method(prepared[size], sun, 0.0)) for size, method, _ in measured]
    timings = frames_in_rounds(renders, args.repeat)
    rows = []
    for (_, method, label), timing in zip(measured, timings):
        best, median, least_cpu, median_cpu = (t / (LAUNCH_SUNS if method is strided_suns else 1) for t in timing)
        rows.append(f"| {label} | {1000 * best:.0f} ms | {1000 * median:.0f} ms | {1000 * least_cpu:.0f} ms | "
                    f"{1000 * median_cpu:.0f} ms | {1 / best:.1f} |")
        print(rows[-1], flush=True)
    # the marches' CPU time per frame against their exponentials at the device's measured exp() rate
    # (the marches' fisheye, sizes[1]); the strided march has the same exponentials (8 per node: single
    # scattering's, at every node)
    exps = march_exps(marched[sizes[1]], RAYMARCH_DEFAULTS.view_steps)
    count = BOUND_PAIRS if not args.smoke else 2
    sentences = [bound_sentence(label, [(cpu / frames, rate) for cpu, rate in
                                        march_beside_bound(lambda: march(prepared[sizes[1]], sun, 0.0), count)],
                                exps, "frames" if frames == 1 else f"launches of {frames} frames")
                 for label, march, frames in (
                     ("Ray march", renderer.render_raymarch, 1),
                     ("with the higher orders' source on every other node", strided.render_raymarch, 1),
                     (f"that march for {LAUNCH_SUNS} suns a launch, per frame", strided_suns, LAUNCH_SUNS))]
    load = load_average()
    bound_line = (f"Ray marches against the exp() bound: their {exps / 1e6:.1f} M exponentials ({EXPS_PER_NODE} per "
                  f"ray node, {RAYMARCH_DEFAULTS.view_steps + 1} nodes, {marched[sizes[1]]} pixels) at the "
                  f"machine's exp() rate (goal: 2x; load average {load:.1f}). "
                  + "; ".join(sentence for sentence, _ in sentences)
                  + f". Each figure is the least frame and the fastest reading among the pairs whose reading is "
                  f"within {100 * FAST_STATE:.0f} % of the fastest.")
    print(bound_line, flush=True)
    animation = "not measured (--skip-animation)"
    if not args.skip_animation:
        with tempfile.TemporaryDirectory() as directory:
            start = time.perf_counter()
            subprocess.run(animate, cwd=directory, check=True)
            animation = f"{time.perf_counter() - start:.0f} s"
        print("default animate:", animation, flush=True)
    lines = [f"Rendering, measured {datetime.date.today()} on {machine()}, OpenCL device "
             f"{describe_device(renderer.engine.device)}; best and median wall time of {args.repeat} frames after a "
             f"warm-up (HDR float64 frame copied to the host), and the least and the median process CPU time of a "
             f"frame (PoCL's workers included); the rows' frames in {args.repeat} rounds of one frame each, in "
             f"turn (the machine's state drifts: every row sees the same mix).", "",
             "| render | best | median | CPU per frame: least | median | frames/s (best) |",
             "|---|---:|---:|---:|---:|---:|", *rows, "",
             f"The 4D table ({four}, float64, sun {LOOKUP4D_SUN_DEG[0]:g} to {LOOKUP4D_SUN_DEG[1]:g} deg, M = 2) "
             f"took {wall4d:.1f} s wall and {cpu4d:.1f} s of process CPU to build; the sky-view map and the "
             f"lookups read the default 3D table {' x '.join(map(str, settings.size))}.", "",
             bound_line, "",
             ("Smoke run: `" + " ".join(["clsky", *animate[3:]]) + "`" if args.smoke else
              "Default `clsky animate` (120 frames, 512 x 512 fisheye, table build, both renderers, comparison, "
              "PNG + MP4 + metrics)")
             + f", wall time of the whole command: **{animation}**."]
    markdown = "\n".join(lines)
    print(markdown)
    if not args.no_readme:
        write_readme_section("render", markdown)


if __name__ == "__main__":
    main()
