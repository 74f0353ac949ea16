"""Benchmark: the quality levels and the scene plan, measured against the converged reference, in one run.

1. The reference (anim/accuracy.py: the 'reference' quality level, one table per frame on the sun
   range that frame needs) and its convergence: each group of its counts doubled in turn.
2. Each quality level, planned for the four frames' sun path (-4 to 45 deg): table build, frame render,
   and the error of its ray-marched frames against the reference; of the same table's lookup and sky-view
   map too (the worst frame).
3. The scene plan of the default animation (sun from -6 to 60 deg, all-sky fisheye from the ground,
   1 % budget) against the full table of the same quality: cells, build time side by side, and the
   error of both against the reference.

Writes the README sections "quality" and "plan", docs/quality.csv and docs/quality_reference.csv (the
reference's convergence). bench/bench_quality_dusk.py measures the same below civil twilight (:data:`DUSK`).

Usage: python bench/bench_quality.py [--size 64] [--groups GROUP ...] [--reference-cache FILE] [--no-readme]
[--docs DIR] [--smoke]

``--groups`` names the reference's count groups to double (clsky.anim.accuracy.REFERENCE_GROUPS; default all;
each costs a rebuild of the four reference tables, 5 to 15 min); ``--reference-cache FILE`` keeps the
reference frames and their convergence in an .npz, read back by later runs (and by
bench/bench_accuracy.py) instead of being computed again.

``--docs DIR``: where quality.csv goes. Default: docs/ when the run writes the README; with
``--no-readme``, nowhere (print only), so that a trial run never overwrites the published data unless
asked.

``--smoke``: 16 x 16 frames, the 'draft' quality level as the reference with one group doubled ("ray
march", unless ``--groups`` names others), every table cut to at most 8 x 32 x 8 nodes, each build
once; quality.csv goes to a temporary directory (or ``--docs DIR``); print only (bench/_report.py).
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import pathlib
import tempfile

import numpy as np
from _report import description_of
from _report import (SMOKE, add_output_arguments, best_timing, load_average, load_note, machine,
                     parse_arguments, timed_with_cpu, write_readme_section)
from _report import integer_in, load_reference_cache, npz_file, save_reference_cache

import clsky
from clsky.anim import accuracy, animate, metrics, writers
from clsky.anim.cameras import FisheyeCamera
from clsky._cl import default_device, describe_device
from clsky.planner import Scene, plan_scene
from clsky.quality import QUALITY_LEVELS
from clsky.render import SkyRenderer

DOCS = pathlib.Path(__file__).resolve().parent.parent / "docs"


@dataclasses.dataclass(frozen=True)
class FrameSet:
    """The frames a run measures the levels on, and what it writes.

    Attributes
    ----------
    elevations : dict
        {frame name: sun elevation [deg]}.
    path : tuple of float
        The sun path [deg] each level's table is planned for (low, high).
    sections : tuple of str
        The README sections it writes: its levels' table, then (with "plan") the default animation's plan.
    csv : str
        The file under docs/ that takes its levels' rows (and, :attr:`reference_csv`, the reference's
        convergence).
    groups : tuple of str
        The reference's count groups doubled by default (:data:`clsky.anim.accuracy.REFERENCE_GROUPS`).
    script : str
        The script that runs it, as its README section names it.
    path_words : str
        The planned path as the README's sentence says it, a format string of its ends ``low`` and ``high``.
    """

    elevations: dict
    path: tuple
    sections: tuple
    csv: str
    groups: tuple
    script: str
    path_words: str

    @property
    def names(self):
        """The frames' names, in order."""
        return list(self.elevations)

    @property
    def reference_csv(self):
        """The file under docs/ that takes the reference's change with each group of its counts doubled, and
        their sum (the scene planner's :data:`clsky.renderer_choice.REFERENCE_RESOLUTION`)."""
        return self.csv.replace(".csv", "_reference.csv")

    @property
    def count(self):
        """How many frames, in words (the README's sentences)."""
        return ("no", "one", "two", "three", "four", "five", "six")[len(self.elevations)]


