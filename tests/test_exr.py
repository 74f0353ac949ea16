"""HDR frames as OpenEXR (anim/exr.py, ``--hdr exr``) and the panoramas as environment maps (issue 13, item 1).

1. write_exr / read_exr round trips: float32 exactly, half within its rounding; refused values.
2. FrameWriter(hdr='exr'): atomic, checked first, header per frame, stale frames of an earlier run.
3. The orientation, through a renderer's own loader: Mitsuba 3's ``envmap`` emitter (scalar_rgb, CPU)
   loads a map whose pixels hold their own directions, and returns each direction where the module
   docstring says it is; the header's sun attributes point at the same place. docs/exr.md's Blender
   script, run in bpy where a Python with it is at hand (slow), and three.js's EXRLoader in Node
   (tests/js, installed by scripts/setup.sh where npm is).
4. An animation's panorama (render_animation, ``clsky animate --hdr exr``): the EXR holds the very
   values of the .npy frames, its header the units, version and sun, and Mitsuba reads the sun's pixel
   and the zenith row back; bad options give one line and exit status 2.
5. Radiance RGBE frames (anim/rgbe.py, ``--hdr hdr``): within the format's 8-bit mantissas of the
   values, and read by Mitsuba's own image reader as the same bytes.
"""

from __future__ import annotations

import math
import os
import pathlib
import re
import subprocess
import sys

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

import clsky
from clsky.anim.cameras import EquirectangularCamera, sun_direction
from clsky.anim.exr import HALF_MAX, enu_to_envmap, envmap_pixel, frame_attributes, read_exr, write_exr
from clsky.anim.writers import FrameWriter, frame_files

import forked_cli

OpenEXR = pytest.importorskip("OpenEXR", reason="the OpenEXR bindings (clsky[anim]) are not installed")

TINY = dict(size=16, table_size=(9, 33, 7), camera="equirectangular", method="lut", frames=2)


def _frame(height=4, width=6):
    return np.zeros((height, width, 3), np.uint8)


def _listing(directory):
    return sorted(path.name for path in directory.iterdir())


# 1. Round trips -----------------------------------------------------------------------------------

def test_float_round_trip_is_exact(tmp_path):
    rng = np.random.default_rng(1)
    # 20 decades, as a sky from deep twilight to the sun's aureole in absolute units
    rgb = (10.0 ** rng.uniform(-12, 8, size=(7, 10, 3))).astype(np.float32)
    rgb[0, 0] = 0.0
    write_exr(tmp_path / "a.exr", rgb, precision="float")
    pixels, header = read_exr(tmp_path / "a.exr")
    assert pixels.dtype == np.float32 and pixels.shape == (7, 10, 3)
    assert_array_equal(pixels, rgb)                     # float32 in, float32 out: bit for bit
    assert [channel.name for channel in header["channels"]] == ["B", "G", "R"]
    assert header["compression"] == OpenEXR.ZIP_COMPRESSION
    assert _listing(tmp_path) == ["a.exr"]


def test_half_round_trip_within_its_rounding(tmp_path):
    rng = np.random.default_rng(2)
    rgb = 10.0 ** rng.uniform(-9, math.log10(HALF_MAX), size=(16, 32, 3))
    write_exr(tmp_path / "h.exr", rgb, precision="half")
    pixels, _ = read_exr(tmp_path / "h.exr")
    assert pixels.dtype == np.float16
    # Round to nearest half: 11 significant bits, so |error| <= 2^-11 |x| where x is normal (>= 2^-14 =
    # 6.1e-5), and <= half the subnormal spacing, 2^-25, below (values under 2^-25 become 0).
    error = np.abs(pixels.astype(np.float64) - rgb)
    bound = np.maximum(2.0 ** -11 * rgb, 2.0 ** -25)
    assert (error <= bound).all(), f"worst error / bound {float((error / bound).max()):.3g}"
    normal = rgb >= 2.0 ** -14
    assert normal.sum() > 500 and (~normal).sum() > 500     # both regimes are exercised
    # and the rounding is the nearest half: exactly NumPy's float16 conversion
    assert_array_equal(pixels, rgb.astype(np.float16))


@pytest.mark.parametrize("bad,match", [(np.full((2, 2, 3), np.nan), "NaN"), (np.full((2, 2, 3), np.inf), "NaN"),
                                       (np.zeros((2, 2)), "shape"), (np.zeros((2, 2, 4)), "shape"),
                                       # stored as float32, 1e39 was an infinity in the file
                                       (np.full((2, 2, 3), 1e39), "beyond float32's range"),
                                       (np.full((2, 2, 3), 1 + 1j), "real numbers"),
                                       # written, then refused by read_exr (radiance only)
                                       (np.full((2, 2, 3), -1e-3), "negative values")])
def test_bad_pixels_are_refused_before_writing(tmp_path, bad, match):
    with pytest.raises(ValueError, match=match):
        write_exr(tmp_path / "x.exr", bad)
    assert _listing(tmp_path) == []


def test_half_clips_what_it_cannot_hold_and_counts_it(tmp_path):
    """Above 65504 a half would be infinity: those pixels (a sky's sun disc) are clipped to 65504,
    and the header counts them; everything else is as in the round trip above."""
    rgb = np.full((3, 4, 3), 2.0)
    rgb[0, 1] = (3.0e5, 1.0e5, 5.0e4)                     # the sun's disc, in relative units
    rgb[2, 3, 2] = 7.0e4
    write_exr(tmp_path / "x.exr", rgb, precision="half")
    pixels, header = read_exr(tmp_path / "x.exr")
    assert np.isfinite(pixels).all() and header["halfClippedPixels"] == 2
    assert_array_equal(pixels[0, 1], np.float16([HALF_MAX, HALF_MAX, 5.0e4]))
    assert pixels[2, 3, 2] == HALF_MAX
    assert_array_equal(np.delete(pixels.reshape(-1, 3), [1, 11], axis=0), 2.0)
    write_exr(tmp_path / "none.exr", np.ones((2, 2, 3)), precision="half")
    assert read_exr(tmp_path / "none.exr")[1]["halfClippedPixels"] == 0
    with pytest.raises(ValueError, match="precision"):
        write_exr(tmp_path / "y.exr", rgb, precision="double")
    write_exr(tmp_path / "y.exr", rgb, precision="float")                # float keeps the sun
    assert_array_equal(read_exr(tmp_path / "y.exr")[0], rgb.astype(np.float32))


def test_existing_file_is_refused_without_force(tmp_path):
    (tmp_path / "a.exr").write_bytes(b"precious")
    with pytest.raises(FileExistsError, match="a.exr"):
        write_exr(tmp_path / "a.exr", np.ones((2, 2, 3)))
    assert (tmp_path / "a.exr").read_bytes() == b"precious"
    write_exr(tmp_path / "a.exr", np.ones((2, 2, 3)), force=True)
    assert_array_equal(read_exr(tmp_path / "a.exr")[0], np.ones((2, 2, 3), np.float32))


