"""clsky.anim.writers: atomic, never-overwriting PNG frames, HDR frames, MP4, PNG, JSON and CSV."""

from __future__ import annotations

import csv
import io
import json
import math
import os
import zlib

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from PIL import Image

from clsky._files import StagedWrites
from clsky.anim.writers import FrameWriter, encode_png, even_padded, write_csv, write_json, write_png

try:
    import imageio.v3 as imageio_v3
    import imageio_ffmpeg  # noqa: F401
except ImportError:                                    # the optional 'anim' extra is missing
    imageio_v3 = None
needs_ffmpeg = pytest.mark.skipif(imageio_v3 is None, reason="MP4 needs imageio and imageio-ffmpeg")


def _frame(index, height=48, width=64):
    """A frame with a flat colour per index plus a small gradient (distinct frames)."""
    image = np.empty((height, width, 3), dtype=np.uint8)
    image[...] = ((40 + 15 * index) % 256, (200 - 10 * index) % 256, (90 + 7 * index) % 256)
    image[:, :8, 0] = np.arange(8, dtype=np.uint8) * 20
    return image


def _listing(directory):
    return sorted(os.listdir(directory))


# PNG frames -------------------------------------------------------------------------------------------

def test_frames_are_named_zero_padded_and_lossless(tmp_path):
    with FrameWriter(directory=tmp_path / "frames", total_frames=3) as writer:
        for index in range(3):
            writer.write(index, _frame(index))
    assert _listing(tmp_path / "frames") == ["frame_00000.png", "frame_00001.png", "frame_00002.png"]
    for index in range(3):
        assert_array_equal(np.asarray(Image.open(tmp_path / "frames" / f"frame_{index:05d}.png")),
                           _frame(index))
    assert writer.paths == [tmp_path / "frames" / f"frame_{index:05d}.png" for index in range(3)]
    wide = FrameWriter(directory=tmp_path / "wide", total_frames=1234567, prefix="sky")
    assert wide.frame_path(42).name == "sky_0000042.png"            # 7 digits for 1234567 frames


def test_hdr_frames_as_float32_npy(tmp_path):
    hdr = np.random.default_rng(0).uniform(0, 3, size=(48, 64, 3))
    with FrameWriter(directory=tmp_path, hdr="npy", total_frames=2) as writer:
        writer.write(1, _frame(1), hdr=hdr)
    assert _listing(tmp_path) == ["frame_00001.npy", "frame_00001.png"]     # no temporary files left
    stored = np.load(tmp_path / "frame_00001.npy")
    assert stored.dtype == np.float32
    assert_array_equal(stored, hdr.astype(np.float32))
    with FrameWriter(directory=tmp_path / "x", hdr="npy") as writer:
        with pytest.raises(ValueError, match="hdr"):
            writer.write(0, _frame(0))


def test_frames_refuse_to_overwrite_and_touch_nothing(tmp_path):
    existing = tmp_path / "frame_00001.png"
    existing.write_bytes(b"precious")
    with pytest.raises(FileExistsError, match="frame_00001.png.*--force"):
        with FrameWriter(directory=tmp_path, total_frames=3) as writer:
            writer.write(0, _frame(0))
    assert existing.read_bytes() == b"precious"
    assert _listing(tmp_path) == ["frame_00001.png"]


