"""Benchmark: the default `clsky animate` end to end, and where its CPU time goes, stage by stage.

- End to end: ``python -m clsky.anim animate`` (120 frames, 512 x 512 fisheye, physical preset, table lookup
  and ray march compared, PNG + MP4 + metrics) in a fresh process: wall time, CPU time of the process
  and its children (ffmpeg) from ``getrusage(RUSAGE_CHILDREN)``, the load average and the machine's exp()
  rate (bench/_report.py, exp_reading: which of its two speeds it ran at) before and after; run
  three times, side by side: with the overlapped frame pipeline (the default: frame i + 1 rendered on a
  worker thread while host threads display and compare the frames before it and the main thread writes,
  ``clsky.anim.pipeline``) with the machine's default number of host threads
  (``clsky.anim.animate.host_frame_workers``: two on 2 cores), with the other choice (one thread where the
  default is more, else two), and without the overlap (``clsky.anim.animate.OVERLAP_FRAMES = False``:
  one frame after the other); after a discarded 3-frame run of the same animation (its kernels compiled
  and cached first, as on a machine that has run clsky before).
- Stage split (without the overlap, so that each stage is timed alone):
  :func:`clsky.anim.animate.render_animation` of the same animation in this process (``--stage-frames``:
  another number of frames; a shorter sweep moves the sun further between frames, and the auto-exposure,
  smoothed over time, lags behind it: a 12-frame sweep showed the display at twice its cost a frame in the
  120-frame one, whose frames leave the gamut less), after a warm-up, under cProfile with the process CPU
  clock as its timer, so that each stage's figure
  counts PoCL's worker threads while the host waits for them (the stages do not overlap). Run twice,
  side by side: with the frame loop's BLAS on one thread (the default, ``clsky._cl.host_blas_single_threaded``)
  and with OpenBLAS's own thread count, to show what the two thread pools cost when they meet.
- Host threads: the frames' host half alone (conversion, metering, display, comparison: what
  ``clsky.anim.animate``'s host threads do, :func:`host_half`) on 1, 2, 4, ... threads up to the default
  (at least 2), over frames of the animation's suns rendered beforehand (no device work while timed), in
  two rounds, up then down:
  how far more threads go on this machine.
Prints the tables and writes them into README.md (section "Speed", ``bench:animate``).

Usage: python bench/bench_animate.py [--frames N] [--size PX] [--stage-frames N] [--no-readme] [--smoke]

``--smoke``: a 2-frame 16 x 16 animation over an 8 x 32 x 8 table for both parts; print only
(bench/_report.py).
"""

from __future__ import annotations

import argparse
import contextlib
import cProfile
import datetime
import os
import pathlib
import pstats
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor

from _report import description_of
from _report import SMOKE, add_output_arguments, children_cpu, exp_reading, load_average, load_note, machine, \
    parse_arguments, state_note, write_readme_section
from _report import frame_count, frame_side

import clsky.anim.animate
from clsky.anim.animate import AnimationConfig, render_animation

#: stage label: the functions (module file suffix, function name[, sign]) whose cumulative CPU time it is,
#: a sign of -1 taking a callee's time out: the sky-view maps (``skyview_maps``, several suns a launch in an
#: animation on a CPU, or one inside ``render_skyview`` through ``skyview_map`` where no map is given) are
#: ray-marched by ``render_raymarch_suns``, so they are a stage of their own, out of both; otherwise the
#: functions of different stages never call one another, so the stages add up. Every ray march, of one sun
#: or of several a launch (``render_raymarch_suns``, the animation's), goes through ``SkyRenderer._raymarch``.
STAGES = {
    "scene plan and table build": [("anim/animate.py", "plan_animation"), ("anim/animate.py", "make_renderer")],
    "lookup (device: the 3D or 4D table, or the sky-view map's per-pixel read)": [
        ("clsky/render.py", "render_table"), ("clsky/render.py", "render_lut4d"),
        ("clsky/render.py", "render_skyview"), ("clsky/render.py", "skyview_map", -1)],
    "sky-view map (the ray march at its nodes)": [("clsky/render.py", "skyview_maps")],
    "ray march (device)": [("clsky/render.py", "_raymarch"), ("clsky/render.py", "skyview_maps", -1)],
    "conversion to cd/m^2 (colorimetry)": [("anim/animate.py", "three_wavelength_frame_to_linear_srgb"),
                                           ("anim/animate.py", "spectral_frame_to_linear_srgb")],
    # the exposure is metered on the host threads before display_frames shows the frame (clsky.anim.pipeline)
    "display (exposure, tone curve, 8 bits)": [("anim/animate.py", "display_frames"),
                                               ("anim/display.py", "metered_ev")],
    "comparison (metrics, Delta E, error image, composite)": [
        ("anim/metrics.py", "frame_comparison"), ("anim/metrics.py", "error_image"),
        ("anim/metrics.py", "relative_error_map"), ("anim/metrics.py", "composite"),
        ("anim/metrics.py", "mean_luminance")],
    "files (PNG, frames to ffmpeg, metrics)": [("anim/writers.py", "write"), ("anim/writers.py", "__exit__"),
                                               ("anim/writers.py", "write_csv"), ("anim/writers.py", "write_json")],
}


