"""Radiance RGBE (``.hdr``) frames: the older HDR format every renderer and image tool still reads.

A pixel is three 8-bit mantissas sharing one 8-bit exponent (G. Ward, "Real pixels", Graphics Gems II,
1991): for ``v = max(r, g, b)`` written as ``v = m 2^e`` with ``m`` in [0.5, 1), the bytes are
``floor(c * 256 / 2^e)`` for each channel c and ``e + 128``; values below 1e-38 are 0 (exponent byte 0).
A channel is decoded as ``(byte + 0.5) 2^(e - 8)`` (Radiance's own ``colr_color``), so each channel is
within ``2^(e - 9) <= v / 256`` of its value: a relative error of at most 2^-8 for the largest channel,
and the same absolute error for the others (a dark channel beside a bright one loses its digits).
Channels are not negative (frames are radiances).

Scan lines are written run-length encoded in Radiance's "new" format with literal runs only (lossless,
no ambiguity with flat data), top row first (``-Y H +X W``); images narrower than 8 or wider than 32767
pixels, which that format cannot hold, are written flat. The header holds ``FORMAT=32-bit_rle_rgbe``,
``SOFTWARE=`` and one ``NAME= value`` line per attribute given (units, sun, orientation: as the EXR
header of :mod:`clsky.anim.exr`, whose orientation conventions hold here too).

References
----------
.. [1] G. Ward, "Real pixels", in Graphics Gems II, J. Arvo (ed.), Academic Press, 80-83 (1991),
   doi:10.1016/B978-0-08-050754-5.50025-0.
.. [2] G. Ward Larson and R. Shakespeare, "Rendering with Radiance" (1998), ch. "The Radiance picture
   file format".

Examples
--------
>>> import numpy as np, pathlib, tempfile
>>> path = pathlib.Path(tempfile.mkdtemp()) / "sky.hdr"
>>> _ = write_rgbe(path, np.full((2, 16, 3), 0.75))
>>> pixels, header = read_rgbe(path)
>>> float(pixels[0, 0, 0]), header["FORMAT"]       # 192 / 256 stored, read at the middle of its step
(0.751953125, '32-bit_rle_rgbe')
"""

from __future__ import annotations

import errno
import math
import os
import pathlib
import re

import numpy as np

import clsky
from clsky._files import as_path, atomic_write, open_regular_file, output_target

__all__ = ["encode_rgbe", "decode_rgbe", "write_rgbe", "read_rgbe", "read_rgbe_header", "save_rgbe"]

#: Widths the run-length encoded scan lines can hold.
_RLE_WIDTHS = range(8, 0x8000)


def encode_rgbe(rgb):
    """(H, W, 3) non-negative finite values -> (H, W, 4) uint8 RGBE; ValueError for other values."""
    rgb = np.asarray(rgb, dtype=np.float64)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.shape[0] < 1 or rgb.shape[1] < 1:
        raise ValueError(f"rgb must have shape (H, W, 3), got {rgb.shape}")
    if not np.isfinite(rgb).all() or (rgb < 0).any():
        raise ValueError("rgb must be finite and >= 0 for an RGBE file")
    largest = rgb.max(axis=2)
    lit = largest >= 1e-38
    _, exponent = np.frexp(np.where(lit, largest, 1.0))              # largest = m 2^exponent, m in [0.5, 1)
    if (exponent > 127).any():
        raise ValueError("rgb holds values above 2^127, beyond RGBE's exponent")
    scale = np.where(lit, np.ldexp(256.0, -exponent), 0.0)
    rgbe = np.empty(rgb.shape[:2] + (4,), np.uint8)
    rgbe[..., :3] = np.minimum(np.floor(rgb * scale[..., None]), 255.0)
    rgbe[..., 3] = np.where(lit, exponent + 128, 0)
    return rgbe


def decode_rgbe(rgbe):
    """(H, W, 4) uint8 RGBE -> (H, W, 3) float64: ``(byte + 0.5) 2^(e - 136)``, 0 where e is 0."""
    rgbe = np.asarray(rgbe, dtype=np.uint8)
    exponent = rgbe[..., 3].astype(np.int64)
    scale = np.where(exponent > 0, np.ldexp(1.0, exponent - 136), 0.0)
    return (rgbe[..., :3] + 0.5) * scale[..., None]