def test_frames_overwrite_with_force_and_delete_stale(tmp_path):
    """A forced, shorter run leaves its own frames only: the earlier run's frames it did not rewrite
    (PNG and .npy, any zero padding) are deleted and reported; other files are never touched."""
    for index in range(3):
        write_png(tmp_path / f"frame_{index:05d}.png", _frame(9))
    np.save(tmp_path / "frame_00000.npy", np.zeros((2, 2, 3), np.float32))    # an earlier --hdr run
    write_png(tmp_path / "frame_0000012.png", _frame(9))                       # 7-digit padding
    for name in ("notes.txt", "frame_final.png", "frame_00003.png.bak", "myframe_00004.png"):
        (tmp_path / name).write_text("mine")
    with FrameWriter(directory=tmp_path, total_frames=2, force=True) as writer:
        for index in range(2):
            writer.write(index, _frame(index))
    for index in range(2):
        assert_array_equal(np.asarray(Image.open(tmp_path / f"frame_{index:05d}.png")), _frame(index))
    assert writer.stale_paths == sorted(tmp_path / name for name in
                                        ("frame_00000.npy", "frame_00002.png", "frame_0000012.png"))
    assert _listing(tmp_path) == ["frame_00000.png", "frame_00001.png", "frame_00003.png.bak", "frame_final.png",
                                  "myframe_00004.png", "notes.txt"]


def test_interrupted_forced_run_keeps_the_earlier_frames(tmp_path):
    """Frames land together at the end of the block: an interruption leaves the earlier run's frames
    exactly as they were (not a mix of old and new) and no temporary file."""
    for index in range(3):
        write_png(tmp_path / f"frame_{index:05d}.png", _frame(9))
    before = {name: (tmp_path / name).read_bytes() for name in _listing(tmp_path)}
    with pytest.raises(KeyboardInterrupt):
        with FrameWriter(directory=tmp_path, total_frames=2, force=True) as writer:
            writer.write(0, _frame(0))
            assert any(name.startswith(".frame_00000.png.") for name in os.listdir(tmp_path))
            raise KeyboardInterrupt
    assert {name: (tmp_path / name).read_bytes() for name in _listing(tmp_path)} == before


def test_frame_directory_made_by_a_concurrent_run(tmp_path, monkeypatch):
    """Two forced runs to one output (CI's 10-round race): the other run creates the frame directory
    between this writer's check and its mkdir. The writer uses that directory, does not count it as its
    own (so it never removes it on failure), and writes its frames."""
    directory = tmp_path / "same_frames"
    original_mkdir = type(directory).mkdir

    def mkdir_after_the_other_run(self, *args, **kwargs):
        if self == directory:
            os.mkdir(self)                                   # the other run wins the race
        return original_mkdir(self, *args, **kwargs)

    monkeypatch.setattr(type(directory), "mkdir", mkdir_after_the_other_run)
    with FrameWriter(directory=directory, total_frames=1, force=True) as writer:
        writer.write(0, _frame(0))
    assert not writer._created_directory
    assert _listing(directory) == ["frame_00000.png"]
    (directory / "frame_00000.png").unlink()
    with pytest.raises(KeyboardInterrupt):
        with FrameWriter(directory=directory, total_frames=1, force=True):
            raise KeyboardInterrupt
    assert directory.is_dir()                                # not this writer's to remove


def test_frame_index_checks(tmp_path):
    with FrameWriter(directory=tmp_path, total_frames=2) as writer:
        writer.write(0, _frame(0))
        with pytest.raises(ValueError, match="already written"):
            writer.write(0, _frame(0))
        with pytest.raises(ValueError, match=r"^index must be an integer in \[0, 1\], got 2$"):
            writer.write(2, _frame(0))
        for index in (None, float("nan"), np.array([1]), True):          # TypeErrors, or a bool taken as 1
            with pytest.raises(ValueError, match=r"^index must be an integer"):
                writer.write(index, _frame(0))
        with pytest.raises(ValueError, match="shape"):
            writer.write(1, _frame(0, height=50))
        with pytest.raises(TypeError, match="uint8"):
            writer.write(1, _frame(0).astype(float))
    with pytest.raises(RuntimeError, match="with"):
        writer.write(1, _frame(1))


