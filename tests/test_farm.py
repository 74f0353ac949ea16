"""Frame farms on Dask (clsky/farm.py, anim/farm.py, clsky/sweep.py; issue 13 item 4).

1. ``render_animation(..., farm=Farm(workers=2))`` writes the single-process run's files bit for bit
   (PNG, EXR, MP4, CSV; the metrics JSON but for its build timings), also when one of the two workers
   is killed (SIGKILL) in the middle of the run.
2. ``clsky table --sweep`` on an existing cluster (``--scheduler``) writes the tables of single builds,
   bit for bit; a sweep is checked whole before any work and lands whole or not at all.
3. ``--workers`` / ``--scheduler``: bad values and a missing Dask are one line, exit status 2, naming the
   option, before any work.
4. A farm that closes while its workers' heartbeats wait for the scheduler prints nothing (3-4 s).

One LocalCluster of two spawned workers serves the module; the animation is tiny (4 frames of 24 x 24
pixels from a 9 x 33 x 7 table). The module takes 25 s on the shared 2-core machine at load average 3
(99 s at 12-13): the cluster's start and the single-process reference 9 s (23 s), the two-worker run 7 s
(24 s; mostly each worker's first frame: importing clsky, reading the table, building its renderer), the
kill 2 s (10 s), the sweep 2 s (4 s); the spectral case (11-15 s) and the other methods (12-26 s each)
are marked slow.
"""

from __future__ import annotations

import contextlib
import json
import os
import pathlib
import subprocess
import sys
import time

import numpy as np
import pytest

pytest.importorskip("distributed")
pytest.importorskip("imageio.v3")

from clsky import ScatteringTable, TableSettings, preset  # noqa: E402
from clsky.anim.animate import AnimationConfig, render_animation  # noqa: E402
from clsky.anim.cli import main  # noqa: E402
from clsky.farm import Farm  # noqa: E402

#: The animation of the farm tests: every output kind (composite PNG frames, EXR frames, MP4, metrics),
#: auto-exposure (the physical preset's default: the one sequential step, smoothed by the client), a full
#: table (no scene plan: no pilot), relative outputs (the frames carry the scene, output path included).
TINY = dict(frames=4, size=24, table_size=(9, 33, 7), hdr="exr", output="sky.mp4")


@contextlib.contextmanager
def inside(directory):
    previous = os.getcwd()
    os.chdir(directory)
    try:
        yield
    finally:
        os.chdir(previous)


def run(directory, farm=None):
    with inside(directory):
        return render_animation(AnimationConfig(**TINY), farm=farm)


def without_timings(value):
    """``value`` (JSON) without the wall and CPU times a table build records (they differ run to run)."""
    if isinstance(value, dict):
        return {k: without_timings(v) for k, v in value.items() if not k.endswith("seconds")}
    if isinstance(value, list):
        return [without_timings(v) for v in value]
    return value


def assert_same_outputs(expected: pathlib.Path, actual: pathlib.Path):
    """Every file under ``expected`` is under ``actual`` with the same bytes; the metrics JSON alike but
    for the table build's timings."""
    names = sorted(str(p.relative_to(expected)) for p in expected.rglob("*") if p.is_file())
    assert names == sorted(str(p.relative_to(actual)) for p in actual.rglob("*") if p.is_file())
    assert len([n for n in names if n.endswith(".png")]) == TINY["frames"]
    assert len([n for n in names if n.endswith(".exr")]) == TINY["frames"]
    for name in names:
        if name.endswith("_metrics.json"):
            old, new = (json.loads((d / name).read_text()) for d in (expected, actual))
            assert without_timings(new) == without_timings(old), name
            assert new["frames"] == old["frames"] and new["temporal"] == old["temporal"]
        else:
            assert (actual / name).read_bytes() == (expected / name).read_bytes(), name


def assert_two_frames_match(options, farm, tmp_path):
    """A two-frame animation of ``options`` here and on ``farm``: the same frames, metrics CSV and MP4."""
    for name, where in (("single", None), ("farm", farm)):
        (tmp_path / name).mkdir()
        with inside(tmp_path / name):
            render_animation(AnimationConfig(**options), farm=where)
    for name in ("sky_frames/frame_00000.png", "sky_frames/frame_00001.png", "sky_metrics.csv", "sky.mp4"):
        assert (tmp_path / "farm" / name).read_bytes() == (tmp_path / "single" / name).read_bytes(), name


