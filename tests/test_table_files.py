"""Table files are trusted only if they are what they say (issue 9, class 2), and no kernel gets a
buffer of the wrong size.

1. Round trip: save then load gives back every array bit for bit (both modes).
2. Damaged files: empty, truncated, flipped bytes (payload, headers, every 37th byte), a .npy renamed
   .npz, not a file: TableFormatError naming the file, never EOFError, BadZipFile, ...
3. Edited files: format_version "three" or 3.5, invalid JSON, data made negative or NaN with the
   stored checksum left as it was (the checksum refuses it) and with it recomputed (the value check
   refuses it), wrong shapes and dtypes, members missing or added, a record that miscounts the orders.
4. Construction and save apply the same checks.
5. Kernel buffers: SkyRenderer and TableLookupEngine refuse, before the launch, a table or buffer whose
   size differs from what the kernel indexes, even when the table's validation was bypassed.

The tables are tiny (4 x 8 x 4 nodes, three orders, NumPy backend): the module runs in seconds.
"""

from __future__ import annotations

import dataclasses
import json
import zipfile

import numpy as np
import pyopencl.array as cla
import pytest

from clsky import ScatteringTable, TableFormatError, TableSettings
from clsky.lookup import TableLookupEngine, check_kernel_buffer
from clsky.render import RAYMARCH_DEFAULTS, SkyRenderer
from clsky.table import FORMAT_VERSION, array_checksum, max_orders_kept

from conftest import black_preset

TINY = TableSettings(size=(4, 8, 4), orders=3, view_steps=8, sun_steps=8, transmittance_size=(8, 16),
                     gather_theta_steps=16, gather_phi_steps=8)
RAY = RAYMARCH_DEFAULTS.replace(view_steps=8, sun_steps=8, transmittance_size=(8, 16))
MODES = ("physical", "atmosphere-plus")
GRID = (4, 8, 4)      # (D, H, W) of TINY


@pytest.fixture(scope="module")
def tables():
    """mode -> a tiny table with three orders and a gathered sum (NumPy backend)."""
    return {mode: ScatteringTable.build(black_preset("physical"), TINY.replace(mode=mode), backend="numpy") for mode in MODES}


@pytest.fixture
def table(tables):
    return tables["physical"]


@pytest.fixture
def saved(table, tmp_path):
    """The physical table saved to tmp_path / 'sky.npz'."""
    return table.save(tmp_path / "sky.npz")


def members_of(path):
    with np.load(path) as archive:
        return {name: archive[name] for name in archive.files}


def rewrite(path, recompute_checksums=True, drop=(), **changes):
    """Edit a saved table's members (``changes``, without ``drop``) as a deliberate editor would:
    the checksums recomputed (the check under test is what must refuse it) unless told otherwise."""
    contents = members_of(path)
    contents.update(changes)
    for name in drop:
        del contents[name]
    if recompute_checksums:
        contents["checksums"] = json.dumps({name: array_checksum(np.asarray(value))
                                            for name, value in contents.items() if name != "checksums"})
    with open(path, "wb") as stream:
        np.savez(stream, **contents)
    return path


def refused(path, *fragments):
    """Load ``path``: it must raise TableFormatError naming the file and each of ``fragments``."""
    with pytest.raises(TableFormatError) as caught:
        ScatteringTable.load(path)
    message = str(caught.value)
    assert str(path) in message, message
    for fragment in fragments:
        assert fragment in message, message
    assert len(message) < 400, message
    return message


def assert_same_table(loaded, table):
    """Every array bit for bit (orders as their float32 copies), every parameter and record equal."""
    assert loaded.data.dtype == table.data.dtype and np.array_equal(loaded.data, table.data)
    assert loaded.gathered.dtype == table.gathered.dtype and np.array_equal(loaded.gathered, table.gathered)
    assert len(loaded.orders) == len(table.orders)
    for stored, built in zip(loaded.orders, table.orders):
        assert stored.dtype == np.float32 and np.array_equal(stored, built.astype(np.float32))
    assert loaded.atmosphere == table.atmosphere and loaded.settings == table.settings
    assert loaded.metadata == table.metadata and loaded.orders_record == table.orders_record