@pytest.mark.parametrize("write", ["png", "json", "csv", "exr", "hdr", "frames"])
def test_writers_refuse_a_force_that_is_no_bool(tmp_path, write):
    """force="no" was true: it replaced the file (and a FrameWriter deleted an earlier run's frames as
    stale). Every writer now takes a bool only, checked before anything is written."""
    from clsky.anim.exr import write_exr
    from clsky.anim.rgbe import write_rgbe

    target = tmp_path / f"old.{write}"
    target.write_bytes(b"precious")
    writers = {"png": lambda force: write_png(target, _frame(0), force=force),
               "json": lambda force: write_json(target, {"a": 1}, force=force),
               "csv": lambda force: write_csv(target, [{"a": 1}], force=force),
               "exr": lambda force: write_exr(target, np.ones((2, 2, 3)), force=force),
               "hdr": lambda force: write_rgbe(target, np.ones((2, 2, 3)), force=force),
               "frames": lambda force: FrameWriter(directory=tmp_path, force=force)}
    if write == "exr":
        pytest.importorskip("OpenEXR")
    for force in ("no", "False", 1, None):
        with pytest.raises(ValueError, match=r"^force must be True or False, got "):
            writers[write](force)
    assert target.read_bytes() == b"precious"


@pytest.mark.parametrize("path, message", [
    (None, r"^path must be a file path \(a str or os.PathLike\), got None"),
    (5, r"^path must be a file path"),
    (b"x.png", r"^path must be a file path"),
    ("", r"^path must be a file path, got an empty one"),
])
def test_writers_refuse_paths_that_are_none(tmp_path, monkeypatch, path, message):
    """A path of None, a number or bytes was pathlib's TypeError, and '' was the current directory (a
    FrameWriter wrote its frames there; its directory=None is no directory, and mp4_path=None no MP4)."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ValueError, match=message):
        write_png(path, _frame(0))
    if path is not None:
        with pytest.raises(ValueError, match=message.replace("path", "directory", 1)):
            FrameWriter(directory=path)
        with pytest.raises(ValueError, match=message.replace("path", "mp4_path", 1)):
            FrameWriter(mp4_path=path)
    assert list(tmp_path.iterdir()) == []


def test_write_png_text_and_write_csv_rows_of_the_wrong_kind_are_refused(tmp_path):
    """A list or a string for the PNG text was an AttributeError, None or lists for the CSV rows a
    TypeError or AttributeError."""
    for text in (["a"], "abc", {1: "x"}):
        with pytest.raises(ValueError, match=r"^text must be None or a dict of PNG text chunks"):
            write_png(tmp_path / "a.png", _frame(0), text=text)
    for rows, message in ((None, r"^rows must be a sequence of dicts, got None"),
                          ([[1, 2]], r"^rows must be a sequence of dicts \(one a line\)")):
        with pytest.raises(ValueError, match=message):
            write_csv(tmp_path / "m.csv", rows)
    assert list(tmp_path.iterdir()) == []


def test_write_csv_refuses_values_that_are_not_finite(tmp_path):
    """write_csv wrote "nan" where write_json, of the same metrics, refuses it."""
    for value in (float("nan"), np.float64(np.inf)):
        with pytest.raises(ValueError, match=r"^rows hold a value that is not finite \(a = (nan|inf)\)"):
            write_csv(tmp_path / "m.csv", [{"a": 1.0}, {"a": value}])
    assert list(tmp_path.iterdir()) == []


def test_a_frame_name_that_is_a_directory_is_refused_before_the_work(tmp_path):
    """With force, a directory named as one of this run's frames failed at that frame (after the table),
    and one named as a stale frame after every new file had landed: both are refused by check()."""
    for name in ("frame_00000.png", "frame_00009.png"):
        directory = tmp_path / name.split(".")[0]
        (directory / name).mkdir(parents=True)
        with pytest.raises(IsADirectoryError, match=rf"^--output: .*{name} is a directory named as a frame"):
            FrameWriter(directory=directory, total_frames=2, force=True).check("--output")
        assert sorted(path.name for path in directory.iterdir()) == [name]


def test_hdr_frames_must_be_finite_float32_values(tmp_path):
    """hdr='npy' frames took NaN, infinities and an empty frame; values beyond float32's range became
    infinities in any format. All are refused before the frame is written."""
    with FrameWriter(directory=tmp_path / "f", hdr="npy") as writer:
        for hdr, message in ((np.full((2, 2, 3), np.nan), "NaN, infinite values"),
                             (np.full((2, 2, 3), 1e39), "beyond float32's range"),
                             (np.zeros((0, 0, 3)), r"H and W >= 1"),
                             (np.full((2, 2, 3), "a"), "real numbers")):
            with pytest.raises(ValueError, match=message):
                writer.write(0, _frame(0), hdr=hdr)
        writer.write(0, _frame(0), hdr=np.ones((2, 2, 3)))
    assert _listing(tmp_path / "f") == ["frame_00000.npy", "frame_00000.png"]


# MP4 --------------------------------------------------------------------------------------------------

@needs_ffmpeg
def test_mp4_decodes_with_the_right_frames(tmp_path):
    target = tmp_path / "sky.mp4"
    with FrameWriter(directory=tmp_path / "frames", mp4_path=target, fps=24, total_frames=12) as writer:
        for index in range(12):
            writer.write(index, _frame(index))
    assert _listing(tmp_path) == ["frames", "sky.mp4"]               # no temporary is left
    assert writer.paths[-1] == target
    video = imageio_v3.imread(target, index=None)
    assert video.shape == (12, 48, 64, 3) and video.dtype == np.uint8
    for index in range(12):
        difference = video[index, :, 8:].astype(float).mean(axis=(0, 1)) - _frame(index)[0, 8]
        # Flat colours through 8-bit limited-range YUV 4:2:0 and CRF 18: measured <= 2.2 LSB (the
        # Y step of limited range is 255/219 = 1.16 LSB, chroma adds about as much).
        assert np.abs(difference).max() < 4.0, (index, difference)


@needs_ffmpeg
def test_mp4_is_tagged_bt709_with_the_srgb_transfer(tmp_path):
    """The stream says how to decode its colours: limited range, BT.709 matrix and primaries, the sRGB
    transfer (MP4_OUTPUT_PARAMS), as FFmpeg itself reads the file back: "yuv420p(tv, colorspace/primaries/
    transfer, ...)". FFmpeg 9.0 wrote "bt709/unknown/unknown" when the tags were output options only."""
    import subprocess

    target = tmp_path / "sky.mp4"
    with FrameWriter(directory=tmp_path / "frames", mp4_path=target, fps=24, total_frames=2) as writer:
        for index in range(2):
            writer.write(index, _frame(index))
    probe = subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-hide_banner", "-i", str(target)], capture_output=True,
                           text=True, timeout=60)
    stream = next(line for line in probe.stderr.splitlines() if "Video:" in line)
    assert "yuv420p(tv, bt709/bt709/iec61966-2-1" in stream, stream


