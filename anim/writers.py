"""Writers: PNG frames, an MP4, single images, JSON and CSV, all atomic and never overwriting.

Writers are separate from renderers (manim's ``SceneFileWriter``): a renderer yields frames, a
:class:`FrameWriter` stores them. Every file is first written to a hidden temporary file with a
unique name in its target's directory and then renamed onto the target (``os.replace``, atomic on
POSIX; see :mod:`clsky._files`), so an interrupted run leaves complete files or none, never a
truncated one, and concurrent writers of one file never share a temporary. Every target is checked
before anything is written (:func:`clsky._files.check_output`); existing outputs are refused with
FileExistsError unless ``force`` (``--force`` on the command line). Each writer takes ``staging=``
(a :class:`clsky._files.StagedWrites`) to make several files land together.

PNG files are encoded here (:func:`encode_png`: NumPy and a deflate, :func:`deflate_module`); Pillow
draws the composite frames' labels and reads PNG files back; the MP4 needs imageio and imageio-ffmpeg,
and EXR frames the OpenEXR bindings (all in the ``anim`` extra of clsky), imported only when an MP4 or
EXR frames are requested.

Examples
--------
>>> import numpy as np, tempfile, os
>>> from clsky.anim.writers import FrameWriter
>>> directory = tempfile.mkdtemp()
>>> with FrameWriter(directory=directory, total_frames=2) as writer:
...     for index in range(2):
...         _ = writer.write(index, np.zeros((4, 6, 3), np.uint8))
>>> sorted(os.listdir(directory))
['frame_00000.png', 'frame_00001.png']
"""

from __future__ import annotations

import contextlib
import csv
import importlib
import io
import json
import math
import os
import pathlib
import re
import shutil
import struct
import warnings
import zlib

import numpy as np

from clsky._files import StagedWrites, as_path, atomic_write, check_output, check_output_directory, output_target
from clsky.errors import check_flag, check_integer, check_real, require_extra, short

from .exr import HDR_FORMATS

__all__ = ["FrameWriter", "frame_files", "encode_png", "write_png", "write_json", "write_csv", "MP4_OUTPUT_PARAMS",
           "even_padded"]

#: ffmpeg output options of the MP4: constant-quality H.264 at CRF 18 (visually lossless for x264),
#: the RGB -> YUV conversion and the stream tagged as BT.709 (so players decode the colours as they
#: were encoded; ffmpeg's untagged default is the BT.601 matrix, which players may not assume), the
#: sRGB transfer tag (the frames are sRGB-encoded, :func:`clsky.anim.display.srgb_encode`, as PNG viewers
#: assume too), and the index at the front of the file (playback starts before the download ends). The
#: tags are set in the filter graph (``setparams``): from FFmpeg 7 on, the frames' own colour properties
#: override the ``-color_primaries`` and ``-color_trc`` output options, and the MP4s of imageio-ffmpeg's
#: FFmpeg 9.0 said "bt709/unknown/unknown" (found 2026-12-05); the output options stay for older builds.
#: The tags change no pixel (the decoded frames hash the same). The chroma samples are sited "left", on
#: the even luma columns and between the rows, as H.264 decoders assume where the stream says nothing (x264
#: writes no chroma location for 'left', the default: ``-chroma_sample_location`` only says what is meant):
#: swscale centred them by default, half a pixel off at every sharp colour edge (the panels' borders,
#: labels, colour bar, the sun; a probe of the MP4, 2026-12-07).
MP4_OUTPUT_PARAMS = ["-crf", "18", "-vf", "scale=out_color_matrix=bt709:out_range=tv:out_h_chr_pos=0:out_v_chr_pos=128,"
                     "setparams=colorspace=bt709:color_primaries=bt709:color_trc=iec61966-2-1:range=tv",
                     "-colorspace", "bt709", "-color_primaries", "bt709", "-color_trc", "iec61966-2-1",
                     "-chroma_sample_location", "left", "-movflags", "+faststart"]


def _check_image(name, image):
    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise TypeError(f"{name} must be uint8, got {image.dtype}")
    if image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"{name} must have shape (H, W, 3), got {image.shape}")
    return np.ascontiguousarray(image)


def _exists_error(path, option=None):
    if option:
        return FileExistsError(f"{option}: {path} exists; use --force to overwrite it")
    return FileExistsError(f"{path} exists (use force=True, or --force on the command line)")


#: The most frames a :class:`FrameWriter` names (frame_<index> with up to 9 digits), and its highest frame rate
#: [1/s] (ffmpeg refused 1e300 only when the video closed).
MAX_FRAMES = 10**9
MAX_FPS = 1000.0