def test_header_attributes_refuse_a_sun_that_is_no_angle():
    """A NaN sun angle gave a sun direction of NaN in every frame's header (a NaN altitude or wavelength
    went in as such); any finite azimuth is a SunPosition's."""
    with pytest.raises(ValueError, match=r"^sun_zenith_deg must be a number in \[0, 180\], got nan"):
        frame_attributes("u", "fisheye", 4, 4, float("nan"), 0.0)
    with pytest.raises(ValueError, match=r"^sun_azimuth_deg must be a finite number, got inf"):
        frame_attributes("u", "fisheye", 4, 4, 30.0, math.inf)
    with pytest.raises(ValueError, match=r"^altitude_m must be a finite number >= 0, got nan"):
        frame_attributes("u", "fisheye", 4, 4, 30.0, 0.0, altitude_m=math.nan)
    with pytest.raises(ValueError, match=r"^wavelengths_nm must be 3 wavelengths \[nm\], finite and > 0"):
        frame_attributes("u", "fisheye", 4, 4, 30.0, 0.0, wavelengths_nm=(650.0, math.nan, 475.0))
    assert frame_attributes("u", "fisheye", 4, 4, 30.0, 800.0)["sunAzimuthDeg"] == 80.0


def test_header_attributes():
    pano = frame_attributes("linear sRGB [cd/m^2] (spectral radiance -> CIE 1931 XYZ -> sRGB)", "equirectangular",
                            64, 32, 60.0, 135.0, altitude_m=250.0)
    assert pano["envmap"] == "latlong"                  # stored as OpenEXR.ENVMAP_LATLONG (below)
    assert pano["software"] == f"clsky {clsky.__version__}" and pano["clskyVersion"] == clsky.__version__
    assert pano["whiteLuminance"] == 1.0 and len(pano["chromaticities"]) == 8
    assert pano["sunAzimuthDeg"] == 135.0 and pano["sunElevationDeg"] == 30.0 and pano["observerAltitude"] == 250.0
    # the ENU vector of clsky.anim.cameras.sun_direction, and the same in the map's axes (east, up, south)
    # stored as float32 (v3f, which three.js reads too): within its rounding, 2^-24 of components <= 1
    assert pano["sunDirectionENU"].dtype == np.float32 and pano["sunDirectionEnvmap"].dtype == np.float32
    assert_allclose(pano["sunDirectionENU"], sun_direction(60.0, 135.0), rtol=0, atol=6e-8)
    east, north, up = sun_direction(60.0, 135.0)
    assert_allclose(pano["sunDirectionEnvmap"], [east, up, -north], rtol=0, atol=6e-8)
    assert_allclose(pano["sunPixel"], [64 * 135.0 / 360.0, 32 * 60.0 / 180.0], rtol=1e-7)
    relative = frame_attributes("relative (incident light I_I per sr)", "fisheye", 32, 32, 80.0, 10.0,
                                wavelengths_nm=(680.0, 550.0, 440.0))
    assert "envmap" not in relative and "whiteLuminance" not in relative and "sunPixel" not in relative
    assert_array_equal(relative["channelWavelengthsNm"], np.float32([680.0, 550.0, 440.0]))


# 2. FrameWriter -----------------------------------------------------------------------------------

def test_frame_writer_exr_frames(tmp_path):
    rng = np.random.default_rng(3)
    hdr = [rng.uniform(0, 3, size=(8, 16, 3)) for _ in range(2)]
    attributes = [frame_attributes("cd/m^2", "equirectangular", 16, 8, 70.0 + k, 200.0) for k in range(2)]
    with FrameWriter(directory=tmp_path, hdr="exr", total_frames=2) as writer:
        for index in range(2):
            writer.write(index, _frame(), hdr=hdr[index], hdr_attributes=attributes[index])
    assert _listing(tmp_path) == ["frame_00000.exr", "frame_00000.png", "frame_00001.exr", "frame_00001.png"]
    for index in range(2):
        pixels, header = read_exr(tmp_path / f"frame_{index:05d}.exr")
        assert_array_equal(pixels, hdr[index].astype(np.float32))
        assert header["sunElevationDeg"] == pytest.approx(20.0 - index, abs=1e-5)   # stored as float32
    with FrameWriter(directory=tmp_path / "half", hdr="exr", hdr_precision="half") as writer:
        writer.write(0, _frame(), hdr=hdr[0], hdr_attributes=attributes[0])
        writer.write(1, _frame(), hdr=np.full((8, 16, 3), 1e5))
        with pytest.raises(ValueError, match="NaN"):
            writer.write(2, _frame(), hdr=np.full((8, 16, 3), np.nan))
    first, header = read_exr(tmp_path / "half" / "frame_00000.exr")
    assert first.dtype == np.float16 and header["halfClippedPixels"] == 0 and "sunPixel" in header
    assert read_exr(tmp_path / "half" / "frame_00001.exr")[1]["halfClippedPixels"] == 8 * 16
    assert _listing(tmp_path / "half") == ["frame_00000.exr", "frame_00000.png", "frame_00001.exr",
                                           "frame_00001.png"]                      # the refused frame: nothing


def test_frame_writer_exr_checks_and_stale_frames(tmp_path):
    with pytest.raises(ValueError, match="hdr_precision"):
        FrameWriter(directory=tmp_path, hdr="npy", hdr_precision="half")
    with pytest.raises(ValueError, match="hdr must be"):
        FrameWriter(directory=tmp_path, hdr="tiff")
    (tmp_path / "frame_00001.exr").write_bytes(b"an earlier run")
    with pytest.raises(FileExistsError, match="frame_00001.exr"):
        FrameWriter(directory=tmp_path, hdr="exr", total_frames=2).check()
    assert frame_files(tmp_path) == [tmp_path / "frame_00001.exr"]
    with FrameWriter(directory=tmp_path, hdr="exr", total_frames=2, force=True) as writer:
        writer.write(0, _frame(), hdr=np.ones((2, 2, 3)))
    assert writer.stale_paths == [tmp_path / "frame_00001.exr"]
    assert _listing(tmp_path) == ["frame_00000.exr", "frame_00000.png"]


def test_interrupted_exr_run_leaves_nothing(tmp_path):
    with pytest.raises(KeyboardInterrupt):
        with FrameWriter(directory=tmp_path / "frames", hdr="exr") as writer:
            writer.write(0, _frame(), hdr=np.ones((2, 2, 3)))
            raise KeyboardInterrupt
    assert _listing(tmp_path) == []                       # no temporary, and the directory it made is gone


# 3. Orientation through Mitsuba 3's envmap emitter ------------------------------------------------

@pytest.fixture(scope="module")
def mitsuba():
    mi = pytest.importorskip("mitsuba", reason="mitsuba (clsky[test]) is not installed")
    mi.set_variant("scalar_rgb")
    return mi