def _scanline_bytes(row):
    """One scan line (W, 4) in the new RLE format with literal runs of at most 128 bytes."""
    width = row.shape[0]
    parts = [bytes([2, 2, width >> 8, width & 0xFF])]
    for component in range(4):
        data = row[:, component].tobytes()
        for start in range(0, width, 128):
            chunk = data[start:start + 128]
            parts.append(bytes([len(chunk)]) + chunk)
    return b"".join(parts)


def _header_value(value):
    """An attribute as one header line's text (arrays as space-separated numbers)."""
    if isinstance(value, np.ndarray):
        value = " ".join(f"{float(v):.9g}" for v in value.ravel())
    elif isinstance(value, (tuple, list)):
        value = " ".join(str(v) for v in value)
    text = str(getattr(value, "name", value))          # enums (OpenEXR's envmap) by name
    return text.replace("\n", " ")


#: EXR attributes (:func:`clsky.anim.exr.frame_attributes`) that Radiance's header has a line of its own for:
#: the primaries and white of the pixels, read by Radiance's tools and ImageMagick (which listed an unknown
#: 'hdr:chromaticities'), and the camera's view, which evalglare and vwrays read (where each pixel looks).
RADIANCE_NAMES = {"chromaticities": "PRIMARIES", "radianceView": "VIEW"}


def save_rgbe(file, rgbe, attributes=None):
    """Write ``rgbe`` (H, W, 4) uint8, from :func:`encode_rgbe`, and ``attributes`` to ``file`` as it
    is, not atomically (the step inside :func:`write_rgbe`'s and :class:`clsky.anim.writers.FrameWriter`'s
    temporary files, which encode first, so that bad values are refused before a file exists)."""
    height, width = rgbe.shape[:2]
    lines = ["#?RADIANCE", "FORMAT=32-bit_rle_rgbe", f"SOFTWARE=clsky {clsky.__version__}"]
    for name, value in (attributes or {}).items():
        if name in ("software", "compression", "type"):
            continue
        if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", name):
            raise ValueError(f"attribute names must be identifiers, got {name!r}")
        # the file's own lines, and Radiance's that scale the pixels (EXPOSURE, COLORCORR) or name their primaries
        if name in ("FORMAT", "SOFTWARE", "EXPOSURE", "COLORCORR", "PRIMARIES", "VIEW"):
            raise ValueError(f"attribute name {name!r} is a header line of the file's own, not an attribute")
        lines.append(f"{RADIANCE_NAMES.get(name, name)}= {_header_value(value)}")
    head = ("\n".join(lines) + f"\n\n-Y {height} +X {width}\n").encode("ascii", "replace")
    if len(head) > _MAX_HEADER:          # clsky's readers read the header from the first 64 KiB
        raise ValueError(f"attributes must make a header of at most {_MAX_HEADER} bytes, got {len(head)}")
    if width in _RLE_WIDTHS:
        body = b"".join(_scanline_bytes(row) for row in rgbe)
    else:
        body = rgbe.tobytes()
    pathlib.Path(file).write_bytes(head + body)


def write_rgbe(path, rgb, attributes=None, force=False, staging=None):
    """Write an RGB image to a Radiance ``.hdr`` file atomically (see the module docstring).

    Parameters
    ----------
    path : str or os.PathLike
        Target file; its directory must exist.
    rgb : array_like, shape (H, W, 3)
        Finite values >= 0, row 0 at the top.
    attributes : dict, optional
        Header lines ``NAME= value`` (:func:`clsky.anim.exr.frame_attributes`).
    force : bool
        Replace an existing file.
    staging : clsky._files.StagedWrites, optional
        Stage the file in this set: it lands when the set commits.

    Returns
    -------
    pathlib.Path

    Raises
    ------
    ValueError
        A bad shape, negative or non-finite values, values above 2^127 (before anything is written).
    FileExistsError, IsADirectoryError, FileNotFoundError, NotADirectoryError, PermissionError
        As :func:`clsky.anim.writers.write_png`.
    """
    path, force = output_target(path, force)
    rgbe = encode_rgbe(rgb)                              # refuse bad values before the temporary exists
    with atomic_write(path, overwrite=force, suffix=".hdr", staging=staging) as temporary:
        save_rgbe(temporary, rgbe, attributes)
    return path


#: Most bytes of a Radiance header (its text and resolution line) :func:`read_rgbe_header` reads.
_MAX_HEADER = 1 << 16


