"""clsky.colour_constants: colour-science's constants kept on disk, the same bits as the live package.

Every comparison with colour-science here is exact (array_equal): the cache holds colour-science's
float64 values and the display's von Kries matrix repeats its operations one for one, so any difference
is a bug, not rounding.
"""

from __future__ import annotations

import os
import subprocess
import sys
import zipfile

import numpy as np
import pytest

colour = pytest.importorskip("colour")

import clsky._cache  # noqa: E402
from clsky import colour_constants  # noqa: E402
from clsky.anim.display import white_balance_matrix  # noqa: E402
from clsky.errors import ParameterError  # noqa: E402


@pytest.fixture
def cache_home(tmp_path, monkeypatch):
    """An empty XDG_CACHE_HOME (no CLSKY_CACHE_DIR), and the in-process constants forgotten before and
    after."""
    monkeypatch.delenv("CLSKY_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    colour_constants._constants.cache_clear()
    yield tmp_path
    colour_constants._constants.cache_clear()


def live_values():
    from colour.models import oklab

    cmfs = colour.MSDS_CMFS[colour_constants.CMFS_NAME]
    return {"cmfs_wavelengths": np.asarray(cmfs.wavelengths, dtype=np.float64),
            "cmfs_values": np.asarray(cmfs.values, dtype=np.float64),
            "oklab_xyz_to_lms": oklab.MATRIX_1_XYZ_TO_LMS, "oklab_lms_to_lab": oklab.MATRIX_2_LMS_TO_LAB}


def assert_same_as_colour_science():
    live = live_values()
    wavelengths, values = colour_constants.cie_1931_cmfs()
    assert np.array_equal(wavelengths, live["cmfs_wavelengths"])
    assert np.array_equal(values, live["cmfs_values"])
    xyz_to_lms, lms_to_lab = colour_constants.oklab_matrices()
    assert np.array_equal(xyz_to_lms, live["oklab_xyz_to_lms"])
    assert np.array_equal(lms_to_lab, live["oklab_lms_to_lab"])
    names = colour_constants.adaptation_transform_names()
    assert set(names) == set(colour.CHROMATIC_ADAPTATION_TRANSFORMS)
    for name in names:
        assert np.array_equal(colour_constants.adaptation_transform(name), colour.CHROMATIC_ADAPTATION_TRANSFORMS[name])


def test_first_use_writes_the_file_and_later_uses_read_the_same_values(cache_home):
    path = colour_constants.cache_path()
    assert path.parent.parent == cache_home and not path.exists()
    assert_same_as_colour_science()
    assert path.is_file()
    colour_constants._constants.cache_clear()
    written = path.stat()
    assert_same_as_colour_science()                  # from the file
    assert (path.stat().st_ino, path.stat().st_mtime_ns) == (written.st_ino, written.st_mtime_ns)  # not rewritten


def test_the_values_are_read_only(cache_home):
    wavelengths, values = colour_constants.cie_1931_cmfs()
    with pytest.raises(ValueError):
        values[0, 0] = 1.0
    with pytest.raises(ValueError):
        colour_constants.adaptation_transform("CAT02")[0, 0] = 1.0


def damage_truncated(path):
    path.write_bytes(path.read_bytes()[:200])


def damage_one_value(path):
    """A CMF value changed inside an otherwise valid file (the digest must catch it)."""
    with np.load(path) as data:
        arrays = {name: data[name] for name in data.files}
    arrays["cmfs_values"] = arrays["cmfs_values"].copy()
    arrays["cmfs_values"][100, 1] *= 1.0 + 2.0 ** -40
    np.savez(path, **arrays)


def damage_version(path):
    with np.load(path) as data:
        arrays = {name: data[name] for name in data.files}
    arrays["version"] = np.array("0.0.1")
    np.savez(path, **arrays)


def damage_missing_array(path):
    with np.load(path) as data:
        arrays = {name: data[name] for name in data.files if name != "oklab_lms_to_lab"}
    np.savez(path, **arrays)


def damage_not_a_zip(path):
    path.write_text("not an npz file")


def _forged(path, **changes):
    """The file with ``changes`` made and its digest recomputed: consistent, and wrong."""
    with np.load(path) as data:
        arrays = {name: data[name] for name in data.files}
    arrays.update(changes)
    arrays["digest"] = colour_constants._digest(arrays)
    np.savez(path, **arrays)


def forge_negated_cmfs(path):
    """Every later render failed after its table: 'sun_white must be three finite values >= 0'."""
    with np.load(path) as data:
        _forged(path, cmfs_values=-data["cmfs_values"])


def forge_singular_oklab(path):
    """'Singular matrix' after the table."""
    _forged(path, oklab_xyz_to_lms=np.zeros((3, 3)))


def forge_two_wavelengths(path):
    """Two CMF rows (360 and 361 nm): accepted, and rendered."""
    with np.load(path) as data:
        _forged(path, cmfs_wavelengths=data["cmfs_wavelengths"][:2].copy(), cmfs_values=data["cmfs_values"][:2].copy())


def inflate_a_member(path):
    """400 kB of deflated zeros declaring a 400 MB member: rejected, but only after 382 MiB were allocated."""
    with np.load(path) as data:
        arrays = {name: data[name] for name in data.files}
    arrays["cmfs_wavelengths"] = np.zeros(50_000_000)
    np.savez_compressed(path, **arrays)


@pytest.mark.parametrize("damage", [damage_truncated, damage_one_value, damage_version, damage_missing_array,
                                    damage_not_a_zip, forge_negated_cmfs, forge_singular_oklab,
                                    forge_two_wavelengths, inflate_a_member])
def test_a_damaged_file_is_ignored_and_rewritten(cache_home, damage):
    colour_constants.cie_1931_cmfs()
    path = colour_constants.cache_path()
    damage(path)
    colour_constants._constants.cache_clear()
    assert colour_constants._read(path, colour_constants.colour_science_version()) is None
    assert_same_as_colour_science()
    assert colour_constants._read(path, colour_constants.colour_science_version()) is not None
    assert zipfile.is_zipfile(path)


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only directories")
def test_an_unwritable_cache_directory_only_costs_the_import(cache_home):
    cache_home.chmod(0o500)
    try:
        assert_same_as_colour_science()
        assert not colour_constants.cache_path().exists()
    finally:
        cache_home.chmod(0o700)


def test_a_cache_path_that_is_a_file_only_costs_the_import(cache_home):
    (cache_home / "clsky").write_text("a file where the directory would be")
    assert_same_as_colour_science()
    assert (cache_home / "clsky").is_file()


def test_clsky_cache_dir_comes_first_when_absolute(cache_home, monkeypatch):
    monkeypatch.setenv("CLSKY_CACHE_DIR", str(cache_home / "own"))
    assert colour_constants.cache_path("1.2.3") == cache_home / "own" / "colour-science-1.2.3.npz"
    monkeypatch.setenv("CLSKY_CACHE_DIR", "relative")
    assert colour_constants.cache_path("1.2.3") == cache_home / "clsky" / "colour-science-1.2.3.npz"


def zero_dimensional_wavelengths(path):
    """Arrays that load but have the wrong rank (a 0-d array has no len())."""
    with np.load(path) as data:
        arrays = {name: data[name] for name in data.files}
    arrays["cmfs_wavelengths"] = np.array(500.0)
    np.savez(path, **arrays)


def test_a_file_of_arrays_of_the_wrong_rank_is_ignored(cache_home):
    colour_constants.cie_1931_cmfs()
    path = colour_constants.cache_path()
    zero_dimensional_wavelengths(path)
    assert colour_constants._read(path, colour_constants.colour_science_version()) is None


def test_another_copy_of_colour_science_on_the_path_writes_no_file(cache_home, monkeypatch):
    """The file's name says the installed distribution's version; values from a colour-science whose
    own version differs (another copy earlier on the path) are used but not kept under that name."""
    monkeypatch.setattr(colour, "__version__", "0.0.0-other-copy")
    assert_same_as_colour_science()
    assert not colour_constants.cache_path().exists()


def test_a_relative_xdg_cache_home_is_ignored(cache_home, monkeypatch):
    """The XDG Base Directory specification: a relative path in XDG_CACHE_HOME is invalid; ~/.cache then."""
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/cache")
    monkeypatch.setenv("HOME", str(cache_home))
    assert colour_constants.cache_path("1.2.3") == cache_home / ".cache" / "clsky" / "colour-science-1.2.3.npz"


def test_a_relative_clsky_cache_dir_is_ignored_with_a_note(cache_home, monkeypatch, caplog):
    """CLSKY_CACHE_DIR must be an absolute path (README): a relative one is ignored, as before, but no longer
    without a word (the cache went where the user had set it not to go)."""
    from clsky import _cache

    monkeypatch.setenv("CLSKY_CACHE_DIR", "relative/cache")
    monkeypatch.setenv("XDG_CACHE_HOME", str(cache_home))
    _cache._ignored_once.cache_clear()
    with caplog.at_level("WARNING", logger="clsky"):
        assert _cache.cache_directory("x") == cache_home / "clsky" / "x"
        _cache.cache_directory("y")
    assert [r.getMessage() for r in caplog.records] == [
        "clsky: note: CLSKY_CACHE_DIR='relative/cache' is not an absolute path: ignored (the cache goes to "
        "$XDG_CACHE_HOME/clsky or ~/.cache/clsky)"]


def test_without_a_home_directory_nothing_is_written(cache_home, monkeypatch):
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setattr(clsky._cache.os.path, "expanduser", lambda path: path)     # "~" stays "~"
    assert colour_constants.cache_path() is None
    monkeypatch.chdir(cache_home)
    assert_same_as_colour_science()
    assert list(cache_home.iterdir()) == []


def test_a_run_with_the_file_does_not_import_colour_science(tmp_path):
    """Two fresh processes on an empty cache: the first imports colour-science and writes the file, the
    second reads it; both give the display's white balance (which uses all three kinds of constants)."""
    script = ("import sys, numpy as np; from clsky.anim.display import white_balance_matrix, linear_srgb_to_oklab;"
              "from clsky import colorimetry;"
              "m = white_balance_matrix([1.0, 0.9, 0.5]); lab = linear_srgb_to_oklab(np.ones((1, 3)));"
              "xyz = colorimetry.spectral_to_xyz(np.ones(3), np.array([450.0, 550.0, 650.0]));"
              "print('colour' in sys.modules, repr(m.tolist()), repr(xyz.tolist()))")
    env = dict(os.environ, CLSKY_CACHE_DIR=str(tmp_path))
    runs = [subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120)
            for _ in range(2)]
    for run in runs:
        assert run.returncode == 0, run.stderr
    first, second = (run.stdout.split(" ", 1) for run in runs)
    assert first[0] == "True" and second[0] == "False"
    assert first[1] == second[1]


