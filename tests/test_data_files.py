"""The shipped data files (clsky/data/*.csv) and their one reader, clsky._data.read_binned_table: the
files read as NumPy's own CSV parser reads them, and every malformed variant is refused with a
DataFileError naming the file and the line, before any value is used."""

from __future__ import annotations

import pathlib

import numpy as np
import pytest

from clsky import ozone, solar
from clsky._data import DataFileError, read_binned_table

DATA = pathlib.Path(ozone.__file__).parent / "data"
FILES = {"solar": (solar.SOLAR_SPECTRUM_FILE, "irradiance_w_m2_nm", solar.solar_spectrum_table),
         "ozone": (ozone.CROSS_SECTION_FILE, "cross_section_m2", ozone.cross_section_table)}
HEADER = "wavelength_min_nm,wavelength_max_nm,value"


@pytest.mark.parametrize("name", sorted(FILES))
def test_shipped_files_read_as_numpy_reads_them(name):
    """The reader against np.loadtxt (an independent parser) on the shipped file: the same 48 bins of
    10 nm from 360 to 840 nm, bit for bit; the module's table is that, read-only."""
    path, column, table = FILES[name]
    file = DATA / pathlib.Path(path).name
    expected = np.loadtxt(file, delimiter=",", comments="#", skiprows=_header_line(file), encoding="utf-8")
    low, high, values = read_binned_table(path, column)
    assert np.array_equal(np.stack([low, high, values], axis=1), expected)
    assert len(values) == 48 and np.all(high - low == 10.0) and low[0] == 360.0 and high[-1] == 840.0
    for got, want in zip(table(), (low, high, values)):
        assert np.array_equal(got, want) and not got.flags.writeable


def _header_line(path):
    """Lines up to and including the header (comments first), for np.loadtxt's skiprows."""
    lines = path.read_text(encoding="utf-8").splitlines()
    return next(i for i, line in enumerate(lines) if line.startswith("wavelength_min_nm")) + 1


#: (file text, words the message must hold): each one malformed in one way.
MALFORMED = {
    "empty": ("", "no header"),
    "comments only": ("# source\n# licence\n", "no header"),
    "header only": (f"# source\n{HEADER}\n", "no data rows"),
    "wrong header name": ("wavelength_nm,wavelength_max_nm,value\n360,370,1\n", "line 1: header"),
    "two columns": ("wavelength_min_nm,wavelength_max_nm\n360,370\n", "line 1: header"),
    "short row": (f"{HEADER}\n360,370,1\n370,380\n", "line 3: 2 fields, expected 3"),
    "long row": (f"{HEADER}\n360,370,1,5\n", "line 2: 4 fields, expected 3"),
    "text value": (f"{HEADER}\n360,370,one\n", "line 2: not a number"),
    "empty field": (f"{HEADER}\n360,,1\n", "line 2: not a number"),
    "nan": (f"{HEADER}\n360,370,nan\n", "line 2: a value is not finite"),
    "inf edge": (f"{HEADER}\n360,inf,1\n", "line 2: a value is not finite"),
    "reversed bin": (f"{HEADER}\n370,360,1\n", "line 2: bin [370, 360) is empty or reversed"),
    "empty bin": (f"{HEADER}\n360,360,1\n", "is empty or reversed"),
    "gap": (f"{HEADER}\n360,370,1\n380,390,1\n", "line 3: bin starts at 380 nm, the previous one ended at 370"),
    "overlap": (f"{HEADER}\n360,370,1\n365,375,1\n", "line 3: bin starts at 365 nm"),
    "out of order": (f"{HEADER}\n370,380,1\n360,370,1\n", "line 3: bin starts at 360 nm"),
    "negative value": (f"# c\n{HEADER}\n360,370,-1e-27\n", "line 3: value -1e-27 is negative"),
}


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_malformed_files_are_refused_naming_file_and_line(tmp_path, case):
    text, words = MALFORMED[case]
    path = tmp_path / "bins.csv"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(DataFileError) as error:
        read_binned_table(path, "value")
    assert str(path) in str(error.value) and words in str(error.value), str(error.value)
    assert isinstance(error.value, ValueError)


def test_unreadable_files_are_refused(tmp_path):
    missing = tmp_path / "missing.csv"
    with pytest.raises(DataFileError, match="missing.csv: cannot be read"):
        read_binned_table(missing, "value")
    binary = tmp_path / "binary.csv"
    binary.write_bytes(b"\xff\xfe\x00bins")
    with pytest.raises(DataFileError, match="binary.csv: cannot be read"):
        read_binned_table(binary, "value")


def test_a_good_file_with_spaces_and_blank_lines_reads():
    """The format's slack: blank lines and spaces around fields are allowed; comments anywhere."""
    import tempfile

    with tempfile.TemporaryDirectory() as directory:
        path = pathlib.Path(directory) / "bins.csv"
        path.write_text(f"# source\n\n {HEADER.replace(',', ' , ')}\n360, 370, 1.5\n# note\n370,380,0\n\n",
                        encoding="utf-8")
        low, high, values = read_binned_table(path, "value")
    assert low.tolist() == [360.0, 370.0] and high.tolist() == [370.0, 380.0] and values.tolist() == [1.5, 0.0]


def test_interpolate_bin_centres_reads_each_bin_at_its_centre():
    """The shipped tables' one interpolation (ozone cross-sections, solar spectrum): at a bin centre the
    bin's value exactly; halfway between two centres their mean (one rounding: 1 ulp); outside the
    centres' range, or NaN, a ValueError naming the range and what was asked for."""
    from clsky._data import interpolate_bin_centres

    table = read_binned_table("data/solar_irradiance_astm_g173_etr_10nm.csv", "irradiance_w_m2_nm")
    low, high, values = table
    centres = 0.5 * (low + high)
    assert interpolate_bin_centres(table, centres, "the solar spectrum").tolist() == values.tolist()
    halfway = interpolate_bin_centres(table, high[:-1], "the solar spectrum")
    np.testing.assert_allclose(halfway, 0.5 * (values[:-1] + values[1:]), rtol=2.0 ** -52, atol=0.0)
    for outside in (centres[0] - 0.5, centres[-1] + 0.5, float("nan")):
        with pytest.raises(ValueError, match=r"wavelengths must be in \[365, 835\] nm for the solar spectrum"):
            interpolate_bin_centres(table, [outside], "the solar spectrum")
    # a 1 nm grid from 360 nm: the first value outside and a count, not the 471 values (a 50-line message)
    with pytest.raises(ValueError, match=r"for the solar spectrum, got 360 \(5 of 471 outside\)$"):
        interpolate_bin_centres(table, np.arange(360.0, 831.0), "the solar spectrum")