@needs_ffmpeg
def test_mp4_chroma_is_sited_as_decoders_assume(tmp_path):
    """H.264 decoders take 4:2:0 chroma as sited 'left' (on the even luma columns) unless the stream says
    otherwise; swscale centred it (the mean of each luma pair), half a pixel off at every sharp colour edge.
    A red | blue edge after luma column 32: centred, the chroma sample of columns 32-33 is the midpoint of
    red's U (102) and blue's (240), 171; sited at column 32, which is red, it is nearer red's (148
    measured, the scaler's filter spreading a little of the blue; 2-3 levels of CRF 18's noise)."""
    import subprocess

    frame = np.zeros((64, 64, 3), np.uint8)
    frame[:, :33], frame[:, 33:] = (255, 0, 0), (0, 0, 255)
    with FrameWriter(mp4_path=tmp_path / "edge.mp4", fps=24, total_frames=2) as writer:
        for index in range(2):
            writer.write(index, frame)
    raw = subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-i", str(tmp_path / "edge.mp4"), "-f",
                          "rawvideo", "-pix_fmt", "yuv420p", "-"], capture_output=True, timeout=60, check=True).stdout
    u = np.frombuffer(raw[64 * 64:64 * 64 + 32 * 32], np.uint8).reshape(32, 32)
    assert abs(int(u[10, 12]) - 102) <= 3 and abs(int(u[10, 20]) - 240) <= 3      # red and blue away from it
    assert u[10, 16] < 160, u[10, 13:20]                                          # not the centred 171