#: The four frames of :data:`clsky.anim.accuracy.SUN_ELEVATIONS` (day to civil twilight), each level planned for
#: their path (-4 to 45 deg), the reference's convergence in every group, and the default animation's plan.
DAY = FrameSet(accuracy.SUN_ELEVATIONS,
               (min(accuracy.SUN_ELEVATIONS.values()), max(accuracy.SUN_ELEVATIONS.values())),
               ("quality", "plan"), "quality.csv", tuple(accuracy.REFERENCE_GROUPS), "bench/bench_quality.py",
               "the four frames' sun path ({low:g} to {high:g} deg)")
#: Below civil twilight (:data:`clsky.anim.accuracy.DUSK_ELEVATIONS`, -6 to -12 deg), each level planned for a
#: sunset's path from the lowest of them up to the day frame's 45 deg (its tables read the orders' source at
#: every view node: :data:`clsky.planner.SOURCE_EVERY_NODE_BELOW_DEG`), the reference's convergence in every
#: group: the scene planner's promise rule needs it (each group rebuilds the four reference tables of these
#: suns, about 13 min at the reference's own size on the 2-core Xeon; ``--groups`` with none measures the
#: levels alone, about 20 min).
DUSK = FrameSet(accuracy.DUSK_ELEVATIONS,
                (min(accuracy.DUSK_ELEVATIONS.values()), max(accuracy.SUN_ELEVATIONS.values())),
                ("quality-dusk",), "quality_dusk.csv", tuple(accuracy.REFERENCE_GROUPS), "bench/bench_quality_dusk.py",
                "a sunset's sun path, from the lowest frame's sun up to the day frame's ({low:g} to {high:g} deg)")


def frames_of(table, ray, size, elevations, method="raymarch"):
    """{frame name: HDR} of the frames of ``elevations`` ({name: sun elevation [deg]}), and the mean wall and
    process CPU time of one frame [s]."""
    directions, valid = FisheyeCamera(size).directions()
    with SkyRenderer(table, ray) as renderer:
        prepared = renderer.prepare(directions, valid)
        render = lambda: accuracy.render_frames(renderer, method, prepared, elevations=elevations)  # noqa: E731
        render()                                                            # warm-up
        frames, wall, cpu = timed_with_cpu(render)
        return frames, wall / len(frames), cpu / len(frames)


def errors(reference, frames, valid):
    """{frame name: p95 relative error of ``frames`` against ``reference``}."""
    return {name: metrics.compare_frames(reference[name], frames[name], valid)["p95_rel"] for name in reference}


def built(atmosphere, settings, repeat=1, smoke=False):
    """The table and its build's wall and process CPU time [s]: the least of each over ``repeat`` builds
    (the least noisy figures). ``smoke``: cut the table to at most SMOKE.table nodes per axis, and build
    it once."""
    if smoke:
        settings = settings.replace(size=tuple(min(n, m) for n, m in zip(settings.size, SMOKE.table)))
        repeat = SMOKE.repeat
    table, wall, cpu, _ = best_timing(lambda: clsky.ScatteringTable.build(atmosphere, settings), repeat)
    return table, wall, cpu


def percent(values):
    return " | ".join(f"{100 * value:.2f}" for value in values.values())


def main(frame_set=DAY, doc=__doc__):
    """Parse the command line and run the benchmark on ``frame_set`` (:class:`FrameSet`); ``doc``: the calling
    script's docstring, for --help."""
    parser = argparse.ArgumentParser(description=description_of(doc))
    parser.add_argument("--size", type=integer_in(16, 2048), default=64)
    default_groups = ("all" if frame_set.groups == tuple(accuracy.REFERENCE_GROUPS) else
                      "; ".join(frame_set.groups) or "none")
    parser.add_argument("--groups", nargs="*", choices=list(accuracy.REFERENCE_GROUPS),
                        help=f"default: {default_groups} (with --smoke: "
                             + ("ray march)" if frame_set.groups else "none)"))
    parser.add_argument("--reference-cache", type=npz_file, metavar="FILE.npz")
    parser.add_argument("--docs", type=pathlib.Path, metavar="DIR",
                        help=f"write {frame_set.csv} into DIR (default: docs/ when writing the README; none with "
                             "--no-readme; a temporary directory with --smoke)")
    add_output_arguments(parser)
    args = parse_arguments(parser, sections=frame_set.sections)
    reference_name = "reference"
    if args.smoke:
        args.size, reference_name = SMOKE.frame, SMOKE.reference_level
    args.groups_given = args.groups is not None
    if args.groups is None:
        args.groups = (["ray march"] if frame_set.groups else []) if args.smoke else list(frame_set.groups)
    with tempfile.TemporaryDirectory() as temporary:
        if args.docs is None and args.smoke:
            args.docs = pathlib.Path(temporary)
        elif args.docs is None and not args.no_readme:
            args.docs = DOCS
        run(args, reference_name, frame_set)


