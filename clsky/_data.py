"""The data files shipped in ``clsky/data/``: one reader that checks a file before anything uses it.

Each file is a small CSV of wavelength bins: ``#`` comment lines (source and licence), a header line
``wavelength_min_nm,wavelength_max_nm,<value column>``, then one row per bin [lower, upper) nm with
the bin's mean value (the ozone cross-sections of :mod:`clsky.ozone`, the solar spectrum of
:mod:`clsky.solar`). :func:`read_binned_table` refuses, with a :class:`DataFileError` naming the file
and line, a file whose header or column count differs, whose numbers do not parse or are not finite,
whose bins are not increasing and contiguous, or whose values are negative: a damaged or edited
installation fails at the first read, never as a NaN in a kernel.
"""

from __future__ import annotations

import importlib.resources
import math
import pathlib

import numpy as np

from .errors import as_real_array, short

__all__ = ["DataFileError", "read_binned_table", "interpolate_bin_centres", "BIN_COLUMNS"]

#: The first two columns of every binned file: the bin's edges [nm].
BIN_COLUMNS = ("wavelength_min_nm", "wavelength_max_nm")


class DataFileError(ValueError):
    """A shipped data file that clsky must not use (malformed header, row or value)."""


def _text(source) -> tuple:
    """(text, name for messages) of a file inside the clsky package (a str such as
    ``"data/x.csv"``) or at a filesystem path (a :class:`pathlib.Path`)."""
    if isinstance(source, pathlib.Path):
        path = source
    else:
        path = importlib.resources.files("clsky").joinpath(source)
    try:
        return path.read_text(encoding="utf-8"), str(path)
    except (OSError, UnicodeDecodeError) as error:
        raise DataFileError(f"{path}: cannot be read ({error})") from None


def read_binned_table(source, value_column: str):
    """The bins of a shipped data file: (lower edge [nm], upper edge [nm], values), read-only arrays.

    Parameters
    ----------
    source : str or pathlib.Path
        A file inside the clsky package (e.g. ``"data/solar_irradiance_astm_g173_etr_10nm.csv"``), or
        a path (tests feed malformed files this way).
    value_column : str
        The expected name of the third column (its unit is in the name and the file's comments).

    Returns
    -------
    (numpy.ndarray, numpy.ndarray, numpy.ndarray)
        Lower edges, upper edges and values, float64, one per bin.

    Raises
    ------
    DataFileError
        If the header is not ``wavelength_min_nm,wavelength_max_nm,<value_column>``; a row does not
        have 3 fields or a field is not a finite number; the file has no row; a bin is empty or
        reversed (upper <= lower), or does not start where the previous one ended; or a value is
        negative. The message names the file and its line.

    Examples
    --------
    >>> low, high, values = read_binned_table("data/solar_irradiance_astm_g173_etr_10nm.csv",
    ...                                       "irradiance_w_m2_nm")
    >>> float(low[0]), float(high[-1]), len(values)
    (360.0, 840.0, 48)
    """
    text, name = _text(source)
    expected = BIN_COLUMNS + (value_column,)
    lines = [(number, line.strip()) for number, line in enumerate(text.splitlines(), start=1)
             if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        raise DataFileError(f"{name}: no header line (expected {','.join(expected)})")
    number, header = lines[0]
    if tuple(field.strip() for field in header.split(",")) != expected:
        raise DataFileError(f"{name}, line {number}: header {header!r}, expected {','.join(expected)!r}")
    if len(lines) == 1:
        raise DataFileError(f"{name}: no data rows after the header")
    rows = []
    for number, line in lines[1:]:
        fields = line.split(",")
        if len(fields) != len(expected):
            raise DataFileError(f"{name}, line {number}: {len(fields)} fields, expected {len(expected)} "
                                f"({','.join(expected)})")
        try:
            values = [float(field) for field in fields]
        except ValueError:
            raise DataFileError(f"{name}, line {number}: not a number in {line!r}") from None
        if not all(math.isfinite(v) for v in values):
            raise DataFileError(f"{name}, line {number}: a value is not finite in {line!r}")
        low, high, value = values
        if not high > low:
            raise DataFileError(f"{name}, line {number}: bin [{low:g}, {high:g}) is empty or reversed")
        if rows and low != rows[-1][1]:
            raise DataFileError(f"{name}, line {number}: bin starts at {low:g} nm, the previous one ended at "
                                f"{rows[-1][1]:g} nm")
        if value < 0.0:
            raise DataFileError(f"{name}, line {number}: {value_column} {value:g} is negative")
        rows.append(values)
    data = np.array(rows, dtype=np.float64)
    columns = tuple(np.ascontiguousarray(column) for column in data.T)
    for column in columns:
        column.setflags(write=False)
    return columns


def interpolate_bin_centres(table, wavelengths_nm, what: str):
    """Values of a binned table at given wavelengths: each bin's mean read as the value at the bin's
    centre, linear interpolation in wavelength between centres.

    Parameters
    ----------
    table : (numpy.ndarray, numpy.ndarray, numpy.ndarray)
        Lower edges [nm], upper edges [nm] and values, as :func:`read_binned_table` returns them.
    wavelengths_nm : array_like
        Wavelengths [nm], between the first and the last bin centre.
    what : str
        What the values are, for the message (e.g. "the solar spectrum").

    Returns
    -------
    numpy.ndarray
        The interpolated values, float64, one per wavelength.

    Raises
    ------
    ValueError
        For a wavelength that is not finite or lies outside [first centre, last centre].

    Examples
    --------
    >>> table = (np.array([360.0, 370.0]), np.array([370.0, 380.0]), np.array([1.0, 3.0]))
    >>> interpolate_bin_centres(table, [365.0, 370.0], "x").tolist()
    [1.0, 2.0]
    """
    low, high, values = table
    centres = 0.5 * (low + high)
    wavelengths = as_real_array("wavelengths", wavelengths_nm, f"wavelengths [nm] for {what}")
    outside = ~(np.isfinite(wavelengths) & (wavelengths >= centres[0]) & (wavelengths <= centres[-1]))
    if np.any(outside):             # the first one outside: a 1 nm grid's whole array filled the message
        raise ValueError(f"wavelengths must be in [{centres[0]:g}, {centres[-1]:g}] nm for {what}, got "
                         f"{short(wavelengths[outside].flat[0])} ({int(outside.sum())} of {wavelengths.size} "
                         f"outside)")
    return np.interp(wavelengths, centres, values)
