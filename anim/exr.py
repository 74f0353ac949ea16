"""OpenEXR frames and latitude-longitude environment maps, through the official OpenEXR bindings.

A frame is written as one scan-line EXR image with channels R, G, B (ZIP compression, lossless), in
float32 (``precision='float'``, the frame's float32 values exactly) or float16 (``'half'``, the usual
format of environment maps: 3 significant decimal digits, values up to 65504, larger ones clipped
to it and counted in ``halfClippedPixels``). The header says what
the numbers are and where they point (:func:`frame_attributes`):

- ``software`` ("clsky X.Y.Z") and ``clskyVersion``;
- ``radianceUnits``: the frames' units (see :func:`clsky.anim.animate.frame_units`); where they are cd/m^2
  (absolute frames converted to linear sRGB: every preset but atmosphere-plus, or ``--wavelengths``) also
  the standard ``whiteLuminance`` = 1 (the luminance of RGB (1, 1, 1) [cd/m^2]) and ``chromaticities``
  (Rec. 709 primaries, D65 white); for relative frames (atmosphere-plus), r, g, b at the table's three
  wavelengths, ``channelWavelengthsNm`` (R, G, B) instead;
- ``camera``, ``observerAltitude`` [m], the sun as ``sunAzimuthDeg`` (from north, clockwise seen from
  above), ``sunElevationDeg`` and the unit vector ``sunDirectionENU`` (east, north, up);
- for the fisheye and perspective cameras, ``radianceView``: the camera as Radiance's view options
  (``-vta`` or ``-vtv``, the directions in east, north, up), a Radiance picture's ``VIEW=`` line;
- for an equirectangular panorama: the standard ``envmap`` attribute = latitude-longitude, the sun in
  the map's own axes (``sunDirectionEnvmap``), the sun's position in the image (``sunPixel``), and the
  orientation in words (``envmapOrientation``).

Orientation of the latitude-longitude maps
------------------------------------------
The panorama is :class:`clsky.anim.cameras.EquirectangularCamera`'s: column ``x`` (pixel centres at
``x + 0.5``) looks at azimuth ``phi = 360 deg * (x + 0.5) / width`` from north, clockwise seen from above
(the left edge is north, a quarter of the way east, the centre south, three quarters west), row ``y``
at elevation ``90 deg - 180 deg * (y + 0.5) / height`` (the top row is the zenith, the bottom row the
nadir). The map is seen from inside the sphere, not mirrored. This is exactly OpenEXR's
latitude-longitude convention (ImfEnvmap.h: the left edge is longitude +pi, the centre longitude 0
= +Z, a quarter from the left longitude +pi/2 = +X, the top row latitude +pi/2 = +Y) with the world
axes

    X = east,  Y = up (zenith),  Z = south  (so -Z = north; right-handed),

the y-up frame of OpenGL, three.js and Mitsuba 3. Mitsuba 3's ``envmap`` emitter uses this very mapping
(``u = atan2(x, -z) / 2 pi``, ``v = acos(y) / pi``), so the file loads there unrotated with -Z north.
Blender's world (Z up) puts the image centre at +X and a quarter from the left at +Y; three.js puts
the centre at +X and a quarter from the left at -Z: see ``docs/exr.md`` for the rotation each needs.

Where within a pixel: clsky's directions are those of the pixel centres, ``u = (x + 0.5) / width``,
``v = (y + 0.5) / height``, as GPU texture sampling (Blender, three.js) reads them. OpenEXR's reference
functions (``LatLongMap``) and Mitsuba 3 (measured, 3.9) put the first and last rows on the poles
(row ``y`` at ``v = y / (height - 1)``), so they see the rows up to half a row from clsky's elevations
(none at the horizon, half a row at the poles); Mitsuba reads the columns at clsky's azimuths.

References
----------
.. [1] OpenEXR, "ImfEnvmap.h" (latitude-longitude environment maps) and "Standard attributes"
   (``envmap``, ``whiteLuminance``, ``chromaticities``), https://openexr.com.
.. [2] W. Jakob et al., Mitsuba 3 documentation, "Environment emitter (envmap)" (2022).

Examples
--------
>>> import numpy as np, pathlib, tempfile
>>> path = pathlib.Path(tempfile.mkdtemp()) / "sky.exr"
>>> rgb = np.linspace(0.0, 1.0, 4 * 8 * 3, dtype=np.float32).reshape(4, 8, 3)
>>> _ = write_exr(path, rgb, precision="float", attributes={"radianceUnits": "cd/m^2"})
>>> pixels, header = read_exr(path)
>>> bool((pixels == rgb).all()), header["radianceUnits"]
(True, 'cd/m^2')
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import io
import math
import os
import pathlib
import sys
import tempfile

import numpy as np

import clsky
from clsky._files import as_path, atomic_write, output_target
from clsky.errors import as_real_array, check_integer, check_real, require_extra, short

__all__ = ["HDR_FORMATS", "PRECISIONS", "HALF_MAX", "ENVMAP_ORIENTATION", "write_exr", "read_exr", "exr_pixels",
           "save_exr", "frame_attributes", "enu_to_envmap", "envmap_pixel", "require_openexr"]

#: HDR frame formats of ``--hdr`` and FrameWriter's ``hdr`` (None: none) -> file suffix. Kept here, in a
#: module importing no optional dependency (OpenEXR is imported only when a file is read or written),
#: so that clsky's command line builds its options without the ``anim`` extra.
HDR_FORMATS = {None: None, "exr": ".exr", "hdr": ".hdr", "npy": ".npy"}

#: EXR pixel types by option value: 16-bit half floats or 32-bit floats.
PRECISIONS = {"half": np.float16, "float": np.float32}

#: Largest finite half float (65504): larger values would become infinity in a 'half' file.
HALF_MAX = float(np.finfo(np.float16).max)

#: The orientation of clsky's latitude-longitude maps in words, stored in their header.
ENVMAP_ORIENTATION = ("OpenEXR latlong with X=east, Y=up, Z=south (-Z=north); u = azimuth from north "
                      "clockwise / 360 deg (left edge north, u=0.25 east, centre south, u=0.75 west); "
                      "top row zenith, bottom row nadir; seen from inside, not mirrored")

#: Rec. 709 / sRGB primaries and D65 white (x, y of red, green, blue, white), as OpenEXR's chromaticities.
REC709_CHROMATICITIES = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)

#: Units of frames in linear sRGB luminance units (clsky.anim.animate.frame_units starts with this then).
LUMINANCE_UNITS = "cd/m^2"


def require_openexr():
    """The ``OpenEXR`` module; ImportError saying how to install it when it is missing."""
    return require_extra("OpenEXR", "EXR files", "pip install 'clsky[anim]' (or pip install OpenEXR)")


def enu_to_envmap(direction_enu):
    """A direction (east, north, up) in the axes of the latitude-longitude map: (x, y, z) = (east, up,
    south), OpenEXR's and Mitsuba 3's y-up frame (module docstring).

    >>> [float(c) for c in enu_to_envmap([0.0, 1.0, 0.0])]      # north is -Z
    [0.0, 0.0, -1.0]
    """
    east, north, up = np.moveaxis(np.asarray(direction_enu, dtype=np.float64), -1, 0)
    return np.stack([east, up, -north], axis=-1)


def envmap_pixel(zenith_deg, azimuth_deg, width, height):
    """Continuous image position (x, y) [pixels] of a direction in the panorama: ``x = width * phi /
    360 deg`` (phi the azimuth from north, clockwise, in [0, 360)), ``y = height * theta / 180 deg``
    (theta the zenith angle); pixel (col, row) covers [col, col + 1) x [row, row + 1).

    >>> envmap_pixel(90.0, 180.0, 64, 32)                     # south, on the horizon: the centre
    (32.0, 16.0)

    ValueError naming an argument that is no such value: the zenith angle in [0, 180] degrees, a finite
    azimuth, a size of at least one pixel (a NaN or 200 deg gave positions outside the image).
    """
    zenith = check_real("zenith_deg", zenith_deg, 0.0, 180.0, unit=" degrees")
    azimuth = check_real("azimuth_deg", azimuth_deg)
    width, height = (check_integer(name, value, 1, 2**31 - 1) for name, value in (("width", width), ("height", height)))
    return width * ((azimuth % 360.0) / 360.0), height * (zenith / 180.0)


def frame_attributes(units, camera, width, height, sun_zenith_deg, sun_azimuth_deg, altitude_m=0.0,
                     wavelengths_nm=None, radiance_view=None):
    """The EXR header attributes of one frame (module docstring).

    Parameters
    ----------
    units : str
        Units of the pixel values (:func:`clsky.anim.animate.frame_units`); cd/m^2 when it starts with
        ``'linear sRGB [cd/m^2]'`` or equals ``'cd/m^2'``.
    camera : str
        Camera name ('fisheye', 'perspective', 'equirectangular'); 'equirectangular' tags the file
        as a latitude-longitude environment map.
    width, height : int
        Image size [pixels].
    sun_zenith_deg, sun_azimuth_deg : float
        The sun's zenith angle in [0, 180] and azimuth (from north, clockwise; any finite) [deg].
    altitude_m : float
        Observer altitude [m], finite and >= 0.
    wavelengths_nm : sequence of 3 float, optional
        The wavelengths of the R, G, B channels [nm], finite and > 0, for frames at the table's three
        wavelengths.
    radiance_view : str, optional
        The camera's view in Radiance's options (:meth:`clsky.anim.cameras.Camera.radiance_view`), stored
        as ``radianceView`` (a Radiance picture's ``VIEW=`` line, :data:`clsky.anim.rgbe.RADIANCE_NAMES`).

    Raises
    ------
    ValueError
        A value out of its range (a NaN gave every header a NaN sun).

    Returns
    -------
    dict
        Attribute name -> value, as OpenEXR.File takes them, except ``envmap``: the string
        ``'latlong'`` (:func:`save_exr` stores it as ``OpenEXR.ENVMAP_LATLONG``), so that the
        attributes need no OpenEXR (the Radiance frames of :mod:`clsky.anim.rgbe` take them as text).
    """
    for name, value in (("width", width), ("height", height)):      # a NaN or negative size: a NaN or negative sunPixel
        check_integer(name, value, 1, 2**31 - 1)
    zenith = math.radians(check_real("sun_zenith_deg", sun_zenith_deg, 0.0, 180.0))      # NaN made the sun NaN
    azimuth = math.radians(check_real("sun_azimuth_deg", sun_azimuth_deg))             # any finite, as SunPosition
    check_real("altitude_m", altitude_m, 0.0)
    sun = np.array([math.sin(zenith) * math.sin(azimuth), math.sin(zenith) * math.cos(azimuth), math.cos(zenith)])
    attributes = {
        "software": f"clsky {clsky.__version__}", "clskyVersion": clsky.__version__,
        "radianceUnits": str(units), "camera": str(camera), "observerAltitude": float(altitude_m),
        "sunAzimuthDeg": float(sun_azimuth_deg) % 360.0, "sunElevationDeg": 90.0 - float(sun_zenith_deg),
        # float32 (v3f): three.js's EXRLoader skips v3d attributes
        "sunDirectionENU": sun.astype(np.float32),
    }
    if str(units) == LUMINANCE_UNITS or str(units).startswith(f"linear sRGB [{LUMINANCE_UNITS}]"):
        attributes["whiteLuminance"] = 1.0
        attributes["chromaticities"] = REC709_CHROMATICITIES
    if wavelengths_nm is not None:
        wavelengths = as_real_array("wavelengths_nm", wavelengths_nm, "3 wavelengths [nm], finite and > 0")
        if wavelengths.shape != (3,) or not (np.isfinite(wavelengths).all() and (wavelengths > 0).all()):
            raise ValueError(f"wavelengths_nm must be 3 wavelengths [nm], finite and > 0, got {short(wavelengths_nm)}")
        attributes["channelWavelengthsNm"] = wavelengths.astype(np.float32)
    if radiance_view is not None:
        if not isinstance(radiance_view, str) or not radiance_view.startswith("-vt") or "\n" in radiance_view:
            raise ValueError(f"radiance_view must be Radiance view options on one line (-vt...), got "
                             f"{short(radiance_view)}")
        attributes["radianceView"] = radiance_view
    if camera == "equirectangular":
        attributes["envmap"] = "latlong"
        attributes["envmapOrientation"] = ENVMAP_ORIENTATION
        attributes["sunDirectionEnvmap"] = enu_to_envmap(sun).astype(np.float32)
        attributes["sunPixel"] = np.array(envmap_pixel(sun_zenith_deg, sun_azimuth_deg, width, height), np.float32)
    return attributes


def exr_pixels(rgb, precision="float"):
    """(pixels, clipped): ``rgb`` as a C-contiguous (H, W, 3) array of the precision's dtype (float32
    or float16), and the number of pixels with a channel above :data:`HALF_MAX` clipped to it with
    'half' (0 with 'float'). A sky's half-float file can hold everything but the sun's disc (I_I / 6.8e-5
    sr, 3e5 in relative units, 1e9 cd/m^2): those few pixels are clipped rather than made infinite.
    ValueError for a bad shape, precision or kind of number, NaN, infinite or negative values (a frame is
    radiance: :func:`read_exr` takes no other), and with 'float' values beyond float32's range (3.4e38:
    infinite once stored)."""
    if not isinstance(precision, str) or precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {list(PRECISIONS)}, got {precision!r}")
    rgb = np.asarray(rgb)
    if rgb.dtype.kind not in "biuf":                 # strings, objects; complex values lost their imaginary part
        raise ValueError(f"rgb must hold real numbers, got an array of {rgb.dtype}")
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.shape[0] < 1 or rgb.shape[1] < 1:
        raise ValueError(f"rgb must have shape (H, W, 3), got {rgb.shape}")
    if not np.isfinite(rgb).all():
        raise ValueError("rgb holds NaN or infinite values: an EXR frame holds finite values only")
    if rgb.min() < 0:
        raise ValueError(f"rgb holds negative values (the least {short(rgb.min())}): an EXR frame holds radiance, "
                         f">= 0")
    if precision == "float" and np.abs(rgb).max() > np.finfo(np.float32).max:
        raise ValueError(f"rgb holds values beyond float32's range ({np.finfo(np.float32).max:.3g}), "
                         f"infinite once stored: {short(np.abs(rgb).max())}")
    clipped = 0
    if precision == "half":
        over = np.abs(rgb) > HALF_MAX
        clipped = int(over.any(axis=2).sum())
        if clipped:
            rgb = np.clip(rgb, -HALF_MAX, HALF_MAX)
    return np.ascontiguousarray(rgb, dtype=PRECISIONS[precision]), clipped


def write_exr(path, rgb, precision="float", attributes=None, force=False, staging=None):
    """Write an RGB image to a scan-line OpenEXR file atomically (ZIP compression).

    Parameters
    ----------
    path : str or os.PathLike
        Target file; its directory must exist.
    rgb : array_like, shape (H, W, 3)
        Linear values, row 0 at the top (stored as the file's first scan line).
    precision : {'float', 'half'}
        32-bit floats (the float32 values exactly) or 16-bit half floats (round to nearest: relative
        error <= 2^-11 from 6.1e-5 to 65504, absolute <= 2^-25 below; values above 65504 are clipped to
        it, and the header's ``halfClippedPixels`` counts the pixels that were).
    attributes : dict, optional
        Header attributes (:func:`frame_attributes`), as OpenEXR.File takes them.
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
        A bad shape or precision; NaN or infinite values; attributes the bindings do not store (an int
        beyond 32 bits was stored as 0; None or a value for one of the file's own attributes raised their
        RuntimeError). Nothing is written then.
    ImportError
        The OpenEXR bindings are missing.
    FileExistsError, IsADirectoryError, FileNotFoundError, NotADirectoryError, PermissionError
        As :func:`clsky.anim.writers.write_png`.
    """
    path, force = output_target(path, force)
    require_openexr()
    check_attributes(attributes)
    pixels, clipped = exr_pixels(rgb, precision)
    if precision == "half":
        attributes = {**(attributes or {}), "halfClippedPixels": clipped}
    with atomic_write(path, overwrite=force, suffix=".exr", staging=staging) as temporary:
        save_exr(temporary, pixels, attributes)
    return path


def check_attributes(attributes):
    """ValueError naming ``attributes`` unless the bindings store each of them as given: written with a
    one-pixel image into a temporary directory first (their errors come only at the write), an int within
    EXR's 32 bits (a larger one was stored as 0)."""
    if attributes is None:
        return
    if not isinstance(attributes, dict) or not all(isinstance(name, str) for name in attributes):
        raise ValueError(f"attributes must be a dict of names to values, got {short(attributes)}")
    for name, value in attributes.items():
        if isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)) \
                and not -2**31 <= value < 2**31:
            raise ValueError(f"attributes[{name!r}] must be an int in [-2147483648, 2147483647] (EXR's int), "
                             f"got {short(value)}")
    with tempfile.TemporaryDirectory(prefix="clsky-exr-") as directory:
        try:
            save_exr(pathlib.Path(directory) / "attributes.exr", np.zeros((1, 1, 3), np.float32), attributes)
        except (RuntimeError, TypeError) as error:
            raise ValueError(f"attributes: the OpenEXR bindings store them not as given "
                             f"({str(error).splitlines()[0] if str(error) else type(error).__name__})") from None