@needs_ffmpeg
def test_mp4_refuses_to_overwrite(tmp_path):
    target = tmp_path / "sky.mp4"
    target.write_bytes(b"old movie")
    with pytest.raises(FileExistsError, match="sky.mp4.*--force"):
        with FrameWriter(mp4_path=target) as writer:
            writer.write(0, _frame(0))
    assert target.read_bytes() == b"old movie"
    assert _listing(tmp_path) == ["sky.mp4"]
    with FrameWriter(mp4_path=target, force=True) as writer:
        for index in range(3):
            writer.write(index, _frame(index))
    assert imageio_v3.imread(target, index=None).shape == (3, 48, 64, 3)
    assert _listing(tmp_path) == ["sky.mp4"]


@needs_ffmpeg
def test_exception_in_block_leaves_no_mp4(tmp_path):
    target = tmp_path / "sky.mp4"
    with pytest.raises(RuntimeError, match="renderer failed"):
        with FrameWriter(directory=tmp_path / "frames", mp4_path=target, total_frames=12) as writer:
            for index in range(3):
                writer.write(index, _frame(index))
            raise RuntimeError("renderer failed")
    # No MP4, no temporary, no frame: the set lands whole or not at all, and the frame directory
    # that the writer created (empty again) is removed.
    assert _listing(tmp_path) == []


@needs_ffmpeg
def test_exception_keeps_an_existing_mp4_with_force(tmp_path):
    target = tmp_path / "sky.mp4"
    target.write_bytes(b"old movie")
    with pytest.raises(KeyboardInterrupt):
        with FrameWriter(mp4_path=target, force=True) as writer:
            writer.write(0, _frame(0))
            raise KeyboardInterrupt
    assert target.read_bytes() == b"old movie"
    assert _listing(tmp_path) == ["sky.mp4"]


@needs_ffmpeg
@pytest.mark.parametrize("fps", [1e-7, 1e-6])
def test_an_ffmpeg_that_fails_replaces_nothing(tmp_path, fps):
    """imageio-ffmpeg does not look at ffmpeg's exit status: at 1e-7 frames per second (written as 0.00)
    ffmpeg refused its input and the empty MP4 replaced a good one, at 1e-6 a broken 261-byte file did,
    and the run ended as a success. The writer now counts the MP4's frames before it lands: OSError, and
    the old movie and frames stay. (The command line refuses such rates first: --fps >= 0.01.)"""
    target = tmp_path / "sky.mp4"
    target.write_bytes(b"old movie")
    with pytest.raises(OSError, match=r"for .*sky\.mp4 .*nothing was replaced"):
        with FrameWriter(directory=tmp_path / "frames", mp4_path=target, fps=fps, force=True) as writer:
            for index in range(2):
                writer.write(index, _frame(index))
    assert target.read_bytes() == b"old movie"
    assert _listing(tmp_path) == ["sky.mp4"]


@needs_ffmpeg
def test_odd_sizes_keep_their_pngs_and_pad_the_mp4(tmp_path):
    """H.264 in yuv420p takes even sizes only: the MP4's frames repeat their last column (and row); the PNG
    frames keep every pixel (they were cropped by a row and a column before, and the HDR frames not)."""
    import imageio.v2 as imageio

    frames = [_frame(index, width=63)[:47] for index in range(2)]
    with FrameWriter(directory=tmp_path / "frames", mp4_path=tmp_path / "sky.mp4") as writer:
        for index, frame in enumerate(frames):
            writer.write(index, frame)
    for index, frame in enumerate(frames):
        np.testing.assert_array_equal(imageio.imread(tmp_path / "frames" / f"frame_{index:05d}.png"), frame)
    decoded = [np.asarray(image) for image in imageio.mimread(tmp_path / "sky.mp4", format="FFMPEG")]
    assert [image.shape for image in decoded] == [(48, 64, 3)] * 2
    padded = even_padded(frames[1])
    assert padded.shape == (48, 64, 3) and (padded[:47, :63] == frames[1]).all()
    assert (padded[47] == padded[46]).all() and (padded[:, 63] == padded[:, 62]).all()