#: ``python -m clsky.anim`` with a setting of clsky.anim.animate changed first
CHANGED = "import sys, clsky.anim.animate, clsky.anim.cli; clsky.anim.animate.{} = {}; " \
          "sys.argv[0] = 'clsky'; sys.exit(clsky.anim.cli.main())"


def end_to_end(arguments, overlap=True, host_workers=None):
    """(wall [s], CPU [s], load before, load after, exp() reading before, after [M per CPU-second]) of
    ``python -m clsky.anim animate <arguments>`` (with ``overlap`` False: the frames one after the
    other; with ``host_workers``: that many host threads, ``HOST_FRAME_WORKERS``)."""
    if not overlap:
        program = ["-c", CHANGED.format("OVERLAP_FRAMES", False)]
    elif host_workers is not None:
        program = ["-c", CHANGED.format("HOST_FRAME_WORKERS", int(host_workers))]
    else:
        program = ["-m", "clsky.anim"]
    with tempfile.TemporaryDirectory() as directory:
        exp_before = exp_reading()
        load_before, cpu, wall = load_average(), children_cpu(), time.perf_counter()
        subprocess.run([sys.executable, *program, "animate", "--progress", "none", *arguments], cwd=directory,
                       check=True, stdout=subprocess.DEVNULL)
        wall, cpu, load_after = time.perf_counter() - wall, children_cpu() - cpu, load_average()
        return wall, cpu, load_before, load_after, exp_before, exp_reading()


def stage_split(config_options, blas_limited=True):
    """({stage: CPU [s]}, total CPU [s] of the process and ffmpeg, wall [s], load after) of one
    in-process animation under cProfile (process CPU clock)."""
    limit = clsky.anim.animate.host_blas_single_threaded
    # cProfile sees the calling thread only: the frames are rendered there, one after the other
    clsky.anim.animate.OVERLAP_FRAMES = False
    with tempfile.TemporaryDirectory() as directory:
        config = AnimationConfig(output=str(pathlib.Path(directory) / "sky.mp4"), **config_options)
        profile = cProfile.Profile(time.process_time)
        if not blas_limited:
            clsky.anim.animate.host_blas_single_threaded = contextlib.nullcontext
        children, cpu, wall = children_cpu(), time.process_time(), time.perf_counter()
        try:
            profile.runcall(render_animation, config)
        finally:
            clsky.anim.animate.host_blas_single_threaded = limit
            clsky.anim.animate.OVERLAP_FRAMES = True
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        ffmpeg = children_cpu() - children
    stats = pstats.Stats(profile).stats
    if config.compares and not any(file.endswith("clsky/render.py") and name == "_raymarch" for file, _, name in stats):
        raise RuntimeError("bench_animate: the ray march's stage function (SkyRenderer._raymarch, STAGES) was not "
                           "called: renamed? The stage split would count the march as 'other'")
    stages = {}
    for label, functions in STAGES.items():
        stages[label] = sum((sign[0] if sign else 1) * entry[3] for (file, _, name), entry in stats.items()
                            for suffix, function, *sign in functions if file.endswith(suffix) and name == function)
    stages["ffmpeg (child process)"] = ffmpeg
    stages["other (Python, cProfile's own overhead)"] = cpu - sum(stages.values()) + ffmpeg
    return stages, cpu + ffmpeg, wall, load_average()


#: Frames rendered for the host-thread timing, and the frames' host halves timed at each thread count
HOST_HALF_RENDERED, HOST_HALF_JOBS = 4, 24