#: Deflate level of the PNG files (:func:`encode_png`): 2, in ISA-L's levels 0-3 and zlib's 0-9 alike.
PNG_COMPRESS_LEVEL = 2


def deflate_module():
    """The module whose ``compress(data, level)`` deflates the PNG files' rows into a zlib stream:
    python-isal's ``isal_zlib`` (Intel's ISA-L, in the ``anim`` extra) where it is installed, else the
    standard library's zlib. Both write a standard zlib stream, which every PNG reader decodes to the same
    pixels. On the default animation's 1614 x 512 composites (2026-12-05, 2-core machine) ISA-L's level 2
    took 3.9 CPU-ms a frame against zlib's 20.0, for 512.7 against 513.6 kB (docs/speed-log.md)."""
    try:
        from isal import isal_zlib
    except ImportError:
        return zlib
    return isal_zlib


_DEFLATE = deflate_module()

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: PNG colour type of an image's channels: grey, RGB, RGBA (PNG specification, section 11.2.2).
_PNG_COLOUR_TYPES = {1: 0, 3: 2, 4: 6}
#: Largest IDAT chunk written (a chunk's length must stay below 2^31).
_IDAT_BYTES = 1 << 30


def _png_chunk(kind, data):
    """One PNG chunk: length, type, data, CRC-32 of type and data (PNG specification, section 5.3)."""
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


#: The images' colour space, sRGB, said as the PNG specification asks (section 11.3.3.5): an sRGB chunk
#: (rendering intent 0, perceptual) with the gAMA (1 / 2.2 as 45455) and cHRM (D65 white and Rec. 709
#: primaries, x and y times 100 000) that decoders without sRGB support read. The frames carried none
#: (a probe of the outputs, 2026-12-07): viewers that manage colour took them as untagged.
_PNG_SRGB_CHUNKS = (_png_chunk(b"sRGB", b"\0") + _png_chunk(b"gAMA", struct.pack(">I", 45455))
                    + _png_chunk(b"cHRM", struct.pack(">8I", 31270, 32900, 64000, 33000, 30000, 60000, 15000, 6000)))


def _itxt(keyword, value):
    """An iTXt chunk's data: Latin-1 keyword of 1-79 characters, uncompressed UTF-8 text, no language
    (PNG specification, section 11.3.4.5); what Pillow's ``PngInfo.add_itxt`` writes."""
    if not (0 < len(keyword) < 80 and keyword == keyword.strip() and "\0" not in keyword
            and all(ord(c) < 256 for c in keyword)):
        raise ValueError(f"a PNG text keyword must be 1-79 Latin-1 characters without leading or trailing "
                         f"spaces, got {keyword!r}")
    # the keyword and its null; compression flag and method 0; an empty language tag and translated
    # keyword, each ended by a null; the text
    return keyword.encode("latin-1") + b"\0" + b"\0\0" + b"\0" + b"\0" + str(value).encode("utf-8")


