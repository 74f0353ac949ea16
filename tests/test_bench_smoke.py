"""Every benchmark in bench/ runs: ``python bench/<name>.py --smoke`` (the README's command lines, at the
tiny sizes of bench/_report.py's SMOKE) exits 0, prints its Markdown table with finite numbers, and
leaves README.md and docs/ byte for byte as they were.

The scripts import ``_report`` from their own directory, so they run by path from the repository root,
exactly as the README shows them. All but two cheap cases are marked slow (``SLOW``: measured wall times,
on a loaded 2-core machine, in the comments); .ci/run runs them after the default suite.
"""

from __future__ import annotations

import math
import os
import pathlib
import re
import subprocess
import sys

import pytest

import forked_cli

ROOT = pathlib.Path(__file__).resolve().parent.parent
BENCH = ROOT / "bench"

#: script: the start of the header line of each Markdown table it prints
HEADERS = {
    "bench_single": ["| settings | OpenCL wall [s] | CPU [s] | NumPy twin wall [s] | CPU [s] | NumPy / OpenCL: wall | CPU "
                     "| load |"],
    "bench_orders": ["| table | W x H x D | orders | first build: wall | CPU | repeated: wall | CPU | load | exp() |",
                     "| mode | orders | OpenCL wall | CPU | NumPy twins wall | CPU | NumPy / OpenCL: wall | CPU | load | "
                     "exp() |",
                     "| mode | sun zenith [deg] | order 1 | order 2 | order 3 | order 4 | orders 5+ |"],
    "bench_montecarlo": ["| mode (preset) | quadrature | altitude [m] | cos view | sun zenith [deg] | deviation [%] | "
                         "deviation [SE] |"],
    "bench_render": ["| render | best | median | CPU per frame: least | median | frames/s (best) |"],
    "bench_skyview": ["| frame | renderer | wall [ms] | CPU [ms] | frames/s (wall) | p95 +30 deg [%] |",
                      "| observer | table | +45 deg | +30 deg |"],
    "bench_renderer_costs": ["| renderer (`--method`) | 8 x 8 (52 px) [ms] |"],
    "bench_animate": ["| run | frames | wall [s] | CPU [s] | CPU / wall | load before | load after | exp() |",
                      "| stage | CPU [s], BLAS 1 thread | per frame [ms] | CPU [s], BLAS unlimited | per frame [ms] |",
                      "| round | host threads | wall a frame [ms] | CPU a frame [ms] | wall, one thread's / this |"],
    "bench_memory": ["| run | table (W x H x D) | measured peak | estimate | estimate / measured |"],
    "bench_accuracy": ["| candidate | knob | build [s] | CPU [s] | render [ms] | CPU [ms] | p95 day [%] |"],
    "bench_quality": ["| level | promise | table | samples | build [s] | CPU [s] | render [ms] | CPU [ms] | day [%] |",
                      "| doubled | day [%] |", "| table | sun axis | cells | build [s] | CPU [s] | day [%] |"],
    "bench_quality_dusk": ["| level | promise | table | samples | build [s] | CPU [s] | render [ms] | CPU [ms] | "
                           "-6 deg [%] | -8 deg [%] | -10 deg [%] | -12 deg [%] | lookup, worst [%] | "
                           "sky-view map, worst [%] | load |", "| doubled | -6 deg [%] |"],
    "bench_view_nodes": ["| preset | sampling | rays | n | Ibar median | Ibar p95 | Ibar max |",
                         "| preset | observer [km] | planner picks | rays hitting the ground |",
                         "| sampling | table [s] | CPU [s] | ray march [ms] | CPU [ms] |"],
    "bench_dusk": ["| sky | display | zenith sRGB (8 bit) | blue: b > g > r | linear b / g | linear g / r |"],
    "bench_spectral": ["| build | batches | wall [s] | CPU [s] | wall / three | load |",
                       "| mode against N = 6 | sun zenith [deg] | PSNR [dB] | mean Delta E 2000 | Bruneton's anchor |"],
    "bench_azimuth": ["| | -6 deg |", "| sun [deg] | view | paths | SE [%] | M = 0 [%] | M = 1 [%] |"],
    "bench_dask": ["| run | repetition | farm start [s] | wall [s] | table [s] | first frame [s] |",
                   "| repetition | 1 worker against here: first frame [s] | wall per frame [ms] | CPU per frame [ms] |"],
    "bench_lookup4d": ["| frame | sun [deg] | 4D lookup p95 | target | 4D mean Delta E | 3D lookup p95 |"],
    "bench_runtimes": ["| round | device | width | 3D lookup: wall |"],
    "bench_twilight": ["| | +5 deg | -6 deg |",
                       "| sun [deg] | view | paths | SE [%] | all orders [%] | all orders [SE] | single: paths |"],
}
#: script: patterns of lines it must print besides its tables, each with one finite number
LINES = {
    "bench_render": [r"Ray marches against the exp\(\) bound: .*?Ray march: .*? \*\*(\S+)x the bound\*\*",
                     r"with the higher orders' source on every other node: .*? \*\*(\S+)x the bound\*\*"],
}
#: Measured wall time of each case (pytest, 2 shared cores): single 3-5 s, orders 5-7 s, montecarlo 10-12 s,
#: render 9-10 s; skyview 18 s (load 9); renderer_costs 2 s (2026-12-06); runtimes 7 s (PoCL and Intel's runtime,
#: 2026-12-02); spectral 5-7 s; twilight 11 s; dusk 10 s (four skies, two of 15 wavelengths); accuracy 41 s
#: (the four 'draft' reference tables: 21 s), quality 109 s (the reference and one doubled group); dask 66 s (two
#: LocalClusters started, at load average 10); animate 15 s (quiet machine, 2026-12-02: two end-to-end runs
#: and the stage split). Every smoke run but two is slow (run by .ci/run after the default suite) since
#: 2026-12-07: the default suite took 10:44 on an empty kernel cache (the AMD EPYC without AVX-512), of
#: which the smoke runs were 77 s of test time (bench_orders 12 s, bench_azimuth 8.7, bench_renderer_costs
#: 8.4, the accuracy replot 8.0, the rest 4-6.5 each). The default suite keeps bench_single and
#: bench_skyview (2 s each), which run the shared _report code.
DEFAULT_SMOKE = {"bench_single", "bench_skyview"}
SLOW = set(HEADERS) - DEFAULT_SMOKE

NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def snapshot():
    """README.md and every file under docs/: {relative path: bytes}."""
    files = [ROOT / "README.md", *sorted(p for p in (ROOT / "docs").rglob("*") if p.is_file())]
    return {str(p.relative_to(ROOT)): p.read_bytes() for p in files}


def table_rows(output, header):
    """The data rows (lists of cells) of the Markdown table whose header line starts with ``header``."""
    lines = output.splitlines()
    starts = [i for i, line in enumerate(lines) if line.startswith(header)]
    assert starts, f"no table with header {header!r} in the output:\n{output}"
    start = starts[0]
    assert set(lines[start + 1]) <= set("|-:"), lines[start + 1]
    rows = []
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        rows.append([cell.strip() for cell in line.strip().strip("|").split("|")])
    return rows


def assert_finite_row(rows):
    """At least one row holds numbers, and every number in every row is finite."""
    numbers_seen = False
    for row in rows:
        values = " | ".join(row[1:])
        assert not re.search(r"\b(nan|inf)\b", values, re.I), row
        numbers = [float(n) for n in NUMBER.findall(values)]
        assert all(math.isfinite(n) for n in numbers), row
        numbers_seen = numbers_seen or bool(numbers)
    assert rows and numbers_seen, rows


def bench_report():
    """bench/_report.py, the benchmarks' shared module (bench/ is no package: imported from its folder)."""
    sys.path.insert(0, str(BENCH))
    try:
        import _report
    finally:
        sys.path.remove(str(BENCH))
    return _report


