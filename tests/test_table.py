"""ScatteringTable as a product: build, save/load round trip, refusals, raw export, atomic writes."""

import json

import numpy as np
import pytest
from numpy.testing import assert_allclose

from clsky import ScatteringTable, TableFormatError, TableSettings
from clsky.table import FORMAT_VERSION, array_checksum

from conftest import black_preset

SETTINGS = TableSettings(size=(8, 16, 6))


@pytest.fixture(scope="module")
def table():
    return ScatteringTable.build(black_preset("physical"), SETTINGS)


def test_opencl_and_numpy_backends_agree(table):
    twin = ScatteringTable.build(black_preset("physical"), SETTINGS, backend="numpy")
    # kernel vs twin, see test_single_twin.py for the justification of 1e-12
    np.testing.assert_allclose(table.data, twin.data, rtol=1e-12, atol=1e-14 * twin.data.max())


def test_notes_layout_averages_mie(table):
    notes = ScatteringTable.build(black_preset("physical"), SETTINGS.replace(mie_layout="notes"))
    assert notes.data.shape == (6, 16, 8, 4)
    np.testing.assert_array_equal(notes.data[..., :3], table.data[..., :3])
    np.testing.assert_allclose(notes.data[..., 3], table.data[..., 3:].mean(axis=-1), rtol=1e-15)


def test_save_load_round_trip(table, tmp_path):
    path = table.save(tmp_path / "sky.npz")
    loaded = ScatteringTable.load(path)
    np.testing.assert_array_equal(loaded.data, table.data)
    assert loaded.atmosphere == table.atmosphere
    assert loaded.settings == table.settings
    assert loaded.parameters_hash == table.parameters_hash
    assert loaded.metadata["backend"] == "opencl"


def test_save_never_overwrites_silently(table, tmp_path):
    path = table.save(tmp_path / "sky.npz")
    before = path.read_bytes()
    other = ScatteringTable.build("atmosphere-plus", SETTINGS)
    with pytest.raises(FileExistsError, match="exists"):
        other.save(path)
    assert path.read_bytes() == before
    other.save(path, overwrite=True)
    assert ScatteringTable.load(path).atmosphere == black_preset("atmosphere-plus")