def encode_png(image_u8, text=None):
    """The PNG file (bytes) of an 8-bit image.

    Every row is filtered with PNG's Sub filter (each byte minus the same channel's byte one pixel to its
    left, modulo 256; PNG specification, section 9.2) and the rows deflated at level
    :data:`PNG_COMPRESS_LEVEL` (:func:`deflate_module`), in one IDAT chunk; ``text`` ({keyword: str}) goes
    into iTXt chunks (UTF-8), which Pillow reads back as ``Image.open(path).text``. The image is tagged as
    sRGB (sRGB, gAMA and cHRM chunks: :data:`_PNG_SRGB_CHUNKS`): every PNG clsky writes is display sRGB.

    Why not Pillow's encoder: it chooses each row's filter by trying all five (adaptive filtering), half
    its time for the animation's frames: on the default animation's 1614 x 512 composites it took 36.8 ms
    a frame at zlib level 1 for 0.55 MB, this 18.5 ms for 0.48 MB (their smooth skies and dither noise
    predict well from the left). The pixels are the same: tests/test_anim_writers.py decodes them with
    Pillow.

    Parameters
    ----------
    image_u8 : numpy.ndarray of uint8, shape (H, W), (H, W, 3) or (H, W, 4)
        Grey, RGB or RGBA pixels, H and W >= 1.
    text : dict of str, optional
        Text chunks {keyword: text}; keywords of 1-79 Latin-1 characters.
    """
    image = np.asarray(image_u8)
    if image.dtype != np.uint8:
        raise TypeError(f"image_u8 must be uint8, got {image.dtype}")
    if not (image.ndim == 2 or (image.ndim == 3 and image.shape[2] in (3, 4))) or 0 in image.shape:
        raise ValueError(f"image_u8 must have shape (H, W), (H, W, 3) or (H, W, 4) with H, W >= 1, got {image.shape}")
    height, width = image.shape[:2]
    channels = 1 if image.ndim == 2 else image.shape[2]
    chunks = [_png_chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, _PNG_COLOUR_TYPES[channels], 0, 0, 0)),
              _PNG_SRGB_CHUNKS]
    if text is not None and not (isinstance(text, dict) and all(isinstance(k, str) for k in text)):
        raise ValueError(f"text must be None or a dict of PNG text chunks {{keyword: text}}, got {short(text)}")
    chunks += [_png_chunk(b"iTXt", _itxt(keyword, value)) for keyword, value in (text or {}).items()]
    rows = image.reshape(height, width * channels)
    filtered = np.empty((height, 1 + width * channels), dtype=np.uint8)
    filtered[:, 0] = 1                                                     # the filter type of each row: Sub
    filtered[:, 1:1 + channels] = rows[:, :channels]
    np.subtract(rows[:, channels:], rows[:, :-channels], out=filtered[:, 1 + channels:])   # wraps modulo 256
    stream = _DEFLATE.compress(filtered, PNG_COMPRESS_LEVEL)
    # a chunk holds less than 2^31 bytes; the image data may run on over several IDAT chunks
    chunks += [_png_chunk(b"IDAT", stream[start:start + _IDAT_BYTES]) for start in range(0, len(stream), _IDAT_BYTES)]
    return _PNG_SIGNATURE + b"".join(chunks) + _png_chunk(b"IEND", b"")


def require_pillow():
    """The ``PIL`` package with its Image module (the ``anim`` extra's Pillow), or ImportError saying how to
    install it: the composite frames' labels and colour bar are drawn with it (a frame directory is
    checked for it, since an animation's frames are composites), and PNG files are read with it.
    Imported where used, so that clsky's table CLI runs without it."""
    pil = require_extra("PIL", "PNG images", "pip install 'clsky[anim]' (or pip install Pillow)")
    importlib.import_module("PIL.Image")
    return pil


def write_png(path, image_u8, force=False, staging=None, text=None):
    """Write a uint8 image to a PNG file atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Target file; its directory must exist.
    image_u8 : numpy.ndarray of uint8, shape (H, W, 3), (H, W, 4) or (H, W)
        RGB, RGBA or grey pixels.
    force : bool
        Replace an existing file.
    staging : clsky._files.StagedWrites, optional
        Stage the file in this set: it lands when the set commits.
    text : dict of str, optional
        PNG text chunks {keyword: text} (iTXt, UTF-8): the scene and clsky's version of a rendered
        frame (:func:`clsky.anim.scene.output_metadata`); read back by Pillow's ``Image.open(path).text``.

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    FileExistsError
        ``path`` exists and not ``force``.
    IsADirectoryError, FileNotFoundError, NotADirectoryError, PermissionError
        ``path`` is a directory; its directory is missing, not one, or not writable (before writing).
    TypeError, ValueError
        Not uint8, or an unsupported shape; a name too long for the file system.
    """
    path, force = output_target(path, force)
    data = encode_png(image_u8, text)          # checks the image (and the keywords) before any file
    with atomic_write(path, overwrite=force, suffix=".png", staging=staging) as temporary:
        pathlib.Path(temporary).write_bytes(data)
    return path


def _json_default(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, pathlib.PurePath):
        return str(value)
    raise TypeError(f"object of type {type(value).__name__} is not JSON serialisable")


def write_json(path, obj, force=False, staging=None):
    """Write ``obj`` as strict JSON (indented, keys in the given order) atomically.

    NumPy scalars and arrays are converted to numbers and lists; NaN and infinity raise ValueError
    (strict JSON has no such numbers), and nothing is written: the text goes to the temporary as it is
    encoded, which the error deletes (100 000 frames' metrics, 58 MB of JSON, took 370 MB more as one string
    first: docs/speed-log.md). The path is checked as in :func:`write_png` (same
    exceptions) before; ``staging`` as there.

    Returns
    -------
    pathlib.Path
    """
    path, force = output_target(path, force)
    with atomic_write(path, overwrite=force, suffix=".json", staging=staging) as temporary:
        with open(temporary, "w", encoding="utf-8") as stream:
            json.dump(obj, stream, indent=2, allow_nan=False, default=_json_default)
            stream.write("\n")
    return path


