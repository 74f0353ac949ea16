"""The constants clsky takes from colour-science, kept in a small file so that a run need not import it.

clsky uses three things of colour-science (Mansencal et al.): the CIE 1931 2-degree colour-matching
functions (``colour.MSDS_CMFS``; :mod:`clsky.colorimetry`), Oklab's two matrices
(``colour.models.oklab``; the display's gamut mapping) and the chromatic adaptation transforms' cone
response matrices (``colour.CHROMATIC_ADAPTATION_TRANSFORMS``; the display's white balance). All are
constants, but ``import colour`` (0.4.7) also imports its plotting module, matplotlib, pandas and SciPy's
interpolation: 0.9-1.0 s of one core on the 2-core machine after clsky's own imports, in every ``clsky
render`` or ``clsky animate`` (docs/speed-log.md, "colour-science's constants kept on disk").

So the first run imports colour-science, takes the constants from it and writes them to
``colour-science-<version>.npz`` in clsky's cache directory (:mod:`clsky._cache`:
``$XDG_CACHE_HOME/clsky`` or ``~/.cache/clsky``; the version of the installed colour-science, read from
its metadata without importing it, so that an upgrade writes a new file); later runs read that file (a
few milliseconds). The file is written atomically under a unique temporary name, so concurrent first runs
leave one writer's whole file. It is validated before use: the exact set of arrays, their dtypes and
shapes, finite values, increasing wavelengths, the version, and a SHA-256 digest of all the arrays' bytes;
a file that fails any check is ignored and rewritten. Where no cache directory can be written the
constants come from colour-science in every run, as before this module. The values are colour-science's,
bit for bit (tests/test_colour_constants.py compares them with the live package).

Examples
--------
>>> wavelengths, cmfs = cie_1931_cmfs()
>>> float(wavelengths[0]), float(wavelengths[-1]), cmfs.shape
(360.0, 830.0, (471, 3))
>>> adaptation_transform("cat02").shape
(3, 3)
"""

from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import pathlib
import zipfile

import numpy as np

from ._cache import cache_directory, store
from .errors import ParameterError

__all__ = ["CMFS_NAME", "cie_1931_cmfs", "oklab_matrices", "adaptation_transform", "adaptation_transform_names",
           "cache_path"]

#: The colour-matching functions used (colour-science's name).
CMFS_NAME = "CIE 1931 2 Degree Standard Observer"
#: Layout of the cached file; a file of another format is rewritten.
_FORMAT = 1
#: The arrays of a cached file and their dtype kinds; the digest covers all the others, in this order.
_ARRAYS = {"format": "i", "version": "U", "cmfs_wavelengths": "f", "cmfs_values": "f", "oklab_xyz_to_lms": "f",
           "oklab_lms_to_lab": "f", "adaptation_names": "U", "adaptation_matrices": "f", "digest": "u"}


def colour_science_version() -> str:
    """The installed colour-science's version, from its metadata (without importing it)."""
    return importlib.metadata.version("colour-science")


def cache_path(version: str | None = None) -> pathlib.Path | None:
    """Where the constants of colour-science ``version`` (default: the installed one) are kept
    (:func:`clsky._cache.cache_directory`); None where there is no cache directory."""
    directory = cache_directory()
    return None if directory is None else directory / f"colour-science-{version or colour_science_version()}.npz"


def _digest(arrays: dict) -> np.ndarray:
    sha = hashlib.sha256()
    for name in _ARRAYS:
        if name != "digest":
            value = np.ascontiguousarray(arrays[name])
            sha.update(f"{name}:{value.dtype.str}:{value.shape}".encode())
            sha.update(value.tobytes())
    return np.frombuffer(sha.digest(), dtype=np.uint8).copy()


def _from_colour_science() -> dict:
    """The constants, from an import of colour-science, labelled with the imported package's version
    (``colour.__version__``). Its import sets NumPy's printing to 1.13's for the whole process
    (``np.set_printoptions(legacy="1.13")`` in colour/__init__.py, 0.4.x): it is imported inside
    ``np.printoptions()``, which puts back the caller's options, so that using clsky does not change how
    the user's arrays print."""
    with np.printoptions():
        import colour
        from colour.models import oklab

    cmfs = colour.MSDS_CMFS[CMFS_NAME]
    names = sorted(colour.CHROMATIC_ADAPTATION_TRANSFORMS)
    arrays = {"format": np.array(_FORMAT), "version": np.array(str(getattr(colour, "__version__", ""))),
              "cmfs_wavelengths": np.array(cmfs.wavelengths, dtype=np.float64),
              "cmfs_values": np.array(cmfs.values, dtype=np.float64),
              "oklab_xyz_to_lms": np.array(oklab.MATRIX_1_XYZ_TO_LMS, dtype=np.float64),
              "oklab_lms_to_lab": np.array(oklab.MATRIX_2_LMS_TO_LAB, dtype=np.float64),
              "adaptation_names": np.array(names),
              "adaptation_matrices": np.array([colour.CHROMATIC_ADAPTATION_TRANSFORMS[n] for n in names],
                                              dtype=np.float64)}
    arrays["digest"] = _digest(arrays)
    return arrays


