"""``clsky info FILE``: one readable block describing a table file or an output of clsky.

- A table (``.npz``, :mod:`clsky.table`): read with :meth:`clsky.ScatteringTable.load`, which checks
  every member's checksum, the parameters hash, shapes, dtypes and values first; then its grid, dtype,
  size in memory and on disk, units, atmosphere, settings, orders record and provenance.
- A PNG frame: its size and the text chunks clsky writes (clsky_version, the TOML scene;
  :mod:`clsky.anim.scene`), read from the chunks before its image data, which is never decompressed.
- A metrics JSON (``<stem>_metrics.json``): the version, the scene, the frames and the table's units.
- An EXR frame (``clsky animate --hdr exr``): its size, channels and header (units, orientation of an
  environment map, the scene and clsky's version), the header alone read with the OpenEXR bindings (the
  pixels are not decoded, so damaged pixels go unnoticed here).
- A Radiance HDR frame (``--hdr hdr``): its size and header lines (the EXR header's attributes but the
  scene), read from its first 64 KiB (:func:`clsky.anim.rgbe.read_rgbe_header`).

A damaged or foreign file is a :class:`clsky.table.TableFormatError` (a ValueError) naming the file:
one line and exit status 2 on the command line.
"""

from __future__ import annotations

import json
import struct
import zlib

import numpy as np

from ._files import as_path, read_user_text
from .errors import counted
from .table import TableFormatError

__all__ = ["describe"]


def _block(title, items):
    """The lines of a file's description: each value one line of printable text (a line break, a tab or a
    terminal's escape in a file's value is shown escaped: a metrics JSON's or an EXR attribute's newline
    added lines of its own to the description, and an escape sequence reached the terminal)."""
    width = max(len(name) for name, _ in items)
    return "\n".join([title] + [f"  {name:<{width}}  {_printable(value)}" for name, value in items])


def _printable(value) -> str:
    """``str(value)`` with every character that is not printable escaped as Python writes it."""
    text = str(value)
    return text if text.isprintable() else "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def _scene_lines(scene):
    return [("scene", "")] + [("", line) for line in scene.rstrip("\n").splitlines() if line.strip()]


def _table(path):
    from .table import ScatteringTable

    table = ScatteringTable.load(path)                  # checks checksums, hash, shapes, values
    width, height, depth = table.settings.size
    record, metadata = table.orders_record, table.metadata
    stored = sum(array.nbytes for array in (table.data, table.gathered, table.ground_irradiance, *table.orders)
                 if array is not None)
    settings = table.settings.to_dict()
    items = [("kind", "scattering table (clsky .npz, checksums valid)"),
             ("grid", (f"{width} x {height} x {depth} x {table.settings.azimuth_size} (altitude x view zenith x "
                       f"sun zenith x azimuth, 4D)" if table.settings.is_4d else
                       f"{width} x {height} x {depth} (altitude x view zenith x sun zenith)")
              + f", {table.settings.channels} channels, {table.data.dtype}"),
             ("size", f"{path.stat().st_size / 2**20:.1f} MiB on disk, {stored / 2**20:.1f} MiB of arrays"),
             ("units", metadata.get("units", "relative (incident light I_I per sr)")),
             ("orders", f"{record.get('orders')} ({record.get('reason') or ('converged' if record.get('converged') else 'not converged')})"),
             ("mode", settings.get("mode")),
             ("ground albedo", f"{table.atmosphere.ground_albedo:g}"),
             ("ozone column", f"{table.atmosphere.ozone_column_du:g} DU"),
             ("wavelengths", " ".join(f"{w:g}" for w in table.atmosphere.wavelengths) + " nm"),
             ("clsky version", metadata.get("clsky_version")),
             ("built", f"{metadata.get('backend')} on {metadata.get('device')} in "
                       f"{float(metadata.get('build_seconds', 0.0)):.2f} s")]
    items += [(f"settings.{name}", value) for name, value in settings.items()]
    return _block(f"{path}:", items)


#: A PNG file's first 8 bytes, and the colour types' Pillow modes (PNG specification, 11.2.2).
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_PNG_MODES = {0: "L", 2: "RGB", 3: "P", 4: "LA", 6: "RGBA"}
#: The most bytes of chunks read before the image data (clsky's frames hold a few kB of text there).
_PNG_MAX_HEADER_BYTES = 16 * 2**20