def reference_frames(args, reference_name, frame_set, loads):
    """(frames {name: HDR}, valid mask, wall [s], process CPU [s] or None, {group: {name: change}}) of the
    reference at ``frame_set``'s suns, and how far it converged with each of ``args.groups`` doubled (plus their
    "sum"): rendered, or read from ``args.reference_cache`` (saved there when rendered). A cache that lacks a
    group ``--groups`` names gets it, measured and saved: it was ignored, and the README said it was not
    measured. ``loads``: the load averages seen, appended to."""
    from clsky._files import check_output

    def convergence(reference, valid, groups):
        return accuracy.reference_convergence(reference, valid, groups=groups, level=reference_name,
                                              elevations=frame_set.elevations)

    def save(reference, valid, seconds, cpu_seconds, change):
        save_reference_cache(args.reference_cache, reference_name, reference, valid, seconds=seconds,
                             cpu_seconds=cpu_seconds, convergence=json.dumps(change))

    if args.reference_cache and args.reference_cache.exists():
        cached = load_reference_cache(args.reference_cache, reference_name, args.size, frame_set.names)
        reference, valid = {name: cached[name] for name in frame_set.names}, cached["valid"]
        seconds, change = float(cached["seconds"]), json.loads(str(cached["convergence"]))
        cpu_seconds = float(cached["cpu_seconds"]) if "cpu_seconds" in cached else None
        missing = [group for group in args.groups if group not in change] if args.groups_given else []
        if missing:
            change.update(convergence(reference, valid, missing))
            groups = [group for group in accuracy.REFERENCE_GROUPS if group in change]     # their order, sum last
            change = {group: change[group] for group in groups}
            change["sum"] = {name: sum(change[group][name] for group in groups) for name in frame_set.names}
            save(reference, valid, seconds, cpu_seconds, change)
        args.groups = [group for group in change if group != "sum"]
        return reference, valid, seconds, cpu_seconds, change
    if args.reference_cache:    # where the cache goes, checked before the minutes of the reference
        try:
            check_output(args.reference_cache, force=True, option="--reference-cache")
        except (OSError, ValueError) as error:
            raise SystemExit(str(error)) from None
    (reference, valid), seconds, cpu_seconds = timed_with_cpu(
        lambda: accuracy.render_reference(args.size, level=reference_name, elevations=frame_set.elevations))
    loads.append(load_average())
    if args.reference_cache:        # kept even if the convergence fails (a doubled group may not fit in memory)
        save(reference, valid, seconds, cpu_seconds, {})
    change = convergence(reference, valid, args.groups) if args.groups else {}
    if args.reference_cache:
        save(reference, valid, seconds, cpu_seconds, change)
    return reference, valid, seconds, cpu_seconds, change


def write_reference_csv(path, change, names):
    """Write the reference's convergence ``change`` ({group: {frame name: change}}, "sum" last) to ``path``, one
    row a group (``doubled``, ``change <frame>`` for each of ``names``), where it holds every group of
    :data:`clsky.anim.accuracy.REFERENCE_GROUPS` and their sum: a partial sum is no resolution for the scene
    planner (:data:`clsky.renderer_choice.REFERENCE_RESOLUTION`), and the file keeps the last whole one. Returns
    what it did, in words."""
    missing = [group for group in accuracy.REFERENCE_GROUPS if group not in change]
    if missing:
        return f"{path} not written: {'; '.join(missing)} not doubled in this run"
    writers.write_csv(path, [{"doubled": group, **{f"change {n}": values[n] for n in names}}
                             for group, values in change.items()], force=True)
    return f"wrote {path}"


