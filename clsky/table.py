"""The scattering table as a product: build, look up, save, load, export for GPU engines.

File format (``.npz``, uncompressed: compression saves little on these values and costs seconds;
:data:`FORMAT_VERSION`): arrays ``data`` (D, H, W, C) at full precision, ``order_1``, ``order_2``, ...
(every scattering order, stored as float32 for inspection), ``gathered`` (the sum of the gathered
in-scatter tables, for the ray march; absent for single scattering), ``format_version``, and JSON strings
``atmosphere``, ``settings``, ``metadata``, ``orders_record`` (how the iteration stopped) and
``parameters_hash`` (SHA-256 of the atmosphere and settings). :meth:`ScatteringTable.load` refuses a file whose version,
hash or shape does not match, with a clear error.

Raw export (:meth:`ScatteringTable.export_raw`): ``<name>.bin`` holds little-endian float32 values,
cell after cell in the order i = x + y W + z W H (x: altitude, y: view zenith, z: sun zenith), C
channels per cell; ``<name>.json`` documents that layout, the mappings, the atmosphere and settings.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import os
import pathlib
import tempfile
import time
from typing import Callable

import numpy as np

from . import __version__
from .atmosphere import AtmosphereParameters, preset
from .lookup import check_queries
from .settings import TableSettings

__all__ = ["ScatteringTable", "TableFormatError", "FORMAT_VERSION", "BACKENDS", "atomic_write",
           "CHANNEL_NAMES"]

FORMAT_VERSION = 3   # 3: settings carry sun_cos_range (the sun axis' sub-range)
BACKENDS = ("opencl", "numpy")
_MULTIPLE_NAMES = ("multiple_r", "multiple_g", "multiple_b")
CHANNEL_NAMES = {6: ("rayleigh_r", "rayleigh_g", "rayleigh_b", "mie_r", "mie_g", "mie_b"),
                 4: ("rayleigh_r", "rayleigh_g", "rayleigh_b", "mie")}
CHANNEL_NAMES[9] = CHANNEL_NAMES[6] + _MULTIPLE_NAMES
CHANNEL_NAMES[7] = CHANNEL_NAMES[4] + _MULTIPLE_NAMES


class TableFormatError(ValueError):
    """A table file that clsky cannot (or must not) load: wrong version, shape or hash."""


@contextlib.contextmanager
def atomic_write(path, overwrite=False, suffix=None):
    """Yield a temporary path beside ``path``; on success it replaces ``path`` atomically.

    An interrupted write leaves no partial file. An existing ``path`` raises FileExistsError unless
    ``overwrite``.
    """
    path = pathlib.Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists (use overwrite=True, or --force on the command line)")
    if not path.parent.is_dir():
        raise FileNotFoundError(f"directory {path.parent} does not exist")
    fd, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix or path.suffix, dir=path.parent)
    os.close(fd)
    temporary = pathlib.Path(temporary)
    umask = os.umask(0)
    os.umask(umask)
    temporary.chmod(0o666 & ~umask)        # mkstemp's 0600 would leak into the final file
    try:
        yield temporary
        os.replace(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)


def parameters_hash(atmosphere: AtmosphereParameters, settings: TableSettings) -> str:
    """SHA-256 of the canonical JSON of the atmosphere and the settings."""
    text = json.dumps({"atmosphere": atmosphere.to_dict(), "settings": settings.to_dict()},
                      sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def to_layout(data6, mie_layout):
    """Factored per-wavelength (D, H, W, 6) values in the requested layout (the notes' layout averages
    the three Mie channels into one); channels after the sixth (the physical mode's phased higher
    orders) are kept as they are."""
    if mie_layout == "notes":
        return np.concatenate([data6[..., :3], data6[..., 3:6].mean(axis=-1, keepdims=True), data6[..., 6:]],
                              axis=-1)
    return data6


@dataclasses.dataclass(frozen=True, eq=False)
class ScatteringTable:
    """A precomputed scattering table with everything that defines it.

    Attributes
    ----------
    atmosphere : AtmosphereParameters
    settings : TableSettings
    data : numpy.ndarray, shape (D, H, W, C)
        Per cell [1/sr], without I_I: channels :data:`CHANNEL_NAMES` [C]. The factored channels
        (Ibar summed over orders in the atmosphere-plus mode, single scattering in the physical mode)
        carry no phase; the physical mode's 3 last channels hold the higher orders, phase applied.
    metadata : dict
        Provenance: clsky version, backend, device, build seconds.
    orders : tuple of numpy.ndarray
        Every order's table (float64 when built, float32 when loaded from a file): order 1 (D, H, W, 6) factored; higher orders (D, H, W, 6)
        factored (atmosphere-plus) or (D, H, W, 3) phased (physical). See :mod:`clsky.orders`.
    orders_record : dict
        How the iteration went: orders computed, converged or not and why, each order's relative
        addition and share.
    gathered : numpy.ndarray (D, H, W, 6) or None
        Sum of the gathered in-scatter tables of the orders (:class:`clsky.orders.OrdersResult`), for
        the per-pixel ray march; None when only single scattering was computed.
    """

    atmosphere: AtmosphereParameters
    settings: TableSettings
    data: np.ndarray
    metadata: dict = dataclasses.field(default_factory=dict)
    orders: tuple = ()
    orders_record: dict = dataclasses.field(default_factory=dict)
    gathered: np.ndarray | None = None

    def __post_init__(self):
        width, height, depth = self.settings.size
        expected = (depth, height, width, self.settings.channels)
        if self.data.shape != expected:
            raise TableFormatError(f"table data has shape {self.data.shape}, settings say {expected} "
                                   f"(D, H, W, channels)")

    # Building -------------------------------------------------------------------------------------
    @classmethod
    def build(cls, atmosphere: AtmosphereParameters | str = "atmosphere-plus",
              settings: TableSettings | None = None, backend="opencl", ctx=None, fast_math=False,
              progress: Callable[[int, int], None] | None = None) -> "ScatteringTable":
        """Compute the table: single scattering, then the orders ``settings`` asks for.

        Parameters
        ----------
        atmosphere : AtmosphereParameters or preset name
        settings : TableSettings, optional
        backend : {'opencl', 'numpy'}
            OpenCL kernels, or their NumPy twins (:mod:`clsky.reference`).
        ctx : pyopencl.Context, optional
        fast_math : bool
            Build kernels with -cl-fast-relaxed-math (opt-in).
        progress : callable, optional
            ``progress(stage, done, total)`` as the work advances (see :func:`clsky.orders.compute_orders`).

        Raises
        ------
        InsufficientMemoryError
            Before any work, when the build needs more memory than the host or device has
            (:func:`clsky.resources.check_memory`).

        Examples
        --------
        >>> table = ScatteringTable.build("physical", TableSettings(size=(8, 16, 8), mode="physical"))
        >>> table.data.shape
        (8, 16, 8, 9)
        >>> table.orders_record["converged"]
        True
        """
        if isinstance(atmosphere, str):
            atmosphere = preset(atmosphere)
        settings = settings or TableSettings()
        if backend not in BACKENDS:
            raise ValueError(f"backend must be one of {list(BACKENDS)}, got {backend!r}")
        from .orders import compute_orders
        from .resources import check_memory, device_of, estimate_table_memory

        check_memory(estimate_table_memory(settings, backend),
                     device=device_of(ctx, settings.dtype) if backend == "opencl" else None)
        start = time.perf_counter()
        result = compute_orders(atmosphere, settings, backend=backend, ctx=ctx, fast_math=fast_math,
                                progress=progress)
        seconds = time.perf_counter() - start
        metadata = {"clsky_version": __version__, "backend": backend, "device": result.record.pop("device"),
                    "build_seconds": seconds, "fast_math": bool(fast_math)}
        return cls(atmosphere, settings, to_layout(result.combined(settings.mode), settings.mie_layout),
                   metadata, tuple(result.orders), result.record, result.gathered)

    # Using ----------------------------------------------------------------------------------------
    @property
    def parameters_hash(self) -> str:
        return parameters_hash(self.atmosphere, self.settings)

    @property
    def channel_names(self):
        return CHANNEL_NAMES[self.settings.channels]

    def radiance(self, altitude, cos_view, cos_sun, cos_scatter, backend="opencl", engine=None):
        """Radiance r, g, b for arbitrary geometry (see :meth:`clsky.lookup.TableLookupEngine.radiance`).

        Parameters
        ----------
        altitude : array_like
            Observer altitude [m], >= 0.
        cos_view, cos_sun, cos_scatter : array_like
            Cosines of the view zenith, sun zenith and scattering angle.
        backend : {'opencl', 'numpy'}
        engine : TableLookupEngine, optional
            Reused across calls to avoid rebuilding (OpenCL backend).
        """
        check_queries(altitude, cos_view, cos_sun, cos_scatter)
        if backend == "numpy":
            from . import reference

            return reference.lookup(self.atmosphere, self.data, altitude, cos_view, cos_sun, cos_scatter,
                                    self.settings.mapping, self.settings.sun_cos_range)
        if backend != "opencl":
            raise ValueError(f"backend must be one of {list(BACKENDS)}, got {backend!r}")
        from .lookup import TableLookupEngine

        engine = engine or TableLookupEngine(dtype=self.settings.dtype)
        return engine.radiance(self.atmosphere, self.data, altitude, cos_view, cos_sun, cos_scatter,
                               self.settings.mapping, self.settings.sun_cos_range)

    # Files ----------------------------------------------------------------------------------------
    def save(self, path, overwrite=False):
        """Write the table to ``path`` (.npz) atomically; never overwrites unless ``overwrite``."""
        path = pathlib.Path(path)
        if path.suffix != ".npz":
            raise ValueError(f"path must end in .npz, got {str(path)!r}")
        with atomic_write(path, overwrite) as temporary:
            with open(temporary, "wb") as stream:
                orders = {f"order_{k}": np.asarray(order, dtype=np.float32)
                          for k, order in enumerate(self.orders, start=1)}
                np.savez(
                    stream, data=self.data, format_version=np.int64(FORMAT_VERSION),
                    atmosphere=json.dumps(self.atmosphere.to_dict()),
                    settings=json.dumps(self.settings.to_dict()),
                    metadata=json.dumps(self.metadata), orders_record=json.dumps(self.orders_record),
                    parameters_hash=self.parameters_hash, **orders,
                    **({} if self.gathered is None else {"gathered": self.gathered}))
        return path

    @classmethod
    def load(cls, path) -> "ScatteringTable":
        """Read a table written by :meth:`save`; TableFormatError if it is not one clsky can trust."""
        path = pathlib.Path(path)
        try:
            with np.load(path, allow_pickle=False) as archive:
                contents = {key: archive[key] for key in archive.files}
        except (OSError, ValueError) as error:
            raise TableFormatError(f"{path} is not a clsky table file: {error}") from error
        required = {"data", "format_version", "atmosphere", "settings", "metadata", "parameters_hash",
                    "orders_record"}
        missing = required - set(contents)
        if missing:
            raise TableFormatError(f"{path} is not a clsky table file (missing {sorted(missing)})")
        version = int(contents["format_version"])
        if version != FORMAT_VERSION:
            raise TableFormatError(f"{path} has table format version {version}; this clsky reads "
                                   f"version {FORMAT_VERSION} (rebuild the table with `clsky table`)")
        try:
            atmosphere = AtmosphereParameters.from_dict(json.loads(str(contents["atmosphere"])))
            settings = TableSettings.from_dict(json.loads(str(contents["settings"])))
        except (ValueError, TypeError) as error:
            raise TableFormatError(f"{path} holds invalid parameters: {error}") from error
        if parameters_hash(atmosphere, settings) != str(contents["parameters_hash"]):
            raise TableFormatError(f"{path}: parameters hash does not match its parameters (corrupted "
                                   f"or edited file)")
        orders = tuple(contents[f"order_{k}"] for k in range(1, len(contents) + 1) if f"order_{k}" in contents)
        return cls(atmosphere, settings, contents["data"], json.loads(str(contents["metadata"])), orders,
                   json.loads(str(contents["orders_record"])), contents.get("gathered"))

    def export_raw(self, path, overwrite=False):
        """Write ``<path>.bin`` (float32 values) and ``<path>.json`` (layout header) for GPU engines.

        Returns the two paths. Both are written atomically; existing files are kept unless
        ``overwrite``.
        """
        path = pathlib.Path(path)
        binary, header = path.with_suffix(".bin"), path.with_suffix(".json")
        for target in (binary, header):
            if target.exists() and not overwrite:
                raise FileExistsError(f"{target} exists (use overwrite=True, or --force on the command line)")
        width, height, depth = self.settings.size
        channels = self.settings.channels
        description = {
            "format": "clsky raw scattering table",
            "format_version": FORMAT_VERSION,
            "dtype": "float32",
            "byte_order": "little",
            "binary": binary.name,
            "size": {"W": width, "H": height, "D": depth, "channels": channels},
            "layout": ("values[(x + y*W + z*W*H) * channels + c]; x: altitude node, y: view-zenith node, "
                       "z: sun-zenith node, c: channel"),
            "channels": list(self.channel_names),
            "mapping": self.settings.mapping,
            "mapping_formulas": {
                "nonlinear": {"u": "sqrt(h/Ha)", "v": "0.5*(1+sign(cos_view)*|cos_view|^(1/3))",
                              "w": "0.5*(1+sign(cos_sun)*|cos_sun|^(1/3))"},
                "linear": {"u": "h/Ha", "v": "0.5*(cos_view+1)", "w": "0.5*(cos_sun+1)"},
                "nodes": "u = x/(W-1), v = y/(H-1), w = w_low + (w_high - w_low) * z/(D-1)",
            },
            "sun_cos_range": list(self.settings.sun_cos_range),
            "sun_w_range": {"w_low": self.settings.sun_w_range[0], "w_high": self.settings.sun_w_range[1]},
            "radiance": ("I = I_I * (F_R(cos theta) * Ibar_R + F_M(cos theta) * Ibar_M [+ multiple]), "
                         "all channels interpolated trilinearly in (u, v, w); the multiple_* channels "
                         "(physical mode) already include their phase"),
            "orders_record": self.orders_record,
            "incident_light": list(self.atmosphere.incident_light),
            "atmosphere": self.atmosphere.to_dict(),
            "settings": self.settings.to_dict(),
            "parameters_hash": self.parameters_hash,
            "metadata": self.metadata,
        }
        with atomic_write(binary, overwrite) as temporary:
            self.data.astype("<f4").tofile(temporary)
        with atomic_write(header, overwrite) as temporary:
            temporary.write_text(json.dumps(description, indent=2) + "\n")
        return binary, header