# The PNG encoder ----------------------------------------------------------------------------------------

@pytest.fixture(params=["default", "zlib"])
def deflate(request, monkeypatch):
    """The PNG encoder's deflate: the one clsky picks (python-isal's where installed) and the standard
    library's zlib it falls back to."""
    from clsky.anim import writers

    if request.param == "zlib":
        monkeypatch.setattr(writers, "_DEFLATE", zlib)
    return writers._DEFLATE


def test_png_deflate_is_isal_where_installed():
    """The anim extra installs python-isal, and the encoder then takes its deflate (docs/speed-log.md: 5x
    zlib's speed for the frames); without it, the standard library's zlib."""
    from clsky.anim import writers

    try:
        from isal import isal_zlib
    except ImportError:
        assert writers.deflate_module() is zlib
    else:
        assert writers.deflate_module() is isal_zlib


@pytest.mark.parametrize("shape, mode", [((7, 5), "L"), ((7, 5, 3), "RGB"), ((7, 5, 4), "RGBA"), ((1, 1, 3), "RGB"),
                                         ((512, 1614, 3), "RGB")])
def test_encode_png_decodes_to_the_same_pixels(shape, mode, deflate):
    """Pillow (libpng-independent C code of its own) decodes what encode_png writes to the same pixels, in
    the mode of the channels, with valid CRCs (verify()), with either deflate; random bytes exercise the
    Sub filter's differences modulo 256 in both directions."""
    image = np.random.default_rng(shape[0]).integers(0, 256, shape, dtype=np.uint8)
    data = encode_png(image)
    Image.open(io.BytesIO(data)).verify()
    with Image.open(io.BytesIO(data)) as decoded:
        assert decoded.mode == mode and decoded.size == (shape[1], shape[0])
        assert_array_equal(np.asarray(decoded), image)


def test_encode_png_tags_its_images_as_srgb(tmp_path):
    """The frames carried no colour space (a probe of the outputs): an sRGB chunk now, with the gAMA and
    cHRM that decoders without sRGB support read (the PNG specification's values, as Pillow reads them
    back), before the image data; clsky info still reads the file."""
    from clsky.info import describe

    data = encode_png(np.zeros((4, 5, 3), np.uint8), {"clsky_version": "9.9"})
    with Image.open(io.BytesIO(data)) as decoded:
        decoded.load()
        assert decoded.info["srgb"] == 0 and decoded.info["gamma"] == pytest.approx(1 / 2.2, abs=1e-5)
        assert decoded.info["chromaticity"] == (0.3127, 0.329, 0.64, 0.33, 0.3, 0.6, 0.15, 0.06)
    assert data.index(b"sRGB") < data.index(b"IDAT") and data.index(b"cHRM") < data.index(b"IDAT")
    (tmp_path / "x.png").write_bytes(data)
    assert "clsky version  9.9" in describe(tmp_path / "x.png")


def test_encode_png_splits_its_data_over_idat_chunks(monkeypatch):
    """Image data longer than a chunk may hold runs on over several IDAT chunks (here of 100 bytes)."""
    from clsky.anim import writers

    monkeypatch.setattr(writers, "_IDAT_BYTES", 100)
    image = np.random.default_rng(2).integers(0, 256, (20, 30, 3), dtype=np.uint8)
    data = encode_png(image)
    assert data.count(b"IDAT") > 10
    with Image.open(io.BytesIO(data)) as decoded:
        assert_array_equal(np.asarray(decoded), image)


