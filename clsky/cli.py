"""Command line: ``clsky devices``, ``clsky info`` and ``clsky table``.

Thin by design: parse, build the configuration objects, call the library, write. Bad arguments give
one line on stderr and exit status 2; ``--verbose`` shows tracebacks of unexpected errors. Every output
path is checked before any work (:func:`check_outputs`). SIGINT, SIGTERM and SIGHUP take the same
path: the temporary files are deleted, one line on stderr, exit status 128 + the signal's number
(130, 143, 129).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import pathlib
import signal
import sys
import threading
import time

from . import __version__
from ._files import INTERRUPT_SIGNALS, binary_and_header, check_suffix
from .errors import short

EXIT_USAGE = 2
EXIT_FAILURE = 1


class UsageError(Exception):
    """A bad command-line value: reported in one line, exit status 2."""


class Interrupted(KeyboardInterrupt):
    """A signal (SIGINT, SIGTERM, SIGHUP) turned into a KeyboardInterrupt, so that every ``with`` and
    ``finally`` cleans up as for Ctrl-C; ``signum`` is the signal's number."""

    def __init__(self, signum):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _interrupt(signum, frame):
    # Later signals are ignored while the interrupted command deletes its temporary files.
    for other in INTERRUPT_SIGNALS:
        signal.signal(other, signal.SIG_IGN)
    raise Interrupted(signum)


@contextlib.contextmanager
def signals_interrupt():
    """Within the block, SIGINT, SIGTERM and SIGHUP raise :class:`Interrupted` (main thread only;
    elsewhere the block runs unchanged); the previous handlers come back after it. A signal ignored
    when clsky started stays ignored (``nohup`` ignores SIGHUP, a shell's ``&`` SIGINT)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {number: signal.signal(number, _interrupt) for number in INTERRUPT_SIGNALS
                if signal.getsignal(number) not in (signal.SIG_IGN, None)}
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)


@contextlib.contextmanager
def written_since_checked(targets, staging, force):
    """Within the block, which ends by committing ``staging`` (:class:`clsky._files.StagedWrites`): the
    FileExistsError of an output that :func:`check_outputs` found absent before the work (without
    ``force``) but that exists when it is put in place, another run on the same output having written it
    meanwhile, is a UsageError naming its option (``targets``: (option, path)) rather than the library's
    hint of ``force=True``, and the files this run put in place before it."""
    try:
        yield
    except FileExistsError:
        if force:
            raise
        ours = {os.path.abspath(path) for path in staging.committed}
        for option, path in targets:
            if os.path.lexists(path) and os.path.abspath(path) not in ours:
                raise written_meanwhile(option, path, staging.committed) from None
        raise


def written_meanwhile(option, path, committed=()):
    """The UsageError of an output at ``path`` that was absent when :func:`check_outputs` looked and that
    another run wrote before this one put its own in place: named as ``option``'s (the file may be one
    derived from it, an animation's metrics from its --output), in :func:`clsky._files.check_output`'s form
    ('--output: FILE exists'), with the files this run had already put in place (``committed``)."""
    placed = f"; this run's files already in place: {', '.join(map(str, committed))}" if committed else ""
    return UsageError(f"{option}: {path} exists: another process wrote it during this run; use --force to "
                      f"overwrite it{placed}")


def check_not_inputs(targets, inputs):
    """UsageError for an output that is one of the command's input files (``inputs``: (what, path), path None
    when not given): with --force it replaced the scene or sweep file it was read from."""
    for what, source in inputs:
        if source is None:
            continue
        source = pathlib.Path(source).resolve()
        for option, path in targets:
            if pathlib.Path(path).resolve() == source:
                raise UsageError(f"{option} {path} is {what} itself: write the output elsewhere")


def check_outputs(targets, force):
    """Check output paths before any work; the first that cannot be written is a UsageError.

    Parameters
    ----------
    targets : iterable of (str, path)
        The option that names each output ('--output', '--raw') and the file.
    force : bool
        Existing files may be replaced (--force).

    Raises
    ------
    UsageError
        One line naming the option and the path: it exists (without --force), is a directory,
        its directory is missing or not one, nothing can be created there, or a name is too long
        (:func:`clsky._files.check_output`).
    """
    from ._files import check_output

    for option, path in targets:
        try:
            check_output(path, force, option)
        except (OSError, ValueError) as error:
            raise UsageError(str(error)) from None


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line instead of argparse's usage block
        raise UsageError(message)


STAGE_LABELS = {"single": ("single scattering", "slab"), "orders": ("scattering orders", "order"),
                "frames": ("frames", "frame"), "tables": ("tables", "table"),
                "reference": ("reference frames", "frame"), "candidates": ("candidates", "candidate"),
                "reference convergence": ("reference convergence", "group")}
#: --progress's choices; "auto", the default, is "leave" where stderr is a terminal and "none" elsewhere.
PROGRESS_MODES = ("auto", "display", "leave", "none")
#: The bar of a stage whose total is unknown (the orders, iterated to convergence): how many, and since when
#: (tqdm's own form, "6order [00:00, 470.20order/s]", ran the count into its unit).
COUNTING_BAR = "{desc}: {n_fmt} [{elapsed}]"


def add_progress_argument(group):
    """The --progress option of the commands that show progress bars (table, animate, bench accuracy)."""
    group.add_argument("--progress", default="auto", choices=PROGRESS_MODES,
                       help="progress bars on stderr: leave (each stage's bar stays), display (cleared when "
                            "done), none; auto (default): leave on a terminal, none in a pipe or log file")


def progress_bar(mode):
    """A tqdm-driven ``progress(stage, done, total)`` callable (or None) and its closer; one bar per
    stage, on stderr (``mode``: one of :data:`PROGRESS_MODES`), made at the stage's first report (its rate
    counts the steps after that one: a bar that began at the first frame's end said 26379 frame/s). The
    orders' total is unknown when they iterate to convergence: their bar counts them."""
    if mode == "auto":
        mode = "leave" if sys.stderr.isatty() else "none"
    if mode == "none":
        return None, lambda: None
    from tqdm import tqdm

    bars = {}

    def update(stage, done, total):
        if stage not in bars:
            for bar in bars.values():
                bar.close()
            label, unit = STAGE_LABELS.get(stage, (stage, "step"))
            counting = stage == "orders"
            bars[stage] = tqdm(desc=label, unit=" " + unit, leave=(mode == "leave"), file=sys.stderr,
                               dynamic_ncols=True, total=None if counting else total, initial=done,
                               bar_format=COUNTING_BAR if counting else None)
        bar = bars[stage]
        bar.n = done
        bar.refresh()

    def close():
        for bar in bars.values():
            bar.close()

    return update, close


