"""Benchmark: one animation rendered here, then on Dask farms of 1 and 2 workers (``clsky animate --workers``).

Each run is :func:`clsky.anim.animate.render_animation` in this process (the client: scene plan, table,
writer), without or with a started :class:`clsky.farm.Farm` (an embedded LocalCluster of spawned
workers; its start is timed apart). Per run:

- wall time of the whole run and of its frame phase: from the end of the table build (the build's last
  progress call) to the last frame written, which includes building the renderer (here) or shipping the
  table and building each worker's renderer (farm);
- process CPU time: the client (``time.process_time``, PoCL's threads included), its finished children
  (ffmpeg, ``RUSAGE_CHILDREN``) and every worker process over the run (psutil, through ``Client.run``);
- the 1-minute load average before and after.

The speedup is the frame phase's wall time here over the farm's, in the same repetition (the runs of a
repetition follow each other; repetitions show the noise). The per-frame overhead is the 1-worker farm
against here, per frame: what shipping the frames and scheduling their tasks costs in wall and CPU time.
Prints the tables and writes them into README.md (section "Frame farms (Dask)", ``bench:bench_dask``).

Usage: python bench/bench_dask.py [--frames N] [--size PX] [--quality LEVEL] [--repeat N] [--no-readme] [--smoke]

``--smoke``: a 2-frame 16 x 16 animation over an 8 x 32 x 8 table, one repetition; print only
(bench/_report.py).
"""

from __future__ import annotations

import argparse
import datetime
import os
import resource
import tempfile
import time

from _report import SMOKE, add_output_arguments, load_average, machine, parse_arguments, write_readme_section

from clsky.anim.animate import AnimationConfig, render_animation
from clsky.farm import Farm

#: The runs of a repetition: (label, workers or None for this process).
RUNS = (("here (no farm)", None), ("farm, 1 worker", 1), ("farm, 2 workers", 2))


def children_cpu() -> float:
    """User + system CPU time [s] of this process's finished, waited-for children (ffmpeg)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def worker_cpu_seconds() -> float:
    """Task run on each worker: its process's user + system CPU time [s]."""
    import psutil

    times = psutil.Process().cpu_times()
    return times.user + times.system


def workers_cpu(farm) -> float:
    return 0.0 if farm is None else sum(farm.client.run(worker_cpu_seconds).values())


def one_run(options, farm):
    """The figures of one animation with ``options`` (AnimationConfig fields), on ``farm`` or here."""
    marks = []

    def progress(stage, done, total):
        marks.append((stage, time.perf_counter()))

    with tempfile.TemporaryDirectory() as directory:
        config = AnimationConfig(output=os.path.join(directory, "sky.mp4"), **options)
        load_before = load_average()
        workers_before, children_before = workers_cpu(farm), children_cpu()
        wall, cpu = time.perf_counter(), time.process_time()
        render_animation(config, progress=progress, farm=farm)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        children, workers = children_cpu() - children_before, workers_cpu(farm) - workers_before
    table_end = max(t for stage, t in marks if stage != "frames")
    frames_wall = max(t for stage, t in marks if stage == "frames") - table_end
    return {"wall": wall, "frames_wall": frames_wall, "client_cpu": cpu + children, "workers_cpu": workers,
            "load_before": load_before, "load_after": load_average()}


def measure(options, repeat):
    """[(repetition, label, workers, figures, farm start wall [s] or None)] of every run."""
    results = []
    for repetition in range(1, repeat + 1):
        for label, workers in RUNS:
            if workers is None:
                results.append((repetition, label, workers, one_run(options, None), None))
                continue
            start = time.perf_counter()
            with Farm(workers=workers) as farm:
                farm.client.wait_for_workers(workers)
                started = time.perf_counter() - start
                results.append((repetition, label, workers, one_run(options, farm), started))
            print(f"repetition {repetition}: {label} done", flush=True)
    return results


def tables(results, frames):
    here = {rep: figures for rep, label, workers, figures, _ in results if workers is None}
    lines = ["| run | repetition | farm start [s] | wall [s] | frames: wall [s] | per frame [ms] | "
             "frames speedup | CPU: client [s] | workers [s] | total [s] | load before | load after |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for rep, label, workers, f, started in results:
        total = f["client_cpu"] + f["workers_cpu"]
        lines.append(f"| {label} | {rep} | {'-' if started is None else f'{started:.1f}'} | {f['wall']:.1f} | "
                     f"{f['frames_wall']:.1f} | {1e3 * f['frames_wall'] / frames:.0f} | "
                     f"{here[rep]['frames_wall'] / f['frames_wall']:.2f} | {f['client_cpu']:.1f} | "
                     f"{f['workers_cpu']:.1f} | {total:.1f} | {f['load_before']:.1f} | {f['load_after']:.1f} |")
    overhead = ["", "| repetition | 1 worker against here: wall per frame [ms] | CPU per frame [ms] |", "|---|---|---|"]
    for rep, label, workers, f, _ in results:
        if workers == 1:
            base = here[rep]
            cpu = (f["client_cpu"] + f["workers_cpu"]) - base["client_cpu"]
            overhead.append(f"| {rep} | {1e3 * (f['frames_wall'] - base['frames_wall']) / frames:+.0f} | "
                            f"{1e3 * cpu / frames:+.0f} |")
    return "\n".join(lines + overhead)


def main(argv=None):
    parser = add_output_arguments(argparse.ArgumentParser(description=__doc__.splitlines()[0]))
    parser.add_argument("--frames", type=int, default=48, help="frames of the animation (default: 48)")
    parser.add_argument("--size", type=int, default=256, help="image height [px] (default: 256)")
    parser.add_argument("--quality", default="default", help="quality level (default: default)")
    parser.add_argument("--repeat", type=int, default=2, help="repetitions of the three runs (default: 2)")
    args = parse_arguments(parser, argv)
    if args.smoke:
        options = dict(frames=SMOKE.animation_frames, size=SMOKE.frame, table_size=SMOKE.table, quality="draft")
        repeat = 1
    else:
        options = dict(frames=args.frames, size=args.size, quality=args.quality)
        repeat = args.repeat
    results = measure(options, repeat)
    table = tables(results, options["frames"])
    description = (f"{options['frames']} frames of {options['size']} x {options['size']} (fisheye, `--method compare`, "
                   f"the physical preset, {options['quality']} quality{', a full 8 x 32 x 8 table' if args.smoke else ', a planned table'}), "
                   f"{machine()}, {datetime.date.today().isoformat()}; the machine was shared with other jobs "
                   f"(load averages in the table): the figures are noisy, hence {repeat} repetitions.")
    markdown = description + "\n\n" + table
    print(markdown)
    if not args.no_readme:
        write_readme_section("bench_dask", markdown)


if __name__ == "__main__":
    main()