@pytest.fixture(scope="module")
def farm():
    environment = dict(os.environ)
    with Farm(workers=2) as started:
        started.client.wait_for_workers(2, timeout=120)
        yield started
    # Dask's nanny set its workers' variables (OMP_NUM_THREADS=1, ...) in this process: undone on close
    assert dict(os.environ) == environment


@pytest.fixture(scope="module")
def single_run(tmp_path_factory):
    directory = tmp_path_factory.mktemp("single")
    result = run(directory)
    return directory, result


# 1. Animations -----------------------------------------------------------------------------------

def test_two_workers_write_the_single_process_files_bit_for_bit(farm, single_run, tmp_path):
    expected, single = single_run
    assert len(farm.client.scheduler_info()["workers"]) == 2
    result = run(tmp_path, farm)
    assert_same_outputs(expected, tmp_path)
    assert result.rows == single.rows
    assert [row["frame"] for row in result.rows] == list(range(TINY["frames"]))       # in order
    # auto-exposure ran (the smoothing the client does in order): the EVs are not all one value
    assert len({row["exposure_ev"] for row in result.rows}) > 1


@pytest.mark.slow        # 12-26 s each beside another test run (the 4D table's build, two more animations)
@pytest.mark.parametrize("method", ["lut", "compare4d"])
def test_other_methods_on_the_farm_are_bit_for_bit(farm, method, tmp_path):
    """The lookup alone, and the 4D table (main's 'compare4d': another table layout in the shipped file and
    another kernel on the workers): the farm's files are the single-process run's. The 4D table takes an
    even number of view nodes: 34 (its 33 was rounded up to that silently before it was refused)."""
    table_size = (9, 34, 7) if method == "compare4d" else TINY["table_size"]
    assert_two_frames_match(dict(TINY, frames=2, size=16, hdr=None, method=method, table_size=table_size), farm,
                            tmp_path)


@pytest.mark.slow        # a planned table (draft) and two animations
def test_the_plans_sky_view_lookup_on_the_farm_is_bit_for_bit(farm, tmp_path):
    """'compare' with a plan whose renderer is the sky-view map (draft, sun down to -4 deg: the 3D
    lookup's error exceeds the budget): the client's lookup goes to the workers with the job, and the
    farm's files are the single-process run's."""
    options = dict(TINY, frames=2, size=16, hdr=None, table_size=None, quality="draft", start_elevation_deg=-4.0,
                   max_elevation_deg=5.0)
    assert_two_frames_match(options, farm, tmp_path)
    rows = (tmp_path / "farm" / "sky_metrics.csv").read_text(encoding="utf-8")
    assert rows.count("sky-view map") == 2


@pytest.mark.slow        # 15 s at load average 13 with 6 wavelengths: two spectral tables of four batches now
def test_spectral_frames_on_the_farm_are_bit_for_bit(farm, tmp_path):
    """With --wavelengths the payload is one table file per batch of three (anim/farm.py), reassembled
    into the SpectralTable on each worker: the frames are still the single-process run's."""
    assert_two_frames_match(dict(TINY, frames=2, size=16, hdr=None, wavelengths=12), farm, tmp_path)


def test_a_worker_killed_mid_run_costs_only_its_frames(farm, single_run, tmp_path):
    """One of the two workers kills its own process (SIGKILL) when it finishes frame 1's display task:
    the frames it held are computed again elsewhere, the nanny restarts it, and the outputs are the
    single-process run's, bit for bit."""
    from farm_kill import KillOnce

    expected, _ = single_run
    marker = tmp_path / "killed.pid"
    before = set(farm.client.scheduler_info()["workers"])
    plugin = KillOnce(marker, "clsky-finish-", "-1")
    farm.client.register_plugin(plugin)
    try:
        (tmp_path / "out").mkdir()
        run(tmp_path / "out", farm)
    finally:
        farm.client.unregister_worker_plugin(plugin.name)
    assert marker.is_file(), "no worker was killed: the test did not test anything"
    assert_same_outputs(expected, tmp_path / "out")
    farm.client.wait_for_workers(2, timeout=120)
    after = set(farm.client.scheduler_info()["workers"])
    assert len(before - after) == 1, (before, after)      # one worker lost, replaced by a new one