def write_csv(path, rows, force=False, fieldnames=None, staging=None):
    """Write a list of dicts as CSV (header + one line per dict) atomically.

    Parameters
    ----------
    path : str or os.PathLike
    rows : sequence of dict
        Missing keys give empty cells.
    force : bool
    fieldnames : sequence of str, optional
        Column order; default: the keys in the order they first appear in ``rows``.
    staging : clsky._files.StagedWrites, optional
        As in :func:`write_png`.

    Returns
    -------
    pathlib.Path

    Raises
    ------
    ValueError
        No rows and no ``fieldnames``, a row with a key not in ``fieldnames``, or a NaN or infinite
        value (as :func:`write_json` refuses; nothing is written).
    OSError, ValueError
        The path, checked as in :func:`write_png`.
    """
    path, force = output_target(path, force)
    if isinstance(rows, (str, bytes, dict)) or not hasattr(rows, "__iter__"):
        raise ValueError(f"rows must be a sequence of dicts, got {short(rows)}")
    rows = list(rows)
    if not all(isinstance(row, dict) for row in rows):
        raise ValueError("rows must be a sequence of dicts (one a line), got items that are not dicts")
    if fieldnames is None:
        if not rows:
            raise ValueError("rows is empty: give fieldnames to write a header-only CSV")
        fieldnames = list(dict.fromkeys(key for row in rows for key in row))
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(fieldnames), lineterminator="\n")
    writer.writeheader()
    for row in rows:
        row = {key: (value.item() if isinstance(value, np.generic) else value) for key, value in row.items()}
        for key, value in row.items():          # as write_json: no NaN or infinity in an output
            if isinstance(value, float) and not math.isfinite(value):
                raise ValueError(f"rows hold a value that is not finite ({key} = {value}): nothing is written")
        writer.writerow(row)
    with atomic_write(path, overwrite=force, suffix=".csv", staging=staging) as temporary:
        temporary.write_text(buffer.getvalue(), encoding="utf-8", newline="")
    return path


def frame_files(directory, prefix="frame"):
    """The files of ``directory`` named as a :class:`FrameWriter` names its frames:
    ``<prefix>_<digits>.png``, ``.npy``, ``.exr`` or ``.hdr`` (sorted); nothing else is ever counted as a frame."""
    directory = pathlib.Path(directory)
    if not directory.is_dir():
        return []
    pattern = re.compile(re.escape(prefix) + r"_\d+\.(png|npy|exr|hdr)")
    return sorted(directory / name for name in os.listdir(directory) if pattern.fullmatch(name))


def _hdr_saver(hdr_format):
    """The function ``(file, values, attributes)`` that writes one HDR frame of ``hdr_format`` to a file
    as it is (the frame writer calls it inside its temporary files), with the values as
    :meth:`FrameWriter.write` prepared them: EXR pixels, RGBE bytes or float32."""
    if hdr_format == "exr":
        from .exr import save_exr
        return save_exr
    if hdr_format == "hdr":
        from .rgbe import save_rgbe
        return save_rgbe
    return lambda file, values, attributes: np.save(file, values)


def even_padded(image):
    """``image`` (H, W, 3) with its last row and/or column repeated where H or W is odd: the MP4's frame
    (H.264 in yuv420p takes even sizes). The frames were cropped instead, in the PNG files too, where
    no such limit holds: a 17 x 17 animation's PNG frames lost a row of pixels."""
    height, width = image.shape[:2]
    if not (height % 2 or width % 2):
        return image
    return np.pad(image, ((0, height % 2), (0, width % 2), (0, 0)), mode="edge")


def _check_ffmpeg():
    """OSError unless imageio-ffmpeg's ffmpeg (its own, or IMAGEIO_FFMPEG_EXE) is an executable file: a
    missing one was found after the scene plan and the table, at the first frame."""
    import imageio_ffmpeg

    try:
        executable = imageio_ffmpeg.get_ffmpeg_exe()
    except RuntimeError as error:
        raise OSError(f"no ffmpeg for the MP4: {error}") from None
    # a path, or a bare name looked up on PATH as the process that runs it will (imageio-ffmpeg without a
    # binary of its own returns 'ffmpeg')
    if shutil.which(executable) is None:
        raise OSError(f"no ffmpeg for the MP4: {executable} (imageio-ffmpeg's, or IMAGEIO_FFMPEG_EXE) is no "
                      f"executable file, nor one on PATH")


def _ffmpeg_path(part):
    """The path ffmpeg is given for ``part``: absolute, for ffmpeg reads a relative 'x:y.mp4' (its temporary
    '.x:y.mp4.XXXXXXXX.mp4') as a URL of protocol '.x' and wrote nothing, found after all the work."""
    return os.path.abspath(part)