def data_payload_offset(path):
    """Byte offset in the file of the first value of the ``data`` member (uncompressed archive)."""
    with zipfile.ZipFile(path) as archive:
        info = archive.getinfo("data.npy")
    raw = path.read_bytes()
    name_length = int.from_bytes(raw[info.header_offset + 26:info.header_offset + 28], "little")
    extra_length = int.from_bytes(raw[info.header_offset + 28:info.header_offset + 30], "little")
    member_start = info.header_offset + 30 + name_length + extra_length
    npy_header_length = info.file_size - np.zeros(GRID + (9,)).nbytes
    return member_start, member_start + npy_header_length


def flip(path, offset):
    raw = bytearray(path.read_bytes())
    raw[offset] ^= 0xFF
    path.write_bytes(bytes(raw))


# 1. Round trip ------------------------------------------------------------------------------------

@pytest.mark.parametrize("mode", MODES)
def test_round_trip_is_bit_for_bit(tables, mode, tmp_path):
    table = tables[mode]
    loaded = ScatteringTable.load(table.save(tmp_path / "sky.npz"))
    assert_same_table(loaded, table)
    again = ScatteringTable.load(loaded.save(tmp_path / "again.npz"))
    assert_same_table(again, table)


def test_file_holds_format_version_and_a_checksum_per_member(saved):
    contents = members_of(saved)
    assert contents["format_version"].dtype == np.int64 and int(contents["format_version"]) == FORMAT_VERSION == 5
    checksums = json.loads(str(contents["checksums"]))
    assert set(checksums) == set(contents) - {"checksums"}
    assert all(checksums[name] == array_checksum(contents[name]) for name in checksums)


def test_checksum_covers_dtype_shape_and_bytes():
    values = np.arange(6.0)
    assert array_checksum(values) == array_checksum(values.copy())
    assert array_checksum(values) != array_checksum(values.astype(np.float32))
    assert array_checksum(values) != array_checksum(values.reshape(2, 3))
    edited = values.copy()
    edited[3] = np.nextafter(edited[3], 10.0)
    assert array_checksum(values) != array_checksum(edited)
    assert array_checksum(np.asfortranarray(values.reshape(2, 3))) == array_checksum(values.reshape(2, 3))


# 2. Damaged files ---------------------------------------------------------------------------------

def test_empty_file(tmp_path):
    path = tmp_path / "empty.npz"
    path.write_bytes(b"")
    refused(path, "not a clsky table file (an empty file)")


@pytest.mark.parametrize("content", [b"x", b"hello world\n", bytes(range(256)) * 8])
def test_file_that_is_no_archive_is_not_called_a_pickle(tmp_path, content):
    """numpy took any file that is neither a zip nor an .npy for a pickle: 'This file contains pickled
    (object) data. If you trust the file you can load it unsafely', advice no table file needs."""
    path = tmp_path / "text.npz"
    path.write_bytes(content)
    message = refused(path, "not an .npz archive: its first bytes are not a zip archive's")
    assert "pickle" not in message and "unsafe" not in message


@pytest.mark.parametrize("fraction", [0.0001, 0.003, 0.1, 0.5, 0.9, 0.999])
def test_truncated_file(saved, fraction):
    raw = saved.read_bytes()
    saved.write_bytes(raw[:max(1, int(len(raw) * fraction))])
    refused(saved)


@pytest.mark.parametrize("cut", [1, 22, 100])
def test_truncated_end_of_archive(saved, cut):
    saved.write_bytes(saved.read_bytes()[:-cut])
    refused(saved)


def test_flipped_byte_in_data_payload(saved):
    _, payload = data_payload_offset(saved)
    flip(saved, payload + 100)
    refused(saved)


@pytest.mark.parametrize("where", ["zip header", "npy header", "npy header bracket"])
def test_flipped_byte_in_data_header(saved, where):
    member_start, _ = data_payload_offset(saved)
    offsets = {"zip header": 30,                    # the member's name in its local header
               "npy header": member_start + 40,     # inside the npy header's dict
               "npy header bracket": saved.read_bytes().index(b"'shape': (") + 9}   # numpy: TokenError
    flip(saved, offsets[where])
    refused(saved)