def save_exr(file, pixels, attributes=None):
    """Write ``pixels`` (from :func:`exr_pixels`) and ``attributes`` to ``file`` as it is, not
    atomically: the step :func:`write_exr` and :class:`clsky.anim.writers.FrameWriter` take inside their
    temporary files."""
    OpenEXR = require_openexr()
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage, **(attributes or {})}
    if isinstance(header.get("envmap"), str):
        envmaps = {"latlong": OpenEXR.ENVMAP_LATLONG, "cube": OpenEXR.ENVMAP_CUBE}
        if header["envmap"] not in envmaps:
            raise ValueError(f"envmap must be one of {list(envmaps)}, got {header['envmap']!r}")
        header["envmap"] = envmaps[header["envmap"]]
    try:
        OpenEXR.File(header, {"RGB": pixels}).write(str(file))
    except RuntimeError as error:
        # the bindings' failures are RuntimeErrors: those of the file (a full disk: a traceback naming the
        # temporary) become an OSError of it, which the atomic writers name by their target; those of the
        # attributes (check_attributes) stay as they are
        message = str(error)
        if str(file) not in message:
            raise
        known = [code for code in (errno.ENOSPC, errno.EFBIG, errno.EDQUOT, errno.EROFS, errno.EACCES)
                 if os.strerror(code).lower() in message.lower()]
        code = known[0] if known else errno.EIO
        # the file named as the writers name it (by their target): the bindings' text names the temporary
        reason = os.strerror(code) if known else message.replace(f'"{file}"', "the file").replace(str(file), "the file")
        raise OSError(code, reason, str(file)) from None