SOURCES = [[1.0, 1.0, 1.0], [0.9505, 1.0, 1.089], [1.2, 1.0, 0.4], [3.0e3, 2.5e3, 0.5e3], [0.0, 1.0, 0.0],
           [1.0e-12, 1.0e-12, 1.0e-12]]


@pytest.mark.parametrize("transform", sorted(colour.CHROMATIC_ADAPTATION_TRANSFORMS))
def test_white_balance_is_colour_sciences_von_kries_bit_for_bit(transform):
    from clsky.anim.display import _matrices

    m = _matrices()
    white = m["rgb_to_xyz"].sum(axis=1)
    for source in SOURCES:
        source = np.asarray(source, dtype=np.float64)
        cat = colour.adaptation.matrix_chromatic_adaptation_VonKries(source, white * source[1] / white[1],
                                                                     transform=transform)
        expected = m["xyz_to_rgb"] @ np.asarray(cat, dtype=np.float64) @ m["rgb_to_xyz"]
        assert np.array_equal(white_balance_matrix(source, transform=transform), expected), (transform, source)
        assert np.array_equal(white_balance_matrix(source, transform=transform.upper()), expected)


def test_an_unknown_transform_is_refused_with_the_valid_names():
    with pytest.raises(ParameterError, match=r"transform must be one of .*CAT02.*, got 'CAT99'"):
        white_balance_matrix([1.0, 1.0, 1.0], transform="CAT99")