def _orders(text):
    if text == "auto":
        return text
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid value {text!r}: an integer K >= 1 or 'auto'") from None


def _add_table_arguments(parser):
    """The table's options. Those that set a TableSettings field default to None: unset, they take the
    value of the --quality level (or of TableSettings)."""
    from .atmosphere import PRESETS
    from .quality import QUALITY_LEVELS
    from .settings import (MAPPINGS, MIE_LAYOUTS, PARAMETERIZATIONS, SAMPLINGS, SCATTERING_MODES,
                           SUN_TRANSMITTANCE_METHODS)

    physics = parser.add_argument_group("atmosphere")
    physics.add_argument("--preset", default="atmosphere-plus", choices=sorted(PRESETS),
                         help="atmosphere preset (default: %(default)s)")
    add_atmosphere_overrides(physics)
    grid = parser.add_argument_group("table")
    grid.add_argument("--quality", choices=list(QUALITY_LEVELS),
                      help="start from a named quality level's settings (clsky/quality.py); the options "
                           "below override them (the defaults they state are those without --quality; the "
                           "levels' strides, TableSettings.source_stride and orders_sun_stride, have no option)")
    grid.add_argument("--size", nargs=3, type=int, metavar=("W", "H", "D"),
                      help="nodes along altitude, view zenith, sun zenith (default: 32 256 32)")
    grid.add_argument("--sun-elevations", nargs=2, type=float, metavar=("LOW", "HIGH"),
                      help="plan the sun axis for sun elevations LOW to HIGH [deg] only, with the margins "
                           "that curvature and higher orders need (clsky/planner.py); D keeps the quality "
                           "level's node spacing unless --size sets it")
    grid.add_argument("--mapping", choices=sorted(MAPPINGS))
    grid.add_argument("--parameterization", choices=list(PARAMETERIZATIONS),
                      help="elek3d (default): altitude x view x sun; 4d: an azimuth axis too, the view axis "
                           "split at the horizon (clsky/table4d.py; needs --mode physical)")
    grid.add_argument("--azimuth-size", type=int, metavar="A",
                      help="azimuth nodes of a 4d table (default: 16)")
    grid.add_argument("--mie-layout", choices=sorted(MIE_LAYOUTS))
    orders = parser.add_argument_group("scattering orders")
    orders.add_argument("--orders", type=_orders, help="K: compute orders 1..K (1 = single scattering); "
                                                       "auto: until converged (default)")
    orders.add_argument("--mode", choices=list(SCATTERING_MODES),
                        help="scheme of the higher orders (default: the --quality level's, else physical for an "
                             "atmosphere with a reflecting ground, such as --preset physical, else atmosphere-plus)")
    orders.add_argument("--azimuth-harmonics", type=int, metavar="M",
                        help="the physical mode's orders k >= 2 carry M cosine harmonics of the view-sun "
                             "azimuth (clsky/azimuth.py; 2 fixes twilight, README 'Twilight against Monte "
                             "Carlo'; default: the --quality level's, 2 for reference, else 0, the azimuth "
                             "average; with --sun-elevations the scene planner's, 2 when LOW is below 30 deg)")
    orders.add_argument("--order-tolerance", type=float, help="auto stops when an order adds less than this "
                                                              "(default: 1e-4)")
    orders.add_argument("--max-orders", type=int, help="most orders auto computes (default: 100)")
    orders.add_argument("--gather-steps", nargs=2, type=int, metavar=("THETA", "PHI"),
                        help="trapezoid steps of the gather's sphere integral (default: 256 128)")
    numerics = parser.add_argument_group("numerics")
    numerics.add_argument("--dtype", choices=["float64", "float32"])
    numerics.add_argument("--view-steps", type=int, help="trapezoid steps per view ray (default: 30)")
    numerics.add_argument("--sun-steps", type=int, help="trapezoid steps per sun ray (default: 30)")
    numerics.add_argument("--sampling", choices=list(SAMPLINGS),
                          help="node placement along rays (default: keller_bohn; ground_end for views from "
                               "altitude, README 'Views from altitude')")
    numerics.add_argument("--sun-transmittance", choices=list(SUN_TRANSMITTANCE_METHODS))
    numerics.add_argument("--multiple-view-steps", type=int,
                          help="trapezoid steps per view ray for the orders k >= 2 (default: 20)")
    numerics.add_argument("--transmittance-size", nargs=2, type=int, metavar=("TW", "TH"),
                          help="2D transmittance table (default: 64 256)")
    numerics.add_argument("--backend", default="opencl", choices=["opencl", "numpy"])
    numerics.add_argument("--fast-math", action="store_true", help="build kernels with -cl-fast-relaxed-math")
    output = parser.add_argument_group("output")
    output.add_argument("-o", "--output", help=f"table file (.npz, default: {DEFAULT_TABLE_OUTPUT}; with --sweep, "
                                               f"each line's own)")
    output.add_argument("--raw", metavar="NAME", help="also export NAME.bin (float32) + NAME.json for GPU engines "
                                                      "(NAME.bin or NAME.json names the same pair)")
    output.add_argument("--texture", metavar="NAME", help="a 4d table: also export NAME.bin + NAME.json as the "
                                                          "three RGBA float32 3D textures docs/lookup4d.glsl reads")
    output.add_argument("--force", action="store_true", help="overwrite existing output files")
    add_progress_argument(output)
    output.add_argument("--sweep", metavar="FILE",
                        help="one table per line of FILE: each line holds table options (at least -o), which "
                             "win over the command line's (README 'Frame farms (Dask)'); the files land together")
    add_farm_arguments(parser)


