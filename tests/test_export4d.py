"""The engine export of the 4D table (clsky/export4d.py) and its GLSL lookup (docs/lookup4d.glsl).

No GLSL compiler is at hand, so the snippet's own text is compiled as OpenCL C (double precision)
behind a prelude that maps GLSL's types, constructors and texelFetch onto OpenCL, and run on random
queries against clsky.reference.lookup4d, on the volumes export_texture wrote (read back from the
file). What the prelude cannot map (structs, out parameters, C casts) the snippet avoids, which a
test here checks too.
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

from clsky import ScatteringTable, TableSettings, reference
from clsky._cl import Source, build_program
from clsky.export4d import GLSL_SNIPPET, export_texture, texture_volumes
from clsky.mapping import cos_azimuth, scatter_cos

ROOT = pathlib.Path(__file__).resolve().parent.parent
SNIPPET = (ROOT / GLSL_SNIPPET).read_text()

PRELUDE = """
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#define float double
typedef double2 vec2;
typedef double3 vec3;
typedef double4 vec4;
typedef int3 ivec3;
typedef __global const double4 *sampler3D;
#define vec3(a, b, c) ((double3)((a), (b), (c)))
#define vec4(a, b, c, d) ((double4)((a), (b), (c), (d)))
#define ivec3(a, b, c) ((int3)((int)(a), (int)(b), (int)(c)))
/* texelFetch of a volume of size.x x size.y texels per layer (size: radiance4d's parameter) */
#define texelFetch(t, p, lod) (t)[(p).x + (int)size.x * ((p).y + (int)size.y * (p).z)]
"""

KERNEL = """
__kernel void run(__global const double4 *t0, __global const double4 *t1, __global const double4 *t2,
                  const double4 size, const int mapping, const double2 sun_range, const double rp, const double ra,
                  const double4 light, const double mie_g, const int modified, __global const double *queries,
                  __global double *out)
{
    const int i = get_global_id(0);
    const double3 value = radiance4d(t0, t1, t2, size, mapping, sun_range, rp, ra, light.xyz, mie_g, modified,
                                     queries[4 * i], queries[4 * i + 1], queries[4 * i + 2], queries[4 * i + 3]);
    out[3 * i] = value.x;
    out[3 * i + 1] = value.y;
    out[3 * i + 2] = value.z;
}
"""

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
    (measured 6e-8); queries with |cos phi| > 1 - 1e-6 are left out (acos, tests/test_table4d.py)."""
    binary, header = export_texture(table, tmp_path / "sky")
    meta = json.loads(header.read_text())
    volumes = np.fromfile(binary, dtype="<f4").reshape(3, -1, 4).astype(np.float64)
    program = build_program(cl_context, [Source("the exported GLSL snippet as OpenCL C", PRELUDE + SNIPPET + KERNEL)])
    kernel = program.run
    queue = cl.CommandQueue(cl_context)
    rng = np.random.default_rng(5)
    n = 4000
    h = rng.choice([0.0, 10.0, 3e3, 5e4, 1e5], n)
    mu_v, mu_s = rng.uniform(-1, 1, n), rng.uniform(-0.3, 0.9, n)
    nu = scatter_cos(mu_v, mu_s, rng.uniform(0, math.pi, n))
    keep = np.abs(cos_azimuth(mu_v, mu_s, nu)) < 1 - 1e-6
    queries = np.stack([h, mu_v, mu_s, nu], axis=1)[keep]
    out = cla.empty(queue, (len(queries), 3), np.float64)
    size = np.array(tuple(float(v) for v in meta["size"]), dtype=cl.cltypes.double4)
    light = np.array(tuple(meta["incident_light"]) + (0.0,), dtype=cl.cltypes.double4)
    sun_range = np.array(tuple(meta["sun_range"]), dtype=cl.cltypes.double2)
    t = [cla.to_device(queue, np.ascontiguousarray(v)) for v in volumes]
    kernel(queue, (len(queries),), None, t[0].data, t[1].data, t[2].data, size, np.int32(meta["mapping"]), sun_range,
           np.float64(meta["planet_radius"]), np.float64(meta["top_radius"]), light, np.float64(meta["mie_g"]),
           np.int32(meta["modified_rayleigh"]), cla.to_device(queue, queries).data, out.data)
    got = out.get()
    expected = reference.lookup4d(table.atmosphere, table.data, *queries.T, SETTINGS.mapping, SETTINGS.sun_cos_range)
    assert_allclose(got, expected, rtol=2e-7, atol=1e-9 * np.abs(expected).max())


def test_export_refuses_a_3d_table(tmp_path):
    table = ScatteringTable.build("atmosphere-plus", TableSettings(size=(4, 8, 4), orders=1))
    with pytest.raises(ValueError, match="4D"):
        export_texture(table, tmp_path / "x")
