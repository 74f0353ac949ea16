"""``clsky animate`` and ``clsky render``: the animation commands, added to clsky's command line.

Thin by design: parse -> :class:`clsky.anim.animate.AnimationConfig` -> library call -> one summary line.
The ``clsky`` console script runs :func:`main`, which is clsky's own command line extended with
these two commands (the core never imports clsky.anim).
"""

from __future__ import annotations

import argparse
import datetime
import sys

from clsky import cli as clsky_cli
from clsky.errors import short


def _date(text):
    try:
        return datetime.date.fromisoformat(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid date {text!r}: use YYYY-MM-DD") from None


def _add_scene_arguments(parser, frames=True):
    from clsky.quality import QUALITY_LEVELS
    from clsky.settings import SAMPLINGS

    from .animate import METHODS

    scene = parser.add_argument_group("scene")
    scene.add_argument("--camera", default="fisheye", choices=["fisheye", "perspective", "equirectangular"])
    scene.add_argument("--size", type=int, default=512, help="image height in pixels, in [16, 8192] (default: 512)")
    scene.add_argument("--fov", type=float, default=90.0,
                       help="perspective: horizontal field of view [deg], in [0.001, 179] (default: 90)")
    scene.add_argument("--heading", type=float, default=None,
                       help="perspective: azimuth of the view [deg from north] (default: 180, south); "
                            "fisheye: azimuth at the top (default: 0, north)")
    scene.add_argument("--pitch", type=float, default=10.0,
                       help="perspective: elevation of the view [deg], in [-90, 90] (default: 10)")
    scene.add_argument("--altitude", type=float, default=0.0, help="observer altitude [m], in [0, 1e8] (default: 0)")
    scene.add_argument("--method", default="compare", choices=list(METHODS),
                       help="table lookup, ray march, or a lookup and the ray march compared (default: "
                            "the plan's lookup for the budget, the sky-view map or the table; with "
                            "--table-size the table); lut4d and compare4d look "
                            "up the 4D table (altitude, view, sun, azimuth) instead of the 3D one; skyview reads "
                            "a small map ray-marched per frame")
    scene.add_argument("--skyview-size", nargs=2, type=int, metavar=("W", "H"),
                       help="--method skyview, and compare where the plan reads the map: the map's azimuth columns in "
                            "[2, 4096] and rows in [4, 4096] (default: 64 128)")
    sky = parser.add_argument_group("sky")
    sky.add_argument("--preset", help="atmosphere preset (default: physical)")
    sky.add_argument("--mode", choices=["atmosphere-plus", "physical"],
                     help="scheme of the higher orders (default: physical)")
    clsky_cli.add_atmosphere_overrides(sky)
    sky.add_argument("--error-budget", type=float,
                     help="relative error allowed in the frames; picks the fastest quality level within it "
                          "(default: 0.01)")
    sky.add_argument("--quality", choices=list(QUALITY_LEVELS), help="a named quality level instead of the budget's")
    sky.add_argument("--table-size", nargs=3, type=int, metavar=("W", "H", "D"),
                     help="a full table of this grid instead of the scene plan's (with lut4d and compare4d: "
                          "W <= 16, H even in [4, 128])")
    sky.add_argument("--samples", type=int, help="ray-march samples per ray (default: the quality level's)")
    sky.add_argument("--sampling", choices=list(SAMPLINGS),
                     help="node placement along rays, table and ray march (default: the scene planner's, "
                          "ground_end above the ground, keller_bohn on it)")
    _add_display_arguments(parser)
    sky.add_argument("--wavelengths", type=int, metavar="N",
                     help="N wavelengths in [12, 47] (fewer integrate to wrong colours) in absolute units, "
                          "frames converted spectral -> XYZ -> linear sRGB [cd/m^2] (default: the table's three, "
                          "converted the same way in cd/m^2; shown as r, g, b in the notes' units for --preset "
                          "atmosphere-plus)")
    if frames:
        sun = parser.add_argument_group("sun path")
        sun.add_argument("--frames", type=int, default=120, help="frames of the sweep, in [2, 100000] (default: 120)")
        sun.add_argument("--start-elevation", type=float, default=-6.0,
                         help="sun elevation before sunrise and after sunset [deg], in [-90, 90] (default: -6)")
        sun.add_argument("--max-elevation", type=float, default=60.0,
                         help="highest sun elevation [deg], in [--start-elevation, 90] (default: 60)")
        sun.add_argument("--location", nargs=2, type=float, metavar=("LAT", "LON"),
                         help="real sun positions (NREL SPA) at this latitude and longitude [deg]")
        sun.add_argument("--date", type=_date, help="day of the real positions, YYYY-MM-DD (default: today)")
        sun.add_argument("--hours", nargs=2, type=float, metavar=("START", "END"), default=[0.0, 24.0],
                         help="time range of the real positions [h, UTC], each in [0, 48] (default: 0 24)")
        sun.add_argument("--step-minutes", type=float, default=10.0,
                         help="time between the real positions' frames [min], in (0, 1440] and at most the "
                              "--hours range, for at most 100000 frames (default: 10)")


def _add_display_arguments(parser):
    from .display import DEFAULT_TONE_MAP, TONE_CURVES, WHITE_BALANCES

    display = parser.add_argument_group("display")
    display.add_argument("--tone-map", choices=list(TONE_CURVES),
                         help=f"tone curve (default: atmosphere-plus, the notes' curve, for --preset atmosphere-plus; "
                              f"{DEFAULT_TONE_MAP} otherwise)")
    display.add_argument("--exposure", type=float, default=0.0, metavar="EV",
                         help="exposure in EV, in [-40, 40]: frames are scaled by 2^EV (default: 0, the frames' "
                              "own values; the old multiplier x is log2(x); about -13 shows a day sky in cd/m^2); "
                              "with auto-exposure, a compensation")
    display.add_argument("--auto-exposure", action=argparse.BooleanOptionalAction,
                         help="meter each frame's log-average luminance to a key of 0.36 (a stop above mid-grey), "
                              "smoothed over the frames (default: on for frames in cd/m^2, every preset but "
                              "atmosphere-plus; off for atmosphere-plus); --no-auto-exposure: the fixed --exposure")
    display.add_argument("--white-balance", choices=list(WHITE_BALANCES),
                         help="white: d65 (none) or the sun's colour adapted to D65 (CAT02) (default: sun for "
                              "frames in cd/m^2, d65 for --preset atmosphere-plus)")


def _add_scene_file_arguments(parser):
    """--scene and --print-scene (anim/scene.py), and the record of the options typed, which win over
    the scene's values."""
    from . import scene

    group = parser.add_argument_group("scene file")
    group.add_argument("--scene", metavar="FILE", help="read the options from a TOML scene (README 'Scene "
                                                       "files'); options typed here win over its values")
    group.add_argument("--print-scene", action="store_true",
                       help="write the TOML scene of this command line to stdout and exit (no work)")
    scene.track_given_options(parser)
    parser.set_defaults(scene_parser=parser)


def register(commands):
    """Adds ``animate`` and ``render`` to clsky's sub-command parsers; returns their handlers."""
    from .exr import HDR_FORMATS, PRECISIONS

    animate = commands.add_parser("animate", help="render a sunrise-to-sunset animation (MP4 + PNG frames)")
    _add_scene_arguments(animate)
    output = animate.add_argument_group("output")
    output.add_argument("-o", "--output", default="sky.mp4",
                        help="MP4 file; frames go to <stem>_frames/, metrics to <stem>_metrics.csv/.json")
    output.add_argument("--fps", type=float, default=30.0,
                        help="frames per second of the MP4, in [0.01, 240] (default: 30)")
    output.add_argument("--no-dither", action="store_true", help="do not dither the 8-bit frames")
    formats = [name for name in HDR_FORMATS if name is not None]
    output.add_argument("--hdr", nargs="?", const="npy", choices=formats, metavar="{" + ",".join(formats) + "}",
                        help="also write HDR frames: the ray march's (with --method compare or compare4d), else the "
                             "frame the method renders; exr: OpenEXR with units, version and sun in the header, a "
                             "latitude-longitude environment map for --camera equirectangular (docs/exr.md); hdr: "
                             "Radiance RGBE, the same header but the scene (8-bit mantissas); npy (the default of a "
                             "bare --hdr): float32 NumPy arrays")
    output.add_argument("--hdr-precision", choices=list(PRECISIONS), default="float",
                        help="pixel type of the EXR frames: float (32-bit, default) or half (16-bit; values above "
                             "65504, the sun's disc, are clipped to it and counted in the header)")
    output.add_argument("--force", action="store_true", help="overwrite existing outputs")
    clsky_cli.add_progress_argument(output)
    clsky_cli.add_farm_arguments(animate)

    render = commands.add_parser("render", help="render one frame (PNG)")
    _add_scene_arguments(render, frames=False)
    sun = render.add_argument_group("sun")
    sun.add_argument("--sun-elevation", type=float, default=10.0, help="[deg], in [-90, 90] (default: 10)")
    sun.add_argument("--sun-azimuth", type=float, default=180.0,
                     help="[deg from north], in [-360, 720] (default: 180, south)")
    out = render.add_argument_group("output")
    out.add_argument("-o", "--output", default="sky.png", help="PNG file (default: sky.png)")
    out.add_argument("--force", action="store_true", help="overwrite an existing file")
    out.add_argument("--no-dither", action="store_true")
    _add_scene_file_arguments(animate)
    _add_scene_file_arguments(render)
    bench = commands.add_parser("bench", help="measurements: `clsky bench accuracy`")
    kinds = bench.add_subparsers(dest="bench", required=True, parser_class=clsky_cli._Parser)
    accuracy = kinds.add_parser("accuracy", help="what each numerical knob costs and buys (CSV, Pareto plot, "
                                                 "error per sun elevation)")
    accuracy.add_argument("--size", type=int, default=128,
                          help="fisheye frames of SIZE x SIZE, in [16, 2048] (default: 128)")
    accuracy.add_argument("-o", "--output", default="accuracy.csv", help="CSV of the candidates (default: %(default)s)")
    accuracy.add_argument("--plot", default="accuracy.png", help="Pareto plot, PNG (default: %(default)s)")
    accuracy.add_argument("--elevation-plot", metavar="PNG",
                          help="error against sun elevation per renderer, PNG (default: beside --plot, "
                               "accuracy_elevation.png for accuracy.png)")
    accuracy.add_argument("--reference-quality", default="reference", choices=["reference", "high", "default"],
                          help="quality level of the reference frames (default: reference, ~5 min to build; "
                               "a cheaper one for smoke runs)")
    accuracy.add_argument("--quick", action="store_true",
                          help="four candidates only: the default table, two ray marches and a 32 x 64 sky-view "
                               "map; still against --reference-quality's frames (with --reference-quality default, "
                               "a smoke run)")
    accuracy.add_argument("--force", action="store_true", help="overwrite existing outputs")
    clsky_cli.add_progress_argument(accuracy)
    return {"animate": run_animate, "render": run_render, "bench": run_bench}


def _config(args):
    """The AnimationConfig of the options (with --scene's values for those not typed); options not
    given (None) keep the config's defaults. UsageError names the option, or the scene file and key,
    of a bad value."""
    import dataclasses

    from clsky.errors import ParameterError

    from . import scene
    from .animate import AnimationConfig

    names = {field.name for field in dataclasses.fields(AnimationConfig)}
    values = scene.field_values(args, args.scene_parser)
    if args.command == "render":                 # its --output is a PNG, not the animation's MP4
        values.pop("output")
    fields = {name: value for name, value in values.items() if name in names and value is not None}
    try:
        return AnimationConfig(force=args.force, **fields)
    except ParameterError as error:
        raise _usage_error(args, error) from None


def _usage_error(args, error):
    """The UsageError of a ParameterError of a config field: naming the option typed, or the scene file and
    key its value came from."""
    from . import scene

    where = scene.source_of(args, error.field)
    if where is not None:
        return clsky_cli.UsageError(error.reworded(where if error.index is None else f"{where}[{error.index}]"))
    return clsky_cli.UsageError(clsky_cli.option_message(error, scene.field_options(args.scene_parser)))


#: The options of each sun path (their dests): the sweep's, and the real positions' but --location.
SWEEP_OPTIONS = ("frames", "start_elevation", "max_elevation")
REAL_POSITION_OPTIONS = ("date", "hours", "step_minutes")
#: The methods whose frames have no ray march (--samples unused) and those without the sky-view map
#: (--skyview-size unused; 'compare' reads it where the scene plan picks it, never with --table-size).
METHODS_WITHOUT_RAY_MARCH = ("lut", "lut4d")
METHODS_WITHOUT_SKYVIEW = ("lut", "raymarch", "lut4d", "compare4d")


def _unused_options(args):
    """[(dest, why)]: the options of this command line that its frames would not use (the camera's that
    its --camera does not take, the ray march's and the sky-view map's where --method renders neither, the
    budget where a quality level is named, the sun path's not taken), each with why, for a message that
    begins with the option."""
    from . import scene

    def where(dest, option):
        return scene.source_of(args, dest) or option

    camera, method = args.camera, args.method
    unused = []
    if camera != "perspective":
        unused += [(dest, f"sets the perspective camera's view, not the {camera}'s (--camera perspective)")
                   for dest in ("fov", "pitch")]
    if camera == "equirectangular":
        unused.append(("heading", "turns the fisheye and the perspective camera: the equirectangular panorama's "
                                  "columns are fixed azimuths, north at its left edge"))
    if method in METHODS_WITHOUT_RAY_MARCH:
        unused.append(("samples", f"sets the ray march, which method '{method}' does not render"))
    if method in METHODS_WITHOUT_SKYVIEW:
        unused.append(("skyview_size", f"sets the sky-view map, which method '{method}' does not read"))
    elif method == "compare" and args.table_size is not None:
        unused.append(("skyview_size", f"sets the sky-view map, which method 'compare' does not read with "
                                       f"{where('table_size', '--table-size')}: without a scene plan it compares "
                                       f"the ray march with the 3D table lookup"))
    if getattr(args, "hdr", None) != "exr" and hasattr(args, "hdr_precision"):     # animate's HDR frames
        frames = f"{where('hdr', '--hdr')} ({args.hdr}) writes" if args.hdr else "without --hdr clsky writes"
        unused.append(("hdr_precision", f"sets the EXR frames' pixel type, and {frames} no EXR frames (--hdr exr)"))
    if args.quality is not None:
        unused.append(("error_budget", f"picks a quality level, and {where('quality', '--quality')} names one "
                                       f"({args.quality}): give one of them"))
    if hasattr(args, "location"):                               # animate's sun path
        if args.location is not None:
            unused += [(dest, f"sets the sweep, which real sun positions ({where('location', '--location')}) "
                              f"replace: their frames are every --step-minutes from --hours START to END")
                       for dest in SWEEP_OPTIONS]
        else:
            unused += [(dest, "sets real sun positions: give --location LAT LON too (the sweep takes --frames, "
                              "--start-elevation and --max-elevation)") for dest in REAL_POSITION_OPTIONS]
    return unused


def _check_options_used(args):
    """UsageError (exit 2) for an option typed on the command line that the frames would not use
    (:func:`_unused_options`): refused, not ignored. A scene file's keys are not refused: a scene holds
    every key (``--print-scene`` writes them all, both sun paths' among them)."""
    from clsky.errors import ParameterError

    from . import scene
    from .animate import check_location

    given = getattr(args, "given_options", {}) or {}
    try:                 # the sweep's options are refused in --location's name: a bad --location is named first
        check_location("location", scene.field_values(args, args.scene_parser).get("location"))
    except ParameterError as error:
        raise _usage_error(args, error) from None
    for dest, why in _unused_options(args):
        if dest in given:
            raise clsky_cli.UsageError(f"{given[dest]} {why}")


def _printed_scene(args, config, **extra):
    """With --print-scene: the TOML scene of the command line, printed (True); else False."""
    from . import scene

    if not args.print_scene:
        return False
    print(scene.scene_text(scene.scene_values(config, args.scene_parser, extra), args.command), end="")
    return True


def _memory_options(args, config):
    """The options each part of an animation's memory comes from, for InsufficientMemoryError."""
    if args.table_size is not None:
        table = "--table-size " + " ".join(str(n) for n in args.table_size)
    elif args.quality is not None:
        table = f"--quality {args.quality}"
    else:
        typed = "" if args.error_budget is not None else " (the default)"
        table = f"--error-budget {config.error_budget:g}{typed}"
    sequence = f"--frames {config.frames}" if config.location is None else f"--step-minutes {config.step_minutes:g}"
    return {"table": table, "frames": f"--size {config.size}", "sequence": sequence}


def _check_memory(args, config, positions):
    """Refuse, before any work, an animation or frame that does not fit the machine (exit 2, one line)."""
    from clsky.resources import device_of

    from .animate import check_animation_memory

    check_animation_memory(config, positions, device_of(), options=_memory_options(args, config))


def run_animate(args):
    from clsky.allocator import reuse_freed_memory

    from . import scene
    from .animate import check_outputs, render_animation, sun_positions

    reuse_freed_memory()                         # before the frames' threads: their memory kept for the next frames
    scene.apply_scene(args, args.scene_parser)
    if not args.print_scene:                     # which writes every option typed (README "Command line")
        _check_options_used(args)                # before the values: an unused option is named as such
    config = _config(args)
    farm = clsky_cli.farm_of(args)               # --workers / --scheduler: checked, started after the checks
    if _printed_scene(args, config):
        return 0
    option = scene.source_of(args, "output") or "--output"
    clsky_cli.check_not_inputs([(option, path) for path in (config.output_path, config.metrics_path(".csv"),
                                                            config.metrics_path(".json")) if path is not None],
                               [("the --scene file", args.scene)])
    try:                                         # the MP4, <stem>_frames/, <stem>_metrics.csv/.json
        check_outputs(config, option=option)
    except (OSError, ValueError, ImportError) as error:
        raise clsky_cli.UsageError(str(error)) from None
    _check_memory(args, config, sun_positions(config))
    progress, close = clsky_cli.progress_bar(args.progress)
    try:
        with clsky_cli.running_farm(farm):
            result = render_animation(config, progress=progress, report=print, farm=farm)
    except FileExistsError as error:      # another run wrote an output since the check: named as the option's
        if config.force or getattr(error, "path", None) is None:
            raise
        raise clsky_cli.written_meanwhile(option, error.path, getattr(error, "committed", ())) from None
    finally:
        close()
    print(result.summary)
    return 0


def run_render(args):
    from clsky._files import StagedWrites, check_suffix

    from . import scene, writers
    from .animate import (LOOKUP_NAMES, comparison, display, display_frames, exposure_limit_note, lookup_of,
                          make_renderer, planned_animation, render_frame)
    from .cameras import AZIMUTH_RANGE_DEG, sun_direction
    from .sunpath import SunPosition

    scene.apply_scene(args, args.scene_parser)

    def name(key, option):
        return scene.source_of(args, key) or option

    if not -90.0 <= args.sun_elevation <= 90.0:
        raise clsky_cli.UsageError(f"{name('sun_elevation_deg', '--sun-elevation')} must be in [-90, 90] degrees, "
                                   f"got {short(args.sun_elevation)}")
    low, high = AZIMUTH_RANGE_DEG                       # --heading's range
    if not low <= args.sun_azimuth <= high:
        raise clsky_cli.UsageError(f"{name('sun_azimuth_deg', '--sun-azimuth')} must be in [{low:g}, {high:g}] "
                                   f"degrees, got {short(args.sun_azimuth)}")
    try:
        output = check_suffix(args.output, ".png", name("output", "--output"))
    except ValueError as error:
        raise clsky_cli.UsageError(str(error)) from None
    if not args.print_scene:
        _check_options_used(args)
    config = _config(args)
    extra = {"sun_elevation_deg": args.sun_elevation, "sun_azimuth_deg": args.sun_azimuth, "output": args.output}
    if _printed_scene(args, config, **extra):
        return 0
    clsky_cli.check_not_inputs([(name("output", "--output"), output)], [("the --scene file", args.scene)])
    clsky_cli.check_outputs([(name("output", "--output"), output)], args.force)
    try:
        writers.require_pillow()
    except ImportError as error:
        raise clsky_cli.UsageError(str(error)) from None
    position = SunPosition(90.0 - args.sun_elevation, args.sun_azimuth)
    _check_memory(args, config, [position])
    planned = planned_animation(config, [position])
    camera, directions, valid, plan = planned.camera, planned.directions, planned.valid, planned.plan
    if plan is not None:
        print(plan.describe())
    renderer, table = make_renderer(config, plan)          # the frame reads data and gathered only
    sun = sun_direction(90.0 - args.sun_elevation, args.sun_azimuth)
    lookup = lookup_of(config, plan)
    hdr = render_frame(renderer, renderer.prepare(directions, valid), sun, config, lookup)
    ev, images, shown = display_frames(display(config, table), hdr, valid, config)
    if config.compares:
        image, numbers, _ = comparison(hdr, images, shown, valid)
        detail = f"; {LOOKUP_NAMES[lookup]} vs ray march: 95th-percentile error {100 * numbers['p95_rel']:.1f} %"
    else:
        image, detail = images[next(iter(hdr))], ""
    text = scene.output_metadata(scene.scene_text(scene.scene_values(config, args.scene_parser, extra), "render"))
    staging = StagedWrites()
    # another run that wrote the frame meanwhile is named as --output's, as a table's or an animation's is
    with clsky_cli.written_since_checked([(name("output", "--output"), output)], staging, args.force), staging:
        writers.write_png(output, image, force=args.force, text=text, staging=staging)
    if note := exposure_limit_note(config, [ev]):
        detail += f"; {note}"
    print(f"frame {camera.width}x{camera.height} ({config.method}, sun elevation {args.sun_elevation:g} deg, "
          f"azimuth {args.sun_azimuth:g} deg, {config.tone_map} at {ev:+.2f} EV){detail} -> {output}")
    return 0


def run_bench(args):
    from clsky._files import check_suffix

    from . import accuracy, accuracy_plot, writers

    if not 16 <= args.size <= 2048:
        raise clsky_cli.UsageError(f"--size must be an integer in [16, 2048], got {short(args.size)}")
    try:                                           # the elevation plot's default comes from a checked --plot
        targets = {option: check_suffix(path, suffix, option) for option, path, suffix in (
            ("--output", args.output, ".csv"), ("--plot", args.plot, ".png"))}
        elevation_plot = (args.elevation_plot if args.elevation_plot is not None else
                          str(accuracy_plot.elevation_plot_path(targets["--plot"])))
        targets["--elevation-plot"] = check_suffix(elevation_plot, ".png", "--elevation-plot")
    except ValueError as error:
        raise clsky_cli.UsageError(str(error)) from None
    if targets["--elevation-plot"].resolve() == targets["--plot"].resolve():
        raise clsky_cli.UsageError(f"--elevation-plot must differ from --plot, got {str(targets['--plot'])!r} twice")
    clsky_cli.check_outputs(targets.items(), args.force)
    try:                                           # the plots need both: refuse before measuring
        accuracy_plot.require_plotting()
        writers.require_pillow()
    except ImportError as error:
        raise clsky_cli.UsageError(str(error)) from None
    candidates = accuracy.default_candidates()
    if args.quick:
        candidates = [c for c in candidates if c.label in ("default", "ray march 16 samples", "ray march 48 samples",
                                                           "sky-view 32 x 64")]
    progress, close = clsky_cli.progress_bar(args.progress)
    try:
        reference, valid = accuracy.render_reference(args.size, level=args.reference_quality, progress=progress)
        rows = accuracy.measure(candidates, reference, valid, progress=progress)
    finally:
        close()
    accuracy_plot.write_sweep(rows, targets["--output"], targets["--plot"], targets["--elevation-plot"], args.size,
                              args.reference_quality, force=args.force)
    for row in rows:
        print(f"{row['candidate']:>24}: build {row['build_s']:6.2f} s ({row['build_cpu_s']:6.2f} CPU-s), frame "
              f"{1e3 * row['render_s']:7.1f} ms ({1e3 * row['render_cpu_s']:7.1f} CPU-ms), "
              f"worst p95 error {100 * row['p95_rel']:8.2f} %, worst mean Delta E {row['mean_delta_e']:6.2f}")
    print(f"{len(rows)} candidates on {args.size} x {args.size} frames, against the '{args.reference_quality}' "
          f"level's -> {targets['--output']}, {targets['--plot']}, {targets['--elevation-plot']}")
    return 0


def main(argv=None):
    """The ``clsky`` command: clsky's command line plus ``animate`` and ``render``."""
    return clsky_cli.main(argv, extensions=(register,))


if __name__ == "__main__":
    sys.exit(main())