def test_every_flipped_byte_is_refused_or_harmless(table, saved):
    """A byte flipped anywhere (every 37th byte): TableFormatError naming the file, or (in bytes zipfile
    ignores, such as timestamps) a table identical to the saved one; never another exception."""
    raw = saved.read_bytes()
    refusals = 0
    for offset in range(0, len(raw), 37):
        damaged = bytearray(raw)
        damaged[offset] ^= 0xFF
        saved.write_bytes(bytes(damaged))
        try:
            loaded = ScatteringTable.load(saved)
        except TableFormatError as error:
            assert str(saved) in str(error)
            refusals += 1
        else:
            assert_same_table(loaded, table)
    assert refusals > 0.9 * len(range(0, len(raw), 37))


def test_npy_renamed_npz(table, tmp_path):
    path = tmp_path / "data.npz"
    with open(path, "wb") as stream:
        np.save(stream, table.data)
    refused(path, ".npy")


def test_not_a_regular_file_or_missing(tmp_path):
    directory = tmp_path / "folder.npz"
    directory.mkdir()
    refused(directory, "not a regular file")
    with pytest.raises(FileNotFoundError, match="missing.npz"):
        ScatteringTable.load(tmp_path / "missing.npz")


def test_archive_without_table_members(tmp_path):
    path = tmp_path / "other.npz"
    np.savez(path, x=np.zeros(3))
    refused(path, "format_version")


# 3. Edited files ----------------------------------------------------------------------------------

@pytest.mark.parametrize("version, shown", [("three", "'three'"), (3.5, "3.5"), (True, "True"),
                                            (np.array([4]), "shape (1,)")])
def test_format_version_must_be_an_integer(saved, version, shown):
    rewrite(saved, format_version=version)
    refused(saved, "format_version must be an integer", shown)


def test_older_version_asks_for_a_rebuild(saved):
    rewrite(saved, format_version=np.int64(3), drop=("checksums",), recompute_checksums=False)
    refused(saved, "version 3", "rebuild")


@pytest.mark.parametrize("name", ["metadata", "orders_record", "settings", "atmosphere", "checksums"])
def test_invalid_json(saved, name):
    rewrite(saved, recompute_checksums=name != "checksums", **{name: '{"unterminated": '})
    refused(saved, name, "not valid JSON")


@pytest.mark.parametrize("text", ["[1, 2]", "3", '"text"'])
def test_json_must_be_an_object(saved, text):
    rewrite(saved, metadata=text)
    refused(saved, "metadata must be a JSON object")


def test_json_member_must_be_a_string(saved):
    rewrite(saved, metadata=np.zeros(3))
    refused(saved, "metadata must be a JSON string")


def test_invalid_parameters(saved, table):
    atmosphere = table.atmosphere.to_dict() | {"planet_radius": "big"}
    rewrite(saved, atmosphere=json.dumps(atmosphere))
    refused(saved, "invalid parameters")


@pytest.mark.parametrize("edit", ["negative", "nan", "inf"])
def test_edited_data_fails_its_stored_checksum(saved, table, edit):
    data = table.data.copy()
    data[1, 2, 3, 4] = {"negative": -1e-3, "nan": np.nan, "inf": np.inf}[edit]
    rewrite(saved, recompute_checksums=False, data=data)
    refused(saved, "data does not match the stored checksum")


@pytest.mark.parametrize("edit, what", [("negative", "1 negative"), ("nan", "1 NaN"), ("inf", "1 infinite")])
@pytest.mark.parametrize("member", ["data", "gathered", "order_2"])
def test_edited_values_with_recomputed_checksum(saved, table, member, edit, what):
    values = members_of(saved)[member].copy()
    values[0, 1, 2, 0] = {"negative": -1e-3, "nan": np.nan, "inf": np.inf}[edit]
    rewrite(saved, **{member: values})
    refused(saved, member, what)


@pytest.mark.parametrize("member, shape", [("data", GRID + (6,)), ("data", (4, 8, 3, 9)),
                                           ("gathered", (4, 8, 3, 6)), ("gathered", GRID + (8,)),
                                           ("gathered", (4 * 8 * 4 * 6,)), ("order_1", GRID + (3,)),
                                           ("order_2", GRID + (6,)), ("order_3", (2, 8, 4, 3))])
def test_wrong_shape(saved, member, shape):
    rewrite(saved, **{member: np.zeros(shape)})
    refused(saved, member, "has shape", str(shape))


