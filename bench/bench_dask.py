"""Benchmark: one animation rendered here, then on Dask farms of 1 and 2 workers (``clsky animate --workers``).

Each run is :func:`clsky.anim.animate.render_animation` in this process (the client: scene plan, table,
writer), without or with a started :class:`clsky.farm.Farm` (an embedded LocalCluster of spawned
workers; its start is timed apart). Per run:

- wall time of the whole run, of the table build (plan included), and up to the first frame written
  after it (building the renderer here; on a farm, shipping the table and each worker's first frame:
  importing clsky, reading the table, building its renderer);
- the frames after the first (the steady state): wall time and process CPU time per frame, the
  client's (``time.process_time``, PoCL's threads included) and every worker process's (psutil, through
  ``Client.run``); the MP4 encoder (ffmpeg, a child process that ends with the run) is left out of all
  runs alike. A farm's workers run ahead of the writer (up to 4 frames here): what they spent on later
  frames before the first was written counts with the first frame (at most 3 of 47 frames, ~6 %; the
  2-frame ``--smoke`` run's CPU per frame means nothing);
- the 1-minute load average before and after.

The speedup is the steady per-frame wall time here over the farm's, in the same repetition (the runs of
a repetition follow each other; repetitions show the noise). The overhead is the 1-worker farm against
here: its first frame's extra wait, and per steady frame the wall and CPU time that shipping the frames
and scheduling their tasks cost.
Prints the tables and writes them into README.md (section "Frame farms (Dask)", ``bench:bench_dask``).

Usage: python bench/bench_dask.py [--frames N] [--size PX] [--quality LEVEL] [--repeat N] [--no-readme] [--smoke]

``--smoke``: a 2-frame 16 x 16 animation over an 8 x 32 x 8 table, one repetition; print only
(bench/_report.py).
"""

from __future__ import annotations

import argparse
import datetime
import os
import tempfile
import time

from _report import description_of
from _report import SMOKE, add_output_arguments, load_average, machine, parse_arguments, write_readme_section
from _report import frame_count, frame_side, positive_integer

from clsky.anim.animate import AnimationConfig, render_animation
from clsky.farm import Farm
from clsky.quality import QUALITY_LEVELS

#: The runs of a repetition: (label, workers or None for this process).
RUNS = (("here (no farm)", None), ("farm, 1 worker", 1), ("farm, 2 workers", 2))


def worker_cpu_seconds() -> float:
    """Task run on each worker: its process's user + system CPU time [s]."""
    import psutil

    times = psutil.Process().cpu_times()
    return times.user + times.system


def workers_cpu(farm) -> float:
    return 0.0 if farm is None else sum(farm.client.run(worker_cpu_seconds).values())


def one_run(options, farm):
    """The figures of one animation with ``options`` (AnimationConfig fields), on ``farm`` or here: the
    times [s] since the start at the end of the table build, at the first frame written and at the last,
    and the CPU [s] (client, workers) at those two frames."""
    marks = {}

    def progress(stage, done, total):
        now = time.perf_counter()
        if stage != "frames":
            marks["table"] = now
        elif done in (1, total):
            marks["first" if done == 1 else "last"] = (now, time.process_time(), workers_cpu(farm))

    with tempfile.TemporaryDirectory() as directory:
        config = AnimationConfig(output=os.path.join(directory, "sky.mp4"), **options)
        load_before = load_average()
        start = time.perf_counter()
        render_animation(config, progress=progress, farm=farm)
        wall = time.perf_counter() - start
    (first, client_first, workers_first), (last, client_last, workers_last) = marks["first"], marks["last"]
    return {"wall": wall, "table": marks["table"] - start, "warm_up": first - marks["table"],
            "steady_wall": last - first, "steady_client": client_last - client_first,
            "steady_workers": workers_last - workers_first, "load_before": load_before, "load_after": load_average()}


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
    """The Markdown tables: every run, then the 1-worker farm's overhead against here."""
    steady = frames - 1                      # the frames after the first
    here = {rep: figures for rep, label, workers, figures, _ in results if workers is None}
    lines = ["| run | repetition | farm start [s] | wall [s] | table [s] | first frame [s] | frames after it: "
             "wall per frame [ms] | CPU per frame [ms], client + workers | frames speedup | load before | load after |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for rep, label, workers, f, started in results:
        cpu = f["steady_client"] + f["steady_workers"]
        lines.append(f"| {label} | {rep} | {'-' if started is None else f'{started:.1f}'} | {f['wall']:.1f} | "
                     f"{f['table']:.1f} | {f['warm_up']:.1f} | {1e3 * f['steady_wall'] / steady:.0f} | "
                     f"{1e3 * cpu / steady:.0f} ({1e3 * f['steady_client'] / steady:.0f} + "
                     f"{1e3 * f['steady_workers'] / steady:.0f}) | {here[rep]['steady_wall'] / f['steady_wall']:.2f} | "
                     f"{f['load_before']:.1f} | {f['load_after']:.1f} |")
    overhead = ["", "| repetition | 1 worker against here: first frame [s] | wall per frame [ms] | CPU per frame [ms] |",
                "|---|---|---|---|"]
    for rep, label, workers, f, _ in results:
        if workers == 1:
            base = here[rep]
            cpu = f["steady_client"] + f["steady_workers"] - base["steady_client"]
            overhead.append(f"| {rep} | {f['warm_up'] - base['warm_up']:+.1f} | "
                            f"{1e3 * (f['steady_wall'] - base['steady_wall']) / steady:+.0f} | {1e3 * cpu / steady:+.0f} |")
    return "\n".join(lines + overhead)


def main(argv=None):
    parser = add_output_arguments(argparse.ArgumentParser(description=description_of(__doc__)))
    parser.add_argument("--frames", type=frame_count, default=48, help="frames of the animation (default: 48)")
    parser.add_argument("--size", type=frame_side, default=256, help="image height [px] (default: 256)")
    parser.add_argument("--quality", default="default", choices=list(QUALITY_LEVELS),
                        help="quality level (default: default)")
    parser.add_argument("--repeat", type=positive_integer, default=2, help="repetitions of the three runs (default: 2)")
    args = parse_arguments(parser, argv, sections=("bench_dask",))
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