@contextlib.contextmanager
def _ffmpeg_failures(target):
    """An OSError of the block (ffmpeg gone, exited or killed: '[Errno 32] Broken pipe' alone) as one naming
    ffmpeg and the MP4 for ``target``."""
    try:
        yield
    except OSError as error:
        raise OSError(f"ffmpeg stopped while writing the MP4 for {target} ({str(error).splitlines()[0]}); "
                      f"nothing was replaced") from None


def _check_video(part, target, frames):
    """OSError unless the MP4 ffmpeg wrote to ``part`` (for ``target``) holds ``frames`` frames: imageio-ffmpeg
    does not look at ffmpeg's exit status, so an ffmpeg that failed (a frame rate it could not parse, a full
    disk) left an empty or broken file that would have replaced ``target``. Counting the frames is a stream
    copy of the file (about 30 ms), no decoding."""
    import imageio_ffmpeg

    try:
        counted_frames, _ = imageio_ffmpeg.count_frames_and_secs(_ffmpeg_path(part))
    except (RuntimeError, OSError) as error:
        raise OSError(f"ffmpeg did not write a readable MP4 for {target} ({str(error).splitlines()[0]}); "
                      f"nothing was replaced") from None
    if counted_frames != frames:
        raise OSError(f"ffmpeg wrote {counted_frames} of {frames} frames to the MP4 for {target}; nothing was replaced")