def _parse_header(data, path):
    """(height, width, header {NAME: text}, offset of the pixels) from the bytes ``data`` that begin a
    Radiance picture; ValueError naming ``path`` without the signature or a ``-Y H +X W`` resolution line
    of at least one pixel each way (spaces between its words as Radiance's own reader takes them). The
    lines that scale the pixels, ``EXPOSURE=`` and ``COLORCORR=``, which Radiance's tools add a step at a
    time and which multiply, have their values joined by '; ', in order; any other name on several lines
    has its last value."""
    if not data.startswith(b"#?"):
        raise ValueError(f"{path}: not a Radiance picture (no '#?' signature)")
    end = data.find(b"\n\n")
    newline = data.find(b"\n", end + 2) if end >= 0 else -1
    line = b"" if newline < 0 else data[end + 2:newline]
    match = re.fullmatch(rb"-Y\s+(\d{1,9})\s+\+X\s+(\d{1,9})\s*", line)
    if match is None:
        other = re.fullmatch(rb"([-+][XY])\s+\d{1,9}\s+([-+][XY])\s+\d{1,9}\s*", line)
        if other is not None:
            raise ValueError(f"{path}: its orientation {line.decode().strip()!r} is not read: only '-Y H +X W' "
                             f"(the top row first, left to right)")
        more = f" in its first {_MAX_HEADER} bytes" if end < 0 and len(data) >= _MAX_HEADER else ""
        raise ValueError(f"{path}: no '-Y H +X W' resolution line{more}")
    height, width = int(match.group(1)), int(match.group(2))
    if height < 1 or width < 1:
        raise ValueError(f"{path}: its resolution {height} x {width} holds no pixel")
    header = {}
    for text in data[:end].decode("ascii", "replace").split("\n")[1:]:
        if "=" in text and not text.startswith("#"):
            name, value = text.split("=", 1)
            joined = name in _SCALING_LINES and name in header
            header[name] = f"{header[name]}; {value.strip()}" if joined else value.strip()
    return height, width, header, newline + 1


#: Radiance header lines that scale the pixels, each line again: every one counts (:func:`_check_scale`).
_SCALING_LINES = ("EXPOSURE", "COLORCORR")


def _number(text):
    """``text`` as a float, or None."""
    try:
        return float(text)
    except ValueError:
        return None


def read_rgbe_header(path):
    """(height, width, header {NAME: text}) of the Radiance picture at ``path``, from its first 64 KiB
    alone (``clsky info``), the file's size checked against what its pixels need at the least; ValueError
    as :func:`read_rgbe`."""
    with _open_picture(path) as stream:
        height, width, header, offset, size = _read_header(stream, path)
    _check_size(path, height, width, size - offset)
    return height, width, header


def _open_picture(path):
    """The file at ``path`` open for reading, once (:func:`clsky._files.open_regular_file`): a FIFO blocked,
    also one swapped in after a check of the name; FileNotFoundError for a file that is not a regular one."""
    path = as_path(path)
    try:
        return open_regular_file(path)
    except IsADirectoryError:
        raise IsADirectoryError(f"{path}: a directory, not a Radiance picture") from None
    except (FileNotFoundError, NotADirectoryError):          # a path through a file: no such file either
        raise FileNotFoundError(f"{path}: no such file") from None
    except OSError as error:
        if error.errno == errno.EINVAL:
            raise FileNotFoundError(f"{path}: not a regular file") from None
        raise


def _read_header(stream, path):
    """(height, width, header, offset of the pixels, file size) of the Radiance header of the file open as
    ``stream``, read from its first 64 KiB: /dev/zero exhausted the memory and a 1 GiB file took 1 GiB
    before its signature was checked."""
    data = stream.read(_MAX_HEADER)
    return (*_parse_header(data, path), os.fstat(stream.fileno()).st_size)