def host_half(options, thread_counts, jobs=HOST_HALF_JOBS):
    """[(threads, wall, CPU)] per frame [s] of the frames' host half alone (:func:`clsky.anim.animate.convert_frames`,
    ``metered_exposure`` and ``frame_outputs``, what the animation's host threads do) on each of
    ``thread_counts`` threads (a pool mapping ``jobs`` frames), over :data:`HOST_HALF_RENDERED` frames of the
    animation ``options`` rendered beforehand, BLAS on one thread as in the animation. CPU: the process's
    user and system time (nothing else runs in it meanwhile)."""
    animate = clsky.anim.animate
    config = AnimationConfig(**options)
    planned = animate.planned_animation(config)
    positions, directions, valid, plan = planned.positions, planned.directions, planned.valid, planned.plan
    renderer, table = animate.make_renderer(config, plan)
    lookup = animate.lookup_of(config, plan)
    prepared = renderer.prepare(directions, valid)
    step = max(1, len(positions) // HOST_HALF_RENDERED)
    rendered = [(sun, animate.render_frame(renderer, prepared, sun.direction, config, lookup, convert=False))
                for sun in positions[::step][:HOST_HALF_RENDERED]]
    pipeline = animate.display(config, table)

    def frame(index):
        sun, raw = rendered[index % len(rendered)]
        hdr = animate.convert_frames(renderer, config, raw)
        return animate.frame_outputs(pipeline, hdr, valid, config, sun, index,
                                     ev=animate.metered_exposure(pipeline, hdr, valid))

    timings = []
    with animate.host_blas_single_threaded():
        frame(0)                                                    # warm-up
        for threads in thread_counts:
            cpu, wall = os.times(), time.perf_counter()
            with ThreadPoolExecutor(threads) as pool:
                list(pool.map(frame, range(jobs)))
            wall, now = time.perf_counter() - wall, os.times()
            timings.append((threads, wall / jobs, (now.user - cpu.user + now.system - cpu.system) / jobs))
    return timings


def main():
    parser = argparse.ArgumentParser(description=description_of(__doc__))
    parser.add_argument("--frames", type=frame_count, default=120, help="frames of the end-to-end run (default 120)")
    parser.add_argument("--size", type=frame_side, default=512, help="frame size [px] (default 512)")
    parser.add_argument("--stage-frames", type=frame_count, default=None,
                        help="frames of the stage split (default: --frames, the same animation)")
    add_output_arguments(parser)
    args = parse_arguments(parser, sections=("animate",))
    extra, options = [], {}
    if args.smoke:
        args.frames, args.stage_frames, args.size = SMOKE.animation_frames, SMOKE.animation_frames, SMOKE.frame
        extra, options = ["--table-size", *map(str, SMOKE.table)], {"table_size": SMOKE.table}
    if args.stage_frames is None:
        args.stage_frames = args.frames
    command = ["--frames", str(args.frames), "--size", str(args.size), *extra]
    # the default number of host threads, and the other choice: one where the default is more, else two
    workers = clsky.anim.animate.host_frame_workers()
    other = 1 if workers > 1 else 2
    variants = {f"overlapped, {workers} host thread{'s' * (workers > 1)} (default)": (True, None),
                f"overlapped, {other} host thread{'s' * (other > 1)}": (True, other),
                "one after the other": (False, None)}
    # first, discarded, the same animation at 3 frames (sunrise, noon, sunset: the same scene plan, table and
    # programs): its kernels compiled into PyOpenCL's cache, which a fresh machine lacks and the first variant
    # alone would otherwise pay for (one candidate for the first H200 machine's figures, README "GPUs")
    warm_up = end_to_end(["--frames", str(min(3, args.frames)), *command[2:]])
    print(f"discarded warm-up ({min(3, args.frames)} frames): wall {warm_up[0]:.1f} s, CPU {warm_up[1]:.1f} s",
          flush=True)
    runs = {}
    for label, (overlap, host_workers) in variants.items():
        runs[label] = end_to_end(command, overlap, host_workers)
        wall, cpu, load_before, load_after, _, _ = runs[label]
        print(f"end to end ({label}): wall {wall:.1f} s, CPU {cpu:.1f} s, load "
              f"{load_before:.1f} -> {load_after:.1f}", flush=True)
    highest = max(max(run[2:4]) for run in runs.values())
    readings = [reading for run in runs.values() for reading in run[4:]]
    # a discarded warm-up at the smoke size: kernel compilation and the colour conversion's tables
    # (built once per process) would otherwise land in the first variant only
    stage_split({"frames": SMOKE.animation_frames, "size": SMOKE.frame, **options})
    options.update(frames=args.stage_frames, size=args.size)
    splits = []
    for limited in (True, False):
        splits.append(stage_split(options, blas_limited=limited))
        highest = max(highest, splits[-1][3])
        print(f"stage split (BLAS {'one thread' if limited else 'unlimited'}): CPU {splits[-1][1]:.1f} s, "
              f"wall {splits[-1][2]:.1f} s", flush=True)
    counts = [1]
    while counts[-1] * 2 <= max(2, workers):
        counts.append(counts[-1] * 2)
    # the suns of the end-to-end animation (every len // HOST_HALF_RENDERED-th)
    host_options = {**options, "frames": max(HOST_HALF_RENDERED, args.frames)}
    jobs = 4 if args.smoke else HOST_HALF_JOBS
    threads = host_half(host_options, counts + counts[::-1], jobs)
    for count, wall, cpu in threads:
        print(f"host half alone, {count} host thread{'s' * (count > 1)}: {1000 * wall:.1f} ms wall, "
              f"{1000 * cpu:.1f} ms CPU a frame", flush=True)
    highest = max(highest, load_average())
    shown = "clsky animate " + " ".join(command)
    same = "the same animation" if args.stage_frames == args.frames else \
        f"the same animation at {args.stage_frames} frames"
    lines = [f"Measured {datetime.date.today()} on {machine()}. End to end: `{shown}` "
             f"in a fresh process (table build, both renderers, comparison, PNG + MP4 + metrics); CPU time of the "
             f"process and its children (ffmpeg), load average before and after; with the overlapped frame "
             f"pipeline and this machine's default number of host threads for the frames' display and "
             f"comparison, with the other choice of threads (one where the default is more, else two), and "
             f"with the frames one after the other, run one after the "
             f"other after a discarded 3-frame run (kernels compiled and cached); exp(): the "
             f"machine's double8 exp() rate read before and after the run [M per CPU-second] (its slow state "
             f"reads a half to two thirds of its fast one: README \"This machine runs at two speeds\")."
             f"{load_note(highest)}{state_note(readings)}", "",
             "| run | frames | wall [s] | CPU [s] | CPU / wall | load before | load after | exp() |",
             "|---|---|---:|---:|---:|---:|---:|---|",
             *(f"| `{shown}` | {label} | {wall:.1f} | {cpu:.1f} | "
               f"{cpu / wall:.2f} | {load_before:.1f} | {load_after:.1f} | {exp_before:.0f} / {exp_after:.0f} |"
               for label, (wall, cpu, load_before, load_after, exp_before, exp_after) in runs.items()), "",
             f"Where the CPU time goes: {same}, one after the other, in "
             f"one process after a warm-up (kernels compiled, the colour conversion's tables built), cProfile "
             f"on the process CPU clock (PoCL's worker threads count towards the stage that waits for them); "
             f"the frame loop's host BLAS on one thread (default) and with OpenBLAS's own threads, side by side.",
             "", "| stage | CPU [s], BLAS 1 thread | per frame [ms] | CPU [s], BLAS unlimited | per frame [ms] |",
             "|---|---:|---:|---:|---:|"]
    for label in splits[0][0]:
        cells = []
        for stages, _, _, _ in splits:
            cells += [f"{stages[label]:.2f}", f"{1000 * stages[label] / args.stage_frames:.0f}"]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    cells = []
    for _, total, split_wall, _ in splits:
        cells += [f"**{total:.2f}** (wall {split_wall:.1f})", f"{1000 * total / args.stage_frames:.0f}"]
    lines.append("| total | " + " | ".join(cells) + " |")
    one = threads[0][1]
    lines += ["", f"Host threads: the frames' host half alone (conversion to cd/m^2, metering, display, comparison) "
              f"on a pool of threads mapping {jobs} frames of {args.size} x {args.size}, {HOST_HALF_RENDERED} of the "
              f"animation's suns rendered beforehand (evenly spaced) and taken in turn (no device work meanwhile), "
              f"each at its own metered exposure, the thread counts up then down, in this process; wall and "
              f"process CPU per frame [ms].", "",
              "| round | host threads | wall a frame [ms] | CPU a frame [ms] | wall, one thread's / this |",
              "|---:|---:|---:|---:|---:|",
              *(f"| {1 + (index >= len(counts))} | {count} | {1000 * wall:.1f} | {1000 * cpu:.1f} | {one / wall:.2f}x |"
                for index, (count, wall, cpu) in enumerate(threads))]
    markdown = "\n".join(lines)
    print(markdown)
    if not args.no_readme:
        write_readme_section("animate", markdown)


if __name__ == "__main__":
    main()