@pytest.mark.parametrize("member, dtype", [("data", np.float32), ("data", np.float16), ("data", np.int64),
                                           ("data", np.complex128), ("gathered", np.float16),
                                           ("order_1", np.float16), ("order_2", np.int32)])
def test_wrong_dtype(saved, member, dtype):
    values = members_of(saved)[member]
    rewrite(saved, **{member: values.astype(dtype)})
    refused(saved, member, "dtype")


def test_data_as_text(saved):
    rewrite(saved, data="not an array")
    refused(saved, "data")


def test_float32_settings_accept_float32_data(tmp_path):
    table = ScatteringTable.build(black_preset("physical"), TINY.replace(dtype="float32", orders=2), backend="numpy")
    assert table.data.dtype == np.float64       # the build is float64 whatever the kernels' dtype
    as_float32 = dataclasses.replace(table, data=table.data.astype(np.float32),
                                     gathered=table.gathered.astype(np.float32))
    loaded = ScatteringTable.load(as_float32.save(tmp_path / "f32.npz"))
    assert loaded.data.dtype == np.float32 and np.array_equal(loaded.data, as_float32.data)


def test_record_must_count_the_orders(saved, table):
    rewrite(saved, orders_record=json.dumps(table.orders_record | {"orders": 2}))
    refused(saved, "orders_record counts 2", "keeps 3")


def test_more_orders_than_the_settings_compute(saved, table):
    rewrite(saved, order_4=table.orders[2].astype(np.float32),
            orders_record=json.dumps(table.orders_record | {"orders": 4}))
    refused(saved, "4 orders", "at most 3")


def test_missing_order_in_the_sequence(saved):
    rewrite(saved, drop=("order_2",))
    refused(saved, "order_1 to order_2")


@pytest.mark.parametrize("name", ["data", "checksums", "parameters_hash", "settings"])
def test_missing_member(saved, name):
    rewrite(saved, drop=(name,), recompute_checksums=name != "checksums")
    refused(saved, "missing", name)


def test_unexpected_member(saved):
    rewrite(saved, payload=np.zeros(3))
    refused(saved, "unexpected members ['payload']")


def test_member_without_checksum(saved):
    contents = members_of(saved)
    checksums = json.loads(str(contents["checksums"]))
    del checksums["gathered"]
    rewrite(saved, recompute_checksums=False, checksums=json.dumps(checksums))
    refused(saved, "checksums list")


def test_edited_parameters_fail_the_hash(saved, table):
    atmosphere = table.atmosphere.to_dict() | {"mie_g": -0.7}
    rewrite(saved, atmosphere=json.dumps(atmosphere))
    refused(saved, "parameters hash")


# 4. Construction and save -------------------------------------------------------------------------

@pytest.mark.parametrize("field, value, fragment", [
    ("data", np.full(GRID + (9,), np.nan), "NaN"),
    ("data", -np.ones(GRID + (9,)), "negative"),
    ("data", np.zeros(GRID + (6,)), "data has shape"),
    ("data", np.zeros(GRID + (9,), dtype=np.float32), "dtype"),
    ("data", [[0.0]], "NumPy array"),
    ("gathered", np.zeros((4, 8, 3, 6)), "gathered has shape"),
    ("gathered", np.full(GRID + (6,), np.inf), "infinite"),
    ("orders", (np.zeros(GRID + (3,)),), "order_1 has shape"),
    ("orders", None, "orders must be a sequence"),
    ("metadata", "provenance", "metadata must be a dict"),
    ("settings", {"size": (4, 8, 4)}, "settings must be TableSettings"),
])
def test_construction_applies_the_same_checks(table, field, value, fragment):
    with pytest.raises(TableFormatError, match=fragment):
        dataclasses.replace(table, **{field: value})


def test_save_refuses_a_table_edited_in_place(tmp_path):
    """A table's own arrays are read-only views; edited through the array it was made from, it is checked
    again before it is saved or exported."""
    built = ScatteringTable.build(black_preset("physical"), TINY.replace(orders=2), backend="numpy")
    own = np.array(built.data)
    table = dataclasses.replace(built, data=own)
    own[0, 0, 0, 0] = np.nan
    with pytest.raises(TableFormatError, match="NaN"):
        table.save(tmp_path / "sky.npz")
    with pytest.raises(TableFormatError, match="NaN"):
        table.export_raw(tmp_path / "sky")
    assert list(tmp_path.iterdir()) == []