def run_smoke(name, *extra, timeout=900):
    before = snapshot()
    result = subprocess.run([sys.executable, f"bench/{name}.py", "--smoke", *extra], cwd=ROOT, capture_output=True,
                            text=True, timeout=timeout)
    assert result.returncode == 0, result.stdout + result.stderr
    after = snapshot()
    assert after.keys() == before.keys(), sorted(set(after) ^ set(before))
    changed = [path for path in before if before[path] != after[path]]
    assert not changed, f"{name} --smoke changed {changed}"
    return result.stdout


@pytest.mark.parametrize("name", [pytest.param(name, marks=pytest.mark.slow) if name in SLOW else name
                                  for name in HEADERS])
def test_smoke_run_prints_its_table_and_writes_nothing(name):
    output = run_smoke(name)
    for header in HEADERS[name]:
        assert_finite_row(table_rows(output, header))
    for pattern in LINES.get(name, []):
        found = re.search(pattern, output)
        assert found and math.isfinite(float(found.group(1))) and float(found.group(1)) > 0, (pattern, output)


@pytest.mark.slow
def test_azimuth_cost_smoke_prints_its_table_and_writes_nothing():
    """``bench_azimuth.py --cost`` (the harmonics' cost in the default animation) at the smoke sizes:
    one row per M, the planner's (2) first; ~10 s."""
    rows = table_rows(run_smoke("bench_azimuth", "--cost"), "| M | table | orders | build: wall |")
    assert [row[0] for row in rows] == ["2", "0"]
    assert_finite_row(rows)


def test_every_bench_script_is_covered():
    """A new bench script (bench_memory.py, ...) must get --smoke and a case here."""
    assert {p.stem for p in BENCH.glob("bench_*.py")} <= set(HEADERS)


def test_smoke_implies_no_readme():
    _report = bench_report()
    import argparse

    parser = _report.add_output_arguments(argparse.ArgumentParser())
    assert _report.parse_arguments(parser, ["--smoke"]).no_readme
    assert not _report.parse_arguments(parser, []).no_readme
    assert not _report.parse_arguments(parser, []).smoke