def run(args, reference_name, frame_set=DAY):
    """Measure the levels on ``frame_set`` against the reference, and (DAY) the default animation's plan; print
    the tables, write the CSV (``args.docs``) and, unless ``--no-readme``, the README sections, all at the
    end."""
    stamp = (f"Measured {datetime.date.today()} on {machine()}, {describe_device(default_device())} (load average "
             f"{load_average():.2f} at the start)")
    loads = []
    reference, valid, reference_seconds, reference_cpu, change = reference_frames(args, reference_name, frame_set,
                                                                                  loads)
    print(f"reference: {reference_seconds:.0f} s", flush=True)
    for group, values in change.items():
        print(f"reference, {group} doubled: {percent(values)} %", flush=True)

    rows = []
    for name, level in QUALITY_LEVELS.items():
        if name == "reference":
            continue
        plan = plan_scene(Scene(frame_set.path, quality=name))
        table, build, build_cpu = built(plan.atmosphere, plan.table, smoke=args.smoke)
        marched, render, render_cpu = frames_of(table, level.ray, args.size, frame_set.elevations)
        lookups = {method: errors(reference, frames_of(table, level.ray, args.size, frame_set.elevations,
                                                       method)[0], valid)
                   for method in ("lut", "skyview")}
        loads.append(load_average())
        error = errors(reference, marched, valid)
        rows.append({"level": name, "budget": level.budget, "table": "x".join(map(str, table.settings.size)),
                     "samples": level.ray.view_steps, "build_s": build, "build_cpu_s": build_cpu,
                     "render_s": render, "render_cpu_s": render_cpu, "load": loads[-1],
                     **{f"p95_rel {n}": error[n] for n in frame_set.names}, "worst": max(error.values()),
                     "lut_worst": max(lookups["lut"].values()), "skyview_worst": max(lookups["skyview"].values()),
                     **{f"skyview p95_rel {n}": lookups["skyview"][n] for n in frame_set.names}})
        print(rows[-1], flush=True)
    if args.docs is not None:
        args.docs.mkdir(parents=True, exist_ok=True)
        writers.write_csv(args.docs / frame_set.csv, rows, force=True)
        print(f"wrote {args.docs / frame_set.csv}", flush=True)
        print(write_reference_csv(args.docs / frame_set.reference_csv, change, frame_set.names), flush=True)

    names = frame_set.names
    lines = [f"{stamp}: {args.size} x {args.size} fisheye frames from the ground (`{frame_set.script}`). "
             f"Each level is planned for {frame_set.path_words.format(low=frame_set.path[0], high=frame_set.path[1])}"
             "; error: 95th percentile of the relative HDR luminance error of its ray-marched frames against the "
             "reference. Build: the table, its wall and process CPU time (every "
             "thread, PoCL's workers included); render: one frame by ray march, the mean of the "
             f"{frame_set.count}. The lookup and sky-view map columns are the same table's 3D lookup and default "
             "sky-view map (worst frame); load: the 1-minute load average after the row." + load_note(max(loads)),
             "", "| level | promise | table | samples | build [s] | CPU [s] | render [ms] | CPU [ms] | "
             + " | ".join(f"{n} [%]" for n in names) + " | lookup, worst [%] | sky-view map, worst [%] | load |",
             "|---|---:|---|---:|---:|---:|---:|---:|" + "---:|" * len(names) + "---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['level']} | {100 * r['budget']:g} % | {r['table']} | {r['samples']} | {r['build_s']:.2f} | "
                     f"{r['build_cpu_s']:.2f} | {1e3 * r['render_s']:.1f} | {1e3 * r['render_cpu_s']:.1f} | "
                     + percent({n: r[f"p95_rel {n}"] for n in names})
                     + f" | {100 * r['lut_worst']:.0f} | {100 * r['skyview_worst']:.2f} | {r['load']:.2f} |")
    reference_level = accuracy.reference_level(level=reference_name)
    reference_line = (f"The reference ('{reference_name}' level: "
                      + "{} x {} altitude x view ".format(*reference_level.table.size[:2])
                      + f"nodes, sun nodes every {reference_level.sun_node_spacing:g} in w on each frame's sun range, "
                      f"{reference_level.ray.view_steps} samples; {reference_seconds:.0f} s"
                      + ("" if reference_cpu is None else f" and {reference_cpu:.0f} CPU-s")
                      + f" for the {frame_set.count} frames)")
    if args.groups:
        lines += ["", reference_line + " changes this much when each group of its counts is doubled; their sum "
                  "stands for the change of doubling them all, the reference's own estimated error (which the scene "
                  "plan adds to a level's)"
                  + ("" if len(args.groups) == len(accuracy.REFERENCE_GROUPS) else
                     " (groups not doubled in this run: " + "; ".join(accuracy.REFERENCE_GROUPS[g] for g in
                                                                    accuracy.REFERENCE_GROUPS if g not in args.groups)
                     + ")") + ":", "",
                  "| doubled | " + " | ".join(f"{n} [%]" for n in names) + " |",
                  "|---|" + "---:|" * len(names)]
        for group, values in change.items():
            label = accuracy.REFERENCE_GROUPS.get(group, "**sum**")
            lines.append(f"| {label} | " + " | ".join(f"{100 * values[n]:.3f}" for n in names) + " |")
    else:
        lines += ["", reference_line + ": how far it converged at these suns was not measured (no group of its "
                  "counts doubled; `--groups` names them)."]
    markdowns = {frame_set.sections[0]: "\n".join(lines)}
    if "plan" in frame_set.sections:
        markdowns["plan"] = plan_report(args, reference, valid, stamp)
    for name, markdown in markdowns.items():
        print(markdown)
    if not args.no_readme:
        for name, markdown in markdowns.items():
            write_readme_section(name, markdown)