def mitsuba_radiance(mi, path, directions_envmap):
    """Mitsuba's envmap emitter's radiance arriving from each direction (in the map's y-up axes)."""
    emitter = mi.load_dict({"type": "envmap", "filename": str(path)})
    values = []
    for direction in np.atleast_2d(directions_envmap):
        interaction = mi.SurfaceInteraction3f()
        interaction.wi = mi.Vector3f(*(-direction))      # wi points away from the emitter
        values.append(list(emitter.eval(interaction)))
    return np.array(values)


def mitsuba_texel_directions(pixels, width, height):
    """ENU directions at which Mitsuba 3 reads pixel (row, column) exactly: its envmap (3.9, measured)
    reads column x at u = (x + 0.5) / width, as clsky's pixel centres, but row y at v = y / (height - 1)
    (the first and last rows on the poles), where clsky's centres are at (y + 0.5) / height (anim/exr.py)."""
    rows, columns = np.asarray(pixels).T
    return sun_direction(180.0 * rows / (height - 1), 360.0 * (columns + 0.5) / width)


def angles(a, b):
    """Angles [rad] between the rows of ``a`` and ``b`` (not necessarily unit vectors)."""
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0))


def test_mitsuba_finds_every_direction_where_the_map_says(tmp_path, mitsuba):
    """Pixels hold their own direction (east, north, up) + 2, so whatever Mitsuba returns for a
    direction tells where it looked. A mirrored, rotated or upside-down map is off by radians."""
    width, height = 64, 32
    directions, _ = EquirectangularCamera(width, height).directions()
    sun = frame_attributes("cd/m^2", "equirectangular", width, height, 55.0, 250.0)
    path = write_exr(tmp_path / "directions.exr", directions + 2.0, precision="float", attributes=sun)
    rng = np.random.default_rng(4)
    elevation = np.radians(rng.uniform(-85.0, 85.0, 300))
    azimuth = np.radians(rng.uniform(0.0, 360.0, 300))
    wanted = np.stack([np.cos(elevation) * np.sin(azimuth), np.cos(elevation) * np.cos(azimuth),
                       np.sin(elevation)], axis=-1)
    seen = mitsuba_radiance(mitsuba, path, enu_to_envmap(wanted)) - 2.0
    # Mitsuba reads each pixel at clsky's azimuth but up to half a row (pi / 64 = 0.049 rad) from its
    # elevation (mitsuba_texel_directions); bilinear interpolation of unit vectors between centres 0.098
    # rad apart shortens them but turns them by < 1e-3 rad. Bound: 0.055 rad (3.2 deg); a mirror or a
    # quarter turn moves most directions by radians.
    assert angles(seen, wanted).max() < 0.055
    # Exactly: at Mitsuba's own texel positions it returns the pixels (float32 rounding of its atan2 /
    # acos moves the bilinear weights by ~1e-7 of a pixel, times a difference <= 0.1 between neighbours).
    # (Not on the first and last rows: Mitsuba reads them at the poles only, where the azimuth is undefined.)
    texels = [(row, column) for row in (1, 7, 16, 30) for column in (0, 5, 16, 33, 63)]
    exact = mitsuba_radiance(mitsuba, path, enu_to_envmap(mitsuba_texel_directions(texels, width, height)))
    assert_allclose(exact, np.array([directions[r, c] + 2.0 for r, c in texels]), rtol=0, atol=1e-5)
    # The zenith is the top row (all of whose pixels have up = cos(pi / 64)).
    zenith = mitsuba_radiance(mitsuba, path, enu_to_envmap([0.0, 0.0, 1.0]))[0]
    assert zenith[2] == pytest.approx(2.0 + math.cos(math.pi / 64), abs=1e-6)
    # The header's sun, in the map's axes, is where Mitsuba finds the sun's ENU direction.
    header = read_exr(path)[1]
    found = mitsuba_radiance(mitsuba, path, header["sunDirectionEnvmap"]) - 2.0
    assert angles(found, header["sunDirectionENU"][None])[0] < 0.055
    # and sunPixel is the pixel whose centre looks closest to the sun (within half a pixel each way)
    column, row = (int(c) for c in np.floor(header["sunPixel"]))
    angle = math.degrees(math.acos(np.clip(directions[row, column] @ header["sunDirectionENU"], -1, 1)))
    assert angle <= math.hypot(360.0 / width, 180.0 / height) / 2


def bpy_python():
    """A Python with Blender's bpy module: this one if it has bpy, else $CLSKY_BPY_PYTHON (bpy's
    wheels are 350 MB and for Python 3.11 only, so they are not in clsky's test extra)."""
    import importlib.util
    import os

    if importlib.util.find_spec("bpy") is not None:
        return sys.executable
    return os.environ.get("CLSKY_BPY_PYTHON") or pytest.skip("no Python with bpy (set CLSKY_BPY_PYTHON)")


