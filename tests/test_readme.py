"""Every command line and code example the README shows, run as a user would run it (issue 9, class 1).

The README is parsed, not copied: a new example in it is run here without anyone editing this file,
and an example that stops working fails here. Examples run at a reduced size, by appending options
(argparse keeps the last value of an option given twice) or, in the Python examples, by textual
substitutions that must each match (so a changed example is noticed, not silently run at full size).

What is reduced, and why it keeps the example's meaning:
- ``clsky animate`` / ``clsky render``: 32-pixel frames, 3 frames, no progress bar; the draft quality
  level where the line names neither a level, a budget nor a table size (the default level's own run
  is the README's main job, ``tests/test_main_job.py``, slow). Real sun positions keep their location
  and date, over two hours around a Munich sunrise.
- ``clsky table``: an 8 x 32 x 8 grid (every other option as written).
- The first line of each command runs through the ``clsky`` console script in a new interpreter, the
  others through the same ``main`` in a process forked from one that has imported clsky
  (``tests/forked_cli.py``: the same code after the imports, 0.7 CPU-s less a line).
- A line whose reduced options are an earlier line's, option for option (``clsky animate --size 8192``
  runs as ``clsky animate`` does), is not run again: it is parsed as typed and its options pass the
  animation's checks at the README's size (``REPEATS``).
- ``--scene FILE``: the scene's keys count as options typed (its location keeps its time range, in two
  steps: 3 frames), except its quality level: the draft level is typed over it (the command line wins;
  the scene at its own level is ``tests/test_scene.py``'s slow test). ``--print-scene`` writes nothing.
- Paths of the repository's files (``examples/dusk.toml``, ``docs/scene_dusk.png``) are given from its
  root, as a user in the repository types them.
- ``clsky bench accuracy``: its ``--quick`` smoke run at 16 pixels against the default level (slow: the
  four reference tables take minutes even so).
- ``python bench/X.py``: run with ``--smoke`` (the same code path at a tiny size; writes no README or
  docs) by ``tests/test_bench_smoke.py``, which checks their tables too; here the README's bench lines
  are checked to be among the scripts that module runs, so they are not run twice.

The README's first two commands are checked for what they promise: the test command is the one
``.ci/run`` runs, and the main job is the command ``tests/test_main_job.py`` runs.
"""

from __future__ import annotations

import argparse
import functools
import pathlib
import re
import shlex
import subprocess
import sys

import numpy as np
import pytest

import forked_cli

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

ROOT = pathlib.Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
TEXT = README.read_text(encoding="utf-8")


def fenced_blocks(language):
    """The contents of the README's ```language blocks, in order."""
    return [match.group(1) for match in re.finditer(rf"^```{language}\n(.*?)^```", TEXT, re.S | re.M)]


def shell_lines(block):
    """Command lines of a shell block: comments after ``#`` (preceded by a space) dropped, and the
    optional parts written as ``[--raw sky]`` included."""
    lines = []
    for line in block.splitlines():
        line = re.split(r"\s+#", line, maxsplit=1)[0].strip()
        if line:
            lines.append(re.sub(r"\[([^\]]*)\]", r"\1", line))
    return lines


def inline_commands():
    """Command lines quoted inline in the prose: `clsky ...` and `python bench/...`."""
    spans = re.findall(r"`((?:clsky|python) [^`]+)`", TEXT)
    return [span for span in dict.fromkeys(spans) if not span.startswith("clsky --")]


def readme_commands():
    """Every command line of the README after its first block (the setup commands, tested below)."""
    blocks = fenced_blocks("sh")
    lines = [line for block in blocks[1:] for line in shell_lines(block)]
    return list(dict.fromkeys(lines + inline_commands()))


def scene_of(argv):
    """The scene a command line reads (``--scene FILE``, a repository path): {section: {key: value}}."""
    path = option_value(argv, "--scene")
    return {} if path is None else tomllib.loads((ROOT / path).read_text(encoding="utf-8"))