def test_workers_of_another_clsky_are_refused_at_the_start(farm, monkeypatch):
    """Every worker must have this clsky (a worker without it cannot even read its tasks: they would wait
    forever): checked when the farm starts, one line (here this process claims another version)."""
    import clsky.farm
    from clsky.farm import FarmError, installed_version

    actual = installed_version()
    monkeypatch.setattr(clsky.farm, "installed_version", lambda: "0.0.1")
    with pytest.raises(FarmError, match=f"workers run clsky {actual}, this is clsky 0.0.1: every worker needs "
                                        f"the same clsky"):
        Farm(scheduler=farm.client.scheduler.address).start()


def test_a_bad_window_is_refused_before_any_task(farm):
    """map_ordered's and animation_frames' window (tasks or frames in flight): a negative one raised
    IndexError after its tasks were submitted, 0, 2.5 and True were taken silently."""
    from clsky.anim.farm import animation_frames

    for window in (-5, 0, 2.5, "x", True):
        with pytest.raises(ValueError, match=r"^window must be None or an integer in \[1, 100000\], got "):
            farm.map_ordered(pow, [(2, 2)], window=window)
        with pytest.raises(ValueError, match=r"^window must be None or an integer in \[1, 100000\], got "):
            animation_frames(farm, None, None, [], None, window=window)
    assert list(farm.map_ordered(pow, [(2, 2), (3, 2), (4, 2)], window=1)) == [4, 9, 16]


def test_what_a_farm_error_reports_is_not_logged_before_it(farm):
    """Dask's scheduler (in this process for an embedded cluster) and client logged, at ERROR, what the
    FarmError then said in its one line ("4 workers died", "Failed to reconnect"): filtered while the farm
    runs, every other record kept."""
    import logging

    from clsky.farm import ReportedAsFarmErrorFilter

    def record(message, *args):
        return logging.LogRecord("distributed.scheduler", logging.ERROR, "scheduler.py", 1, message, args, None)

    reported = ReportedAsFarmErrorFilter()
    assert not reported.filter(record("Task %s marked as failed because %d workers died", "clsky-render-x-1", 4))
    assert not reported.filter(record("Failed to reconnect to scheduler after %.2f seconds, closing client", 10.0))
    assert reported.filter(record("Task %s marked as failed because it timed out waiting", "x"))
    for name in ReportedAsFarmErrorFilter.LOGGERS:
        assert any(isinstance(f, ReportedAsFarmErrorFilter) for f in logging.getLogger(name).filters)


def test_the_shipped_table_is_checked_as_a_table_file():
    """What workers receive (anim/farm.py: the table file's bytes) is read back the same, and a damaged
    payload is refused by the table file's own checks (here: the archive's CRC of the data member), not
    rendered."""
    from clsky.anim.farm import load_table_payload, table_payload
    from clsky.table import TableFormatError

    table = ScatteringTable.build("atmosphere-plus", TableSettings(size=(8, 32, 8), orders=2))
    payload = table_payload(table)
    same = load_table_payload(payload)
    np.testing.assert_array_equal(same.data, table.data)
    assert same.settings == table.settings and same.atmosphere == table.atmosphere
    data = bytearray(payload["files"][0])
    offset = data.index(np.ascontiguousarray(table.data).tobytes()[:64])   # the data member, stored uncompressed
    data[offset + 7] ^= 0x40                                              # one bit of one value
    with pytest.raises(TableFormatError, match=r"is damaged .*Bad CRC-32 for file 'data.npy'"):
        load_table_payload({"files": [bytes(data)]})


# 2. Table sweeps -----------------------------------------------------------------------------------

SWEEP = """# two weather states
--preset physical --ground-albedo 0.1 -o clear.npz
--preset physical --ground-albedo 0.8 -o snow.npz   # fresh snow
"""
SWEEP_OPTIONS = ["--size", "8", "32", "8", "--orders", "3", "--progress", "none"]


