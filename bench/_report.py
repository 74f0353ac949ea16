"""Shared by the benchmarks: machine description, timing, and writing a table into README.md.

A benchmark writes its Markdown table between ``<!-- bench:NAME -->`` and ``<!-- /bench:NAME -->`` in
the README, so the figures there are always those of the last run.

Every benchmark also takes ``--smoke`` (:func:`add_output_arguments`, :data:`SMOKE`): the same code
path at a tiny size, to prove that the script runs (tests/test_bench_smoke.py). A smoke run prints its
table and writes nothing into README.md or docs/: it implies ``--no-readme``, and any file it would
write goes to a temporary directory instead.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import pathlib
import platform
import re
import resource
import statistics
import sys
import time

README = pathlib.Path(__file__).resolve().parent.parent / "README.md"


@dataclasses.dataclass(frozen=True)
class SmokeSizes:
    """The sizes of a ``--smoke`` run: small enough that each benchmark runs in seconds to a minute on
    two cores, large enough that every code path (tables, orders, renders, plots) still runs."""

    #: table (W, H, D): altitude x view x sun nodes
    table: tuple = (8, 32, 8)
    #: Monte Carlo paths per channel and case
    photons: int = 300
    #: side of a rendered frame [px]
    frame: int = 16
    #: timing repetitions
    repeat: int = 1
    #: quality level standing in for the accuracy reference (anim/accuracy.py); 'draft' is the cheapest
    reference_level: str = "draft"
    #: frames of the animation run by bench_render.py
    animation_frames: int = 2


#: The one set of smoke sizes every benchmark uses.
SMOKE = SmokeSizes()


def add_output_arguments(parser: argparse.ArgumentParser):
    """Add the options every benchmark shares: ``--no-readme`` and ``--smoke``."""
    parser.add_argument("--no-readme", action="store_true", help="print only: leave README.md as it is")
    parser.add_argument("--smoke", action="store_true",
                        help="the same code path at a tiny size (bench/_report.py: SMOKE), to check that the "
                             "script runs; prints its table, writes nothing into README.md or docs/ "
                             "(implies --no-readme); its sizes, paths and counts replace the options that set "
                             "them")
    return parser


def integer_in(low: int, high: int):
    """An argparse type: an integer in [low, high], else argparse's one-line error naming the option and
    what was typed (exit status 2, before any work)."""
    def integer(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or not low <= value <= high:
            raise argparse.ArgumentTypeError(f"must be an integer in [{low}, {high}], got {text!r}")
        return value
    return integer


def real_in(low: float, high: float, high_open=False):
    """An argparse type: a finite number in [low, high] (or [low, high) with ``high_open``), else argparse's
    one-line error naming the option and what was typed."""
    def real(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not (low <= value < high if high_open else low <= value <= high):
            raise argparse.ArgumentTypeError(f"must be a number in [{low:g}, {high:g}{')' if high_open else ']'}, "
                                             f"got {text!r}")
        return value
    return real


def listed(item_type):
    """An argparse type: a comma-separated list of ``item_type`` values (at least one), each checked by it."""
    def items(text: str) -> list:
        values = [item_type(item) for item in text.split(",")]
        return values
    return items


#: An argparse type: a count of runs, rounds or repetitions (at least 1: a count of 0 measured nothing, and
#: wrote empty tables or inf into README.md).
positive_integer = integer_in(1, 10**6)
#: Argparse types of the options shared by several benchmarks, with the API's ranges: frame sides [px], a
#: sweep's frames, a table's node counts, Monte Carlo paths per channel, a relative standard error to reach.
frame_side = integer_in(16, 8192)
frame_count = integer_in(2, 100_000)
table_nodes = integer_in(2, 4096)
photon_count = integer_in(2, 10**10)
standard_error = real_in(0.0, 1.0, high_open=True)


def npz_file(text: str) -> pathlib.Path:
    """An argparse type: a path ending in .npz (NumPy's savez adds the suffix to a name without it, so a cache
    named without it was written under another name and never read again)."""
    path = pathlib.Path(text)
    if path.suffix != ".npz" or path.name == ".npz":
        raise argparse.ArgumentTypeError(f"must end in .npz after a file name (NAME.npz), got {text!r}")
    return path


def save_reference_cache(path: pathlib.Path, level: str, reference: dict, valid, **extra):
    """The accuracy reference's frames (``reference``: {frame name: HDR}, ``valid``: the fisheye's mask) and
    ``extra`` arrays saved in ``path`` (bench_quality.py, read by bench_accuracy.py), with the quality level
    that rendered them; written to a temporary beside it and renamed (an interrupted save left a torn file)."""
    import numpy as np

    from clsky._files import atomic_write

    with atomic_write(path, overwrite=True) as temporary:
        np.savez(temporary, valid=valid, level=level, **reference, **extra)


def load_reference_cache(path: pathlib.Path, level: str, size: int, names) -> dict:
    """The arrays of a reference cache (:func:`save_reference_cache`), after checking that its frames are
    ``names``' at ``size`` x ``size`` rendered at the quality level ``level``; SystemExit naming the file
    otherwise (a --smoke cache, rendered at the draft level, was taken for the 'reference' level's)."""
    import zipfile

    import numpy as np

    try:
        with np.load(path) as cached:
            arrays = {name: cached[name] for name in cached.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as error:
        raise SystemExit(f"--reference-cache {path}: cannot read it ({error})") from None
    again = "; delete it to render the reference again"
    held = f"the {str(arrays['level'])!r} level" if "level" in arrays else "an unrecorded level (an older cache)"
    if held != f"the {level!r} level":
        raise SystemExit(f"--reference-cache {path} holds frames of {held}, not of the {level!r} level this run "
                         f"compares with{again}")
    missing = [name for name in ("valid", *names) if name not in arrays]
    if missing:
        raise SystemExit(f"--reference-cache {path} lacks the frames {', '.join(map(repr, missing))}{again}")
    if arrays["valid"].shape != (size, size):
        raise SystemExit(f"--reference-cache {path} holds {' x '.join(map(str, arrays['valid'].shape))} frames, not "
                         f"{size} x {size} (--size){again}")
    for name in names:              # a damaged or edited frame reached the comparison (a traceback there)
        frame = arrays[name]
        if frame.shape != (size, size, 3) or frame.dtype.kind != "f":
            raise SystemExit(f"--reference-cache {path}: frame {name!r} is {frame.dtype} of shape {frame.shape}, not "
                             f"{size} x {size} x 3 radiances{again}")
        if not (np.isfinite(frame).all() and (frame >= 0).all()):
            raise SystemExit(f"--reference-cache {path}: frame {name!r} holds NaN, infinite or negative values{again}")
    return arrays


def description_of(doc: str) -> str:
    """A script's ``--help`` description: the first sentence of its docstring's first paragraph, joined
    across its lines (the first line alone cut three of them mid-sentence)."""
    paragraph = " ".join(doc.strip().split("\n\n")[0].split())
    end = paragraph.find(". ")
    return paragraph if end < 0 else paragraph[:end + 1]


def parse_arguments(parser: argparse.ArgumentParser, argv=None, sections=()):
    """``parser.parse_args(argv)``, with ``--smoke`` implying ``--no-readme``. ``sections``: the README
    sections the script writes (names, or a function of the parsed arguments that returns them), checked
    before any work unless --no-readme (:func:`check_readme_sections`)."""
    args = parser.parse_args(argv)
    if args.smoke:
        args.no_readme = True
    if not args.no_readme:
        check_readme_sections(sections(args) if callable(sections) else sections)
    return args


def _section_pattern(name):
    begin, end = f"<!-- bench:{name} -->", f"<!-- /bench:{name} -->"
    return begin, end, re.compile(re.escape(begin) + ".*?" + re.escape(end), re.S)


def check_readme_sections(names, readme: pathlib.Path | None = None):
    """SystemExit unless ``readme`` holds every section ``names`` and its folder takes a new file (the README
    is replaced through a temporary there): a missing section was found after the work (minutes; up to
    818 s for bench_twilight), and bench_dusk had replaced its picture by then."""
    import os

    readme = README if readme is None else readme
    text = readme.read_text()
    for name in names:
        begin, end, pattern = _section_pattern(name)
        if not pattern.search(text):
            raise SystemExit(f"README.md has no {begin} ... {end} section")
    if names and not os.access(readme.parent, os.W_OK | os.X_OK):
        raise SystemExit(f"cannot write in {readme.parent}, where README.md is replaced")


def machine() -> str:
    """CPU model and core count, e.g. 'AMD EPYC ..., 2 cores'."""
    model = platform.processor() or platform.machine()
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{model}, {os.cpu_count()} cores"


def best_of(function, repeat):
    """(minimum, median) wall time [s] of ``repeat`` calls; the minimum is the least noisy figure."""
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return min(times), statistics.median(times)


def write_readme_section(name: str, markdown: str, readme: pathlib.Path = README):
    """Replace the README section between the bench markers of ``name`` (which must exist), atomically
    (:func:`clsky._files.atomic_write`: a uniquely named temporary renamed over the README, so that an
    interrupted benchmark or two writing at once never leave it half written)."""
    from clsky._files import atomic_write

    text = readme.read_text()
    begin, end, pattern = _section_pattern(name)
    if not pattern.search(text):
        raise SystemExit(f"README.md has no {begin} ... {end} section")
    with atomic_write(readme, overwrite=True) as temporary:
        pathlib.Path(temporary).write_text(pattern.sub(lambda _: f"{begin}\n{markdown.strip()}\n{end}", text))


def timed_with_cpu(function):
    """(result, wall [s], process CPU [s]) of one call. The process CPU time counts every thread of this
    process (PoCL's workers too): on a loaded machine it stays close to the quiet figure while the wall
    time does not (issue 12)."""
    wall, cpu = time.perf_counter(), time.process_time()
    result = function()
    return result, time.perf_counter() - wall, time.process_time() - cpu


def timed_in_turn(renders, rounds, after_round=None):
    """[[(wall, CPU) [s] of each timed call] for each of ``renders``]: each called once to warm up, then in
    rounds, each render once a round, in turn (:func:`timed_with_cpu`). ``rounds``: an int, or one a render
    (a render then takes part in the first of the rounds only); ``after_round()`` runs after each round.

    Why in turn: this machine's speed drifts between two states for seconds to minutes (README "This
    machine runs at two speeds"); renders measured one after the other each caught a state of their own
    (the lookups' CPU a frame moved by 23 % between two runs of 2026-12-06). In turn, every render sees the
    same mix of states, and its least time the fast state whenever a round had it."""
    counts = [rounds] * len(renders) if isinstance(rounds, int) else list(rounds)
    for render in renders:
        render()
    times = [[] for _ in renders]
    for round_ in range(max(counts, default=0)):
        for render, count, timed in zip(renders, counts, times):
            if round_ < count:
                timed.append(timed_with_cpu(render)[1:])
        if after_round is not None:
            after_round()
    return times


def best_timing(function, repeat):
    """(last result, least wall [s], least CPU [s], highest load average) over ``repeat`` calls of
    :func:`timed_with_cpu`: the least of each, the least noisy figures."""
    walls, cpus, loads, result = [], [], [], None
    for _ in range(repeat):
        result, wall, cpu = timed_with_cpu(function)
        walls.append(wall)
        cpus.append(cpu)
        loads.append(load_average())
    return result, min(walls), min(cpus), max(loads)


def children_cpu() -> float:
    """User + system CPU time [s] of the waited-for child processes (and their waited-for children): a
    command run with subprocess, ffmpeg under it included."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def load_average() -> float:
    """The 1-minute load average, with a warning on stderr the first time it exceeds the core count
    (the wall times measured meanwhile are then inflated: compare CPU times)."""
    global _LOAD_WARNED
    load = os.getloadavg()[0]
    if load > (os.cpu_count() or 1) and not _LOAD_WARNED:
        _LOAD_WARNED = True
        print(f"warning: load average {load:.1f} exceeds the {os.cpu_count()} cores: wall times are inflated, "
              f"compare the CPU times", file=sys.stderr, flush=True)
    return load


def load_note(highest: float) -> str:
    """A sentence for a benchmark's README text when the highest load average seen exceeded the cores."""
    if highest <= (os.cpu_count() or 1):
        return ""
    return (f" The load average reached {highest:.1f} on {os.cpu_count()} cores during the run: the wall times "
            f"are inflated by other processes, the CPU times much less.")


_LOAD_WARNED = False

#: The fraction of a run's fastest exp() reading below which a reading is of the slow state.
SLOW_STATE = 0.8
_EXP_CONTEXT = None


def exp_reading() -> float:
    """One reading of the machine's state: ``double8`` exp() per CPU-second [M/s] on clsky's device
    (bench/_bound.py, one run of about 0.1 s).

    On the 2-core virtual machines it reads 1500-1700 M in a fast state and about 900 M in a slow one
    (the AMD EPYC with AVX-512; the one without it 540-618 and 326-360 M), which lasts seconds to
    minutes and takes the ray march about a third more CPU for the same frame
    (README "This machine runs at two speeds"): readings before and after a row tell which state it
    ran in, where the load average does not."""
    global _EXP_CONTEXT
    from _bound import exp_rate
    from clsky import _cl

    if _EXP_CONTEXT is None:
        _EXP_CONTEXT = _cl.make_context()
    return exp_rate(_EXP_CONTEXT, repeat=1) / 1e6


def state_note(readings) -> str:
    """A sentence for a benchmark's README text when its exp() readings (:func:`exp_reading`) spread
    over both of the machine's states."""
    if not readings or min(readings) >= SLOW_STATE * max(readings):
        return ""
    return (f" The exp() readings spread from {min(readings):.0f} to {max(readings):.0f} M per CPU-second: "
            f"rows read below {SLOW_STATE * max(readings):.0f} M ran at least in part in this machine's slow "
            f"state, their CPU times up to a third higher (README \"This machine runs at two speeds\").")
