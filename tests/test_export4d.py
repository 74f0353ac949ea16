"""The engine export of the 4D table (clsky/export4d.py) and its GLSL lookup (docs/lookup4d.glsl).

No GLSL compiler is at hand, so the snippet's own text is compiled as OpenCL C (in double precision,
and in single precision as a shader runs it) behind a prelude that maps GLSL's types, constructors and
texelFetch onto OpenCL, and run on random queries against clsky.reference.lookup4d, on the volumes
export_texture wrote (read back from the file). What the prelude cannot map (structs, out parameters, C
casts) the snippet avoids, which a test here checks too.
"""

from __future__ import annotations

import json
import math
import pathlib
import re

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
import pytest
from numpy.testing import assert_allclose

from clsky import AtmosphereParameters, ScatteringTable, TableSettings, reference
from clsky._cl import Source, build_program
from clsky.export4d import GLSL_SNIPPET, export_texture, texture_volumes
from clsky.mapping import cos_azimuth, scatter_cos

ROOT = pathlib.Path(__file__).resolve().parent.parent
SNIPPET = (ROOT / GLSL_SNIPPET).read_text()

def prelude(real):
    """The prelude that maps GLSL onto OpenCL C with ``real`` ('double' or 'float') as GLSL's float."""
    return f"""
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
{"#define float double" if real == "double" else ""}
typedef {real}2 vec2;
typedef {real}3 vec3;
typedef {real}4 vec4;
typedef int3 ivec3;
typedef __global const {real}4 *sampler3D;
#define vec3(a, b, c) (({real}3)((a), (b), (c)))
#define vec4(a, b, c, d) (({real}4)((a), (b), (c), (d)))
#define ivec3(a, b, c) ((int3)((int)(a), (int)(b), (int)(c)))
/* texelFetch of a volume of size.x x size.y texels per layer (size: radiance4d's parameter) */
#define texelFetch(t, p, lod) (t)[(p).x + (int)size.x * ((p).y + (int)size.y * (p).z)]
"""


def kernel(real):
    return f"""
__kernel void run(__global const {real}4 *t0, __global const {real}4 *t1, __global const {real}4 *t2,
                  const {real}4 size, const int mapping, const {real}2 sun_range, const {real} rp, const {real} ra,
                  const {real}4 light, const {real} mie_g, const int modified, __global const {real} *queries,
                  __global {real} *out)
{{
    const int i = get_global_id(0);
    const {real}3 value = radiance4d(t0, t1, t2, size, mapping, sun_range, rp, ra, light.xyz, mie_g, modified,
                                     queries[4 * i], queries[4 * i + 1], queries[4 * i + 2], queries[4 * i + 3]);
    out[3 * i] = value.x;
    out[3 * i + 1] = value.y;
    out[3 * i + 2] = value.z;
}}
"""


def run_snippet(cl_context, table, directory, queries, real="double"):
    """The snippet's radiance (N, 3) for ``queries`` (N, 4) of (h, mu_v, mu_s, nu), on the volumes that
    export_texture writes for ``table`` (read back from the file), in GLSL's float as OpenCL's ``real``
    (a float32 shader: literals single precision too, -cl-single-precision-constant)."""
    dtype, types = (np.float64, cl.cltypes.double4) if real == "double" else (np.float32, cl.cltypes.float4)
    binary, header = export_texture(table, directory / f"sky-{real}")
    meta = json.loads(header.read_text())
    volumes = np.fromfile(binary, dtype="<f4").reshape(3, -1, 4).astype(dtype)
    options = () if real == "double" else ("-cl-single-precision-constant",)
    program = build_program(cl_context, [Source(f"the exported GLSL snippet as OpenCL C ({real})",
                                                prelude(real) + SNIPPET + kernel(real))], options)
    queue = cl.CommandQueue(cl_context)
    out = cla.empty(queue, (len(queries), 3), dtype)
    size = np.array(tuple(float(v) for v in meta["size"]), dtype=types)
    light = np.array(tuple(meta["incident_light"]) + (0.0,), dtype=types)
    sun_range = np.array(tuple(meta["sun_range"]), dtype=getattr(cl.cltypes, f"{real}2"))
    t = [cla.to_device(queue, np.ascontiguousarray(v)) for v in volumes]
    cl.Kernel(program, "run")(queue, (len(queries),), None, t[0].data, t[1].data, t[2].data, size,
                              np.int32(meta["mapping"]), sun_range, dtype(meta["planet_radius"]),
                              dtype(meta["top_radius"]), light, dtype(meta["mie_g"]),
                              np.int32(meta["modified_rayleigh"]),
                              cla.to_device(queue, queries.astype(dtype)).data, out.data)
    return out.get().astype(np.float64)


def random_queries(n, seed, sun_cos_range):
    """(N, 4) queries (h, mu_v, mu_s, nu) over the table's sun range, those with |cos phi| > 1 - 1e-6 left out
    (acos, tests/test_table4d.py)."""
    rng = np.random.default_rng(seed)
    h = rng.choice([0.0, 10.0, 3e3, 5e4, 1e5], n)
    mu_v, mu_s = rng.uniform(-1, 1, n), rng.uniform(*sun_cos_range, n)
    nu = scatter_cos(mu_v, mu_s, rng.uniform(0, math.pi, n))
    keep = np.abs(cos_azimuth(mu_v, mu_s, nu)) < 1 - 1e-6
    return np.stack([h, mu_v, mu_s, nu], axis=1)[keep]