def test_export_raw_refuses_a_header_that_is_no_strict_json(table, tmp_path):
    """A NaN in the table's metadata went into the raw export's header as NaN (not JSON); refused first."""
    odd = dataclasses.replace(table, metadata={**table.metadata, "note": float("nan")})
    with pytest.raises(ValueError, match=r"^the raw export's header would hold NaN or infinite values"):
        odd.export_raw(tmp_path / "sky")
    assert list(tmp_path.iterdir()) == []


def test_build_refuses_a_table_with_nan(monkeypatch):
    """A build whose numbers went wrong (e.g. an absurd planet) raises instead of returning NaN."""
    import clsky.orders

    compute_orders = clsky.orders.compute_orders

    def with_nan(*args, **kwargs):
        result = compute_orders(*args, **kwargs)
        result.orders[0][0, 0, 0, 0] = np.nan
        return result

    monkeypatch.setattr(clsky.orders, "compute_orders", with_nan)
    with pytest.raises(TableFormatError, match="computed table is unusable: data holds 1 NaN"):
        ScatteringTable.build(black_preset("physical"), TINY, backend="numpy")


def test_orders_are_kept_as_a_tuple(table):
    assert isinstance(dataclasses.replace(table, orders=list(table.orders)).orders, tuple)


# 5. Kernel buffers --------------------------------------------------------------------------------

def forbid_kernels(monkeypatch, engine):
    """Make any launch of ``engine``'s kernels fail the test: a refusal must come before it."""
    def launched(*args, **kwargs):
        raise AssertionError("the kernel was launched")

    monkeypatch.setattr(engine, "kernels", {name: launched for name in engine.kernels})


def bypassed(table, **changes):
    """A copy of ``table`` with ``changes`` set behind the validation's back."""
    copy = dataclasses.replace(table)
    for name, value in changes.items():
        object.__setattr__(copy, name, value)
    return copy


SUN = np.array([0.0, 0.6, 0.8])
DIRECTIONS = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.0, -0.8, 0.6]])


@pytest.fixture(scope="module")
def renderer(cl_context, tables):
    with SkyRenderer(tables["physical"], RAY, ctx=cl_context) as renderer:
        yield renderer


def test_renderer_renders_the_valid_table(renderer):
    for method in (renderer.render_table, renderer.render_raymarch):
        radiance = method(DIRECTIONS, SUN)
        assert radiance.shape == (3, 3) and np.all(np.isfinite(radiance)) and np.all(radiance >= 0)


@pytest.mark.parametrize("changes, fragment", [
    ({"gathered": np.ones((4, 8, 3, 6))}, "gathered has shape"),     # issue 9: read past the buffer
    ({"gathered": np.ones((8, 16, 8, 6))}, "gathered has shape"),
    ({"data": np.ones((4, 8, 3, 9))}, "data has shape"),
    ({"data": np.ones(GRID + (12,))}, "data has shape"),
    ({"data": np.full(GRID + (9,), np.nan)}, "NaN"),
    ({"settings": TINY.replace(size=(8, 8, 4), mode="physical")}, "data has shape"),
])
def test_renderer_refuses_a_bypassed_table(cl_context, table, changes, fragment):
    with pytest.raises(ValueError, match=fragment):
        SkyRenderer(bypassed(table, **changes), RAY, ctx=cl_context)


@pytest.mark.parametrize("method", ["render_table", "render_raymarch"])
@pytest.mark.parametrize("changes", [{"settings": TINY.replace(size=(8, 8, 4), mode="physical")},
                                     {"settings": TINY.replace(mode="atmosphere-plus")},
                                     {"data": np.ones((4, 8, 3, 9))}, {"gathered": np.ones((4, 8, 3, 6))}])
def test_renderer_refuses_a_table_changed_after_upload(cl_context, table, monkeypatch, method, changes):
    copy = bypassed(table)
    with SkyRenderer(copy, RAY, ctx=cl_context) as renderer:
        for name, value in changes.items():
            object.__setattr__(copy, name, value)
        forbid_kernels(monkeypatch, renderer.engine)
        with pytest.raises(ValueError, match="changed since the renderer uploaded it"):
            getattr(renderer, method)(DIRECTIONS, SUN)