def _png_chunks(path):
    """(type, data) of each chunk of the PNG at ``path`` before its image data (IDAT), each CRC checked;
    TableFormatError naming the file for anything else."""
    def damaged(why):
        return TableFormatError(f"{path}: not a readable PNG ({why})")

    with open(path, "rb") as stream:
        if stream.read(len(_PNG_SIGNATURE)) != _PNG_SIGNATURE:
            raise damaged("no PNG signature")
        total = 0
        while True:
            head = stream.read(8)
            if len(head) < 8:
                raise damaged("it ends before its image data")
            length, kind = struct.unpack(">I4s", head)
            if kind in (b"IDAT", b"IEND"):
                return
            total += length
            if total > _PNG_MAX_HEADER_BYTES:
                raise damaged(f"more than {_PNG_MAX_HEADER_BYTES // 2**20} MiB of chunks before its image data")
            data, crc = stream.read(length), stream.read(4)
            if len(data) < length or len(crc) < 4 or zlib.crc32(kind + data) != struct.unpack(">I", crc)[0]:
                raise damaged(f"its {kind.decode('latin-1')!r} chunk is damaged")
            yield kind, data


def _png(path):
    """The size, colour type and clsky's text of a PNG, from its chunks before the image data: nothing is
    decompressed (clsky's frames put their text there, as iTXt), so a frame of any size costs a few reads,
    where Pillow decoded the whole image for its text and refused images of over 179 million pixels (a
    69-byte file that claimed 60000 x 60000 pixels, and clsky's own 8192-pixel composites)."""
    size = mode = None
    text = {}
    for kind, data in _png_chunks(path):
        if kind == b"IHDR" and len(data) == 13:
            width, height, _, colour = struct.unpack(">IIBB", data[:10])
            size, mode = (width, height), _PNG_MODES.get(colour, f"colour type {colour}")
        elif kind == b"tEXt":
            keyword, _, value = data.partition(b"\0")
            text[keyword.decode("latin-1")] = value.decode("latin-1")
        elif kind == b"iTXt":
            keyword, _, rest = data.partition(b"\0")
            if rest[:1] == b"\0":                     # uncompressed (clsky's); language and keyword skipped
                value = rest[2:].split(b"\0", 2)[-1]
                text[keyword.decode("latin-1")] = value.decode("utf-8", "replace")
    if size is None:
        raise TableFormatError(f"{path}: not a readable PNG (no image header)")
    version = text.get("clsky_version", "- (not written by clsky)")
    items = [("kind", "PNG image"), ("size", f"{size[0]} x {size[1]} pixels, {mode}"),
             ("clsky version", version if version.isprintable() else repr(version))]
    if "scene" in text:
        items += _scene_lines(text["scene"])
    return _block(f"{path}:", items)


def _json_member(path, document, key, kind):
    """``document[key]`` checked to be of ``kind`` (list, dict, str); absent: None. TableFormatError
    naming the file and the key otherwise."""
    value = document.get(key)
    if value is not None and not isinstance(value, kind):
        names = {list: "a list", dict: "an object", str: "a string"}
        raise TableFormatError(f"{path}: not an animation's metrics JSON ('{key}' must be {names[kind]}, "
                               f"got {type(value).__name__})")
    return value


def _orders_text(count) -> str:
    """A metrics file's count of orders as words: '1 order', '7 orders' (as recorded where not an integer)."""
    return counted(count, "order") if isinstance(count, int) and not isinstance(count, bool) else f"{count} orders"


def _first_line(error) -> str:
    return str(error).splitlines()[0] if str(error) else type(error).__name__


def _no_constant(name):
    """json's hook for NaN, Infinity and -Infinity, which clsky's strict JSON never writes."""
    raise ValueError(f"{name} is no JSON number (clsky writes strict JSON)")