def test_interrupted_save_leaves_no_file(table, tmp_path, monkeypatch):
    def fail(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(np, "savez", fail)
    with pytest.raises(KeyboardInterrupt):
        table.save(tmp_path / "sky.npz")
    assert list(tmp_path.iterdir()) == []


def rewrite(path, **changes):
    """Edit members of a saved table and recompute its checksums (as a deliberate edit would), so that
    the check under test, not the checksum, is what refuses it."""
    with np.load(path) as archive:
        contents = {key: archive[key] for key in archive.files}
    contents.update(changes)
    contents["checksums"] = json.dumps({name: array_checksum(np.asarray(value))
                                        for name, value in contents.items() if name != "checksums"})
    np.savez(path, **contents)


def test_wrong_version_is_refused(table, tmp_path):
    path = table.save(tmp_path / "sky.npz")
    rewrite(path, format_version=np.int64(FORMAT_VERSION + 1))
    with pytest.raises(TableFormatError, match="version"):
        ScatteringTable.load(path)


def test_format_4_file_asks_for_a_rebuild(table, tmp_path):
    """A file saved before azimuth_harmonics (format 4, settings without it) is refused as an older
    format to rebuild, not as a corrupted file (its parameters hash is of the old settings)."""
    path = table.save(tmp_path / "sky.npz")
    settings = {key: value for key, value in table.settings.to_dict().items() if key != "azimuth_harmonics"}
    rewrite(path, format_version=np.int64(4), settings=json.dumps(settings))
    with pytest.raises(TableFormatError, match=r"table format version 4; this clsky reads version 5 "
                                               r"\(rebuild the table with `clsky table`\)"):
        ScatteringTable.load(path)


def test_wrong_shape_is_refused(table, tmp_path):
    path = table.save(tmp_path / "sky.npz")
    rewrite(path, data=table.data[:, :, :-1])
    with pytest.raises(TableFormatError, match="shape"):
        ScatteringTable.load(path)


def test_edited_parameters_are_refused(table, tmp_path):
    path = table.save(tmp_path / "sky.npz")
    atmosphere = table.atmosphere.to_dict() | {"mie_g": -0.7}
    rewrite(path, atmosphere=json.dumps(atmosphere))
    with pytest.raises(TableFormatError, match="hash"):
        ScatteringTable.load(path)


def test_not_a_table_is_refused(tmp_path):
    path = tmp_path / "junk.npz"
    path.write_bytes(b"not a zip file")
    with pytest.raises(TableFormatError, match="not a clsky table"):
        ScatteringTable.load(path)


def test_raw_export_layout(table, tmp_path):
    binary, header = table.export_raw(tmp_path / "sky")
    description = json.loads(header.read_text())
    values = np.fromfile(binary, dtype="<f4")
    size = description["size"]
    w, h, d, c = size["W"], size["H"], size["D"], size["channels"]
    assert (w, h, d, c) == (8, 16, 6, 6)
    assert values.size == w * h * d * c
    # index i = x + y W + z W H, channels innermost
    x, y, z, channel = 5, 11, 3, 4
    assert values[(x + y * w + z * w * h) * c + channel] == np.float32(table.data[z, y, x, channel])
    assert description["channels"][channel] == "mie_g"
    assert description["parameters_hash"] == table.parameters_hash
    with pytest.raises(FileExistsError):
        table.export_raw(tmp_path / "sky")


@pytest.mark.parametrize("name", ["physical", "atmosphere-plus"])
def test_raw_export_says_what_its_phase_functions_are(name, cl_context, tmp_path):
    """The raw header named F_R and F_M without saying what they are: their formulas (no 1/(4 pi)), what c
    is, and the sign of g, which with the usual 1 + g^2 - 2 g c puts the Mie peak opposite the sun. The
    header's formulas, evaluated as written (^ as a power, juxtaposition as a product), are clsky's phase
    functions to rounding, and their Mie peak is toward the sun."""
    import re

    from clsky.phase import mie_phase, rayleigh_phase

    atmosphere = black_preset(name)
    mode = "physical" if name == "physical" else "atmosphere-plus"
    table = ScatteringTable.build(atmosphere, SETTINGS.replace(mode=mode, orders=1), ctx=cl_context)
    _, header = table.export_raw(tmp_path / "sky")
    phases = json.loads(header.read_text())["phase_functions"]
    assert phases["g"] == atmosphere.mie_g and "no 1/(4 pi)" in phases["normalization"]

    def evaluated(formula, c, g):
        code = re.sub(r"\)\s*\(", ")*(", formula.replace("^", "**"))
        code = re.sub(r"(\d)\s*\(", r"\1*(", code)
        code = re.sub(r"(\d|\))\s+([cg])\b", r"\1*\2", code)
        code = re.sub(r"\b([cg])\s+([cg(])", r"\1*\2", code)
        return eval(code, {"c": c, "g": g})

    c = np.linspace(-1.0, 1.0, 41)
    assert_allclose(evaluated(phases["F_R"], c, atmosphere.mie_g), rayleigh_phase(atmosphere, c), rtol=1e-14)
    mie = evaluated(phases["F_M"], c, atmosphere.mie_g)
    assert_allclose(mie, mie_phase(atmosphere, c), rtol=1e-14)
    assert np.argmax(mie) == c.size - 1 and "g < 0 peaks toward the sun" in phases["sign_of_g"]


def test_invalid_build_arguments(table):
    with pytest.raises(ValueError, match="backend"):
        ScatteringTable.build(black_preset("physical"), SETTINGS, backend="cuda")
    with pytest.raises(ValueError, match="preset"):
        ScatteringTable.build("mars", SETTINGS)
    with pytest.raises(ValueError, match=r"\.npz"):
        table.save("sky.txt")


def test_a_tables_arrays_are_read_only_once_checked(table):
    """table.data[...] = -5 after the checks reached the lookups as negative radiance (the renderers read
    the host table for each frame's slice): the arrays are read-only views, the caller's own array keeps
    its flags, and a table made from edited arrays is checked again."""
    import dataclasses

    for array in (table.data, table.gathered, *table.orders):
        assert not array.flags.writeable
        with pytest.raises(ValueError, match="read-only"):
            array[...] = -5.0
    own = np.array(table.data)
    copy = dataclasses.replace(table, data=own)
    assert own.flags.writeable and not copy.data.flags.writeable
    np.testing.assert_array_equal(copy.data, table.data)
    with pytest.raises(TableFormatError, match="negative"):
        dataclasses.replace(table, data=-own)
    # pickled and deep-copied tables skip __post_init__: theirs are read-only too
    import copy
    import pickle

    for twin in (pickle.loads(pickle.dumps(table)), copy.deepcopy(table)):
        assert not any(array.flags.writeable for array in (twin.data, twin.gathered, *twin.orders))
        np.testing.assert_array_equal(twin.data, table.data)