class FrameWriter:
    """Context manager storing an animation as PNG frames, HDR frames (EXR, Radiance .hdr or .npy) and/or an
    MP4.

    Parameters
    ----------
    directory : str or os.PathLike, optional
        Directory of the PNG (and HDR) frames, created if missing; None for no frames.
    mp4_path : str or os.PathLike, optional
        Target MP4 file (its directory must exist); None for no video.
    fps : float
        Frames per second of the MP4, in (0, :data:`MAX_FPS`]. An odd width or height is padded for the MP4 alone
        (:func:`even_padded`: H.264 in yuv420p needs even ones); the PNG frames keep the frame's size.
    total_frames : int, optional
        Number of frames, if known, in [1, :data:`MAX_FRAMES`]: sets the zero padding of the names to
        max(5, its digits) and bounds the indices.
    hdr : {None, 'exr', 'hdr', 'npy'}
        Also store each frame's HDR values in ``directory``: 'exr', an OpenEXR image
        ``<prefix>_<index>.exr`` (:func:`clsky.anim.exr.write_exr`, with the header attributes given to
        :meth:`write`); 'hdr', a Radiance RGBE image ``<prefix>_<index>.hdr`` (:mod:`clsky.anim.rgbe`, 8-bit
        mantissas, the same attributes as header lines); 'npy', a float32 NumPy array
        ``<prefix>_<index>.npy``.
    hdr_precision : {'float', 'half'}
        Pixel type of the EXR frames: 32-bit floats (default) or 16-bit half floats (values up to
        65504, larger ones clipped). The .npy frames are always float32: 'half' needs ``hdr='exr'``.
    force : bool
        Overwrite existing outputs, and delete the stale frames of an earlier run (see Notes).
    prefix : str
        File name prefix of the frames: ``<prefix>_00001.png``.
    staging : clsky._files.StagedWrites, optional
        Stage every file in this set, to land with the caller's other files when the set commits
        (an animation's metrics); default: the writer's own set, committed when the block ends.
    text : dict of str, optional
        Text chunks of every PNG frame, as in :func:`write_png`.

    Attributes
    ----------
    paths : list of pathlib.Path
        The targets written so far: frames, then the MP4 (added at the end of the block). They are
        in place once the staging set has committed (at the end of the block by default).
    stale_paths : list of pathlib.Path
        After a forced run: the frame files of an earlier run (``<prefix>_<digits>.png``, ``.npy``, ``.exr``, ``.hdr``)
        that this run did not rewrite. They are deleted when the set commits, so the directory holds
        this run's frames only.

    Raises
    ------
    FileExistsError
        On entering (or :meth:`check`): the MP4, or any frame file (``<prefix>_<digits>.png``,
        ``.npy``, ``.exr`` or ``.hdr``) in ``directory`` exists and not ``force``. Nothing is touched then.
    ImportError
        On entering (or :meth:`check`): an MP4 without imageio-ffmpeg, EXR frames without OpenEXR.
    IsADirectoryError, FileNotFoundError, NotADirectoryError, PermissionError
        On entering (or :meth:`check`): an output that cannot be written (see
        :func:`clsky._files.check_output`). Nothing is touched then.
    ValueError
        Bad arguments; a name too long for the file system.

    Notes
    -----
    - Everything lands together: each frame (PNG and its HDR file) and the MP4 are written to hidden temporary
      files with unique names (``.<name>.XXXXXXXX<suffix>``) beside their targets, and renamed when
      the block exits normally (with ``staging``, when that set commits): the frames first, the MP4
      last (when it is there, its frames are too), then the stale frames are deleted. An exception inside the block (KeyboardInterrupt
      included) deletes every temporary, and the frame directory if this writer created it and it
      is empty: the outputs of an earlier run stay as they were, never mixed with new ones.
    - MP4: H.264, yuv420p, :data:`MP4_OUTPUT_PARAMS`. yuv420p halves the chroma resolution, so width
      and height must be even: an odd size is padded for the MP4 alone (:func:`even_padded`, the last
      row or column repeated), the PNG frames keep every pixel. A block that writes no frame creates no
      MP4 (with a warning).
    - Two writers of the same outputs at once (``force``) each rename their own complete files: the
      MP4 is always one writer's whole video, and the last rename wins per file (the frames may
      then mix both runs). A writer that fails removes the frame directory it created only if it
      is empty; a concurrent writer that has not yet staged a frame there then fails to create its
      temporary (one-line error, nothing half written).
    - The frames become visible only at the end of the block (they wait as hidden temporaries, the
      same disk space as the frames themselves).

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> directory = tempfile.mkdtemp()
    >>> movie = os.path.join(directory, "sky.mp4")
    >>> with FrameWriter(mp4_path=movie, fps=10) as writer:
    ...     for index in range(3):
    ...         _ = writer.write(index, np.full((16, 16, 3), 80 * index, np.uint8))
    >>> [path.name for path in writer.paths]
    ['sky.mp4']
    """

    #: HDR frame formats (None: none) -> file suffix: :data:`clsky.anim.exr.HDR_FORMATS`.
    HDR_FORMATS = HDR_FORMATS

    def __init__(self, directory=None, mp4_path=None, fps=30, total_frames=None, hdr=None, force=False,
                 prefix="frame", staging=None, hdr_precision="float", text=None):
        from .exr import PRECISIONS

        if directory is None and mp4_path is None:
            raise ValueError("give a frame directory, an mp4_path, or both")
        if not (hdr is None or isinstance(hdr, str)) or hdr not in self.HDR_FORMATS:
            raise ValueError(f"hdr must be one of {list(self.HDR_FORMATS)}, got {hdr!r}")
        if hdr is not None and directory is None:
            raise ValueError(f"hdr={hdr!r} needs a frame directory")
        if not isinstance(hdr_precision, str) or hdr_precision not in PRECISIONS:
            raise ValueError(f"hdr_precision must be one of {list(PRECISIONS)}, got {hdr_precision!r}")
        if hdr_precision != "float" and hdr != "exr":
            raise ValueError(f"hdr_precision {hdr_precision!r} needs hdr='exr' (.npy frames are float32)")
        fps = check_real("fps", fps, 0.0, MAX_FPS, low_open=True)
        total_frames = check_integer("total_frames", total_frames, 1, MAX_FRAMES, optional=True)
        if not isinstance(prefix, str) or not prefix or os.sep in prefix or (os.altsep and os.altsep in prefix):
            raise ValueError(f"prefix must be a non-empty file name part, got {prefix!r}")
        self.directory = None if directory is None else as_path(directory, "directory")
        self.mp4_path = None if mp4_path is None else as_path(mp4_path, "mp4_path")
        self.fps = fps
        self.total_frames = total_frames
        self.hdr = hdr
        self.hdr_precision = hdr_precision
        self.force = check_flag("force", force)
        self.prefix = prefix
        self.text = dict(text or {})
        self.width = max(5, len(str(total_frames))) if total_frames else 5
        self.paths = []
        self.stale_paths = []
        self._existing = []
        self._indices = set()
        self._size = None
        self._hdr_shape = None
        self._video = None
        self._part = None
        self._own_staging = staging is None
        self._staging = staging
        self._temporaries = []
        self._created_directory = False
        self._state = "new"                             # then "open", then "closed"

    # Names ----------------------------------------------------------------------------------------
    def frame_path(self, index, suffix=".png"):
        """Path of frame ``index``: ``<directory>/<prefix>_<zero-padded index><suffix>``."""
        if self.directory is None:
            raise ValueError("this FrameWriter writes no frame files (directory=None)")
        return self.directory / f"{self.prefix}_{index:0{self.width}d}{suffix}"

    @property
    def _mp4_suffix(self):
        return self.mp4_path.suffix or ".mp4"           # ffmpeg picks the container from it

    # Checks ---------------------------------------------------------------------------------------
    def check(self, option=None):
        """Check every output before any work (the animation calls it before building its table).

        Parameters
        ----------
        option : str, optional
            The command-line option that named the outputs: it starts the messages.

        Raises
        ------
        FileExistsError, IsADirectoryError, FileNotFoundError, NotADirectoryError, PermissionError,
        ValueError
            As for the class; ImportError when an MP4 is asked for without imageio-ffmpeg.
        """
        if self.mp4_path is not None:
            check_output(self.mp4_path, self.force, option, suffix=self._mp4_suffix)
            for module in ("imageio", "imageio_ffmpeg"):   # fail before writing anything
                require_extra(module, "MP4 videos", "pip install 'clsky[anim]'")
            _check_ffmpeg()
        if self.directory is not None:
            last = (self.total_frames or 1) - 1
            check_output_directory(self.directory, option, names=[self.frame_path(last, suffix).name
                                                                  for suffix in (".png", ".npy", ".exr", ".hdr")])
            existing = frame_files(self.directory, self.prefix)
            folders = [path for path in existing if path.is_dir()]
            if folders:          # with force, the run's frame there failed after the table, a stale one after the rest
                raise IsADirectoryError(f"{option + ': ' if option else ''}{folders[0]} is a directory named as a "
                                        f"frame: neither a frame to replace nor one to delete; move it")
            if existing and not self.force:
                raise _exists_error(existing[0], option)
            require_pillow()
        if self.hdr == "exr":
            from .exr import require_openexr
            require_openexr()                      # fail before writing anything

    # Context --------------------------------------------------------------------------------------
    def __enter__(self):
        if self._state != "new":
            raise RuntimeError("a FrameWriter can be entered only once")
        self.check()
        if self.directory is not None:
            self._existing = frame_files(self.directory, self.prefix)
            try:
                self.directory.mkdir(parents=True)
                self._created_directory = True
            except FileExistsError:                      # there already, or made by a concurrent run just now
                if not self.directory.is_dir():
                    raise
        if self._own_staging:
            self._staging = StagedWrites()
        self._state = "open"
        return self

    def __exit__(self, exc_type, exc, traceback):
        video, self._video = self._video, None
        self._state = "closed"
        if exc_type is not None:
            if video is not None:
                try:
                    video.close()
                except Exception:  # noqa: BLE001  (the block's exception is the one to report)
                    pass
            self._discard()
            return False
        try:
            if video is not None:
                with _ffmpeg_failures(self.mp4_path):
                    video.close()
                _check_video(self._part, self.mp4_path, len(self._indices))
                self.paths.append(self.mp4_path)
            elif self.mp4_path is not None:
                warnings.warn(f"no frame was written: {self.mp4_path} not created", RuntimeWarning,
                              stacklevel=2)
            written = set(self.paths)
            self.stale_paths = [path for path in self._existing if path not in written]
            for path in self.stale_paths:
                self._staging.remove_on_commit(path)
            if self._own_staging:
                self._staging.commit()
        except BaseException:
            self._discard()
            raise
        return False

    def _discard(self):
        """Delete this writer's temporaries (and the frame directory if it created it and it is empty)."""
        for temporary in self._temporaries:
            self._staging.discard(temporary)
        self._temporaries = []
        if self._created_directory:
            try:
                self.directory.rmdir()
            except OSError:                              # not empty: someone else's files are there
                pass

    # Writing --------------------------------------------------------------------------------------
    def _open_video(self):
        """Stage the MP4 and start ffmpeg on it (imageio takes the frame size from the first frame)."""
        import imageio.v2 as imageio
        self._part = self._staging.stage(self.mp4_path, self.force, suffix=self._mp4_suffix, last=True)
        self._temporaries.append(self._part)
        # ffmpeg's errors only (its warnings are the default): they say why it failed (an encoder it lacks), before
        # clsky's own line; nothing on success
        self._video = imageio.get_writer(_ffmpeg_path(self._part), format="FFMPEG", mode="I", fps=self.fps,
                                         codec="libx264", pixelformat="yuv420p", quality=None,
                                         macro_block_size=1, output_params=list(MP4_OUTPUT_PARAMS),
                                         ffmpeg_log_level="error")

    def _write_files(self, index, image, hdr, hdr_attributes):
        """Stage frame ``index``'s PNG (and HDR file); returns their targets."""
        written = []
        data = encode_png(image, self.text)
        with atomic_write(self.frame_path(index), self.force, suffix=".png", staging=self._staging) as temporary:
            self._temporaries.append(temporary)
            pathlib.Path(temporary).write_bytes(data)
        written.append(self.frame_path(index))
        if self.hdr is not None:
            suffix = self.HDR_FORMATS[self.hdr]
            target = self.frame_path(index, suffix)
            with atomic_write(target, self.force, suffix=suffix, staging=self._staging) as temporary:
                self._temporaries.append(temporary)
                if self.hdr == "exr" and "scene" in self.text:   # the version is the header's clskyVersion;
                    hdr_attributes = {"scene": self.text["scene"], **(hdr_attributes or {})}   # Radiance: one line each
                _hdr_saver(self.hdr)(temporary, hdr, hdr_attributes)
            written.append(target)
        return written

    def write(self, index, display_u8, hdr=None, hdr_attributes=None):
        """Store frame ``index`` (in a temporary file, renamed at the end of the block).

        Parameters
        ----------
        index : int
            Frame number (>= 0, < total_frames if given, each at most once). It names the files;
            the MP4 gets the frames in call order.
        display_u8 : numpy.ndarray of uint8, shape (H, W, 3)
            Tone-mapped pixels; every frame has the same size.
        hdr : numpy.ndarray, shape (H', W', 3), optional
            HDR values, stored when the writer was made with ``hdr='exr'``, ``'hdr'`` or ``'npy'`` (then
            required); ignored otherwise. Its shape need not be the display's (a display frame may be
            a composite of several renders), but it is the same for every frame. EXR frames must be
            finite (ValueError before anything of the frame is written); with
            ``hdr_precision='half'``, values above 65504 are clipped to it (:func:`clsky.anim.exr.exr_pixels`).
        hdr_attributes : dict, optional
            Header attributes of this frame (:func:`clsky.anim.exr.frame_attributes`) for EXR and RGBE
            frames; ignored with 'npy'.

        Returns
        -------
        list of pathlib.Path
            The frame files this frame will have (empty for an MP4-only writer).
        """
        if self._state != "open":
            raise RuntimeError("use FrameWriter.write inside its with statement")
        index = check_integer("index", index, 0, MAX_FRAMES - 1 if self.total_frames is None else self.total_frames - 1)
        if index in self._indices:
            raise ValueError(f"frame {index} was already written")
        image = _check_image("display_u8", display_u8)
        if self._size is not None and image.shape != self._size:
            raise ValueError(f"frame {index} has shape {image.shape}, the first frame had {self._size}")
        if self.hdr is not None:
            if hdr is None:
                raise ValueError(f"this FrameWriter stores HDR frames (hdr={self.hdr!r}): pass hdr=")
            hdr = np.asarray(hdr)
            if hdr.dtype.kind not in "biuf":
                raise ValueError(f"hdr must hold real numbers, got an array of {hdr.dtype}")
            with np.errstate(over="ignore"):
                hdr = hdr.astype(np.float32)
            if hdr.ndim != 3 or hdr.shape[2] != 3 or hdr.size == 0:
                raise ValueError(f"hdr must have shape (H, W, 3), H and W >= 1, got {hdr.shape}")
            if not np.isfinite(hdr).all():          # NaN, infinity, or beyond float32's range (3.4e38)
                raise ValueError(f"frame {index}: hdr holds NaN, infinite values or values beyond float32's range "
                                 f"(3.4e38)")
            if self.hdr == "exr":
                from .exr import exr_pixels
                hdr, clipped = exr_pixels(hdr, self.hdr_precision)
                if self.hdr_precision == "half":
                    hdr_attributes = {**(hdr_attributes or {}), "halfClippedPixels": clipped}
            elif self.hdr == "hdr":
                from .rgbe import encode_rgbe
                hdr = encode_rgbe(hdr)                 # refuse what RGBE cannot hold before writing the frame
            if self._hdr_shape is not None and hdr.shape != self._hdr_shape:
                raise ValueError(f"frame {index}: hdr has shape {hdr.shape}, the first frame's had {self._hdr_shape}")
        if self._size is None and self.mp4_path is not None:
            self._open_video()
        self._size = image.shape
        if self.hdr is not None:
            self._hdr_shape = hdr.shape
        written = self._write_files(index, image, hdr, hdr_attributes) if self.directory is not None else []
        if self._video is not None:
            with _ffmpeg_failures(self.mp4_path):
                self._video.append_data(even_padded(image))
        self._indices.add(index)
        self.paths.extend(written)
        return written