@pytest.mark.slow
def test_accuracy_smoke_writes_its_files_where_asked(tmp_path):
    pytest.importorskip("matplotlib")
    run_smoke("bench_accuracy", "--docs", str(tmp_path))
    assert (tmp_path / "accuracy.csv").read_text().startswith("candidate,")
    for name in ("accuracy.png", "accuracy_elevation.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_accuracy_replot_draws_the_published_csv_where_asked(tmp_path):
    """bench_accuracy.py --replot: the two plots of docs/accuracy.csv, without measuring, into --docs; with
    --smoke and no --docs into a temporary directory (run_smoke: docs/ and README.md unchanged)."""
    pytest.importorskip("matplotlib")
    out = run_smoke("bench_accuracy", "--replot", "docs/accuracy.csv", "--size", "64", "--docs", str(tmp_path))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["accuracy.png", "accuracy_elevation.png"]
    for name in ("accuracy.png", "accuracy_elevation.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert out.startswith("wrote ")
    assert run_smoke("bench_accuracy", "--replot", "docs/accuracy.csv", "--size", "64").startswith("wrote ")


def test_memory_bench_honours_the_atmosphere_options():
    """bench_memory's --ground-albedo / --ozone-column reach every measured command and its estimate: an
    atmosphere-plus table with a ground is built in the physical mode (clsky.ground.default_settings:
    3 more channels), and the estimate is that table's, not the preset's."""
    import argparse

    from clsky import TableSettings
    from clsky.resources import BASE_PROCESS_BYTES, estimate_table_memory

    sys.path.insert(0, str(BENCH))
    try:
        import bench_memory
    finally:
        sys.path.remove(str(BENCH))
    arguments = ["table", "--preset", "atmosphere-plus", "--size", "8", "16", "8", "--progress", "none"]
    given = argparse.Namespace(ground_albedo=0.3, ozone_column_du=250.0)
    overridden = bench_memory.with_overrides(arguments, given)
    assert overridden == arguments + ["--ground-albedo", "0.3", "--ozone-column", "250.0"]
    assert bench_memory.with_overrides(arguments, argparse.Namespace(ground_albedo=None, ozone_column_du=None)) \
        == arguments
    plain, size = bench_memory.estimate(arguments)
    ground, _ = bench_memory.estimate(overridden)
    assert size == (8, 16, 8)
    assert plain == estimate_table_memory(TableSettings(size=size), saving=True).peak_bytes() + BASE_PROCESS_BYTES
    physical = TableSettings(size=size, mode="physical")
    assert ground == estimate_table_memory(physical, saving=True).peak_bytes() + BASE_PROCESS_BYTES > plain


@pytest.mark.parametrize("name, option", [("bench_orders", "--twin-runs"), ("bench_orders", "--repeat"),
                                          ("bench_orders", "--fresh-runs"), ("bench_render", "--repeat"),
                                          ("bench_renderer_costs", "--rounds")])
@pytest.mark.parametrize("typed", ["0", "-2", "x"])
def test_counts_below_one_are_refused_before_any_work(name, option, typed):
    """A count of runs or rounds below 1 would leave nothing to take the least of: argparse refuses it
    (exit status 2) with a line naming the option and what was typed, before any table is built."""
    result = forked_cli.run_script(ROOT / "bench" / f"{name}.py", option, typed, "--no-readme", cwd=ROOT, timeout=120)
    assert result.returncode == 2
    assert f"argument {option}: must be an integer in [1, 1000000], got '{typed}'" in result.stderr.splitlines()[-1]


def test_readme_section_is_replaced_atomically(tmp_path):
    """write_readme_section replaces one section's text, leaves the rest and no temporary behind, and
    refuses a README without the section before writing anything."""
    _report = bench_report()
    readme = tmp_path / "README.md"
    readme.write_text("head\n<!-- bench:x -->\nold\n<!-- /bench:x -->\ntail\n")
    _report.write_readme_section("x", "| new |\n", readme)
    assert readme.read_text() == "head\n<!-- bench:x -->\n| new |\n<!-- /bench:x -->\ntail\n"
    assert [p.name for p in tmp_path.iterdir()] == ["README.md"]
    with pytest.raises(SystemExit, match="README.md has no <!-- bench:y -->"):
        _report.write_readme_section("y", "| other |", readme)
    assert readme.read_text() == "head\n<!-- bench:x -->\n| new |\n<!-- /bench:x -->\ntail\n"


@pytest.mark.parametrize("name, options, message", [
    # counts of 0 measured nothing and wrote empty tables (bench_dask, bench_runtimes) or inf (bench_view_nodes)
    # into README.md, exit status 0
    ("bench_dask", ["--repeat", "0"], "argument --repeat: must be an integer in [1, 1000000], got '0'"),
    ("bench_runtimes", ["--rounds", "0"], "argument --rounds: must be an integer in [1, 1000000], got '0'"),
    ("bench_view_nodes", ["--repeat", "0"], "argument --repeat: must be an integer in [1, 1000000], got '0'"),
    # tracebacks naming the API's parameter, some after seconds of work
    ("bench_twilight", ["--target", "5"], "argument --target: must be a number in [0, 1), got '5'"),
    ("bench_spectral", ["--spectral", "5"], "argument --spectral: must be an integer in [12, 47], got '5'"),
    ("bench_azimuth", ["--elevations", "5,100"], "argument --elevations: must be a number in [-90, 90], got '100'"),
    # np.savez added .npz to a cache named without it: bench_quality recomputed its reference every run (minutes),
    # bench_accuracy ended in a traceback
    ("bench_quality", ["--reference-cache", "refc"], "argument --reference-cache: must end in .npz after a file "
                                                     "name (NAME.npz), got 'refc'"),
    ("bench_accuracy", ["--reference-cache", "refc"], "argument --reference-cache: must end in .npz after a file "
                                                      "name (NAME.npz), got 'refc'"),
])
def test_a_bad_option_is_one_line_before_any_work(name, options, message):
    """A bench script's bad option is argparse's one line naming it and its range, exit status 2, before any
    work, and README.md is left as it was."""
    before = snapshot()
    result = subprocess.run([sys.executable, f"bench/{name}.py", *options], cwd=ROOT, capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 2 and result.stdout == "", result.stdout + result.stderr
    assert result.stderr.strip().splitlines()[-1] == f"{name}.py: error: {message}"
    assert snapshot() == before


@pytest.mark.slow
def test_a_cached_reference_gets_the_groups_asked_for(tmp_path):
    """A reference cache without a doubled group that --groups names: the group was ignored (the cache's own
    groups taken) and the README said the convergence was not measured; now it is measured, said, and saved
    with the cache (a third run without --groups shows it); a second group joins in the groups' order, the sum
    after them (it came before the new group). The sum's cells are printed to 3 decimals: within 2e-3."""
    cache = str(tmp_path / "dusk.npz")
    run_smoke("bench_quality_dusk", "--reference-cache", cache, "--groups")     # none: the smoke's default is one
    header = "| doubled | -6 deg [%] |"
    asked = run_smoke("bench_quality_dusk", "--reference-cache", cache, "--groups", "ray march")
    assert [row[0] for row in table_rows(asked, header)] == ["the ray march's samples, sun steps and transmittance "
                                                             "table", "**sum**"]
    assert table_rows(run_smoke("bench_quality_dusk", "--reference-cache", cache), header) == table_rows(asked, header)
    # a group added to a cache that holds one: in REFERENCE_GROUPS' order, the sum last and over both
    both = table_rows(run_smoke("bench_quality_dusk", "--reference-cache", cache, "--groups", "table quadrature"),
                      header)
    assert [r[0] for r in both] == ["the table's view and sun steps and its transmittance table",
                                    "the ray march's samples, sun steps and transmittance table", "**sum**"]
    assert both[1] == table_rows(asked, header)[0]
    for column in range(1, len(both[0])):
        assert float(both[2][column]) == pytest.approx(float(both[0][column]) + float(both[1][column]), abs=2e-3)


def test_the_references_convergence_file_holds_every_group_or_is_not_written(tmp_path):
    """bench_quality writes docs/*_reference.csv (the scene planner's REFERENCE_RESOLUTION is its "sum" row) only
    from a run that doubled every group: a partial sum written there would have replaced the last whole one."""
    import csv

    sys.path.insert(0, str(BENCH))
    try:
        import bench_quality
    finally:
        sys.path.remove(str(BENCH))
    groups = list(bench_quality.accuracy.REFERENCE_GROUPS)
    change = {group: {"a": 0.001 * (i + 1), "b": 0.002} for i, group in enumerate(groups)}
    change["sum"] = {"a": 0.01, "b": 0.008}
    path = tmp_path / "quality_reference.csv"
    partial = {group: change[group] for group in ("ray march", "sum")}
    assert bench_quality.write_reference_csv(path, partial, ["a", "b"]) == (
        f"{path} not written: sun nodes; view axis, gather; table quadrature not doubled in this run")
    assert not path.exists()
    assert bench_quality.write_reference_csv(path, change, ["a", "b"]) == f"wrote {path}"
    with open(path, newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert [r["doubled"] for r in rows] == groups + ["sum"]
    assert [float(r["change a"]) for r in rows] == [0.001, 0.002, 0.003, 0.004, 0.01]
    assert [float(r["change b"]) for r in rows] == [0.002] * 4 + [0.008]


def test_a_reference_cache_holds_its_level_and_is_written_whole(tmp_path):
    """bench_quality's cache of the accuracy reference's frames (read by bench_accuracy): a --smoke cache,
    rendered at the draft level, was taken for the 'reference' level's; it now records its level, checked
    on reading with the frames' size, and is written through a temporary (np.savez wrote in place)."""
    import numpy as np

    _report = bench_report()
    frames = {"day": np.ones((4, 4, 3)), "dusk": np.zeros((4, 4, 3))}
    path = tmp_path / "refc.npz"
    _report.save_reference_cache(path, "draft", frames, np.ones((4, 4), bool), seconds=2.5)
    assert [p.name for p in tmp_path.iterdir()] == ["refc.npz"]
    cached = _report.load_reference_cache(path, "draft", 4, frames)
    assert float(cached["seconds"]) == 2.5 and (cached["day"] == 1).all() and str(cached["level"]) == "draft"
    again = "; delete it to render the reference again"
    with pytest.raises(SystemExit, match=re.escape(f"refc.npz holds frames of the 'draft' level, not of the "
                                                   f"'reference' level this run compares with{again}")):
        _report.load_reference_cache(path, "reference", 4, frames)
    with pytest.raises(SystemExit, match=re.escape(f"refc.npz holds 4 x 4 frames, not 8 x 8 (--size){again}")):
        _report.load_reference_cache(path, "draft", 8, frames)
    with pytest.raises(SystemExit, match=re.escape(f"refc.npz lacks the frames 'night'{again}")):
        _report.load_reference_cache(path, "draft", 4, [*frames, "night"])
    # a cache written before the level was recorded, a missing file, a damaged one: named, no traceback
    np.savez(tmp_path / "old.npz", valid=np.ones((4, 4), bool), **frames)
    with pytest.raises(SystemExit, match=re.escape("old.npz holds frames of an unrecorded level (an older cache)")):
        _report.load_reference_cache(tmp_path / "old.npz", "draft", 4, frames)
    (tmp_path / "torn.npz").write_bytes(path.read_bytes()[:100])
    for name in ("torn.npz", "absent.npz"):
        with pytest.raises(SystemExit, match=re.escape(f"--reference-cache {tmp_path / name}: cannot read it (")):
            _report.load_reference_cache(tmp_path / name, "draft", 4, frames)
    # frames of another shape or with NaN reached the comparison, a traceback there (probe of input files)
    for name, frame, message in (
            ("shape.npz", np.ones(3), "frame 'day' is float64 of shape (3,), not 4 x 4 x 3 radiances"),
            ("nan.npz", np.full((4, 4, 3), np.nan), "frame 'day' holds NaN, infinite or negative values")):
        _report.save_reference_cache(tmp_path / name, "draft", {**frames, "day": frame}, np.ones((4, 4), bool))
        with pytest.raises(SystemExit, match=re.escape(f"--reference-cache {tmp_path / name}: {message}{again}")):
            _report.load_reference_cache(tmp_path / name, "draft", 4, frames)


def test_bench_accuracy_needs_matplotlib_before_it_measures(tmp_path):
    """bench_accuracy.py measured for minutes, replaced accuracy.csv, then failed on the plots without
    matplotlib (a traceback; the CSV out of step with the plots): refused first, one line, nothing written."""
    fake = tmp_path / "fake" / "matplotlib"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text('raise ImportError("no matplotlib here")\n')
    docs = tmp_path / "docs"
    docs.mkdir()
    (docs / "accuracy.csv").write_text("kept\n")
    result = subprocess.run([sys.executable, "bench/bench_accuracy.py", "--smoke", "--docs", str(docs)], cwd=ROOT,
                            capture_output=True, text=True, timeout=120,
                            env={**os.environ, "PYTHONPATH": str(fake.parent)})
    assert result.returncode == 2 and result.stdout == "", result.stdout + result.stderr
    assert result.stderr.strip().splitlines()[-1].startswith("bench_accuracy.py: error: the accuracy plots need "
                                                             "matplotlib")
    assert (docs / "accuracy.csv").read_text() == "kept\n" and [p.name for p in docs.iterdir()] == ["accuracy.csv"]


def test_bench_accuracy_replot_of_a_bad_csv_is_one_line(tmp_path):
    """--replot of a CSV its reader refuses (naming the file, line and column) or of a directory ended in a
    traceback: one line now, nothing drawn."""
    pytest.importorskip("matplotlib")
    (tmp_path / "short.csv").write_text("candidate,knob\nx,y\n")
    for csv_path, expected in ((tmp_path / "short.csv", f"--replot: {tmp_path / 'short.csv'}: no rows, or missing "
                                                        f"columns"),
                               (tmp_path, f"--replot: {tmp_path}: cannot read it (Is a directory)")):
        result = subprocess.run([sys.executable, "bench/bench_accuracy.py", "--replot", str(csv_path), "--docs",
                                 str(tmp_path / "plots")], cwd=ROOT, capture_output=True, text=True, timeout=120)
        assert result.returncode == 1 and result.stdout == "", result.stdout + result.stderr
        assert result.stderr.count("\n") == 1 and result.stderr.startswith(expected), result.stderr
    assert not (tmp_path / "plots").exists() or list((tmp_path / "plots").iterdir()) == []


def test_readme_sections_are_checked_before_the_work(tmp_path, monkeypatch):
    """A README section a bench writes was looked for after its work (minutes; bench_dusk had replaced its
    picture by then): parse_arguments checks them first unless --no-readme or --smoke. The README holds
    every section a bench names."""
    import argparse

    _report = bench_report()
    readme = tmp_path / "README.md"
    readme.write_text("<!-- bench:dusk -->\nold\n<!-- /bench:dusk -->\n")
    monkeypatch.setattr(_report, "README", readme)
    parser = _report.add_output_arguments(argparse.ArgumentParser())
    assert not _report.parse_arguments(parser, [], sections=("dusk",)).no_readme
    missing = re.escape("README.md has no <!-- bench:montecarlo --> ... <!-- /bench:montecarlo --> section")
    with pytest.raises(SystemExit, match=missing):
        _report.parse_arguments(parser, [], sections=lambda args: ("dusk", "montecarlo"))
    for skipped in (["--no-readme"], ["--smoke"]):
        assert _report.parse_arguments(parser, skipped, sections=("montecarlo",)).no_readme
    # bench_quality.py and bench_quality_dusk.py take theirs from bench_quality's frame sets (DAY, DUSK), which
    # name them: bench_quality checks its set's, and bench_quality_dusk runs it on DUSK (their smoke runs check
    # each prints its own set's frames)
    sys.path.insert(0, str(BENCH))
    try:
        import bench_quality
    finally:
        sys.path.remove(str(BENCH))
    frame_sets = {"bench_quality": bench_quality.DAY, "bench_quality_dusk": bench_quality.DUSK}
    named = {section for frames in frame_sets.values() for section in frames.sections}
    for script in BENCH.glob("bench_*.py"):
        text = script.read_text()
        if script.stem in frame_sets:
            assert ("sections=frame_set.sections" in text if script.stem == "bench_quality"
                    else "main(DUSK, __doc__)" in text), script.name
            continue
        assert "sections=" in text, f"{script.name} names no README section to check"
        call = text.split("sections=", 1)[1]
        named |= set(re.findall(r'"([\w-]+)"', call[:call.index(")\n")]))
    written = {name for script in BENCH.glob("bench_*.py")
               for name in re.findall(r'write_readme_section\(\s*"([\w-]+)"', script.read_text())}
    assert written <= named, written - named
    _report.check_readme_sections(sorted(named - {"black"}), ROOT / "README.md")


def test_bench_help_says_its_first_sentence_whole():
    """--help's description was the docstring's first line: three stopped mid-sentence ('... with three')."""
    result = subprocess.run([sys.executable, "bench/bench_dusk.py", "--help"], cwd=ROOT, capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0
    assert "with three and with N = 15 wavelengths, and through the old and the new display." in \
        " ".join(result.stdout.split())