def test_a_sweep_on_an_existing_cluster_writes_the_tables_of_single_builds(farm, tmp_path, capsys):
    (tmp_path / "weather.txt").write_text(SWEEP)
    address = farm.client.scheduler.address
    with inside(tmp_path):
        assert main(["table", "--sweep", "weather.txt", *SWEEP_OPTIONS, "--scheduler", address]) == 0
    assert f"farm: the Dask cluster at {address}, 2 workers, 2 threads\n" in capsys.readouterr().out
    for name, albedo in (("clear.npz", 0.1), ("snow.npz", 0.8)):
        table = ScatteringTable.load(tmp_path / name)
        single = ScatteringTable.build(preset("physical").replace(ground_albedo=albedo),
                                       TableSettings(size=(8, 32, 8), mode="physical", orders=3))
        assert table.atmosphere == single.atmosphere and table.settings == single.settings
        np.testing.assert_array_equal(table.data, single.data)        # bit for bit: the same kernels
        np.testing.assert_array_equal(table.gathered, single.gathered)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clear.npz", "snow.npz", "weather.txt"]


@pytest.mark.parametrize("line, message", [
    ("--preset physical --ground-albedo 2 -o a.npz", "weather.txt line 3: --ground-albedo must be a number in [0, 1], got 2"),
    ("--preset nowhere -o a.npz", "weather.txt line 3: argument --preset: invalid choice: 'nowhere'"),
    ("--preset physical -o clear.npz", "weather.txt line 3: --output clear.npz is written by weather.txt line 2 too"),
    ("--preset physical -o a.txt", "weather.txt line 3: --output must end in .npz after a file name (NAME.npz), got 'a.txt'"),
    ("--preset physical --workers 2 -o a.npz", "weather.txt line 3: --workers belongs to the command line"),
    ("--preset physical -o 'a.npz", "weather.txt line 3: No closing quotation"),
    ("--preset physical --ground-albedo 0.3", "weather.txt line 3: -o FILE is missing"),
    ("--preset physical -o ''", "weather.txt line 3: --output must be a file path, got an empty one"),   # table.npz
    ("--preset physical -o a.npz --raw .bin", "weather.txt line 3: --raw must be a file name (NAME gives NAME.bin "
                                              "and NAME.json), got '.bin'"),
    ("--preset physical -o a.npz --raw clear.json", "weather.txt line 3: --raw clear.bin is written by weather.txt line 2 too"),
    ("--preset physical --parameterization 4d -o a.npz --texture clear", "weather.txt line 3: --texture clear.bin is "
                                                                           "written by weather.txt line 2 too"),
    ("--preset physical -o a.npz --texture t3", "weather.txt line 3: --texture exports a 4d table as textures"),
    # argparse's abbreviations let run options through as --workers and --progress, silently ignored
    ("--preset physical --work 2 -o a.npz", "weather.txt line 3: unrecognized arguments: --work 2"),
    ("--preset physical --prog leave -o a.npz", "weather.txt line 3: unrecognized arguments: --prog leave"),
    # -h printed the help and ended the sweep with status 0, building nothing
    ("--preset physical -o a.npz -h", "weather.txt line 3: -h belongs to the command line"),
    ("--preset physical -o weather.txt --force", "weather.txt line 3: --output must end in .npz"),
])
def test_a_bad_sweep_line_is_one_line_before_any_work(line, message, tmp_path, capsys):
    (tmp_path / "weather.txt").write_text("# states\n--preset physical -o clear.npz --raw clear\n" + line + "\n")
    with inside(tmp_path):
        assert main(["table", "--sweep", "weather.txt", *SWEEP_OPTIONS]) == 2
    error = capsys.readouterr().err
    assert error.startswith("clsky: error: " + message) and error.count("\n") == 1, error
    assert sorted(p.name for p in tmp_path.iterdir()) == ["weather.txt"]


def test_the_readme_sweep_message_on_the_example_file(tmp_path, capsys):
    """README "Frame farms": a bad line is named by its line in the file, comments counted: the README gave
    'line 3' for the third table line of examples/weather.txt, which its three comment lines make line 6."""
    lines = (pathlib.Path(__file__).resolve().parents[1] / "examples" / "weather.txt").read_text().splitlines()
    table_lines = [n for n, line in enumerate(lines) if line.strip() and not line.lstrip().startswith("#")]
    lines[table_lines[2]] = "--preset physical --ground-albedo 2 -o ozone_high.npz"
    (tmp_path / "weather.txt").write_text("\n".join(lines) + "\n")
    with inside(tmp_path):
        assert main(["table", "--sweep", "weather.txt", *SWEEP_OPTIONS]) == 2
    shown = "weather.txt line 6: --ground-albedo must be a number in [0, 1], got 2"
    assert capsys.readouterr().err == f"clsky: error: {shown}\n"
    readme = (pathlib.Path(__file__).resolve().parents[1] / "README.md").read_text()
    assert " ".join(shown.split()) in " ".join(readme.replace("`", "").split())