def plan_report(args, reference, valid, stamp):
    """The Markdown of the default animation's plan (exactly as `clsky animate` makes it) against the full table
    of the same quality, side by side, on the four frames of :data:`DAY` (``reference``: theirs)."""
    config = animate.AnimationConfig(size=SMOKE.frame) if args.smoke else animate.AnimationConfig()
    plan = animate.planned_animation(config).plan
    planned, planned_build, planned_cpu = built(plan.atmosphere, plan.table, repeat=3, smoke=args.smoke)
    full, full_build, full_cpu = built(plan.atmosphere, plan.full_table, repeat=3, smoke=args.smoke)
    plan_load = load_average()
    planned_frames, _, _ = frames_of(planned, plan.level.ray, args.size, DAY.elevations)
    full_frames, _, _ = frames_of(full, plan.level.ray, args.size, DAY.elevations)
    planned_error, full_error = errors(reference, planned_frames, valid), errors(reference, full_frames, valid)
    between = errors(full_frames, planned_frames, valid)
    cells = [int(np.prod(t.settings.size)) for t in (planned, full)]
    lines = [f"{stamp}. The plan of the README's main job (`clsky animate`: sun from -6 to 60 deg, all-sky "
             "fisheye from the ground, 1 % budget), as `clsky animate` prints it:", "", "```",
             plan.describe(), "```", "",
             "| table | sun axis | cells | build [s] | CPU [s] | " + " | ".join(f"{n} [%]" for n in DAY.names) + " |",
             "|---|---|---:|---:|---:|" + "---:|" * len(DAY.names),
             f"| planned | {planned.settings.size[2]} nodes, elevations {np.degrees(np.arcsin(plan.table.sun_cos_range[0])):.1f} "
             f"to {np.degrees(np.arcsin(plan.table.sun_cos_range[1])):.1f} deg | {cells[0]} | {planned_build:.2f} | "
             f"{planned_cpu:.2f} | "
             + percent(planned_error) + " |",
             f"| full, same quality | {full.settings.size[2]} nodes, whole axis | {cells[1]} | {full_build:.2f} | "
             f"{full_cpu:.2f} | "
             + percent(full_error) + " |",
             f"| planned vs full | | {cells[0] / cells[1]:.2f} x | {planned_build / full_build:.2f} x | "
             f"{planned_cpu / full_cpu:.2f} x | "
             + percent(between) + " |", "",
             "Errors: 95th percentile against the reference (planned vs full: between the two), ray march "
             f"{plan.level.ray.view_steps} samples, {args.size} x {args.size} frames. Build times: the least wall "
             f"and the least process CPU time of three builds each, in the same run (load average "
             f"{plan_load:.2f} after them)."]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