def reduced(argv, scheduler=None):
    """``argv`` (the README's words) with the options that make it small; a ``--scheduler`` address
    replaced by ``scheduler`` (a cluster this test started: the README's address is an example)."""
    command = argv[1] if len(argv) > 1 else ""
    if "--scheduler" in argv:
        argv = [scheduler if index and argv[index - 1] == "--scheduler" else word for index, word in enumerate(argv)]
    sun = scene_of(argv).get("sun", {})
    extra = []
    if command in ("animate", "render"):
        extra = ["--size", "32", "--progress", "none"] if command == "animate" else ["--size", "32"]
        if command == "animate":
            if "--location" in argv:                # sunrise in Munich on 21 June: about 03:15 UTC
                extra += ["--hours", "2.5", "4.5", "--step-minutes", "60"]
            elif "location" in sun:                 # the scene's time range, in two steps
                extra += ["--step-minutes", str((sun["end_hour"] - sun["start_hour"]) * 60.0 / 2)]
            else:                                   # the sweep (real positions refuse --frames)
                extra += ["--frames", "3"]
        if not {"--quality", "--error-budget", "--table-size"} & set(argv):
            extra += ["--quality", "draft"]
    elif command == "table":
        extra = ["--size", "8", "32", "8", "--progress", "none"]
    elif argv[1:3] == ["bench", "accuracy"]:
        extra = ["--quick", "--size", "16", "--reference-quality", "default", "--progress", "none"]
    words = [str(ROOT / word) if "/" in word and (ROOT / word).is_file() else word for word in argv[1:]]
    return [str(pathlib.Path(sys.executable).parent / "clsky"), *words, *extra]


def option_value(argv, *names):
    for index, word in enumerate(argv[:-1]):
        if word in names:
            return argv[index + 1]
    return None


def check_outputs(argv, directory):
    """The files the command line names exist and hold what they should."""
    command = argv[1] if len(argv) > 1 else ""
    output = option_value(argv, "-o", "--output") or scene_of(argv).get("output", {}).get("output")
    if "--print-scene" in argv:                     # the scene on stdout, no file
        assert list(directory.iterdir()) == []
    elif command == "table" and "--sweep" in argv:  # one table per line of the sweep file, named by its -o
        from clsky import ScatteringTable

        lines = [shlex.split(line, comments=True) for line in
                 (ROOT / option_value(argv, "--sweep")).read_text(encoding="utf-8").splitlines()]
        outputs = [option_value(words, "-o", "--output") for words in lines if words]
        assert outputs and sorted(p.name for p in directory.iterdir()) == sorted(outputs)
        for name in outputs:
            table = ScatteringTable.load(directory / name)
            assert table.settings.size == (8, 32, 8) and np.isfinite(table.data).all() and (table.data >= 0).all()
    elif command == "table":
        from clsky import ScatteringTable

        table = ScatteringTable.load(directory / (output or "table.npz"))
        assert table.settings.size == (8, 32, 8)
        assert np.isfinite(table.data).all() and (table.data >= 0).all()
        raw = option_value(argv, "--raw")
        if raw:
            assert (directory / f"{raw}.bin").stat().st_size == table.data.size * 4
            assert (directory / f"{raw}.json").is_file()
        texture = option_value(argv, "--texture")
        if texture:                                 # docs/lookup4d.glsl's textures: 12 floats a cell
            import json

            header = json.loads((directory / f"{texture}.json").read_text())
            assert header["format"].startswith("clsky 4D scattering table, RGBA textures")
            assert (directory / f"{texture}.bin").stat().st_size == table.data[..., 0].size * 12 * 4
    elif command == "animate":
        imageio = pytest.importorskip("imageio.v3")
        movie = directory / (output or "sky.mp4")
        frames = imageio.imread(movie)
        assert frames.ndim == 4 and frames.shape[0] == 3 and frames.shape[1] == 32
        stem = movie.with_suffix("")
        assert len(list(pathlib.Path(f"{stem}_frames").glob("frame_*.png"))) == 3
        assert pathlib.Path(f"{stem}_metrics.csv").is_file() and pathlib.Path(f"{stem}_metrics.json").is_file()
        if "--hdr" in argv:
            frames = pathlib.Path(f"{stem}_frames")
            if option_value(argv, "--hdr") == "exr":
                from clsky.anim.exr import read_exr

                exr = [read_exr(path) for path in sorted(frames.glob("frame_*.exr"))]
                hdr = [pixels for pixels, _ in exr]
                if option_value(argv, "--camera") == "equirectangular":   # tagged as an environment map
                    assert all("envmap" in header and "sunDirectionEnvmap" in header for _, header in exr)
            else:                                   # a bare --hdr, or --hdr npy
                hdr = [np.load(path) for path in sorted(frames.glob("frame_*.npy"))]
            assert len(hdr) == 3 and all(np.isfinite(h).all() and (h >= 0).all() for h in hdr)
    elif command == "render":
        imageio = pytest.importorskip("imageio.v3")
        image = imageio.imread(directory / (output or "sky.png"))
        assert image.ndim == 3 and image.shape[0] == 32