def test_a_sweep_refuses_what_it_would_ignore_or_overwrite(tmp_path, capsys):
    """The command line's -o was dropped without a word (every line names its own); a line whose output was
    the sweep file itself replaced it with --force."""
    (tmp_path / "weather.npz").write_text("--preset physical -o weather.npz --force\n")
    (tmp_path / "weather.txt").write_text("--preset physical -o clear.npz\n")
    with inside(tmp_path):
        assert main(["table", "--sweep", "weather.npz", *SWEEP_OPTIONS]) == 2
        assert capsys.readouterr().err == ("clsky: error: weather.npz line 1: --output weather.npz is the sweep file "
                                           "itself\n")
        assert main(["table", "--sweep", "weather.txt", "-o", "x.npz", *SWEEP_OPTIONS]) == 2
        assert capsys.readouterr().err == ("clsky: error: -o/--output names the table of a single build; with --sweep "
                                           "each line names its own (-o x.npz was given on the command line)\n")
        assert main(["table", "--backend", "numpy", "--fast-math", "-o", "n.npz", *SWEEP_OPTIONS]) == 2
        assert capsys.readouterr().err == ("clsky: error: --fast-math sets how the OpenCL kernels are built, and "
                                           "--backend numpy runs none\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["weather.npz", "weather.txt"]


@pytest.mark.parametrize("make, message", [
    (lambda path: None, "--sweep: cannot read weather.txt: No such file or directory"),
    (lambda path: path.mkdir(), "--sweep: cannot read weather.txt: Is a directory"),
    (lambda path: path.write_bytes(b"-o \xff.npz\n"), "--sweep weather.txt: not a text file (not UTF-8 text)"),
])
def test_an_unreadable_sweep_file_is_one_line(make, message, tmp_path, capsys):
    make(tmp_path / "weather.txt")
    with inside(tmp_path):
        assert main(["table", "--sweep", "weather.txt", *SWEEP_OPTIONS]) == 2
    assert capsys.readouterr().err == f"clsky: error: {message}\n"


def test_a_failed_sweep_leaves_no_table(tmp_path, monkeypatch, capsys):
    """The second table's build fails: the first, already built, does not land either (one set)."""
    import clsky.farm
    from clsky.errors import NumericalError

    original, built = clsky.farm.build_table_task, []

    def failing(*task):
        if built:
            raise NumericalError("the second table failed")
        built.append(original(*task))
        return built[-1]

    monkeypatch.setattr(clsky.farm, "build_table_task", failing)
    (tmp_path / "weather.txt").write_text(SWEEP)
    with inside(tmp_path):
        assert main(["table", "--sweep", "weather.txt", *SWEEP_OPTIONS]) == 1
    assert "the second table failed" in capsys.readouterr().err
    assert built and sorted(p.name for p in tmp_path.iterdir()) == ["weather.txt"]    # no table, no temporary


# 3. Options --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("options, message", [
    (["--workers", "0"], "--workers must be an integer in [1, 256], got 0"),
    (["--workers", "-3"], "--workers must be an integer in [1, 256], got -3"),
    (["--workers", "two"], "argument --workers: invalid int value: 'two'"),
    (["--scheduler", "localhost:8786"], "--scheduler must be a scheduler address tcp://HOST:PORT"),
    (["--scheduler", "tcp://host:0"], "--scheduler must be a scheduler address tcp://HOST:PORT"),
    (["--scheduler", "tcp://host:65536"], "--scheduler must be a scheduler address tcp://HOST:PORT"),
    (["--scheduler", "http://host:8786"], "--scheduler must be a scheduler address tcp://HOST:PORT"),
    (["--workers", "2", "--scheduler", "tcp://host:8786"], "argument --scheduler: not allowed with argument --workers"),
])
@pytest.mark.parametrize("command", [["animate", "--frames", "2", "--size", "16", "-o", "sky.mp4"],
                                     ["table", "--size", "8", "32", "8", "-o", "sky.npz"]])