def add_farm_arguments(parser):
    """--workers and --scheduler (clsky/farm.py), for ``clsky table`` and ``clsky animate`` alike."""
    farm = parser.add_argument_group("farm (Dask, pip install 'clsky[dask]')")
    where = farm.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, metavar="N",
                       help="run on an embedded Dask LocalCluster of N worker processes (the table is built "
                            "here, the frames or sweep's tables on the workers)")
    where.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                       help="run on the existing Dask cluster of this scheduler (its workers need clsky)")


def farm_of(args):
    """The :class:`clsky.farm.Farm` of --workers or --scheduler, checked but not started (None without
    either). UsageError (exit 2) names the option: a bad value, or Dask not installed."""
    if getattr(args, "workers", None) is None and getattr(args, "scheduler", None) is None:
        return None
    from .errors import ParameterError
    from .farm import Farm, require_dask

    option = "--workers" if args.workers is not None else "--scheduler"
    try:
        require_dask(option)
        return Farm(workers=args.workers, scheduler=args.scheduler)
    except ImportError as error:
        raise UsageError(str(error)) from None
    except ParameterError as error:
        raise UsageError(error.reworded(option)) from None


@contextlib.contextmanager
def running_farm(farm):
    """Start ``farm`` (None: nothing) for the block and close it after; a scheduler that does not answer
    is a UsageError naming --scheduler."""
    if farm is None:
        yield None
        return
    try:
        farm.start()
    except ConnectionError as error:
        raise UsageError(f"--scheduler: {error}") from None
    try:
        print(farm.describe())
        yield farm
    finally:
        farm.close()


