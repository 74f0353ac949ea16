"""``clsky table --sweep FILE``: one table per line of a list of atmospheres, here or on a Dask farm.

A sweep file (``examples/weather.txt`` is one) holds one table per line: the options of ``clsky table``
(``--preset``, ``--ground-albedo``, ``--ozone-column``, ``--quality``, ... and ``-o``), parsed after
the command line's, so that a line's options win over the command line's and the rest are shared.
Blank lines and ``#`` comments are skipped; the run options ``--sweep``, ``--workers``, ``--scheduler``
and ``--progress`` belong to the command line only. Every line is checked (values, outputs, memory)
before any table is built, and a bad one is one line naming the file, the line and the option
(``weather.txt line 3: --ground-albedo must be in [0, 1], got 2``), exit status 2.

The tables are built one after the other in this process, or with ``--workers N`` / ``--scheduler``
on a Dask farm (:class:`clsky.farm.Farm`, one table per task: :func:`clsky.farm.build_table_task`),
and come back in order. Each is saved to a hidden temporary as it arrives, and the files land
together when the last one is in (:class:`clsky._files.StagedWrites`): an interrupted or failed
sweep leaves the earlier files as they were and no temporary. Without ``--sweep``, ``--workers``
builds the command line's one table on the farm the same way.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import pathlib
import shlex
import time

from ._files import as_path, check_suffix, read_user_text
from .cli import (DEFAULT_TABLE_OUTPUT, UsageError, check_outputs, export_targets, farm_of, print_report,
                  progress_bar, running_farm, table_atmosphere, table_report, table_settings, write_exports,
                  written_since_checked, _check_table_memory)

__all__ = ["SweepJob", "read_sweep", "sweep_jobs", "run_sweep"]

#: Options of the command line only: a sweep line may not hold them.
RUN_OPTIONS = ("--sweep", "--workers", "--scheduler", "--progress")


@dataclasses.dataclass(frozen=True)
class SweepJob:
    """One table of a sweep: where it comes from ('FILE line N', or the command line), its parsed
    options, atmosphere, settings and outputs."""

    source: str
    args: argparse.Namespace
    atmosphere: object
    settings: object
    output: pathlib.Path


def without_comment(line: str) -> str:
    """``line`` up to its comment, as the shell reads one: a ``#`` that begins a word outside quotes and
    escapes (shlex's ``comments=True`` ends a word at any ``#``: ``--raw sky#2`` wrote sky.bin).

    >>> without_comment("--raw sky#2 'a #b' # the rest")
    "--raw sky#2 'a #b' "
    """
    quote, escaped, word_start = None, False, True
    for index, character in enumerate(line):
        if escaped:
            escaped, word_start = False, False
        elif quote is not None:
            if character == quote:
                quote = None
            elif character == "\\" and quote == '"':
                escaped = True
        elif character == "\\":
            escaped, word_start = True, False
        elif character in "'\"":
            quote, word_start = character, False
        elif character.isspace():
            word_start = True
        elif character == "#" and word_start:
            return line[:index]
        else:
            word_start = False
    return line


def read_sweep(path) -> list[tuple[int, list[str]]]:
    """(line number, words) of each table line of the sweep file at ``path``; UsageError for a file
    that cannot be read, a line shlex cannot split, or a file without a table line."""
    try:
        path = as_path(path, "--sweep")
    except ValueError as error:
        raise UsageError(str(error)) from None
    try:
        text = read_user_text(path)
    except OSError as error:                            # as --scene's (anim/scene.py)
        raise UsageError(f"--sweep: cannot read {path}: {error.strerror or error}") from None
    except UnicodeDecodeError:
        raise UsageError(f"--sweep {path}: not a text file (not UTF-8 text)") from None
    lines = []
    for number, line in enumerate(text.splitlines(), start=1):
        try:
            words = shlex.split(without_comment(line))
        except ValueError as error:
            raise UsageError(f"{path} line {number}: {error}") from None
        if words:
            lines.append((number, words))
    if not lines:
        raise UsageError(f"--sweep: {path} holds no table line (one line of `clsky table` options per table)")
    return lines


def sweep_jobs(args) -> list[SweepJob]:
    """The tables of the command line: one per line of ``--sweep`` (the line's options over the command
    line's), or the command line's own. Every value and output is checked here, before any work."""
    if args.sweep is None:
        lines = [("the command line", args)]
    else:
        if args.output is not None:                 # each line's own -o would replace it: it named nothing
            raise UsageError(f"-o/--output names the table of a single build; with --sweep each line names its "
                             f"own (-o {args.output} was given on the command line)")
        lines = [(f"{args.sweep} line {number}", _sweep_line(args, f"{args.sweep} line {number}", words))
                 for number, words in read_sweep(args.sweep)]
    jobs = []
    for source, line in lines:
        try:
            atmosphere = table_atmosphere(line)
            settings = table_settings(line, atmosphere)
            output = check_suffix(DEFAULT_TABLE_OUTPUT if line.output is None else line.output, ".npz", "--output")
            export_targets(line)
        except (UsageError, ValueError) as error:
            raise UsageError(error if args.sweep is None else f"{source}: {error}") from None
        jobs.append(SweepJob(source, line, atmosphere, settings, output))
    _check_jobs(args, jobs)
    return jobs


def _sweep_line(args, source, words):
    """The options of one sweep line over the command line's. Options are matched in full: argparse's
    abbreviations let --work 2 or --prog leave (run options, refused in a line) through as --workers and
    --progress, silently ignored; and -h in a line printed the help and ended the sweep with status 0."""
    refused = [word.split("=")[0] for word in words if word.split("=")[0] in RUN_OPTIONS + ("-h", "--help")]
    if refused:
        raise UsageError(f"{source}: {refused[0]} belongs to the command line, not to a sweep line")
    if not any(word in ("-o", "--output") or word.startswith(("-o", "--output=")) for word in words):
        raise UsageError(f"{source}: -o FILE is missing (each line names its table's file)")
    parser = args.table_parser
    parser.allow_abbrev = False
    try:
        return parser.parse_args(words, namespace=copy.copy(args))
    except UsageError as error:
        raise UsageError(f"{source}: {error}") from None
    finally:
        parser.allow_abbrev = True


def _check_jobs(args, jobs):
    """Outputs (distinct, writable) and memory of every job, before any work."""
    seen = {}
    for job in jobs:
        for where, path in _job_targets(args, job):
            if args.sweep is not None and path.resolve() == pathlib.Path(args.sweep).resolve():
                raise UsageError(f"{where} {path} is the sweep file itself")
            other = seen.setdefault(path.resolve(), job.source)
            if other != job.source:
                raise UsageError(f"{where} {path} is written by {other} too")
            check_outputs([(where, path)], job.args.force)
        try:
            _check_table_memory(job.args, job.settings)
        except UsageError as error:
            raise UsageError(error if args.sweep is None else f"{job.source}: {error}") from None


def _job_targets(args, job):
    """(the option as messages name it, path) of each output of ``job``; with --sweep, after its line."""
    targets = [("--output", job.output)] + export_targets(job.args)
    return [(option if args.sweep is None else f"{job.source}: {option}", path) for option, path in targets]


def run_sweep(args):
    """``clsky table --sweep`` (or ``--workers`` / ``--scheduler``): module docstring."""
    from ._files import StagedWrites
    from .farm import build_table_task

    jobs = sweep_jobs(args)
    farm = farm_of(args)
    start = time.perf_counter()
    progress, close = progress_bar(args.progress)
    try:
        unforced = [target for job in jobs if not job.args.force for target in _job_targets(args, job)]
        staging = StagedWrites()
        with running_farm(farm), written_since_checked(unforced, staging, force=False), staging:
            tasks = [(job.atmosphere, job.settings, job.args.backend, job.args.fast_math) for job in jobs]
            tables = farm.map_ordered(build_table_task, tasks, label="clsky-table") if farm is not None \
                else (build_table_task(*task) for task in tasks)
            # printed once the files land, each warning after its table's line: a failed or interrupted sweep
            # writes none
            reports = []
            for done, (job, table) in enumerate(zip(jobs, tables), start=1):
                table.save(job.output, overwrite=job.args.force, staging=staging)
                write_exports(job.args, table, staging)
                reports.append(table_report(job.args, table, job.output, time.perf_counter() - start))
                del table
                if progress is not None:
                    progress("tables", done, len(jobs))
    finally:
        close()
    for report in reports:
        print_report(report)
    if len(jobs) > 1:
        print(f"{len(jobs)} tables in {time.perf_counter() - start:.2f} s")
    return 0