def test_bad_farm_options_are_one_line_before_any_work(command, options, message, tmp_path, capsys):
    with inside(tmp_path):
        assert main([*command, "--progress", "none", *options]) == 2
    error = capsys.readouterr().err
    assert error.startswith("clsky: error: " + message) and error.count("\n") == 1, error
    assert list(tmp_path.iterdir()) == []


def test_a_scheduler_that_does_not_answer_is_one_line(tmp_path, capsys, monkeypatch):
    import clsky.farm

    monkeypatch.setattr(clsky.farm, "CONNECT_TIMEOUT_S", 1)        # no port 1 answers: 1 s is as good as 10
    with inside(tmp_path):
        assert main(["table", "--size", "8", "32", "8", "--progress", "none", "-o", "sky.npz",
                     "--scheduler", "tcp://127.0.0.1:1"]) == 2
    error = capsys.readouterr().err
    assert error.startswith("clsky: error: --scheduler: no Dask scheduler answered at tcp://127.0.0.1:1")
    assert error.count("\n") == 1 and list(tmp_path.iterdir()) == []


@pytest.fixture
def silent_listener():
    """The port of a TCP listener that accepts connections and never answers (as an HTTP server on Dask's
    dashboard port, or any other server, does to Dask's protocol)."""
    import socket

    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen()
        yield listener.getsockname()[1]


def test_a_listener_that_is_no_scheduler_is_one_line_within_the_timeout(tmp_path, capsys, monkeypatch,
                                                                        silent_listener):
    """distributed's Client waited forever on a peer that accepted the connection and never spoke
    (measured: still waiting after 90 s, where the README promises one line after 10 s): the farm gives up
    after CONNECT_TIMEOUT_S + CONNECT_GRACE_S (here 1 + 2 s), its abandoned client's threads daemons."""
    import clsky.farm

    monkeypatch.setattr(clsky.farm, "CONNECT_TIMEOUT_S", 1)
    start = time.perf_counter()
    with inside(tmp_path):
        assert main(["table", "--size", "8", "32", "8", "--progress", "none", "-o", "sky.npz",
                     "--scheduler", f"tcp://127.0.0.1:{silent_listener}"]) == 2
    # 3 s of waiting; 20 s bounds a loaded machine's start of the command, and the hang it replaces
    assert time.perf_counter() - start < 20
    error = capsys.readouterr().err
    assert error.startswith(f"clsky: error: --scheduler: no Dask scheduler answered at tcp://127.0.0.1:"
                            f"{silent_listener} within 1 s (the connection opened, but no Dask scheduler answered")
    assert error.count("\n") == 1 and list(tmp_path.iterdir()) == []


def test_a_client_made_after_the_deadline_is_closed(monkeypatch):
    """A scheduler that answers after the farm gave up: the client made then is closed at once, not left
    open as the process's default Dask client (a stand-in client that answers after 2 s, a 0.5 s deadline)."""
    import threading

    import clsky.farm
    from clsky.farm import Farm

    made, answered = [], threading.Event()

    class LateClient:
        def __init__(self, address, timeout):
            time.sleep(2.0)
            self.closed = False
            made.append(self)

        def close(self):
            self.closed = True
            answered.set()

    monkeypatch.setattr(clsky.farm, "CONNECT_TIMEOUT_S", 0.5)
    monkeypatch.setattr(clsky.farm, "CONNECT_GRACE_S", 0.0)
    with pytest.raises(ConnectionError, match="within 0.5 s"):
        Farm(scheduler="tcp://127.0.0.1:8786")._connect(LateClient)
    assert answered.wait(10.0) and len(made) == 1 and made[0].closed


def test_tls_without_dask_tls_configuration_is_one_line(tmp_path, capsys):
    """A tls:// address needs Dask's TLS configuration (clsky passes no security=): without it, distributed
    raised a TypeError and clsky printed its 58-line traceback."""
    import dask

    with inside(tmp_path), dask.config.set({"distributed.comm.tls.ca-file": None,
                                            "distributed.comm.tls.client.cert": None}):
        assert main(["table", "--size", "8", "32", "8", "--progress", "none", "-o", "sky.npz",
                     "--scheduler", "tls://127.0.0.1:1"]) == 2
    error = capsys.readouterr().err
    assert error.startswith("clsky: error: --scheduler: tls://127.0.0.1:1 needs Dask's TLS configuration")
    assert error.count("\n") == 1 and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("option", ["--workers", "--scheduler"])