#: TableSettings field -> the attribute of the parsed arguments that sets it (None: not given).
SETTING_OPTIONS = {"size": "size", "mapping": "mapping", "view_steps": "view_steps", "sun_steps": "sun_steps",
                   "sampling": "sampling", "sun_transmittance": "sun_transmittance",
                   "transmittance_size": "transmittance_size", "mie_layout": "mie_layout", "dtype": "dtype",
                   "mode": "mode", "orders": "orders", "order_tolerance": "order_tolerance",
                   "max_orders": "max_orders", "multiple_view_steps": "multiple_view_steps",
                   "azimuth_harmonics": "azimuth_harmonics", "parameterization": "parameterization",
                   "azimuth_size": "azimuth_size"}

#: TableSettings field -> the option a user types, or one per item of a tuple field; for messages.
TABLE_OPTION_NAMES = {
    "size": ("--size W", "--size H", "--size D"), "mapping": "--mapping", "view_steps": "--view-steps",
    "sun_steps": "--sun-steps", "sampling": "--sampling", "sun_transmittance": "--sun-transmittance",
    "transmittance_size": ("--transmittance-size TW", "--transmittance-size TH"), "mie_layout": "--mie-layout",
    "dtype": "--dtype", "mode": "--mode", "orders": "--orders", "order_tolerance": "--order-tolerance",
    "max_orders": "--max-orders", "multiple_view_steps": "--multiple-view-steps",
    "azimuth_harmonics": "--azimuth-harmonics", "parameterization": "--parameterization",
    "azimuth_size": "--azimuth-size", "gather_theta_steps": "--gather-steps THETA", "gather_phi_steps": "--gather-steps PHI",
    "sun_cos_range": "--sun-elevations", "quality": "--quality", "preset": "--preset",
    "ground_albedo": "--ground-albedo", "ozone_column_du": "--ozone-column",
}


def add_atmosphere_overrides(group):
    """--ground-albedo and --ozone-column (the fields of :data:`clsky.atmosphere.OVERRIDE_RANGES`, None
    when not given), for ``clsky table`` and the animation's commands alike."""
    from .atmosphere import EARTH_GROUND_ALBEDO, OVERRIDE_RANGES

    low, high, _ = OVERRIDE_RANGES["ground_albedo"]
    group.add_argument("--ground-albedo", type=float, metavar="A",
                       help=f"albedo of a Lambertian ground in [{low:g}, {high:g}] (default: the preset's, "
                            f"{EARTH_GROUND_ALBEDO:g} for physical, the Earth's mean, 0 for atmosphere-plus; "
                            f"> 0 is the physical mode's, the default mode then; --mode atmosphere-plus refuses it)")
    low, high, unit = OVERRIDE_RANGES["ozone_column_du"]
    group.add_argument("--ozone-column", type=float, metavar="DU", dest="ozone_column_du",
                       help=f"ozone column in Dobson units, in [{low:g}, {high:g}]{unit}, in Bruneton 2017's tent "
                            f"(10 to 40 km) (default: the preset's, 300 for physical, 0 for atmosphere-plus)")