def _metrics(path):
    try:
        document = json.loads(read_user_text(path), parse_constant=_no_constant)
    except OSError as error:
        raise TableFormatError(f"{path}: cannot read it ({error.strerror or error})") from None
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as error:
        raise TableFormatError(f"{path}: not a readable JSON file ({_first_line(error)})") from None
    except ValueError as error:             # an integer of more digits than Python converts
        raise TableFormatError(f"{path}: not a readable JSON file ({_first_line(error)})") from None
    if not isinstance(document, dict) or "frames" not in document:
        raise TableFormatError(f"{path}: not an animation's metrics JSON (no 'frames')")
    frames = _json_member(path, document, "frames", list)
    if frames is None:
        raise TableFormatError(f"{path}: not an animation's metrics JSON ('frames' must be a list, got null)")
    table = _json_member(path, document, "table", dict) or {}
    settings = _json_member(path, table, "settings", dict) or {}
    orders = _json_member(path, table, "orders", dict) or {}
    size = _json_member(path, settings, "size", list) or []
    scene = _json_member(path, document, "scene", str)
    if not all(isinstance(frame, dict) for frame in frames):
        raise TableFormatError(f"{path}: not an animation's metrics JSON (its frames must be objects)")
    version = _json_member(path, document, "clsky_version", str)
    units = _json_member(path, table, "frame_units", str)
    if not all(type(n) is int for n in size):
        raise TableFormatError(f"{path}: not an animation's metrics JSON (the table's size must be integers)")
    items = [("kind", "animation metrics (JSON)"), ("frames", len(frames)),
             ("clsky version", "- (older clsky)" if version is None else version),
             ("table", f"{' x '.join(map(str, size))} ({settings.get('mode')}, {_orders_text(orders.get('orders'))})"),
             ("frame units", "-" if units is None else units)]
    if scene is not None:
        items += _scene_lines(scene)
    return _block(f"{path}:", items)


#: The attributes every EXR header holds (OpenEXR's "Technical Introduction", required attributes) and clsky's
#: own, with their types.
_EXR_TYPES = {"channels": "chlist", "compression": "compression", "dataWindow": "box2i", "displayWindow": "box2i",
              "lineOrder": "lineOrder", "pixelAspectRatio": "float", "screenWindowCenter": "v2f",
              "screenWindowWidth": "float"}
_CLSKY_EXR_TYPES = {"clskyVersion": "string", "scene": "string"}
#: The most bytes of an EXR file's header read to check its attributes' types.
_EXR_MAX_HEADER = 16 * 2**20


def _exr_attribute_types(path) -> dict:
    """{name: type name} of the attributes in the header of the EXR file at ``path`` (its first part), read
    from the file's bytes (name, type, size, value, until an empty name); TableFormatError naming the file
    where those bytes are no such header. The bindings' header_only read stopped at an attribute of a
    damaged type and filled in defaults: a 56 x 32 frame whose dataWindow was typed box2f was described as
    64 x 64 pixels, 'not written by clsky'."""
    def damaged(why):
        return TableFormatError(f"{path}: not a readable EXR file ({why})")

    with open(path, "rb") as stream:
        data = stream.read(_EXR_MAX_HEADER)
    if data[:4] != b"\x76\x2f\x31\x01":
        raise damaged("no EXR magic number")
    types, at = {}, 8
    while True:
        end = data.find(b"\0", at)
        if end < 0:
            raise damaged("its header is cut short")
        name = data[at:end].decode("latin-1")
        at = end + 1
        if not name:
            return types
        end = data.find(b"\0", at)
        if end < 0 or end + 5 > len(data):
            raise damaged(f"its attribute {name!r:.40} is cut short")
        kind = data[at:end].decode("latin-1")
        size = int.from_bytes(data[end + 1:end + 5], "little", signed=True)
        if size < 0:
            raise damaged(f"its attribute {name!r:.40} has a negative size")
        types[name] = kind
        at = end + 5 + size