def test_encode_png_rows_are_sub_filtered(deflate):
    """The IDAT stream holds each row as filter type 1 and each byte minus the byte 3 to its left
    (modulo 256): 10 - 250 = 16; the first pixel as it is."""
    image = np.array([[[250, 0, 7], [10, 255, 7]]], dtype=np.uint8)
    data = encode_png(image)
    start = data.index(b"IDAT") + 4
    length = int.from_bytes(data[start - 8:start - 4], "big")
    assert zlib.decompress(data[start:start + length]) == bytes([1, 250, 0, 7, 16, 255, 0])


def test_encode_png_text_chunks_and_checks():
    text = {"scene": "[sun]\nelevation = 2.0  # \u00b0", "clsky_version": "0.1.0"}
    with Image.open(io.BytesIO(encode_png(np.zeros((2, 2, 3), np.uint8), text))) as decoded:
        decoded.load()
        assert decoded.text == text
    for keyword in ("", " scene", "x" * 80, "a\0b", "\u0394"):
        with pytest.raises(ValueError, match="PNG text keyword"):
            encode_png(np.zeros((2, 2, 3), np.uint8), {keyword: "x"})
    with pytest.raises(TypeError, match="uint8"):
        encode_png(np.zeros((2, 2, 3)))
    for shape in ((2, 2, 2), (0, 2, 3), (2,), (2, 2, 3, 1)):
        with pytest.raises(ValueError, match="image_u8 must have shape"):
            encode_png(np.zeros(shape, np.uint8))


# Single files -------------------------------------------------------------------------------------------

def test_write_png_atomic_and_no_overwrite(tmp_path):
    target = tmp_path / "sky.png"
    assert write_png(target, _frame(1)) == target
    assert_array_equal(np.asarray(Image.open(target)), _frame(1))
    with pytest.raises(FileExistsError, match="--force"):
        write_png(target, _frame(2))
    assert_array_equal(np.asarray(Image.open(target)), _frame(1))
    write_png(target, _frame(2), force=True)
    assert_array_equal(np.asarray(Image.open(target)), _frame(2))
    assert _listing(tmp_path) == ["sky.png"]
    with pytest.raises(TypeError, match="uint8"):
        write_png(tmp_path / "bad.png", _frame(0).astype(np.float32))


def test_write_json_atomic_strict(tmp_path):
    target = tmp_path / "metrics.json"
    data = {"rmse": np.float64(0.25), "frames": np.arange(3), "pixels": np.int64(7), "name": "table"}
    write_json(target, data)
    assert json.loads(target.read_text()) == {"rmse": 0.25, "frames": [0, 1, 2], "pixels": 7, "name": "table"}
    with pytest.raises(FileExistsError, match="metrics.json"):
        write_json(target, {})
    with pytest.raises(ValueError):                   # NaN is not JSON: refused, no file left
        write_json(tmp_path / "nan.json", {"x": float("nan")})
    write_json(target, {"a": 1}, force=True)
    assert json.loads(target.read_text()) == {"a": 1}
    assert _listing(tmp_path) == ["metrics.json"]
    # the text goes to the temporary as it is encoded: a value found late (after a MB of rows) leaves the
    # file there as it was and deletes the temporary, alone and in a staging set
    late = {"frames": [{"frame": i, "mean": 0.5} for i in range(20_000)] + [{"frame": -1, "mean": math.inf}]}
    with pytest.raises(ValueError):
        write_json(target, late, force=True)
    with pytest.raises(ValueError), StagedWrites() as staging:
        write_json(target, late, force=True, staging=staging)
    assert json.loads(target.read_text()) == {"a": 1}
    assert _listing(tmp_path) == ["metrics.json"]