def table_atmosphere(args):
    """The atmosphere of the table options: the --preset's, with --ground-albedo and --ozone-column if
    given. UsageError names the option of a bad value."""
    from .atmosphere import OVERRIDE_RANGES, preset
    from .errors import ParameterError, check_real

    changes = {field: getattr(args, field) for field in OVERRIDE_RANGES if getattr(args, field, None) is not None}
    try:
        for field, value in changes.items():
            low, high, unit = OVERRIDE_RANGES[field]
            check_real(field, value, low, high, unit=unit)
        return preset(args.preset).replace(**changes)
    except ParameterError as error:
        raise UsageError(option_message(error, TABLE_OPTION_NAMES)) from None


def option_message(error, options):
    """The message of a :class:`clsky.errors.ParameterError` naming the option the user typed:
    ``options`` maps a field to its option, or to one option per item of a tuple field. Fields
    without an option keep their name."""
    option = options.get(error.field)
    if isinstance(option, tuple):
        option = option[error.index] if error.index is not None else option[0].split(" ")[0]
    if option is None:
        return str(error)
    return error.reworded(option)


#: The table file `clsky table` writes without -o.
DEFAULT_TABLE_OUTPUT = "table.npz"


def table_settings(args, atmosphere):
    """TableSettings from the table options: the --quality level's (or the defaults), overridden by the
    options given, with the sun axis planned for --sun-elevations. UsageError names the option."""
    from .errors import ParameterError

    from .ground import check_ground_mode
    from .table4d import check_atmosphere

    try:
        settings = _table_settings(args, atmosphere)
        check_ground_mode(atmosphere, settings.mode, "" if getattr(args, "ground_albedo", None) is not None
                          else f"the {args.preset} preset's ground")
        if settings.is_4d:              # here, not at the build: named as an option, a sweep's line too
            check_atmosphere(atmosphere, settings)
    except ParameterError as error:
        if (error.field == "azimuth_harmonics" and getattr(args, "azimuth_harmonics", None) is None
                and getattr(args, "gather_steps", None) is not None):     # the level's or planner's M: PHI is typed
            harmonics = error.value
            raise UsageError(f"--gather-steps PHI must be at least twice the azimuth harmonics (M = {harmonics}, "
                             f"the --quality level's or the scene planner's), {2 * harmonics}, got "
                             f"{args.gather_steps[1]}") from None
        raise UsageError(option_message(error, TABLE_OPTION_NAMES)) from None
    _check_table_options_used(args, settings)
    return settings


def _check_table_options_used(args, settings):
    """UsageError for a table option given that the table would not use, rather than ignoring it: the 4d
    table's azimuth axis on another parameterization, the stopping rule of --orders auto with a count K,
    and the higher orders' quadratures with single scattering only. (The table options' defaults are
    None: a value is one typed, on the command line or a --sweep line.)"""
    unused = []
    if settings.parameterization != "4d":
        unused.append(("azimuth_size", "--azimuth-size", "sets the 4d table's azimuth axis: give --parameterization 4d"))
        unused.append(("texture", "--texture", "exports a 4d table as textures for docs/lookup4d.glsl: give "
                                               "--parameterization 4d (--raw exports any table)"))
    if settings.orders != "auto":
        count = "single scattering only" if settings.orders == 1 else f"{settings.orders} orders"
        unused += [(dest, option, f"sets when --orders auto stops, and --orders {settings.orders} computes {count}")
                   for dest, option in (("order_tolerance", "--order-tolerance"), ("max_orders", "--max-orders"))]
    if settings.orders == 1:
        unused += [(dest, option, "sets the higher orders, which --orders 1 (single scattering only) does not "
                                  "compute")
                   for dest, option in (("multiple_view_steps", "--multiple-view-steps"),
                                        ("gather_steps", "--gather-steps"),
                                        ("azimuth_harmonics", "--azimuth-harmonics"))]
    for dest, option, why in unused:
        if getattr(args, dest, None) is not None:
            raise UsageError(f"{option} {why}")
    if getattr(args, "fast_math", False) and getattr(args, "backend", "opencl") != "opencl":
        raise UsageError("--fast-math sets how the OpenCL kernels are built, and --backend numpy runs none")