COMMANDS = readme_commands()


@pytest.fixture(scope="module")
def dask_scheduler():
    """The address of a Dask cluster (one spawned worker) for the README's ``--scheduler`` examples."""
    pytest.importorskip("distributed")
    from clsky.farm import Farm

    with Farm(workers=1) as farm:
        yield farm.client.scheduler.address


def test_the_readme_shows_command_lines():
    """The parser finds the README's examples (guards this module against a README it cannot read)."""
    assert len(COMMANDS) >= 10
    assert any(line.startswith("clsky animate --camera equirectangular") for line in COMMANDS)
    assert any(line.startswith("python bench/") for line in COMMANDS)


#: The lines that install and use Intel's CPU OpenCL runtime (an opt-in): run by tests/test_intel_opencl.py
#: (slow: the install downloads about 250 MB), which finds them in the README itself.
RUNTIME_COMMANDS = [line for line in COMMANDS if line.startswith(("./scripts/intel_opencl.sh", "OCL_ICD_VENDORS="))]
CLSKY_COMMANDS = [line for line in COMMANDS if not line.startswith("python bench/") and line not in RUNTIME_COMMANDS]
BENCH_COMMANDS = [line for line in COMMANDS if line.startswith("python bench/")]


#: Command lines whose reduced run still takes minutes on two cores (slow: run by .ci/run when time allows):
#: `clsky bench accuracy` builds four reference tables at the default level even in its --quick run; the
#: other three build full-size tables that the reduction cannot shrink (a 32 x 256 x 32 --table-size, the
#: level an --error-budget picks, a table planned for a view from 32.7 km): 12-29 s each (measured on
#: the 2-core machine), which the default suite's 10-minute budget cannot hold.
#: The farm lines start Dask clusters of spawned workers, each of which imports clsky and builds its
#: renderer: 13-43 s each at load average 10 (tests/test_farm.py runs a two-worker farm in the default suite).
SLOW_COMMANDS = {"clsky bench accuracy", "clsky animate --error-budget 0.05",
                 "clsky animate --workers 2 --quality draft --size 256 -o farm.mp4",
                 "clsky animate --scheduler tcp://127.0.0.1:8786 --frames 1000 -o long.mp4",
                 "clsky table --sweep examples/weather.txt --workers 2 --quality draft",
                 "clsky animate --table-size 32 256 32 --samples 48 -o full.mp4",
                 "clsky render --altitude 32700 --sampling ground_end -o altitude.png"}


@functools.lru_cache(maxsize=None)
def clsky_parser():
    """``clsky``'s argument parser (one, so that the parsers a namespace holds compare equal)."""
    from clsky.anim.cli import register
    from clsky.cli import build_parser

    return build_parser(extensions=(register,))[0]


def parsed(words):
    """The namespace that ``clsky`` parses ``words`` (the arguments after ``clsky``) to, as a dict."""
    return vars(clsky_parser().parse_args(words))


def repeats_of(lines):
    """{line: the earlier line it repeats}: the lines whose reduced run is an earlier line's, option for
    option (``clsky animate --size 8192`` and ``clsky animate --frames 2 --size 256`` both run as
    ``clsky animate`` at 32 pixels and 3 frames). Those are parsed, not run a second time."""
    runs, repeats = [], {}                         # runs: (options, line) of the lines that run
    for line in lines:
        argv = shlex.split(line)
        if "--scheduler" in argv:                  # its address is replaced when the test runs
            continue
        options = parsed(reduced(argv)[1:])
        earlier = [run for known, run in runs if known == options]
        if earlier:
            repeats[line] = earlier[0]
        else:
            runs.append((options, line))
    return repeats