def test_importing_colour_science_leaves_numpys_printing_as_it_was(tmp_path):
    """colour-science's import sets NumPy's printing to 1.13's for the whole process; clsky's import of it
    (a first run, an empty cache) must not change how the user's arrays print."""
    script = ("import sys, numpy as np; from clsky import colour_constants;"
              "before = repr(np.array([1.0, 2.5])); colour_constants.cie_1931_cmfs();"
              "print('colour' in sys.modules, np.get_printoptions()['legacy'], before == repr(np.array([1.0, 2.5])))")
    env = dict(os.environ, CLSKY_CACHE_DIR=str(tmp_path))
    run = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == ["True", "False", "True"], run.stdout


def test_a_fifo_in_the_cache_is_passed_by(tmp_path):
    """A FIFO where a cache file belongs (the colour constants, a pilot's share) blocked `clsky render` for
    ever: np.load and read_text waited for a writer. Both readers now take it for a missing file."""
    from clsky import planner

    fifo = tmp_path / "constants.npz"
    os.mkfifo(fifo)
    assert colour_constants._read(fifo, colour_constants.colour_science_version()) is None
    assert planner._kept_share(fifo, "any key") is None


def test_an_inflating_member_is_refused_before_it_is_read(cache_home):
    """The file's 1 MiB cap bounds what its members inflate to, read from the archive's directory first:
    a 400 kB file of deflated zeros made one read allocate 382 MiB before it was rejected (tracemalloc
    sees NumPy's allocations; a valid read takes well under 1 MB)."""
    import tracemalloc

    colour_constants.cie_1931_cmfs()
    path = colour_constants.cache_path()
    inflate_a_member(path)
    tracemalloc.start()
    try:
        assert colour_constants._read(path, colour_constants.colour_science_version()) is None
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 10 * 2**20