def _check_size(path, height, width, held):
    """ValueError unless ``held`` bytes can hold ``height`` x ``width`` pixels: at the least 4 bytes of
    header and 4 runs of 127 pixels in 2 bytes a scan line, or 4 a pixel flat (before the pixels are read,
    or their array made)."""
    least = height * (4 + 8 * -(-width // 127) if width in _RLE_WIDTHS else 4 * width)
    if held < least:
        raise ValueError(f"{path}: its {height} x {width} pixels need at least {least} bytes, it holds {held}")


def _check_scale(path, header):
    """ValueError unless the pixels are at their own scale: every ``EXPOSURE=`` line multiplies them (their
    product must be 1) and every ``COLORCORR=`` line multiplies each channel (each must be 1 1 1). Only the
    last EXPOSURE line was checked, and COLORCORR not at all: pixels at half or twice their values were read
    as they were."""
    exposures = [_number(text) for text in header.get("EXPOSURE", "1").split(";")]
    if None in exposures or not math.isclose(math.prod(exposures), 1.0, rel_tol=1e-9):
        raise ValueError(f"{path}: its EXPOSURE is {header['EXPOSURE']!r:.40}: only pixels at their own scale "
                         f"(EXPOSURE 1 or none, the product of its lines) are read")
    for line in header.get("COLORCORR", "1 1 1").split(";"):
        factors = [_number(text) for text in line.split()]
        if len(factors) != 3 or factors != [1.0, 1.0, 1.0]:
            raise ValueError(f"{path}: its COLORCORR is {header['COLORCORR']!r:.40}: only pixels at their own "
                             f"scale (COLORCORR 1 1 1 or none) are read")


def _check_primaries(path, header):
    """ValueError unless the pixels' ``PRIMARIES=`` (if any) are Rec. 709's and D65, as the reader returns
    them (linear sRGB), as :func:`clsky.anim.exr.read_exr` checks an EXR's chromaticities."""
    if "PRIMARIES" not in header:
        return
    from .exr import is_rec709

    values = [_number(text) for text in header["PRIMARIES"].split()]
    if None in values or not is_rec709(values):
        raise ValueError(f"{path}: its PRIMARIES ({header['PRIMARIES']!r:.60}) are not Rec. 709's: the reader "
                         f"returns linear sRGB")


def read_rgbe(path):
    """(pixels (H, W, 3) float64, header {NAME: text}) of a Radiance file with a ``-Y H +X W``
    resolution line, its scan lines flat or in the new run-length format (runs and literals); the old
    run-length format is not read. ValueError naming the file for one without the signature or resolution
    line, not at its own scale (EXPOSURE, COLORCORR), whose resolution its bytes cannot hold, or whose scan
    lines are damaged (cut short, runs past the line's end). The file is opened once."""
    with _open_picture(path) as stream:
        height, width, header, offset, size = _read_header(stream, path)
        # pixels clsky decodes as they are: an XYZE picture's X, Y, Z were read as R, G, B, and a scale ignored
        if header.get("FORMAT", "32-bit_rle_rgbe") != "32-bit_rle_rgbe":
            raise ValueError(f"{path}: its FORMAT is {header['FORMAT']!r:.40}: only 32-bit_rle_rgbe (R, G, B) is "
                             f"read")
        _check_scale(path, header)
        _check_primaries(path, header)
        _check_size(path, height, width, size - offset)
        stream.seek(offset)
        body = memoryview(stream.read())
    rgbe = np.empty((height, width, 4), np.uint8)
    try:
        used = _decode_scanlines(body, rgbe)
    except (IndexError, ValueError) as error:
        raise ValueError(f"{path}: damaged pixel data ({error})") from None
    if used != len(body):
        raise ValueError(f"{path}: {len(body) - used} bytes after its {height} x {width} pixels (damaged or not "
                         f"this resolution's)")
    return decode_rgbe(rgbe), header


def _decode_scanlines(body, rgbe):
    """Fill ``rgbe`` (H, W, 4) from the scan lines in ``body``; returns the bytes they took. IndexError or
    ValueError where they are damaged (a run-length line's own width other than the picture's too)."""
    height, width = rgbe.shape[:2]
    at = 0
    for row in range(height):
        if width in _RLE_WIDTHS and bytes(body[at:at + 2]) == b"\x02\x02" and body[at + 2] < 128:
            if (body[at + 2] << 8 | body[at + 3]) != width:
                raise ValueError(f"scan line {row}: its width {body[at + 2] << 8 | body[at + 3]}, not {width}")
            at += 4
            for component in range(4):
                column = 0
                while column < width:
                    count = body[at]
                    length = count - 128 if count > 128 else count      # a run, or a literal of count bytes
                    if length == 0 or column + length > width:
                        raise ValueError(f"scan line {row}: a run of {length} at column {column} of {width}")
                    if count > 128:                      # a run: one byte repeated count - 128 times
                        rgbe[row, column:column + length, component] = body[at + 1]
                        at += 2
                    else:
                        literal = np.frombuffer(body[at + 1:at + 1 + length], np.uint8)
                        rgbe[row, column:column + length, component] = literal
                        at += 1 + length
                    column += length
        else:
            rgbe[row] = np.frombuffer(body[at:at + 4 * width], np.uint8).reshape(width, 4)
            at += 4 * width
    return at