def test_without_dask_the_option_says_how_to_install_it(option, tmp_path):
    """Dask hidden from the import system (``sys.modules['distributed'] = None``), as if not installed."""
    value = "2" if option == "--workers" else "tcp://127.0.0.1:8786"
    code = ("import sys; sys.modules['distributed'] = None; from clsky.anim.cli import main; "
            f"sys.exit(main(['animate', '--frames', '2', '--size', '16', '--progress', 'none', '{option}', '{value}']))")
    result = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert result.returncode == 2
    assert result.stderr == (f"clsky: error: {option} needs Dask (dask.distributed), which is not installed: "
                             f"pip install 'clsky[dask]'\n")
    assert list(tmp_path.iterdir()) == []


# 4. Shutdown -------------------------------------------------------------------------------------

#: A farm that closes while each worker's heartbeat waits for the scheduler's answer: the scheduler (in this
#: process, a LocalCluster's) answers heartbeats only after 30 s, so the workers close their connections
#: under them. Before clsky.farm.ClosingWorkerConnectionFilter each worker printed distributed's "Failed to
#: communicate with scheduler during heartbeat." and a CommClosedError's traceback (as once in CI, at the end
#: of `clsky animate --workers 2`).
HEARTBEAT_IN_FLIGHT = """
import asyncio, sys, time
from clsky.farm import Farm

def stall_heartbeats(dask_scheduler):
    answer = dask_scheduler.handlers["heartbeat_worker"]
    async def stalled(*args, **kwargs):
        print("heartbeat stalled", file=sys.stderr, flush=True)
        await asyncio.sleep(30)
        return answer(*args, **kwargs)
    dask_scheduler.handlers["heartbeat_worker"] = stalled

with Farm(workers=2) as farm:
    farm.client.wait_for_workers(2, timeout=120)
    farm.client.run_on_scheduler(stall_heartbeats)
    time.sleep(1.5)                  # three heartbeat periods (0.5 s for small clusters): both workers wait
print("closed")
"""


def test_a_heartbeat_cut_short_by_the_farms_close_prints_nothing(tmp_path):
    """The farm closes with both workers' heartbeats on their way (2.4 s on the quiet 2-core machine):
    nothing on stderr but the test's own lines, and the close does not wait for the stalled answers."""
    start = time.perf_counter()
    result = subprocess.run([sys.executable, "-c", HEARTBEAT_IN_FLIGHT], cwd=tmp_path, capture_output=True,
                            text=True, timeout=120)
    # the stalled answers come after 30 s: a close that took that long would have let them through
    assert time.perf_counter() - start < 25.0, "the close waited for the stalled heartbeats"
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout == "closed\n"
    lines = result.stderr.splitlines()
    assert lines.count("heartbeat stalled") >= 2, "no heartbeat was in flight: the test did not test anything"
    assert set(lines) == {"heartbeat stalled"}, result.stderr[-2000:]


def test_the_filter_drops_connection_errors_of_a_closing_worker_only():
    """clsky.farm.ClosingWorkerConnectionFilter on records like distributed's: a connection error (an
    OSError) passes while the worker runs and is dropped once it closes; other records always pass."""
    import logging
    import types

    from distributed.comm.core import CommClosedError
    from distributed.core import Status

    from clsky.farm import ClosingWorkerConnectionFilter

    def record(error):
        try:
            raise error
        except Exception:
            return logging.LogRecord("distributed.worker", logging.ERROR, __file__, 1, "Failed to communicate "
                                     "with scheduler during heartbeat.", None, sys.exc_info())

    worker = types.SimpleNamespace(status=Status.running)
    keep = ClosingWorkerConnectionFilter(worker).filter
    closed, unexpected = CommClosedError("Stream is closed"), ValueError("a bug")
    plain = logging.LogRecord("distributed.worker", logging.ERROR, __file__, 1, "no exception", None, None)
    assert keep(record(closed)) and keep(record(unexpected)) and keep(plain)
    for status in (Status.closing_gracefully, Status.closing, Status.closed):
        worker.status = status
        assert not keep(record(closed)) and not keep(record(ConnectionResetError()))
        assert keep(record(unexpected)) and keep(plain)