def test_write_csv_atomic(tmp_path):
    target = tmp_path / "jumps.csv"
    rows = [{"frame": 0, "excess": np.float64(0.0)}, {"frame": 1, "excess": 0.125, "note": "step"}]
    write_csv(target, rows)
    with open(target, newline="") as handle:
        read = list(csv.DictReader(handle))
    assert read == [{"frame": "0", "excess": "0.0", "note": ""},
                    {"frame": "1", "excess": "0.125", "note": "step"}]
    with pytest.raises(FileExistsError, match="jumps.csv"):
        write_csv(target, rows)
    write_csv(target, rows[:1], force=True)
    assert target.read_text().splitlines() == ["frame,excess", "0,0.0"]
    with pytest.raises(ValueError, match="empty"):
        write_csv(tmp_path / "empty.csv", [])
    assert _listing(tmp_path) == ["jumps.csv"]


# ffmpeg: the path it is given, and when it is missing or stops ------------------------------------------------

def test_an_mp4_name_with_a_colon_is_written(tmp_path, monkeypatch):
    """ffmpeg took a relative 'x:y.mp4' (its temporary '.x:y.mp4.XXXXXXXX.mp4') for a URL of protocol '.x' and
    wrote nothing, found after all the work: it is given absolute paths."""
    import imageio_ffmpeg

    monkeypatch.chdir(tmp_path)
    (tmp_path / "d:x").mkdir()
    for name in ("x:y.mp4", "d:x/a.mp4"):
        with FrameWriter(mp4_path=name, fps=10) as writer:
            for index in range(3):
                writer.write(index, np.full((16, 16, 3), 40 * index, np.uint8))
        assert imageio_ffmpeg.count_frames_and_secs(str(tmp_path / name))[0] == 3


def test_a_missing_or_failing_ffmpeg_is_named(tmp_path, monkeypatch):
    """An IMAGEIO_FFMPEG_EXE that is not there was found at the first frame, after the plan and the table: the
    check before the work names it. An ffmpeg that exits at once gave '[Errno 32] Broken pipe' or an unreadable
    MP4: the message names ffmpeg and the MP4, nothing lands and no temporary is left."""
    import imageio_ffmpeg

    monkeypatch.setenv("IMAGEIO_FFMPEG_EXE", str(tmp_path / "nothere"))
    with pytest.raises(OSError, match=r"^no ffmpeg for the MP4: .*nothere \(imageio-ffmpeg's, or IMAGEIO_FFMPEG_EXE\) "
                                      r"is no executable file, nor one on PATH$"):
        FrameWriter(mp4_path=tmp_path / "a.mp4").check()
    # a bare name is looked up on PATH, as imageio-ffmpeg without a binary of its own gives it ('ffmpeg')
    monkeypatch.delenv("IMAGEIO_FFMPEG_EXE")
    real = imageio_ffmpeg.get_ffmpeg_exe()
    (tmp_path / "bin").mkdir()
    (tmp_path / "bin" / "my-ffmpeg").symlink_to(real)
    monkeypatch.setenv("PATH", f"{tmp_path / 'bin'}{os.pathsep}{os.environ['PATH']}")
    monkeypatch.setenv("IMAGEIO_FFMPEG_EXE", "my-ffmpeg")
    FrameWriter(mp4_path=tmp_path / "a.mp4").check()
    failing = tmp_path / "ffmpeg"
    failing.write_text("#!/bin/sh\nexit 1\n")
    failing.chmod(0o755)
    monkeypatch.setenv("IMAGEIO_FFMPEG_EXE", str(failing))
    out = tmp_path / "out"
    out.mkdir()
    with pytest.raises(OSError, match=r"^ffmpeg (stopped while writing|did not write a readable) .*MP4 for .*a\.mp4 "
                                      r".*nothing was replaced$"):
        with FrameWriter(mp4_path=out / "a.mp4", fps=10) as writer:
            for index in range(40):
                writer.write(index, np.full((64, 64, 3), index, np.uint8))
    assert list(out.iterdir()) == []