def _exr(path):
    try:
        import OpenEXR
    except ImportError as error:
        raise ImportError("describing an EXR file needs the OpenEXR bindings: pip install 'clsky[anim]'") from error
    types = _exr_attribute_types(path)
    for name, kind in {**_EXR_TYPES, **_CLSKY_EXR_TYPES}.items():
        if name in _EXR_TYPES and name not in types:
            raise TableFormatError(f"{path}: not a readable EXR file (no {name} attribute)")
        if name in types and types[name] != kind:
            raise TableFormatError(f"{path}: not a readable EXR file (its {name} attribute is a {types[name]!r:.40}, "
                                   f"not a {kind}: damaged)")
    from .anim.exr import bindings_failure, window_text

    try:                            # the header alone: damaged pixels are not info's to decode
        with OpenEXR.File(str(path), header_only=True) as exr:
            header, parts = dict(exr.header()), [part.name() for part in exr.parts]
        channels = [channel.name for channel in header.get("channels", [])]
    except Exception as error:  # noqa: BLE001  (the bindings raise RuntimeError and others for a bad file)
        raise TableFormatError(f"{path}: not a readable EXR file ({bindings_failure(error, path=path)})") from None
    window = header.get("dataWindow")
    items = [("kind", "OpenEXR image"),
             ("size", "-" if window is None else f"{window[1][0] - window[0][0] + 1} x {window[1][1] - window[0][1] + 1}"
                                                  f" pixels, channels {', '.join(channels)}"),
             ("clsky version", header.get("clskyVersion", "- (not written by clsky)"))]
    if len(parts) > 1:              # the first part was described without a word of the others
        items.append(("parts", f"{len(parts)} ({', '.join(map(repr, parts))}; this is the first's header)"))
    display = header.get("displayWindow")
    if window is not None and display is not None and window_text(window) != window_text(display):
        items.append(("windows", f"data {window_text(window)} in display {window_text(display)}"))
    for name in sorted(header):
        if name in ("clskyVersion", "scene", "dataWindow", "displayWindow", "channels"):
            continue
        items.append((name, _exr_value(header[name])))
    if "scene" in header:
        items += _scene_lines(header["scene"])
    return _block(f"{path}:", items)


def _exr_value(value):
    """A header attribute's value as text: numbers and vectors as numbers, the bindings' enums by name, and
    an attribute of a type the bindings do not read (another tool's, or a damaged type name) by that alone:
    its raw bytes are no text."""
    if isinstance(value, (str, int, float)):
        return value
    if isinstance(value, (tuple, list, np.ndarray)) and np.ndim(value) == 1 \
            and np.issubdtype(np.asarray(value).dtype, np.number):
        return " ".join(f"{v:g}" for v in np.asarray(value).tolist())
    if type(value).__name__ == "OpaqueAttribute":
        return "- (an attribute of a type the OpenEXR bindings do not read)"
    if type(value).__module__ == "OpenEXR" and isinstance(getattr(value, "name", None), str):
        return value.name              # an enum: ZIP_COMPRESSION, not the repr Compression.ZIP_COMPRESSION
    return str(value)


def _hdr(path):
    from .anim.rgbe import read_rgbe_header

    try:
        height, width, header = read_rgbe_header(path)
    except (ValueError, OSError) as error:
        raise TableFormatError(f"{path}: not a readable Radiance HDR file "
                               f"({str(error).removeprefix(f'{path}: ')})") from None
    picture_format = header.get("FORMAT", "32-bit_rle_rgbe")
    kind = "Radiance RGBE image" if picture_format == "32-bit_rle_rgbe" else f"Radiance image ({picture_format})"
    items = [("kind", kind), ("size", f"{width} x {height} pixels"),
             ("clsky version", header.get("clskyVersion", "- (not written by clsky)"))]
    items += [(name, header[name]) for name in sorted(header) if name != "clskyVersion"]
    return _block(f"{path}:", items)


READERS = {".npz": _table, ".png": _png, ".json": _metrics, ".exr": _exr, ".hdr": _hdr}


def describe(path) -> str:
    """A readable block of text describing ``path``: a table (.npz), a PNG, a metrics JSON, an EXR or HDR frame.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist, or is no regular file (a FIFO, a device).
    IsADirectoryError
        ``path`` is a directory.
    ValueError
        Its suffix is none of :data:`READERS`' (``.npz``, ``.png``, ``.json``, ``.exr``, ``.hdr``).
    TableFormatError
        A damaged or foreign file (message names the file).
    ImportError
        An EXR file without the OpenEXR bindings (the ``anim`` extra), saying so.
    """
    path = as_path(path)
    if path.is_dir():
        raise IsADirectoryError(f"{path}: a directory, not a file: clsky info reads {', '.join(READERS)} files")
    reader = READERS.get(path.suffix.lower())
    if reader is None:
        raise ValueError(f"{path}: clsky info reads {', '.join(READERS)} files, got {path.suffix or 'no suffix'!r}")
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file" if not path.exists() else f"{path}: not a regular file")
    return reader(path)