#: The most pixels :func:`read_exr` reads: its header's data window is checked first (a 3.5 kB file declaring
#: 100000 x 100000 pixels had the bindings allocate 56 GiB); clsky's largest frame, an 8192-row panorama, has
#: 2**27.
MAX_READ_PIXELS = 2**28


def bindings_failure(error, printed=(), path=None) -> str:
    """Why the OpenEXR bindings could not read a file (at ``path``), for a message naming it: their exception
    ``error`` and the lines their library ``printed`` meanwhile (the file's name and 'Warning: ' taken off).
    A damaged or cut pixel table left the bindings with no part ('Invalid part index '0': file has 0
    parts.', wrong about the file), the cause in a line they printed; a string attribute of other text than
    UTF-8 (Latin-1, which exrheader and OpenImageIO read) raised Python's UnicodeDecodeError, as if the file
    were damaged."""
    if isinstance(error, UnicodeDecodeError):
        return "a string attribute holds text that is not UTF-8, which the OpenEXR bindings cannot read"
    message = str(error).splitlines()[0] if str(error) else repr(error)
    if "has 0 parts" in message:
        causes = (line.removeprefix(f"{path}: ").removeprefix("Warning: ").strip() for line in printed)
        cause = next((line for line in causes if line), "")
        return "its pixel data is damaged or cut short" + (f" ({cause})" if cause else "")
    return message