def _table_settings(args, atmosphere):
    from .planner import Scene, azimuth_harmonics, sun_axis
    from .quality import QUALITY_LEVELS, quality_level

    level = quality_level(args.quality) if args.quality else None
    from .ground import default_settings

    # a reflecting ground needs the physical scheme (clsky/ground.py): the default for such an atmosphere
    base = level.table if level else default_settings(atmosphere)
    changes = {field: getattr(args, option) for field, option in SETTING_OPTIONS.items()
               if getattr(args, option) is not None}
    changes = {k: tuple(v) if isinstance(v, list) else v for k, v in changes.items()}
    if args.gather_steps is not None:
        changes.update(gather_theta_steps=args.gather_steps[0], gather_phi_steps=args.gather_steps[1])
    settings = base.replace(**changes)
    if args.sun_elevations is not None:
        try:
            scene = Scene(sun_elevations_deg=tuple(args.sun_elevations))
        except ValueError:
            raise UsageError(f"--sun-elevations must be LOW <= HIGH in [-90, 90] degrees, "
                             f"got {' '.join(short(v) for v in args.sun_elevations)}") from None
        cos_range, nodes, _, _ = sun_axis(atmosphere, scene, level or QUALITY_LEVELS["default"],
                                          settings.mapping, orders=settings.orders != 1)
        depth = settings.size[2] if args.size is not None else nodes
        settings = settings.replace(size=settings.size[:2] + (depth,), sun_cos_range=cos_range)
        if args.azimuth_harmonics is None and settings.orders != 1:     # the scene planner's choice
            harmonics, _ = azimuth_harmonics(level or QUALITY_LEVELS["default"], scene.sun_elevations_deg,
                                             settings.mode)
            settings = settings.replace(azimuth_harmonics=harmonics)
    return settings


def build_parser(extensions=()):
    """The parser and the command handlers; each extension ``register(subparsers) -> {name: handler}``
    adds commands (the animation package adds ``animate`` and ``render`` this way, so that clsky never
    imports it)."""
    parser = _Parser(prog="clsky", description="Daylight and twilight skies: precomputed scattering on OpenCL.")
    parser.add_argument("--version", action="version", version=f"clsky {__version__}")
    parser.add_argument("--verbose", action="store_true", help="show tracebacks of unexpected errors")
    commands = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    commands.add_parser("devices", help="list OpenCL platforms and devices, and the one clsky uses")
    table = commands.add_parser("table", help="compute a scattering table and save it")
    _add_table_arguments(table)
    table.set_defaults(table_parser=table)          # clsky/sweep.py parses the --sweep lines with it
    info = commands.add_parser("info", help="describe a table file (.npz) or an output (PNG, EXR, HDR, metrics JSON)")
    info.add_argument("file", help="a .npz table, a PNG, EXR or HDR frame, or a <stem>_metrics.json")
    handlers = dict(COMMANDS)
    for register in extensions:
        handlers.update(register(commands))
    return parser, handlers