def test_renderer_refuses_gathered_added_after_upload(cl_context, table, monkeypatch):
    copy = bypassed(table, gathered=None, orders=table.orders[:1], orders_record=table.orders_record | {"orders": 1})
    with SkyRenderer(copy, RAY, ctx=cl_context) as renderer:
        object.__setattr__(copy, "gathered", table.gathered)      # the upload holds a 2 x 2 x 2 stand-in
        forbid_kernels(monkeypatch, renderer.engine)
        with pytest.raises(ValueError, match="changed since"):
            renderer.render_raymarch(DIRECTIONS, SUN)


@pytest.mark.parametrize("method, buffer", [("render_table", "_table_d"), ("render_raymarch", "_gathered_d"),
                                            ("render_raymarch", "_sun_table_d")])
def test_renderer_checks_each_buffer_before_the_launch(renderer, monkeypatch, method, buffer):
    """A device buffer one value short (a fault injected after the upload) never reaches the kernel."""
    original = getattr(renderer, buffer)
    short = cla.empty(renderer.queue, original.size - 1, original.dtype)
    monkeypatch.setattr(renderer, buffer, short)
    forbid_kernels(monkeypatch, renderer.engine)
    with pytest.raises(ValueError, match=f"{method}: buffer .* holds {original.size - 1}"):
        getattr(renderer, method)(DIRECTIONS, SUN)


@pytest.mark.parametrize("method", ["render_table", "render_raymarch"])
def test_renderer_checks_prepared_directions(renderer, monkeypatch, method):
    prepared = renderer.prepare(DIRECTIONS)
    forbid_kernels(monkeypatch, renderer.engine)
    short_mask = dataclasses.replace(prepared, valid=cla.zeros(renderer.queue, 2, np.uint8))
    with pytest.raises(ValueError, match="buffer valid holds 2"):
        getattr(renderer, method)(short_mask, SUN)
    wrong_shape = dataclasses.replace(prepared, shape=(4,))
    with pytest.raises(ValueError, match="shape"):
        getattr(renderer, method)(wrong_shape, SUN)
    other_dtype = np.float32 if renderer.engine.dtype == np.float64 else np.float64
    wrong_dtype = dataclasses.replace(prepared, array=cla.zeros(renderer.queue, (3, 3), other_dtype))
    with pytest.raises(ValueError, match="buffer directions"):
        getattr(renderer, method)(wrong_dtype, SUN)


@pytest.fixture(scope="module")
def lookup_engine(cl_context):
    with TableLookupEngine(ctx=cl_context) as engine:
        yield engine


QUERIES = (np.array([0.0, 1e3]), np.array([0.5, -0.1]), np.array([0.3, 0.9]), np.array([0.2, 0.1]))


@pytest.mark.parametrize("data", [np.ones((4, 8, 4)), np.ones((4, 8, 4, 5)), np.ones((4, 8, 4, 12)),
                                  np.ones((1, 8, 4, 6)), np.ones((4, 8, 4, 6), dtype=complex),
                                  np.ones((4, 8, 4, 6, 1))])
def test_lookup_engine_refuses_raw_arrays_of_the_wrong_shape(lookup_engine, table, monkeypatch, data):
    forbid_kernels(monkeypatch, lookup_engine)
    with pytest.raises(ValueError, match="table data"):
        lookup_engine.radiance(table.atmosphere, data, *QUERIES)


def test_table_radiance_refuses_a_bypassed_table(lookup_engine, table, monkeypatch):
    forbid_kernels(monkeypatch, lookup_engine)
    for backend in ("opencl", "numpy"):
        with pytest.raises(ValueError, match="data has shape"):
            bypassed(table, data=np.ones((4, 8, 3, 9))).radiance(*QUERIES, backend=backend, engine=lookup_engine)


def test_lookup_engine_checks_its_table_buffer_before_the_launch(lookup_engine, table, monkeypatch):
    """A table upload one value short (a fault injected into the upload) never reaches the kernel."""
    import clsky.lookup

    class ShortTableUpload:
        def __getattr__(self, name):
            return getattr(cla, name)

        @staticmethod
        def to_device(queue, array):
            return cla.to_device(queue, array.reshape(-1)[:-1] if array.ndim == 4 else array)

    monkeypatch.setattr(clsky.lookup, "cla", ShortTableUpload())
    forbid_kernels(monkeypatch, lookup_engine)
    with pytest.raises(ValueError, match="lookup: buffer table holds"):
        lookup_engine.radiance(table.atmosphere, table.data, *QUERIES)