REPEATS = repeats_of(CLSKY_COMMANDS)
RUN_COMMANDS = [line for line in CLSKY_COMMANDS if line not in REPEATS]
#: The lines run by the ``clsky`` console script itself, in a new interpreter: the first of each command
#: (``clsky table``, ``clsky animate``, ...). The others run the same ``main`` in a process forked from
#: one that has imported clsky (tests/forked_cli.py: 0.7 CPU-s less a line).
CONSOLE_SCRIPT_COMMANDS = {next(line for line in RUN_COMMANDS if line.split()[1] == command)
                           for command in dict.fromkeys(line.split()[1] for line in RUN_COMMANDS)}


def test_repeated_lines_are_valid_as_typed_and_run_as_the_line_they_repeat():
    """Each line not run (REPEATS) is one of the README's, parses as typed, and its options as typed pass
    the animation's checks (at the README's size and frame count, which the run of the line it repeats
    overrides); its reduced options are those of the line that runs."""
    from clsky.anim import cli as anim_cli
    from clsky.anim import scene

    assert REPEATS, "no README line repeats another: the dedup below has nothing to do (remove it?)"
    for line, original in REPEATS.items():
        assert original in RUN_COMMANDS and line in CLSKY_COMMANDS
        argv = shlex.split(line)
        args = argparse.Namespace(**parsed(argv[1:]))
        assert args.command == "animate", line      # the only command whose reduction makes repeats today
        scene.apply_scene(args, args.scene_parser)
        config = anim_cli._config(args)
        assert config.size == int(option_value(argv, "--size") or 512), line
        assert parsed(reduced(argv)[1:]) == parsed(reduced(shlex.split(original))[1:]), (line, original)


@pytest.mark.parametrize("line", [pytest.param(line, marks=pytest.mark.slow) if line in SLOW_COMMANDS else line
                                  for line in RUN_COMMANDS], ids=[line[:60] for line in RUN_COMMANDS])
def test_readme_command_line_runs(line, tmp_path, request):
    argv = shlex.split(line)
    assert argv[0] == "clsky", f"the README shows a command this test cannot run: {line}"
    scheduler = request.getfixturevalue("dask_scheduler") if "--scheduler" in argv else None
    command = reduced(argv, scheduler)
    if line in CONSOLE_SCRIPT_COMMANDS:
        result = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, timeout=600)
    else:
        result = forked_cli.run("clsky.anim", *command[1:], cwd=tmp_path, timeout=600)
    assert result.returncode == 0, f"{line!r} exited {result.returncode}:\n{result.stderr[-2000:]}"
    assert "Traceback" not in result.stderr
    check_outputs(argv, tmp_path)


@pytest.mark.parametrize("line", BENCH_COMMANDS)
def test_readme_bench_lines_are_run_by_the_smoke_tests(line):
    """``python bench/X.py`` as the README shows it: X exists and tests/test_bench_smoke.py runs it."""
    from test_bench_smoke import HEADERS

    argv = shlex.split(line)
    assert len(argv) == 2 and (ROOT / argv[1]).is_file(), line
    assert pathlib.Path(argv[1]).stem in HEADERS


def test_readme_runtime_lines_are_run_by_their_tests():
    """The install line of Intel's runtime and the line that uses it are the ones tests/test_intel_opencl.py
    runs (it reads them from the README: a new line of this kind must be one it knows)."""
    from test_intel_opencl import INSTALL, USE

    assert RUNTIME_COMMANDS, "the README no longer shows how to install Intel's CPU OpenCL runtime"
    for line in RUNTIME_COMMANDS:
        assert line == INSTALL or line.startswith(USE), line