def run_devices(args):
    from ._cl import list_devices, no_device_hint, pocl_cache_problem

    devices = list_devices()
    if not devices:
        print(f"no OpenCL device found; {no_device_hint()}")
        return EXIT_FAILURE
    for d in devices:
        mark = "*" if d["chosen"] else " "
        print(f"{mark} {d['device']} [{d['type']}, {d['compute_units']} compute units, "
              f"fp64 {'yes' if d['fp64'] else 'no'}]\n    platform: {d['platform']} "
              f"({d['platform_version']}), {d['device_version']}")
    print("(*: the device clsky uses; choose another with PYOPENCL_CTX)")
    problem = pocl_cache_problem()
    if problem and any(d["platform"].startswith("Portable Computing Language") for d in devices):
        # PoCL lists its device with a cache it cannot write (POCL_CACHE_DIR a file), and fails every build
        # (make_context refuses it, so that PYOPENCL_CTX would seem to select none below)
        print(f"clsky: error: {problem}", file=sys.stderr)
        return EXIT_FAILURE
    if not any(d["chosen"] for d in devices):       # only where PYOPENCL_CTX names none of them
        raise UsageError(f"PYOPENCL_CTX={os.environ.get('PYOPENCL_CTX', '')!r} selects none of the devices above: "
                         f"unset it (clsky then picks one), or give PLATFORM:DEVICE by their order (0:0 the first; "
                         f"PyOpenCL matches other numbers and words in the devices' names)")
    return 0


def _check_table_memory(args, settings):
    """Refuse, before any work, a table (with its save) that does not fit the machine (exit 2, one line)."""
    from .resources import check_table_memory

    if args.size is not None:
        option = "--size " + " ".join(str(n) for n in args.size)
    else:
        option = f"--quality {args.quality}" if args.quality else None
    check_table_memory(settings, args.backend, saving=True, options={"table": option})


def run_table(args):
    from ._files import StagedWrites
    from .table import ScatteringTable

    if args.sweep is not None or farm_of(args) is not None:     # several tables, or on a farm
        from .sweep import run_sweep

        return run_sweep(args)
    atmosphere = table_atmosphere(args)
    settings = table_settings(args, atmosphere)
    try:
        output = check_suffix(DEFAULT_TABLE_OUTPUT if args.output is None else args.output, ".npz", "--output")
        targets = [("--output", output)] + export_targets(args)
    except ValueError as error:
        raise UsageError(str(error)) from None
    check_outputs(targets, args.force)
    _check_table_memory(args, settings)
    progress, close = progress_bar(args.progress)
    start = time.perf_counter()
    try:
        table = ScatteringTable.build(atmosphere, settings, backend=args.backend,
                                      fast_math=args.fast_math, progress=progress)
    finally:
        close()
    staging = StagedWrites()                      # the table and its exports land together
    with written_since_checked(targets, staging, args.force), staging:
        table.save(output, overwrite=args.force, staging=staging)
        write_exports(args, table, staging)
    report_table(args, table, output, time.perf_counter() - start)
    return 0


#: A table's exports for engines, by option: (args attribute, ScatteringTable method); each writes NAME.bin and
#: NAME.json (:func:`clsky._files.binary_and_header`).
TABLE_EXPORTS = {"--raw": ("raw", "export_raw"), "--texture": ("texture", "export_texture")}


def export_targets(args) -> list:
    """[(option, path)] of the exports ``args`` asks for (:data:`TABLE_EXPORTS`), each checked; ValueError for
    a name that is no file name, or two exports of one name (both write NAME.bin and NAME.json)."""
    targets = []
    for option, (attribute, _) in TABLE_EXPORTS.items():
        name = getattr(args, attribute, None)
        if name is not None:
            targets += [(option, path) for path in binary_and_header(name, option)]
    paths = [path.resolve() for _, path in targets]
    if len(set(paths)) < len(paths):
        raise ValueError(f"--raw and --texture must name different files, got {args.raw!r} and {args.texture!r}: "
                         f"each writes NAME.bin and NAME.json")
    return targets


def write_exports(args, table, staging):
    """Stage the exports ``args`` asks for (:data:`TABLE_EXPORTS`) of ``table`` in ``staging``."""
    for attribute, method in TABLE_EXPORTS.values():
        name = getattr(args, attribute, None)
        if name is not None:
            getattr(table, method)(name, overwrite=args.force, staging=staging)


def orders_phrase(settings, record) -> str:
    """What a table's orders were: '7 orders, converged' (or 'not converged') for --orders auto, and for
    a count K the orders asked for, which no convergence test judged ('single scattering only' for 1)."""
    count = record["orders"]
    if settings.orders == "auto":
        return f"{count} orders, {'converged' if record['converged'] else 'not converged'}"
    return "single scattering only" if count == 1 else f"{count} orders as asked (--orders {count})"