@contextlib.contextmanager
def _library_output(lines):
    """Within the block, the process's stdout and stderr (file descriptors 1 and 2) go to a temporary file,
    whose lines are appended to ``lines`` after it: the OpenEXR library prints its read errors ('Warning:
    Exception raised reading pixel data ...' on stdout, which 2>/dev/null kept, three lines on stderr) beside
    the exception the bindings raise. What other threads print meanwhile goes there too."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    python = io.StringIO()      # the bindings' own warning goes through sys.stdout (pybind11's print)
    saved = []
    try:                        # a closed descriptor (a daemon's, '>&-'), no room for the file: not caught
        # copies above 2: with fd 2 closed, os.dup(1) returned 2, which the redirection then overwrote
        saved = [fcntl.fcntl(descriptor, fcntl.F_DUPFD_CLOEXEC, 3) for descriptor in (1, 2)]
        sink = tempfile.TemporaryFile()
    except OSError:
        for descriptor in saved:
            os.close(descriptor)
        with contextlib.redirect_stdout(python), contextlib.redirect_stderr(python):
            yield
        lines.extend(python.getvalue().splitlines())
        return
    with sink:
        try:
            os.dup2(sink.fileno(), 1)
            os.dup2(sink.fileno(), 2)
            with contextlib.redirect_stdout(python), contextlib.redirect_stderr(python):
                yield
        finally:
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for descriptor in saved:
                os.close(descriptor)
            sink.seek(0)
            lines.extend(python.getvalue().splitlines() + sink.read().decode("utf-8", "replace").splitlines())


def read_exr(path):
    """(pixels (H, W, 3) float16 or float32 as stored, header dict) of a single-part RGB (or RGBA: its R, G,
    B) EXR file whose pixels are radiance, as clsky's frames are: finite and >= 0, in Rec. 709 / sRGB
    primaries (or without ``chromaticities``), their data window the whole display window.

    The OpenEXR library's own lines about a damaged file go into the error's message, not onto stdout and
    stderr (:func:`_library_output`).

    Raises
    ------
    FileNotFoundError, IsADirectoryError
        No such file, or a directory.
    ValueError
        Not a readable EXR file (the bindings' error, named: :func:`bindings_failure`), a data window of
        more than :data:`MAX_READ_PIXELS` or that is not the display window (the pixels' place in the image
        was dropped), more than one part (the first was read without a word), chromaticities other than
        Rec. 709's (an ACES file's were taken for sRGB), no R, G, B channels, or pixels that are not half or
        float numbers, finite and >= 0 (NaN, infinities, negative or integer pixels were returned as they
        were).
    """
    OpenEXR = require_openexr()
    path = as_path(path)
    if path.is_dir():
        raise IsADirectoryError(f"{path}: a directory, not an EXR file")
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file" if not path.exists() else f"{path}: not a regular file")
    def read(header_only):
        """(header, parts, channels' names, R, G, B pixels or None) by the bindings, their errors (RuntimeError
        and others for a bad file) named as the file's."""
        printed = []
        try:
            # channel by channel: the bindings' RGB view refused a valid file of half R, B and float G
            with _library_output(printed), OpenEXR.File(str(path), header_only=header_only,
                                                        separate_channels=True) as exr:
                header, parts = dict(exr.header()), len(exr.parts)
                if header_only:
                    return header, parts, [], None
                channels = exr.channels()         # emptied when the file closes: its names taken now
                if not all(name in channels for name in "RGB"):
                    return header, parts, sorted(channels), None
                planes = [np.asarray(channels[name].pixels) for name in "RGB"]
                dtype = np.result_type(*planes)    # half and float together: float
                pixels = np.stack([plane.astype(dtype, copy=False) for plane in planes], axis=-1)
                return header, parts, sorted(channels), pixels
        except MemoryError:
            raise
        except Exception as error:  # noqa: BLE001
            raise ValueError(f"{path}: not a readable EXR file ({bindings_failure(error, printed, path)})") from None

    header, parts, _, _ = read(header_only=True)
    window = header.get("dataWindow")
    try:
        (x0, y0), (x1, y1) = window
        pixel_count = (int(x1) - int(x0) + 1) * (int(y1) - int(y0) + 1)
    except (TypeError, ValueError):
        raise ValueError(f"{path}: not a readable EXR file (no data window)") from None
    if not 0 < pixel_count <= MAX_READ_PIXELS:
        raise ValueError(f"{path}: its data window holds {pixel_count} pixels, the reader takes 1 to "
                         f"{MAX_READ_PIXELS}")
    _check_placed_rgb(path, header, parts)
    header, _, names, pixels = read(header_only=False)
    if pixels is None:
        raise ValueError(f"{path}: no R, G, B channels (has {names})")
    if pixels.dtype not in (np.float16, np.float32):
        raise ValueError(f"{path}: its pixels are {pixels.dtype}, not half or float radiance")
    if pixels.size and not (pixels.min() >= 0 and pixels.max() <= np.finfo(pixels.dtype).max):   # NaN fails both
        raise ValueError(f"{path}: its pixels hold NaN, infinite or negative values: no radiance")
    return pixels, header