SETTINGS = TableSettings(size=(6, 8, 6), mode="physical", parameterization="4d", azimuth_size=5,
                         azimuth_harmonics=2, view_steps=8, sun_steps=8, gather_theta_steps=16, gather_phi_steps=16,
                         transmittance_size=(16, 32), sun_cos_range=(-0.3, 0.9))


@pytest.fixture(scope="module")
def table():
    return ScatteringTable.build("physical", SETTINGS)


def test_volumes_pack_sun_and_azimuth_into_the_depth(table):
    volumes = texture_volumes(table.data)
    assert volumes.shape == (3, 5 * 6, 8, 6, 4) and volumes.dtype == np.float32
    a, z, y, x = 3, 2, 5, 1
    packed = np.concatenate([volumes[0, z + 6 * a, y, x], volumes[1, z + 6 * a, y, x], volumes[2, z + 6 * a, y, x]])
    assert_allclose(packed[:9], table.data[a, z, y, x].astype(np.float32), rtol=0, atol=0)
    assert np.all(packed[9:] == 0)


def test_snippet_keeps_to_the_shared_subset():
    code = re.sub(r"//.*", "", SNIPPET)
    assert "struct" not in code and not re.search(r"\bout\b", code) and not re.search(r"\(\s*(int|float)\s*\)", code)
    assert not re.search(r"\bfloat\s*\(", code)          # no int -> float conversion constructors


def test_glsl_lookup_matches_the_python_lookup(table, tmp_path, cl_context):
    """The snippet (compiled as OpenCL C, double) on the exported volumes against clsky.reference.lookup4d
    on the table's float64 data: the export rounds the values to float32 (5.96e-8 relative), and the
    snippet's pow(x, 1/3) and loop order differ from cbrt and the kernel's order by rounding: rtol 2e-7
    (measured 6e-8)."""
    queries = random_queries(4000, 5, SETTINGS.sun_cos_range)
    got = run_snippet(cl_context, table, tmp_path, queries)
    expected = reference.lookup4d(table.atmosphere, table.data, *queries.T, SETTINGS.mapping, SETTINGS.sun_cos_range)
    assert_allclose(got, expected, rtol=2e-7, atol=1e-9 * np.abs(expected).max())


@pytest.mark.parametrize("mie_g", [-0.85, -0.9999, 0.9999])
def test_glsl_lookup_in_float32_is_finite_at_the_mie_peak(tmp_path, cl_context, mie_g):
    """The snippet as a shader runs it, in float32: finite and non-negative for every query, the sun's own
    direction (nu = 1) and its opposite included, at the default g and at the limits +-0.9999
    (MAX_MIE_G). Without the guard on the phase's base (as kernels/phase.cl's), 1 + g^2 + 2gc rounded to
    0 at g = -0.9999, nu = 1: inf, and NaN where Ibar_M is 0. Away from the peak (base > 0.1, where the
    float32 base keeps about 6 digits) the radiance is within 1e-4 of clsky's float64 lookup: the float32
    snippet's own rounding through the mapping's cube roots and the quadrilinear sums, measured up to
    2.9e-5 on PoCL (2026-12-07); 1e-4, about 800 float32 ulps, leaves room for another device's FMA
    contraction and pow's few ulps (OpenCL's single-precision bound) without hiding an error of the
    snippet's own (a wrong node or weight is off by percents)."""
    atmosphere = AtmosphereParameters(mie_g=mie_g)
    settings = SETTINGS.replace(azimuth_harmonics=0, orders=2)
    table = ScatteringTable.build(atmosphere, settings)
    queries = random_queries(2000, 7, settings.sun_cos_range)
    # the sun's direction (the peak of g < 0) and its opposite (of g > 0), and two more
    peak = [[0.0, 0.5, 0.5, 1.0], [0.0, 0.2, 0.2, 1.0], [0.0, -0.2, 0.2, -1.0], [3e3, -0.1, 0.5, -0.7]]
    queries = np.concatenate([queries, peak])
    got = run_snippet(cl_context, table, tmp_path, queries, real="float")
    assert np.all(np.isfinite(got)) and np.all(got >= 0)
    expected = reference.lookup4d(table.atmosphere, table.data, *queries.T, settings.mapping, settings.sun_cos_range)
    nu = queries[:, 3]
    away = 1.0 + mie_g * mie_g + 2.0 * mie_g * nu > 0.1
    assert_allclose(got[away], expected[away], rtol=1e-4, atol=1e-6 * np.abs(expected).max())


def test_export_refuses_a_3d_table(tmp_path):
    table = ScatteringTable.build("atmosphere-plus", TableSettings(size=(4, 8, 4), orders=1))
    with pytest.raises(ValueError, match="4D"):
        export_texture(table, tmp_path / "x")