def _valid(arrays: dict, version: str) -> bool:
    """Whether ``arrays`` (read from a file) are a whole, untouched set for ``version``."""
    if set(arrays) != set(_ARRAYS) or any(arrays[name].dtype.kind != kind for name, kind in _ARRAYS.items()):
        return False
    if arrays["cmfs_wavelengths"].ndim != 1 or arrays["adaptation_names"].ndim != 1:
        return False
    n, k = len(arrays["cmfs_wavelengths"]), len(arrays["adaptation_names"])
    shapes = {"format": (), "version": (), "cmfs_wavelengths": (n,), "cmfs_values": (n, 3),
              "oklab_xyz_to_lms": (3, 3), "oklab_lms_to_lab": (3, 3), "adaptation_names": (k,),
              "adaptation_matrices": (k, 3, 3), "digest": (32,)}
    if n < 2 or k < 1 or any(arrays[name].shape != shape for name, shape in shapes.items()):
        return False
    reals = [arrays[name] for name, kind in _ARRAYS.items() if kind == "f"]
    if any(value.dtype != np.float64 or not np.isfinite(value).all() for value in reals):
        return False
    return (int(arrays["format"]) == _FORMAT and str(arrays["version"]) == version
            and np.array_equal(arrays["digest"], _digest(arrays)) and _plausible(arrays))


#: What colour-science's CIE 1931 2-degree functions are: 1 nm from 360 to 830 nm, each function's sum
#: (its integral at 1 nm) 106.86, 106.86 and 106.89 (colour-science 0.4.x). A file holding others is no
#: copy of them, whatever its digest (which the file itself holds: it finds damage, not a wrong table).
_CMFS_WAVELENGTHS = np.arange(360.0, 831.0)
_CMFS_SUMS = (106.865, 106.857, 106.892)


def _plausible(arrays: dict) -> bool:
    """Whether the constants are colour-science's kind of values: its CMFs' wavelengths, non-negative
    functions with their sums within 0.1 %, and invertible 3 x 3 matrices (Oklab's, the adaptations'). A
    self-consistent file of negated CMFs or zero matrices was used, and every render failed after its
    table with a message about sun_white or a singular matrix."""
    values = arrays["cmfs_values"]
    matrices = [arrays["oklab_xyz_to_lms"], arrays["oklab_lms_to_lab"], *arrays["adaptation_matrices"]]
    return (np.array_equal(arrays["cmfs_wavelengths"], _CMFS_WAVELENGTHS) and bool(np.all(values >= 0.0))
            and np.allclose(values.sum(axis=0), _CMFS_SUMS, rtol=1e-3, atol=0.0)
            and all(abs(np.linalg.det(matrix)) > 1e-3 for matrix in matrices))


#: The largest constants file read [bytes] (it takes 19 kB).
_MAX_BYTES = 2**20


def _read(path: pathlib.Path, version: str):
    """The arrays of the file at ``path`` if it is a valid set for ``version``, else None."""
    try:
        if not path.is_file() or path.stat().st_size > _MAX_BYTES:   # a FIFO there blocked np.load for ever
            return None
        with zipfile.ZipFile(path) as archive:       # what the members inflate to, before any is read:
            if sum(info.file_size for info in archive.infolist()) > _MAX_BYTES:   # 400 kB of zeros took 382 MiB
                return None
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: data[name] for name in data.files}
        return arrays if _valid(arrays, version) else None
    except Exception:                       # missing, unreadable, or damaged (zipfile.BadZipFile, zlib.error, ...)
        return None


@functools.lru_cache(maxsize=1)
def _constants() -> dict:
    version = colour_science_version()
    path = cache_path(version)
    arrays = None if path is None else _read(path, version)
    if arrays is None:
        arrays = _from_colour_science()
        # kept only when the imported colour-science is the installed distribution (not another copy
        # earlier on the path): the file's name and label say which version its values are; and only values
        # the reader takes (another version's of another kind would be written, refused, and recomputed
        # every run)
        if path is not None and str(arrays["version"]) == version and _plausible(arrays):
            store(path, lambda file: np.savez(file, **arrays))
    for value in arrays.values():
        value.setflags(write=False)
    return arrays


def cie_1931_cmfs():
    """(wavelengths [nm], values (n, 3)) of colour-science's CIE 1931 2-degree colour-matching functions
    (:data:`CMFS_NAME`: 1 nm from 360 to 830 nm), read-only float64."""
    arrays = _constants()
    return arrays["cmfs_wavelengths"], arrays["cmfs_values"]


def oklab_matrices():
    """(M1: XYZ -> LMS, M2: LMS' -> Lab) of Oklab (Ottosson 2020) as colour-science has them, read-only."""
    arrays = _constants()
    return arrays["oklab_xyz_to_lms"], arrays["oklab_lms_to_lab"]


def adaptation_transform_names() -> tuple:
    """The names of colour-science's chromatic adaptation transforms (``CAT02``, ``Bradford``, ...)."""
    return tuple(str(name) for name in _constants()["adaptation_names"])


def adaptation_transform(name: str) -> np.ndarray:
    """The XYZ -> cone response matrix of the chromatic adaptation transform ``name`` (case-insensitive,
    as colour-science matches it), read-only; ParameterError for an unknown name."""
    names = adaptation_transform_names()
    lower = [n.lower() for n in names]
    if not isinstance(name, str) or name.lower() not in lower:
        raise ParameterError("transform", "one of " + ", ".join(names), name)
    return _constants()["adaptation_matrices"][lower.index(name.lower())]