def report_table(args, table, output, seconds):
    """Print the summary line of a table written to ``output`` and its raw export (and a warning if its orders
    did not converge)."""
    print_report(table_report(args, table, output, seconds))


def table_report(args, table, output, seconds) -> tuple:
    """(summary line, warning or None) of a table written (or, in a sweep, to be written) to ``output``."""
    return table_summary(args, table, output, seconds), unconverged_warning(table)


def print_report(report):
    """Print a :func:`table_report`: its line on stdout, its warning on stderr."""
    line, warning = report
    print(line, flush=True)
    if warning is not None:
        print(warning, file=sys.stderr, flush=True)


def table_summary(args, table, output, seconds) -> str:
    """The summary line of a table written (or, in a sweep, to be written) to ``output`` and its exports."""
    settings = table.settings
    grid = "x".join(map(str, settings.size + ((settings.azimuth_size,) if settings.is_4d else ())))
    return (f"table {grid} {settings.dtype} ({args.preset}, mode {settings.mode}, "
            f"{orders_phrase(settings, table.orders_record)}; "
            f"{table.metadata['device']}): built in {table.metadata['build_seconds']:.2f} s, "
            f"total {seconds:.2f} s -> {output}"
            + "".join(f", {path}" for _, path in export_targets(args)))


def unconverged_warning(table):
    """The warning line of a table whose orders did not converge, else None."""
    if table.settings.orders == "auto" and not table.orders_record["converged"]:
        return f"clsky: warning: {table.orders_record['reason']}"
    return None


def run_info(args):
    from .info import describe

    try:
        text = describe(args.file)
    except ImportError as error:                  # a PNG or EXR without the [anim] extra
        raise UsageError(str(error)) from None
    except OSError as error:                      # describe's own, or the system's (a name too long)
        raise UsageError(str(error) if error.errno is None else
                         f"{error.filename or args.file}: cannot be read ({error.strerror})") from None
    print(text)                                   # a reader that leaves: _run's BrokenPipeError
    return 0


COMMANDS = {"devices": run_devices, "table": run_table, "info": run_info}


def main(argv=None, extensions=()):
    """Run the command line; returns the exit status (2 for bad arguments, one line on stderr;
    128 + the signal's number when SIGINT, SIGTERM or SIGHUP interrupts it)."""
    with signals_interrupt():
        try:
            return _main(argv, extensions)
        except KeyboardInterrupt as error:
            signum = getattr(error, "signum", signal.SIGINT)
            print(f"clsky: interrupted by {signal.Signals(signum).name}", file=sys.stderr)
            return 128 + signum


def _main(argv, extensions):
    from ._cl import quiet_compiler_output

    with quiet_compiler_output():
        return _run(argv, extensions)


def one_line(message) -> str:
    """``message`` on one line: the line breaks a path or a file's value may hold, escaped (the brief's one
    line of error, which a file named 'missing\\nline.npz' broke in two)."""
    return str(message).replace("\r", "\\r").replace("\n", "\\n")


def _run(argv, extensions):
    from ._cl import KernelBuildError, NoDeviceError
    from .errors import NumericalError
    from .farm import FarmError

    verbose = "--verbose" in (sys.argv[1:] if argv is None else argv)
    try:
        parser, handlers = build_parser(extensions)
        args = parser.parse_args(argv)
        return handlers[args.command](args)
    except UsageError as error:
        print(f"clsky: error: {one_line(error)}", file=sys.stderr)
        return EXIT_USAGE
    except (ValueError, FileExistsError) as error:
        if verbose:
            raise
        print(f"clsky: error: {one_line(error)}", file=sys.stderr)
        return EXIT_USAGE
    except BrokenPipeError:             # `clsky info FILE | head -1`: the reader left, as with SIGPIPE's default
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())       # nothing more to flush at exit
        return 128 + signal.SIGPIPE
    except (NoDeviceError, KernelBuildError, NumericalError, OSError, FarmError) as error:
        if verbose:
            raise
        print(f"clsky: error: {str(error).splitlines()[0]}", file=sys.stderr)
        return EXIT_FAILURE