def test_check_kernel_buffer(cl_context):
    import pyopencl as cl

    queue = cl.CommandQueue(cl_context)
    buffer = cla.zeros(queue, (2, 3), np.float64)
    check_kernel_buffer("kernel", "x", buffer, 6, np.float64)
    with pytest.raises(ValueError, match="kernel: buffer x holds 6 float64 values, the kernel indexes 7"):
        check_kernel_buffer("kernel", "x", buffer, 7, np.float64)
    with pytest.raises(ValueError, match="indexes 6 float32"):
        check_kernel_buffer("kernel", "x", buffer, 6, np.float32)


# A probe of the files clsky reads (2026-12-07) ---------------------------------------------------------

def _with_deflated_member(path, name, nbytes, deflated=True):
    """Add to the archive at ``path`` a member ``name`` of ``nbytes`` zeros (a float64 array), deflated:
    a few kB on disk for megabytes once read (or stored, as clsky stores its members)."""
    import zipfile

    header = np.lib.format.header_data_from_array_1_0(np.zeros(0))
    header["shape"] = (nbytes // 8,)
    with zipfile.ZipFile(path, "a", compression=zipfile.ZIP_DEFLATED if deflated else zipfile.ZIP_STORED) as archive:
        with archive.open(name + ".npy", "w", force_zip64=True) as stream:
            np.lib.format.write_array_header_1_0(stream, header)
            chunk = bytes(2**20)
            for _ in range(nbytes // len(chunk)):
                stream.write(chunk)


def test_a_path_through_a_file_is_no_table(saved):
    """'sky.npz/x.npz' (ENOTDIR) was a TableFormatError 'not readable: NotADirectoryError' once the file was
    opened at once: it does not exist, as any missing path."""
    with pytest.raises(FileNotFoundError, match="does not exist"):
        ScatteringTable.load(saved / "x.npz")


def _reads_of(monkeypatch):
    """The members read from now on (NpzFile.__getitem__), in order."""
    read = []
    original = np.lib.npyio.NpzFile.__getitem__
    monkeypatch.setattr(np.lib.npyio.NpzFile, "__getitem__", lambda self, key: read.append(key) or original(self, key))
    return read


@pytest.mark.parametrize("name,deflated,expected", [
    ("zjunk", True, "unexpected members ['zjunk']"),
    ("gathered", True, "member gathered is compressed (zip method 8); clsky's table files store their members "
                       "uncompressed"),
    ("gathered", False, "member gathered inflates to"),
], ids=["foreign", "deflated", "stored"])
def test_a_member_that_inflates_beyond_its_settings_is_refused_unread(saved, name, deflated, expected, monkeypatch):
    """A 2 MB file whose deflated member held 2 GB of zeros took 2 GB of memory and 12 s before the member
    was refused. Names come from the archive's directory and sizes and compression with them, before any
    member is read: a deflated member is refused (clsky stores its members), and a stored one beyond its
    settings' size (8 or 64 MB here, where the 4 x 8 x 4 table's gathered sum takes 6 kB)."""
    if name == "gathered":
        rewrite(saved, drop=("gathered",), recompute_checksums=False)
    _with_deflated_member(saved, name, (64 if deflated else 8) * 2**20, deflated)
    assert saved.stat().st_size < (2**20 if deflated else 9 * 2**20)
    read = _reads_of(monkeypatch)
    message = refused(saved, expected)
    assert name not in read, message
    if name == "zjunk" or deflated:
        assert read == []                               # refused by its name or its compression alone


def test_a_forged_grid_cannot_inflate_deflated_members(saved, monkeypatch):
    """The probe's forgery (2026-12-07): settings that declare a grid of 256 x 1024 x 96 allow a data member
    of 1.6 GB, which 1.7 MB of deflated zeros held (1.8 GB of memory before any check after the sizes).
    Refused for its compression, from the archive's directory, before any member is read."""
    import zipfile

    contents = members_of(saved)
    settings = json.loads(contents["settings"].item())
    settings["size"] = [256, 1024, 96]
    contents["settings"] = np.array(json.dumps(settings))
    with zipfile.ZipFile(saved, "w", compression=zipfile.ZIP_DEFLATED) as archive:     # np.savez_compressed's way
        for member, value in contents.items():
            with archive.open(member + ".npy", "w", force_zip64=True) as stream:
                np.lib.format.write_array(stream, np.asanyarray(value), allow_pickle=False)
    read = _reads_of(monkeypatch)
    refused(saved, "is compressed")
    assert read == []


def test_more_orders_than_the_settings_compute_are_refused_unread(saved, monkeypatch):
    """Every member was read, then the orders counted: a forged file of 5 orders of 340 MB each took 3.6 GB
    before 'the settings compute at most 1'. The count is checked from the directory, the orders unread."""
    contents = members_of(saved)
    limit = max_orders_kept(TableSettings.from_dict(json.loads(contents["settings"].item())))
    extra = {f"order_{k}": contents["order_1"] for k in range(1, limit + 2)}
    rewrite(saved, **extra)
    read = _reads_of(monkeypatch)
    refused(saved, f"{limit + 1} orders kept, the settings compute at most {limit}")
    assert not any(name.startswith("order_") for name in read), read


@pytest.mark.parametrize("member", ["data", "gathered", "order_2"])
def test_values_too_large_for_a_table_are_refused(saved, member):
    """Finite but huge values passed the "finite and >= 0" check and rendered as infinities (1e39 in a float32
    table's kernels, 1e307 times a phase function in float64): a table's values are at most 1e12."""
    values = members_of(saved)[member].copy()
    values[0, 1, 2, 0] = 1e38 if values.dtype == np.float32 else 1e39      # the orders are stored as float32
    rewrite(saved, **{member: values})
    refused(saved, member, "1 values beyond 1e+12")


def test_a_file_of_higher_orders_needs_its_gathered_source(saved):
    """Without its gathered sum a file of 3 orders rendered its ray march without them (24 % darker on the
    probe's physical table of 9 orders): refused."""
    rewrite(saved, drop=("gathered",))
    refused(saved, "gathered must be present exactly when the table has higher orders", "counts 3 orders",
            "gathered is missing")


def test_a_single_scattering_file_has_no_gathered_source(saved, table):
    """A gathered sum added to a single-scattering file made its ray march add light it lacks (+6.5 %)."""
    rewrite(saved, drop=("order_2", "order_3"), orders_record=json.dumps(table.orders_record | {"orders": 1}))
    refused(saved, "gathered must be present exactly when the table has higher orders", "gathered is present")


@pytest.mark.parametrize("record, what", [({}, "orders_record lacks orders"),
                                          ({"orders": True}, "orders_record's orders must be an integer"),
                                          ({"orders": "many"}, "got 'many'")])
def test_the_record_must_count_its_orders(saved, record, what):
    rewrite(saved, orders_record=json.dumps(record))
    refused(saved, what)


@pytest.mark.parametrize("metadata, what", [
    ({"build_seconds": [1, 2]}, "metadata's build_seconds must be a number of seconds >= 0, got [1, 2]"),
    ({"build_seconds": "fast"}, "build_seconds"), ({"fast_math": "no"}, "metadata's fast_math must be true or false"),
    ({"clsky_version": "9.9\nFAKE LINE"}, "metadata's clsky_version must be one line of printable text"),
    ({"units": ["W"]}, "metadata's units must be one line"),
])
def test_metadata_that_clsky_reads_back_is_checked(saved, table, metadata, what):
    """``clsky info`` ended in TypeError on a forged build_seconds of [1, 2], and a version with a newline
    added a line to its output (the units go into the frames' headers too)."""
    rewrite(saved, metadata=json.dumps(table.metadata | metadata))
    refused(saved, what)


@pytest.mark.parametrize("record, what", [
    ({"reason": "line1\nline2 \x1b[31mRED\x1b[0m"}, "orders_record's reason must be one line of printable text"),
    ({"reason": 7}, "orders_record's reason must be one line of printable text, got 7"),
    ({"converged": "no"}, "orders_record's converged must be true or false, got 'no'"),
])
def test_the_orders_record_that_clsky_prints_is_checked(saved, table, record, what):
    """``clsky info`` printed a forged reason's newline and escape codes as they were, and "converged" for
    a converged of "no"."""
    rewrite(saved, orders_record=json.dumps(table.orders_record | record))
    refused(saved, what)