def test_the_first_lines_are_the_two_commands():
    """The README opens with exactly two commands: the main job and the tests; .ci/run runs the test
    command itself, and tests/test_main_job.py runs the main job's ``clsky animate`` with no options."""
    first = shell_lines(fenced_blocks("sh")[0])
    assert TEXT.startswith("```sh\n")
    assert first == ["./scripts/setup.sh && .venv/bin/clsky animate",
                     "./scripts/setup.sh && .venv/bin/python -m pytest"]
    ci = (ROOT / ".ci" / "run").read_text()
    assert re.search(r"^" + re.escape(first[1]) + r"(\s|$)", ci, re.M), ".ci/run does not run the README's test command"
    main_job = (ROOT / "tests" / "test_main_job.py").read_text()
    assert '"animate", "--progress", "none"]' in main_job


def test_the_readme_names_the_python_that_pyproject_requires():
    """The README said nothing of the Python it needs (setup.sh's pip then failed on an older one)."""
    required = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["requires-python"]
    assert required.startswith(">=")
    assert f"Python {required[2:]} or later" in " ".join(TEXT.split())


@pytest.mark.parametrize("failing", ["setup", "tests"])
def test_ci_run_stops_at_a_failed_setup_or_default_suite(tmp_path, failing):
    """.ci/run under ``set -e``: bash does not stop for a failure on the left of ``&&``, so a failed
    scripts/setup.sh skipped the default suite and the run went on (exit 0 with CLSKY_CI_SLOW=0: green
    with no test run). A copy of .ci/run with stand-ins for setup.sh and the venv's python (each records
    its call and fails as asked) must stop with the failing step's status and run nothing after it."""
    for folder in (".ci", "scripts", ".venv/bin"):
        (tmp_path / folder).mkdir(parents=True)
    (tmp_path / ".ci" / "run").write_text((ROOT / ".ci" / "run").read_text())
    calls = tmp_path / "calls"
    for stand_in, name, status in ((tmp_path / "scripts" / "setup.sh", "setup", 3),
                                   (tmp_path / ".venv" / "bin" / "python", "tests", 5)):
        stand_in.write_text(f'#!/usr/bin/env bash\necho "{name} $*" >> "{calls}"\n'
                            f'exit {status if failing == name else 0}\n')
        stand_in.chmod(0o755)
    for slow in ("0", "1"):
        calls.unlink(missing_ok=True)
        done = subprocess.run(["bash", str(tmp_path / ".ci" / "run")], env={"PATH": "/usr/bin:/bin",
                              "CLSKY_CI_SLOW": slow}, capture_output=True, text=True, timeout=60)
        ran = calls.read_text().splitlines()
        assert done.returncode == (3 if failing == "setup" else 5), (slow, done.returncode, ran, done.stderr)
        assert ran == (["setup "] if failing == "setup" else ["setup ", "tests -m pytest -q"]), (slow, ran)


#: (README text, reduced text) for the Python examples; each left side must occur in the README.
PYTHON_REDUCTIONS = [
    ("TableSettings(size=(32, 256, 32), mode=\"physical\", orders=\"auto\")",
     "TableSettings(size=(8, 32, 8), mode=\"physical\", orders=\"auto\")"),
    ("FisheyeCamera(512)", "FisheyeCamera(32)"),
    ("AnimationConfig(frames=120, size=512, output=\"sky.mp4\")",
     "AnimationConfig(frames=3, size=32, quality=\"draft\", output=\"sky.mp4\")"),
    ("error_budget=0.01))", "error_budget=0.1))"),
]


def test_readme_python_examples_run(tmp_path, monkeypatch):
    """The README's Python blocks, in order, in one namespace (each builds on the one before)."""
    code = "\n".join(fenced_blocks("python"))
    for original, small in PYTHON_REDUCTIONS:
        assert original in code, f"the README's Python examples no longer contain {original!r}"
        code = code.replace(original, small)
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "readme_example"}
    exec(compile(code, str(README), "exec"), namespace)       # noqa: S102  (the README is ours)
    assert namespace["same"].settings.size == (8, 32, 8)        # the first block's table, loaded back
    assert namespace["table"].settings == namespace["plan"].table     # the last block's planned table
    assert np.isfinite(namespace["lookup"]).all() and np.isfinite(namespace["reference"]).all()
    assert namespace["result"].rows and len(namespace["result"].rows) == 3
    assert len(namespace["planned"].positions) == 3 and namespace["planned"].plan is not None
    assert (tmp_path / "sky.mp4").is_file() and (tmp_path / "sky.bin").is_file()