def is_rec709(chromaticities) -> bool:
    """Whether ``chromaticities`` (x, y of red, green, blue and white, 8 numbers; an EXR's attribute, a
    Radiance PRIMARIES line) are Rec. 709's and D65 (:data:`REC709_CHROMATICITIES`, within 1e-4: an EXR holds
    them as float32), the primaries clsky's readers return their pixels in."""
    values = np.ravel(np.asarray(chromaticities, dtype=np.float64))
    return values.shape == (8,) and bool(np.all(np.abs(values - REC709_CHROMATICITIES) <= 1e-4))


def window_text(box) -> str:
    """'(x0, y0)-(x1, y1)' of an EXR window (two int pairs), as read_exr's and clsky info's lines show it."""
    (x0, y0), (x1, y1) = box
    return f"({int(x0)}, {int(y0)})-({int(x1)}, {int(y1)})"


def _check_placed_rgb(path, header, parts):
    """ValueError naming ``path`` unless its pixels are what :func:`read_exr` returns them as: one part, the
    data window the display window, Rec. 709 chromaticities (or none), flat (not deep) pixels."""
    if "deep" in str(header.get("type", "")):
        raise ValueError(f"{path}: its pixels are deep data (samples at several depths a pixel); the reader takes "
                         f"flat images")
    if parts != 1:
        raise ValueError(f"{path}: it has {parts} parts; the reader takes single-part images")
    display = header.get("displayWindow")
    if display is not None and window_text(display) != window_text(header["dataWindow"]):
        raise ValueError(f"{path}: its data window {window_text(header['dataWindow'])} is not its display window "
                         f"{window_text(display)}; the reader takes whole images")
    chromaticities = header.get("chromaticities")
    if chromaticities is not None and not is_rec709(chromaticities):
        shown = " ".join(f"{v:g}" for v in np.ravel(chromaticities))
        raise ValueError(f"{path}: its chromaticities ({shown}) are not Rec. 709's: the reader returns linear sRGB")