@pytest.mark.slow                                      # ~30 s of Cycles where bpy is at hand
def test_blender_snippet_puts_north_on_plus_y(tmp_path):
    """docs/exr.md's Blender script, run in bpy on a map whose pixels hold their direction + 2: Cycles
    sees, along each Blender axis, the clsky direction the doc promises (x east, y north, z up), and
    its sun lamp shines away from the sun. 1e-3: bilinear interpolation between pixel centres 1.4 deg
    apart (error (2 pi / 256)^2 / 4 = 1.5e-4) and the 1 deg camera's pixels (symmetric about the
    axis: second order, 4e-5)."""
    import json

    python = bpy_python()
    directions, _ = EquirectangularCamera(256, 128).directions()
    path = write_exr(tmp_path / "directions.exr", directions + 2.0)
    # Not the poles themselves: Blender's lookup wraps vertically too, and blends the top and bottom rows
    # within half a row of the zenith and the nadir (measured, 4.2: up = 0 at the zenith; docs/exr.md).
    views = np.array([[0, 1, 0], [1, 0, 0], [0, -1, 0], [0.3, 0.2, 0.93], [-0.9, 0.1, 0.3], [0.05, 0, 1],
                      [0.5, 0, -1]], float)
    root = pathlib.Path(__file__).resolve().parent.parent
    result = subprocess.run([python, str(root / "tests" / "blender_world.py"), str(root / "docs" / "exr.md"),
                             str(path), str(tmp_path), *(",".join(str(c) for c in view) for view in views)],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    lamp = json.loads(result.stdout.strip().splitlines()[-1])["lamp_shines_along"]
    sun = np.array([0.17, -0.62, 0.77])                   # the snippet's sun_enu
    assert_allclose(lamp, -sun / np.linalg.norm(sun), rtol=0, atol=1e-6)
    for index, view in enumerate(views):
        rendered = _rgba(tmp_path / f"view_{index}.exr")
        assert_allclose(rendered.mean(axis=(0, 1)) - 2.0, view / np.linalg.norm(view), rtol=0, atol=1e-3)


def _rgba(path):
    """The R, G, B of a Blender render (channels R, G, B, A)."""
    with OpenEXR.File(str(path)) as exr:
        return np.array(exr.channels()["RGBA"].pixels)[..., :3]


JS = pathlib.Path(__file__).resolve().parent / "js"


def three_js():
    """``node`` with three.js installed in tests/js (``npm ci --prefix tests/js``, which
    scripts/setup.sh runs where npm is), else skip."""
    import shutil

    node = shutil.which("node")
    if node is None or not (JS / "node_modules" / "three" / "package.json").is_file():
        pytest.skip("no node, or no three.js in tests/js/node_modules (npm ci --prefix tests/js)")
    return node


def test_three_js_exr_loader_reads_the_frames(tmp_path):
    """three.js's EXRLoader (the loader of the doc's snippet), in Node: the values come out exactly
    (float as float32, half as the same halves), bottom row first as WebGL textures want it (so v = 1,
    the zenith, is the file's top row), with the envmap tag, the units and the sun in its header."""
    import json

    node = three_js()
    directions, _ = EquirectangularCamera(16, 8).directions()
    attributes = frame_attributes("cd/m^2", "equirectangular", 16, 8, 60.0, 250.0)
    for precision, dtype in (("float", np.float32), ("half", np.float16)):
        path = write_exr(tmp_path / f"{precision}.exr", directions + 2.0, precision, attributes)
        result = subprocess.run([node, str(JS / "load_exr.mjs"), precision, str(path)], cwd=JS,
                                capture_output=True, text=True, timeout=120)
        assert result.returncode == 0, result.stderr
        assert "Skipped" not in result.stderr, result.stderr      # every attribute type is one it reads
        loaded = json.loads(result.stdout.strip().splitlines()[-1])
        assert (loaded["width"], loaded["height"], loaded["rgba"]) == (16, 8, True)
        assert loaded["float"] == (precision == "float")
        rgba = np.array(loaded["values"], dtype=np.float64).reshape(8, 16, 4)
        stored = read_exr(path)[0]
        assert stored.dtype == dtype
        assert_array_equal(rgba[::-1, :, :3], stored.astype(np.float64))    # rows bottom first, exactly
        assert_array_equal(rgba[..., 3], 1.0)
        header = loaded["header"]
        assert header["envmap"] == "ENVMAP_LATLONG" and header["radianceUnits"] == "cd/m^2"
        assert header["whiteLuminance"] == 1.0 and header["clskyVersion"] == clsky.__version__
        assert_allclose(header["sunDirectionEnvmap"], attributes["sunDirectionEnvmap"], rtol=0, atol=0)
        assert_allclose(header["sunPixel"], attributes["sunPixel"], rtol=0, atol=0)


# 4. An animation's panorama -----------------------------------------------------------------------

@pytest.fixture(scope="module")
def panoramas(tmp_path_factory, cl_context):
    """The same small panorama animation with EXR, RGBE and .npy frames (the default physical preset:
    absolute frames), and with EXR frames of the atmosphere-plus preset (relative frames)."""
    from clsky.anim.animate import AnimationConfig, render_animation

    directory = tmp_path_factory.mktemp("panorama")
    runs = {}
    for hdr in ("exr", "hdr", "npy"):
        config = AnimationConfig(hdr=hdr, output=str(directory / f"{hdr}.mp4"), **TINY)
        runs[hdr] = (config, render_animation(config, ctx=cl_context))
    config = AnimationConfig(hdr="exr", output=str(directory / "plus.mp4"), preset="atmosphere-plus", **TINY)
    runs["exr atmosphere-plus"] = (config, render_animation(config, ctx=cl_context))
    return runs


# The header's sun angles are float32 (EXR float attributes): below 360 degrees their rounding is at most
# half a unit in the last place, 256 * 2^-24 = 1.5e-5 degrees; 360 * 2^-24 = 2.2e-5 bounds it.
FLOAT32_DEGREES = 360.0 * 2.0 ** -24


@pytest.mark.parametrize("run", ["exr", "exr atmosphere-plus"])
def test_panorama_exr_holds_the_frames_values_and_says_what_they_are(panoramas, cl_context, run):
    from clsky import preset
    from clsky.anim.animate import build_table, frame_units

    config, result = panoramas[run]
    units = frame_units(config, build_table(config, ctx=cl_context))
    for row in result.rows:
        index = row["frame"]
        pixels, header = read_exr(config.frames_directory / f"frame_{index:05d}.exr")
        assert pixels.dtype == np.float32 and pixels.shape == (16, 32, 3)
        if run == "exr":
            npy_config, _ = panoramas["npy"]
            frame = np.load(npy_config.frames_directory / f"frame_{index:05d}.npy")
            assert_array_equal(pixels, frame)                # the same render, stored exactly
        assert header["envmap"] == OpenEXR.ENVMAP_LATLONG
        assert header["clskyVersion"] == clsky.__version__
        assert header["sunAzimuthDeg"] == pytest.approx(row["sun_azimuth_deg"] % 360.0, abs=FLOAT32_DEGREES)
        assert header["sunElevationDeg"] == pytest.approx(90.0 - row["sun_zenith_deg"], abs=FLOAT32_DEGREES)
        assert header["radianceUnits"] == units
        if config.absolute:
            # linear sRGB in cd/m^2: its channels are primaries, not wavelengths
            assert units.startswith("linear sRGB [cd/m^2]") and header["whiteLuminance"] == 1.0
            assert "channelWavelengthsNm" not in header
        else:
            # atmosphere-plus: r, g, b radiance at the table's three wavelengths
            assert "relative" in units and "whiteLuminance" not in header
            assert_array_equal(header["channelWavelengthsNm"], np.float32(preset(config.preset).wavelengths))
    table_units = result.paths[-1].read_text(encoding="utf-8")          # the metrics JSON
    assert header["radianceUnits"] in table_units


def test_panorama_rgbe_frames(panoramas):
    from clsky.anim.rgbe import read_rgbe

    config, result = panoramas["hdr"]
    npy_config, _ = panoramas["npy"]
    for row in result.rows:
        pixels, header = read_rgbe(config.frames_directory / f"frame_{row['frame']:05d}.hdr")
        frame = np.load(npy_config.frames_directory / f"frame_{row['frame']:05d}.npy").astype(np.float64)
        assert (np.abs(pixels - frame) <= frame.max(axis=2, keepdims=True) / 256.0).all()   # RGBE's mantissas
        assert header["envmap"] == "latlong" and header["clskyVersion"] == clsky.__version__
        assert float(header["sunElevationDeg"]) == pytest.approx(90.0 - row["sun_zenith_deg"], abs=1e-6)
        # the primaries in Radiance's own line (an unknown 'chromaticities=' line to Radiance and ImageMagick)
        assert header["PRIMARIES"] == "0.64 0.33 0.3 0.6 0.15 0.06 0.3127 0.329" and "chromaticities" not in header
        assert "VIEW" not in header and "radianceView" not in header      # Radiance has no view of a panorama


@pytest.mark.parametrize("camera, hdr", [("fisheye", "hdr"), ("perspective", "exr")])
def test_frames_carry_the_cameras_radiance_view(tmp_path, cl_context, camera, hdr):
    """A fisheye's or perspective camera's frames carry its Radiance view: a Radiance picture as its VIEW=
    line (evalglare and vwrays read it), an EXR as ``radianceView``; the view is the camera's own
    (Camera.radiance_view, whose directions tests/test_anim_cameras.py checks against Radiance's)."""
    from clsky.anim.animate import AnimationConfig, _camera, render_animation
    from clsky.anim.rgbe import read_rgbe

    config = AnimationConfig(hdr=hdr, output=str(tmp_path / "sky.mp4"), **{**TINY, "camera": camera},
                             heading_deg=30.0)
    render_animation(config, ctx=cl_context)
    path = config.frames_directory / f"frame_00000.{hdr}"
    header = read_rgbe(path)[1] if hdr == "hdr" else read_exr(path)[1]
    expected = _camera(config).radiance_view()
    assert expected.startswith("-vta" if camera == "fisheye" else "-vtv")
    assert header["VIEW" if hdr == "hdr" else "radianceView"] == expected


def test_radiance_view_attribute_is_checked():
    """frame_attributes takes Radiance view options on one line, else ValueError naming radiance_view."""
    assert frame_attributes("u", "fisheye", 4, 4, 30.0, 0.0, radiance_view="-vta -vh 180")["radianceView"] == \
        "-vta -vh 180"
    for bad in ("-vta\nEXPOSURE= 2", "vta", 3):
        with pytest.raises(ValueError, match="radiance_view must be Radiance view options on one line"):
            frame_attributes("u", "fisheye", 4, 4, 30.0, 0.0, radiance_view=bad)


def test_mitsuba_loads_the_panorama(panoramas, mitsuba):
    """The sun's pixel, the top (zenith) row and others, looked up by Mitsuba where it reads them
    (mitsuba_texel_directions), are the values clsky wrote: the bilinear weights there are 1 and 0 up to
    float32 rounding of Mitsuba's atan2 / acos (~1e-7 of a pixel), times neighbour contrasts below 100."""
    config, _ = panoramas["exr"]
    path = config.frames_directory / "frame_00001.exr"
    pixels, header = read_exr(path)
    column, row = (int(c) for c in np.floor(header["sunPixel"]))
    looked = [(row, column), (1, 3), (1, 20), (7, 31), (14, 9)]
    seen = mitsuba_radiance(mitsuba, path, enu_to_envmap(mitsuba_texel_directions(looked, 32, 16)))
    assert_allclose(seen, np.array([pixels[r, c] for r, c in looked]), rtol=1e-5, atol=0)
    # The zenith: Mitsuba reads the top row there (between two of its pixels, which hold the sky
    # pi / 32 from the zenith).
    zenith = mitsuba_radiance(mitsuba, path, enu_to_envmap([0.0, 0.0, 1.0]))[0]
    assert (zenith >= pixels[0].min(axis=0) * (1 - 1e-6)).all() and (zenith <= pixels[0].max(axis=0) * (1 + 1e-6)).all()
    assert header["envmap"] == OpenEXR.ENVMAP_LATLONG


def test_cli_hdr_exr_panorama(tmp_path):
    result = subprocess.run([sys.executable, "-m", "clsky.anim", "animate", "--camera", "equirectangular", "--hdr", "exr",
                             "--hdr-precision", "half", "--size", "16", "--frames", "2", "--table-size", "9", "33",
                             "7", "--method", "lut", "--progress", "none", "-o", "pano.mp4"],
                            cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    files = sorted(path.name for path in (tmp_path / "pano_frames").iterdir())
    assert files == ["frame_00000.exr", "frame_00000.png", "frame_00001.exr", "frame_00001.png"]
    pixels, header = read_exr(tmp_path / "pano_frames" / "frame_00000.exr")
    assert pixels.dtype == np.float16 and pixels.shape == (16, 32, 3) and np.isfinite(pixels).all()
    assert (pixels >= 0).all() and header["envmap"] == OpenEXR.ENVMAP_LATLONG


@pytest.mark.parametrize("args,named", [
    (["--hdr", "tiff"], "--hdr"),
    (["--hdr", "exr", "--hdr-precision", "double"], "--hdr-precision"),
    (["--hdr-precision", "half"], "--hdr-precision"),
    (["--hdr", "npy", "--hdr-precision", "half"], "--hdr-precision"),
    (["--hdr", "hdr", "--hdr-precision", "half"], "--hdr-precision"),
    # an option the frames would not use is refused, whatever its value (the default 'float' typed ran)
    (["--hdr", "hdr", "--hdr-precision", "float"], "--hdr-precision sets the EXR frames' pixel type, and --hdr (hdr) "
                                                   "writes no EXR frames (--hdr exr)"),
    (["--hdr-precision", "float"], "--hdr-precision sets the EXR frames' pixel type, and without --hdr clsky writes "
                                   "no EXR frames (--hdr exr)"),
    (["--hdr", "npy", "--hdr-precision", "half"], "--hdr-precision sets the EXR frames' pixel type, and --hdr (npy)"),
], ids=lambda value: " ".join(value) if isinstance(value, list) else value)
def test_cli_bad_hdr_options_one_line_exit_2(tmp_path, args, named):
    result = forked_cli.run("clsky.anim", "animate", *args, "--progress", "none", cwd=tmp_path, timeout=120)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("clsky: error:") and named in lines[0], lines[0]
    assert list(tmp_path.iterdir()) == []


def test_a_scenes_hdr_precision_without_exr_frames_names_the_key_and_the_option(tmp_path):
    """A scene's output.hdr_precision = 'half' with --hdr npy typed: the scene key is named, with the option
    that would make it apply (the message had dropped --hdr exr)."""
    (tmp_path / "s.toml").write_text('[output]\nhdr = "exr"\nhdr_precision = "half"\n')
    result = forked_cli.run("clsky.anim", "animate", "--scene", "s.toml", "--hdr", "npy", "--progress", "none",
                            cwd=tmp_path, timeout=120)
    assert result.returncode == 2
    assert result.stderr.splitlines() == [
        "clsky: --hdr npy overrides s.toml's output.hdr = \"exr\"",
        "clsky: error: s.toml: output.hdr_precision must be 'float' unless hdr is 'exr' (--hdr exr; .npy and .hdr "
        "frames have no other pixel type), got 'half'"], result.stderr


def test_envmap_pixel_matches_the_camera():
    """envmap_pixel inverts EquirectangularCamera: each pixel centre's direction maps to that centre."""
    width, height = 12, 6
    directions, _ = EquirectangularCamera(width, height).directions()
    for row in range(height):
        for column in range(width):
            east, north, up = directions[row, column]
            zenith = math.degrees(math.acos(up))
            azimuth = math.degrees(math.atan2(east, north))
            assert_allclose(envmap_pixel(zenith, azimuth, width, height), (column + 0.5, row + 0.5), atol=1e-12)


# 5. Radiance RGBE ---------------------------------------------------------------------------------

def test_rgbe_round_trip_within_its_mantissas(tmp_path):
    from clsky.anim.rgbe import read_rgbe, write_rgbe

    rng = np.random.default_rng(5)
    rgb = 10.0 ** rng.uniform(-12, 8, size=(9, 40, 3))          # 20 decades, channels far apart too
    rgb[0, 0] = 0.0
    attributes = frame_attributes("cd/m^2", "equirectangular", 40, 9, 60.0, 250.0)
    write_rgbe(tmp_path / "a.hdr", rgb, attributes)
    pixels, header = read_rgbe(tmp_path / "a.hdr")
    # Each channel is read at the middle of its mantissa step 2^(e - 8), v = max(r, g, b) in
    # [2^(e - 1), 2^e): |error| <= 2^(e - 9) <= v / 256, i.e. 2^-8 relative for the largest channel.
    largest = rgb.max(axis=2, keepdims=True)
    assert (np.abs(pixels - rgb) <= largest / 256.0).all()
    assert_array_equal(pixels[0, 0], 0.0)
    brightest = rgb.argmax(axis=2)[..., None]
    lit = largest > 0
    assert (np.abs(np.take_along_axis(pixels, brightest, 2)[lit] / largest[lit] - 1.0) <= 2.0 ** -8).all()
    assert header["FORMAT"] == "32-bit_rle_rgbe" and header["SOFTWARE"] == f"clsky {clsky.__version__}"
    assert header["envmap"] == "latlong" and header["radianceUnits"] == "cd/m^2"
    assert_allclose([float(v) for v in header["sunDirectionEnvmap"].split()], attributes["sunDirectionEnvmap"],
                    rtol=0, atol=1e-9)
    assert _listing(tmp_path) == ["a.hdr"]


@pytest.mark.parametrize("width", [40, 5])                     # run-length encoded scan lines, and flat ones
def test_mitsuba_reads_the_rgbe_bytes(tmp_path, mitsuba, width):
    """Mitsuba's Bitmap decodes each channel as byte 2^(e - 8) (Ward's rgbe2float, without Radiance's
    half step): exactly that, in float32, for every pixel in its place."""
    from clsky.anim.rgbe import encode_rgbe, write_rgbe

    rng = np.random.default_rng(6)
    rgb = 10.0 ** rng.uniform(-6, 6, size=(7, width, 3))
    write_rgbe(tmp_path / "b.hdr", rgb)
    bitmap = np.array(mitsuba.Bitmap(str(tmp_path / "b.hdr")))
    rgbe = encode_rgbe(rgb)
    expected = rgbe[..., :3] * np.ldexp(1.0, rgbe[..., 3:].astype(int) - 136)
    assert bitmap.shape == (7, width, 3)
    assert_array_equal(bitmap, expected.astype(np.float32))


@pytest.mark.parametrize("bad", [np.full((2, 9, 3), -1.0), np.full((2, 9, 3), np.nan), np.full((2, 9, 3), 1e39),
                                 np.zeros((2, 9))])
def test_rgbe_refuses_what_it_cannot_hold(tmp_path, bad):
    from clsky.anim.rgbe import write_rgbe

    with pytest.raises(ValueError):
        write_rgbe(tmp_path / "x.hdr", bad)
    assert _listing(tmp_path) == []


def test_damaged_or_missing_hdr_files_are_refused_by_name(tmp_path):
    """read_rgbe raised IndexError (a cut run-length scan line), a broadcast error (a run past the line's
    end) or a MemoryError of 3.5 EiB (a resolution line of 999999999 x 999999999 in 40 bytes), and
    read_exr the bindings' RuntimeError for a foreign or missing file: each is now a ValueError naming
    the file (FileNotFoundError for a missing one)."""
    from clsky.anim.rgbe import read_rgbe, write_rgbe

    write_rgbe(tmp_path / "good.hdr", np.ones((2, 16, 3)))
    data = (tmp_path / "good.hdr").read_bytes()
    body = data.index(b"+X 16\n") + 6
    line = data.index(b"\x02\x02\x00\x10")
    damaged = {"cut.hdr": data[:body + 9],
               "run.hdr": data[:body + 4] + bytes([128 + 100]) + data[body + 5:],    # a run of 100 in 16
               "huge.hdr": b"#?RADIANCE\n\n-Y 999999999 +X 999999999\n",
               # read before: XYZ as R, G, B; a scale ignored; an empty picture; a row dropped; bytes after the
               # pixels; a run-length line of another width than the picture's
               "xyze.hdr": data.replace(b"FORMAT=32-bit_rle_rgbe", b"FORMAT=32-bit_rle_xyze"),
               "exposure.hdr": data.replace(b"SOFTWARE", b"EXPOSURE=2.0\nSOFTWARE"),
               "empty.hdr": data.replace(b"-Y 2 +X 16", b"-Y 0 +X 16"),
               "short.hdr": data.replace(b"-Y 2 +X 16", b"-Y 1 +X 16"),
               "tail.hdr": data + b"\0" * 1000,
               "width.hdr": data[:line] + b"\x02\x02\x00\x11" + data[line + 4:]}
    for name, content in damaged.items():
        (tmp_path / name).write_bytes(content)
        with pytest.raises(ValueError, match=rf"^{tmp_path / name}: "):
            read_rgbe(tmp_path / name)
    # a FIFO blocked the reader, and /dev/zero exhausted the memory: a regular file or nothing
    os.mkfifo(tmp_path / "fifo.hdr")
    for path in (tmp_path / "fifo.hdr", "/dev/zero"):
        with pytest.raises(FileNotFoundError, match="not a regular file"):
            read_rgbe(path)
    with pytest.raises(FileNotFoundError, match="no such file"):
        read_rgbe(tmp_path / "missing.hdr")
    with pytest.raises(IsADirectoryError):
        read_rgbe(tmp_path)
    # clsky info describes a valid picture whose pixels read_rgbe does not decode (XYZE, an EXPOSURE)
    from clsky.info import describe

    assert "Radiance image (32-bit_rle_xyze)" in describe(tmp_path / "xyze.hdr")
    assert "Radiance RGBE image" in describe(tmp_path / "exposure.hdr")
    pytest.importorskip("OpenEXR")
    (tmp_path / "junk.exr").write_bytes(b"v/1\x01junk")
    with pytest.raises(ValueError, match=rf"^{tmp_path / 'junk.exr'}: not a readable EXR file"):
        read_exr(tmp_path / "junk.exr")
    with pytest.raises(FileNotFoundError, match="no such file"):
        read_exr(tmp_path / "missing.exr")


def test_radiance_scales_and_resolution_lines_as_radiance_reads_them(tmp_path):
    """Radiance multiplies every EXPOSURE line (its tools add one a step) and applies COLORCORR per channel:
    only the last EXPOSURE line was checked and COLORCORR not at all, so pixels at half their values or
    with their red doubled were read as they were (probe of HDR files, 2026-12-07). Their product must be 1
    now; spaces in the resolution line as Radiance's reader takes them, and another orientation named."""
    from clsky.anim.rgbe import read_rgbe, read_rgbe_header, write_rgbe
    from clsky.info import describe

    write_rgbe(tmp_path / "good.hdr", np.full((2, 16, 3), 0.75))
    data = (tmp_path / "good.hdr").read_bytes()

    def variant(name, old, new):
        (tmp_path / name).write_bytes(data.replace(old, new))
        return tmp_path / name

    refused = {"two.hdr": (b"SOFTWARE", b"EXPOSURE=0.5\nEXPOSURE=1\nSOFTWARE", "its EXPOSURE is '0.5; 1'"),
               "colorcorr.hdr": (b"SOFTWARE", b"COLORCORR= 2 1 0.5\nSOFTWARE", "its COLORCORR is '2 1 0.5'"),
               "flipped.hdr": (b"-Y 2 +X 16", b"+Y 2 +X 16", "its orientation '+Y 2 +X 16' is not read")}
    for name, (old, new, message) in refused.items():
        with pytest.raises(ValueError, match=rf"^{variant(name, old, new)}: {re.escape(message)}"):
            read_rgbe(tmp_path / name)
    assert "EXPOSURE       0.5; 1" in describe(tmp_path / "two.hdr")      # info shows every line
    expected, _ = read_rgbe(tmp_path / "good.hdr")
    for name, old, new in (("product.hdr", b"SOFTWARE", b"EXPOSURE=2\nEXPOSURE= 0.5\nSOFTWARE"),
                           ("unit.hdr", b"SOFTWARE", b"COLORCORR= 1 1 1\nSOFTWARE"),
                           ("spaces.hdr", b"-Y 2 +X 16", b"-Y  2 +X 16 \r")):
        pixels, _ = read_rgbe(variant(name, old, new))
        assert np.array_equal(pixels, expected), name
    # another repeated line keeps its last value, as Radiance takes it (two FORMAT lines were refused)
    pixels, header = read_rgbe(variant("formats.hdr", b"SOFTWARE", b"FORMAT=32-bit_rle_rgbe\nSOFTWARE"))
    assert np.array_equal(pixels, expected) and header["FORMAT"] == "32-bit_rle_rgbe"
    # a path through a file is no such file (a NotADirectoryError of the OS before)
    with pytest.raises(FileNotFoundError, match="no such file"):
        read_rgbe(tmp_path / "good.hdr" / "x.hdr")
    # clsky info checks that the file can hold the pixels its header declares (a 3.5 kB file of 30000 x 1e9)
    (tmp_path / "huge.hdr").write_bytes(data.replace(b"-Y 2 +X 16", b"-Y 999999999 +X 30000"))
    with pytest.raises(ValueError, match="pixels need at least"):
        read_rgbe_header(tmp_path / "huge.hdr")


def test_read_exr_takes_whole_single_part_srgb_images_and_says_why_not(tmp_path, capfd):
    """From a probe of HDR files (2026-12-07): a data window inside a larger display window was returned
    without its place, a second part was dropped without a word and ACES chromaticities were taken for
    sRGB; a cut file printed the library's lines on stdout and stderr and was 'Invalid part index '0': file
    has 0 parts.'; a Latin-1 attribute made a valid file 'not a readable EXR file ('utf-8' codec ...)'.
    Each is now one message naming the file and why, nothing printed; clsky info shows the windows and
    parts."""
    OpenEXR = pytest.importorskip("OpenEXR")
    from clsky.info import describe

    rgb = np.ones((24, 40, 3), np.float32)
    plain = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}

    def box(x0, y0, x1, y1):
        return np.array([x0, y0], np.int32), np.array([x1, y1], np.int32)

    OpenEXR.File({**plain, "dataWindow": box(10, 5, 49, 28), "displayWindow": box(0, 0, 59, 39)},
                 {"RGB": rgb}).write(str(tmp_path / "window.exr"))
    parts = [OpenEXR.Part(dict(plain), {"RGB": rgb}, "beauty"), OpenEXR.Part(dict(plain), {"RGB": 9 * rgb}, "other")]
    OpenEXR.File(parts).write(str(tmp_path / "parts.exr"))
    aces = (0.7347, 0.2653, 0.0, 1.0, 0.0001, -0.077, 0.32168, 0.33767)
    OpenEXR.File({**plain, "chromaticities": aces}, {"RGB": rgb}).write(str(tmp_path / "aces.exr"))
    good = write_exr(tmp_path / "good.exr", np.random.default_rng(1).random((64, 64, 3)), attributes={"note": "cafe"})
    (tmp_path / "cut.exr").write_bytes(good.read_bytes()[:len(good.read_bytes()) * 2 // 3])
    data = good.read_bytes()
    at = data.index(b"cafe") + 3
    (tmp_path / "latin1.exr").write_bytes(data[:at] + b"\xe9" + data[at + 1:])
    capfd.readouterr()
    for name, message in (("window", "its data window (10, 5)-(49, 28) is not its display window (0, 0)-(59, 39)"),
                          ("parts", "it has 2 parts; the reader takes single-part images"),
                          ("aces", "its chromaticities (0.7347 0.2653 0 1 0.0001 -0.077 0.32168 0.33767) are not "
                                   "Rec. 709's"),
                          ("cut", "not a readable EXR file (its pixel data is damaged or cut short ("),
                          ("latin1", "not a readable EXR file (a string attribute holds text that is not UTF-8")):
        with pytest.raises(ValueError, match=rf"^{re.escape(str(tmp_path / name))}.exr: {re.escape(message)}"):
            read_exr(tmp_path / f"{name}.exr")
    assert capfd.readouterr() == ("", "")                   # the library's lines went into the messages
    assert "windows             data (10, 5)-(49, 28) in display (0, 0)-(59, 39)" in describe(tmp_path / "window.exr")
    assert "parts               2 ('beauty', 'other'; this is the first's header)" in describe(tmp_path / "parts.exr")
    assert np.array_equal(read_exr(good)[0], read_exr(good)[0]) and capfd.readouterr() == ("", "")
    # with stdout closed (a daemon's) a good file was 'not readable ([Errno 9] Bad file descriptor)'
    script = f"from clsky.anim.exr import read_exr; read_exr({str(good)!r})"
    closed = subprocess.run([sys.executable, "-c", script], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, timeout=120, preexec_fn=lambda: os.close(1))
    assert closed.returncode == 0, closed.stderr
    # with stderr closed, the copy of stdout took descriptor 2, which the redirection overwrote: what the
    # process printed after the read went into a deleted temporary
    script = f"from clsky.anim.exr import read_exr; print('before'); read_exr({str(good)!r}); print('after')"
    closed = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120,
                            preexec_fn=lambda: os.close(2))
    assert closed.returncode == 0 and closed.stdout == "before\nafter\n", closed.stdout
    # channels of mixed types make a valid file that the bindings' RGB view refused ('cannot coalesce'):
    # read channel by channel, as float; a layer's channels are named in full when no R, G, B are there
    half, full = np.full((24, 40), 0.5, np.float16), np.full((24, 40), 0.25, np.float32)
    OpenEXR.File(dict(plain), {"R": half, "G": full, "B": half}).write(str(tmp_path / "mixed.exr"))
    pixels, _ = read_exr(tmp_path / "mixed.exr")
    assert pixels.dtype == np.float32 and pixels[0, 0].tolist() == [0.5, 0.25, 0.5]
    OpenEXR.File(dict(plain), {f"diffuse.{c}": full for c in "RGB"}).write(str(tmp_path / "layer.exr"))
    with pytest.raises(ValueError, match=re.escape("no R, G, B channels (has ['diffuse.B', 'diffuse.G', "
                                                   "'diffuse.R'])")):
        read_exr(tmp_path / "layer.exr")


def test_read_exr_takes_radiance_only(tmp_path):
    """read_exr returned NaN, infinite, negative and integer pixels as they were, said 'has []' for any file
    without an RGB layer (the bindings empty their channels when the file closes) and refused an RGBA file;
    a 3.5 kB file declaring 100000 x 100000 pixels had the bindings allocate 56 GiB."""
    OpenEXR = pytest.importorskip("OpenEXR")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}

    def written(name, channels):
        OpenEXR.File(header, channels).write(str(tmp_path / name))
        return tmp_path / name

    for value, message in ((np.nan, "NaN, infinite or negative"), (np.inf, "NaN, infinite or negative"),
                           (-5.0, "NaN, infinite or negative")):
        rgb = np.ones((4, 8, 3), np.float32)
        rgb[1, 1, 1] = value
        with pytest.raises(ValueError, match=message):
            read_exr(written("bad.exr", {"RGB": rgb}))
    with pytest.raises(ValueError, match="its pixels are uint32, not half or float radiance"):
        read_exr(written("uint.exr", {"RGB": np.ones((4, 8, 3), np.uint32)}))
    with pytest.raises(ValueError, match=r"no R, G, B channels \(has \['Y'\]\)"):
        read_exr(written("y.exr", {"Y": np.ones((4, 8), np.float32)}))
    rgba = np.full((4, 8, 4), 0.5, np.float32)
    pixels, _ = read_exr(written("rgba.exr", {"RGBA": rgba}))
    assert pixels.shape == (4, 8, 3) and np.all(pixels == 0.5)
    data = bytearray(written("small.exr", {"RGB": np.ones((4, 8, 3), np.float32)}).read_bytes())
    for name in (b"dataWindow\0box2i\0", b"displayWindow\0box2i\0"):
        at = data.index(name) + len(name) + 4
        data[at:at + 16] = np.array([0, 0, 99999, 99999], "<i4").tobytes()
    (tmp_path / "huge.exr").write_bytes(bytes(data))
    with pytest.raises(ValueError, match=r"its data window holds 10000000000 pixels, the reader takes 1 to"):
        read_exr(tmp_path / "huge.exr")


def test_rgbe_refuses_an_attribute_named_as_its_own_header_lines(tmp_path):
    """An attribute FORMAT (or SOFTWARE) added a second line of that name, which won on reading; EXPOSURE,
    COLORCORR and PRIMARIES would say the pixels are at another scale or in other primaries. A file whose
    PRIMARIES are not Rec. 709's is refused on reading, as an EXR's chromaticities are."""
    from clsky.anim.rgbe import read_rgbe, write_rgbe

    for name in ("FORMAT", "SOFTWARE", "EXPOSURE", "COLORCORR", "PRIMARIES", "VIEW"):
        with pytest.raises(ValueError, match=f"attribute name '{name}' is a header line of the file's own"):
            write_rgbe(tmp_path / "x.hdr", np.ones((2, 8, 3)), attributes={name: "x"})
    assert _listing(tmp_path) == []
    aces = (0.7347, 0.2653, 0.0, 1.0, 0.0001, -0.077, 0.32168, 0.33767)
    write_rgbe(tmp_path / "aces.hdr", np.ones((2, 8, 3)), attributes={"chromaticities": aces})
    with pytest.raises(ValueError, match=r"its PRIMARIES \('0.7347 0.2653 0.0 1.0 0.0001 -0.077 0.32168 0.33767'\) are "
                                         r"not Rec. 709's"):
        read_rgbe(tmp_path / "aces.hdr")


def test_frame_writer_rgbe_frames(tmp_path):
    from clsky.anim.rgbe import read_rgbe

    hdr = np.random.default_rng(7).uniform(0, 3, size=(8, 16, 3))
    attributes = frame_attributes("relative (incident light I_I per sr)", "fisheye", 16, 8, 70.0, 200.0)
    with FrameWriter(directory=tmp_path, hdr="hdr", total_frames=1) as writer:
        writer.write(0, _frame(), hdr=hdr, hdr_attributes=attributes)
    assert _listing(tmp_path) == ["frame_00000.hdr", "frame_00000.png"]
    pixels, header = read_rgbe(tmp_path / "frame_00000.hdr")
    assert (np.abs(pixels - hdr.astype(np.float32)) <= hdr.max(axis=2, keepdims=True) / 256.0).all()
    assert header["camera"] == "fisheye" and "envmap" not in header
    assert frame_files(tmp_path) == [tmp_path / "frame_00000.hdr", tmp_path / "frame_00000.png"]


@pytest.mark.parametrize("call, message", [
    (lambda: frame_attributes("cd/m^2", "equirectangular", -5, 2, 45.0, 10.0), r"^width must be an integer"),
    (lambda: frame_attributes("cd/m^2", "equirectangular", 4, float("nan"), 45.0, 10.0), r"^height must be"),
    (lambda: frame_attributes("cd/m^2", "equirectangular", "abc", 2, 45.0, 10.0), r"^width must be"),  # TypeError
    (lambda: envmap_pixel(float("nan"), 10.0, 8, 4), r"^zenith_deg must be a number in \[0, 180\] degrees"),
    (lambda: envmap_pixel(200.0, 10.0, 8, 4), r"^zenith_deg must be"),          # below the image's last row
    (lambda: envmap_pixel(90.0, float("inf"), 8, 4), r"^azimuth_deg must be a finite number, got inf"),
])
def test_header_positions_refuse_what_is_no_size_or_angle(call, message):
    """frame_attributes checked the sun's angles but not the size, whose NaN or negative value made a NaN or
    negative sunPixel; envmap_pixel (public) checked nothing."""
    with pytest.raises(ValueError, match=message):
        call()


@pytest.mark.parametrize("attributes, message", [
    ({"x": None}, r"^attributes: the OpenEXR bindings store them not as given \(unrecognized type"),   # RuntimeError
    ({"compression": 0}, r"^attributes: the OpenEXR bindings store them not as given"),
    ({"x": 2**40}, r"^attributes\['x'\] must be an int in \[-2147483648, 2147483647\] \(EXR's int\), got 1"),  # 0
])
def test_write_exr_refuses_attributes_it_cannot_store(tmp_path, attributes, message):
    pytest.importorskip("OpenEXR")
    with pytest.raises(ValueError, match=message):
        write_exr(tmp_path / "a.exr", np.ones((2, 2, 3)), attributes=attributes)
    assert not (tmp_path / "a.exr").exists()
