// lookup4d.glsl -- sky radiance from a clsky 4D scattering table (clsky/table4d.py), for engines.
//
// Load the files of ScatteringTable.export_texture(NAME) (NAME.bin, NAME.json): three RGBA32F 3D
// textures of W x H x (D A) texels, t0 = (Ibar_R r, g, b, Ibar_M r), t1 = (Ibar_M g, b, L r, g),
// t2 = (L b, 0, 0, 0), texel (x, y, z + D a): x altitude node, y view node (0..H/2-1 rays that hit the
// ground, H/2..H-1 rays that reach space), z sun node, a azimuth node. Every constant below is in
// NAME.json. The lookup is quadrilinear by texelFetch, never by the hardware filter: the view axis must
// not blend the two sides of the horizon (nodes H/2-1 and H/2), and the sun and azimuth axes share the
// texture's depth. The phase functions are applied at the exact scattering angle: the table holds no
// sharp Mie peak. Radiance = I_I (F_R(nu) Ibar_R + F_M(nu) Ibar_M + L), for an observer inside the
// atmosphere (altitude in [0, Ha]).
//
// The code keeps to the subset of GLSL that tests/test_export4d.py also compiles as OpenCL C (a prelude
// maps the types, texelFetch and the constructors) and compares with clsky's lookup: no structs, no
// out parameters, no int -> float conversions (node counts are floats), no swizzles but .xyzw.

float horizon_cos4d(float h, float rp)
{
    return -sqrt(max(h * (2.0 * rp + h), 0.0)) / (rp + h);
}

// Node coordinate along the view axis (height nodes) of view cosine mu at altitude [m] (clamped to [0, Ha]).
float view4d(float altitude, float mu, float height, float rp, float ra)
{
    float ha = ra - rp;
    float h = clamp(altitude, 0.0, ha);
    float r = rp + h;
    float rho = sqrt(h * (2.0 * rp + h));
    float k = sqrt(ha * (2.0 * rp + ha));
    float half_nodes = floor(height / 2.0);
    float above = max(h * (2.0 * rp + h), 0.0);
    float d_ground = above / max(sqrt(max(r * mu * r * mu - above, 0.0)) - r * mu, 1e-30);
    float inside = max((ha - h) * (ra + r), 0.0);
    float root = sqrt(inside + r * mu * r * mu);
    float d_top = mu > 0.0 ? inside / max(r * mu + root, 1e-30) : root - r * mu;
    float x_ground = clamp((d_ground - h) / max(rho - h, 1e-30), 0.0, 1.0);
    float x_sky = clamp((d_top - (ha - h)) / max(rho + k - (ha - h), 1e-30), 0.0, 1.0);
    return mu < horizon_cos4d(h, rp) ? (half_nodes - 1.0) * x_ground
                                     : half_nodes + (half_nodes - 1.0) * (1.0 - x_sky);
}

// Node coordinate along the azimuth axis (azimuths nodes over [0, pi]) of (mu_v, mu_s, nu).
float azimuth4d(float mu_v, float mu_s, float nu, float azimuths)
{
    float denominator = sqrt(max(1.0 - mu_v * mu_v, 0.0) * max(1.0 - mu_s * mu_s, 0.0));
    float cos_phi = denominator > 1e-30 ? clamp((nu - mu_v * mu_s) / denominator, -1.0, 1.0) : 1.0;
    return acos(cos_phi) * ((azimuths - 1.0) / 3.14159265358979323846);
}

// Lower node (the first of the two interpolated) along an axis of n nodes at coordinate f.
float lower4d(float f, float n)
{
    return clamp(floor(f), 0.0, n - 2.0);
}

// Radiance r, g, b toward the view (zenith cosine mu_v) of an observer at altitude h [m] with the sun at
// zenith cosine mu_s and nu = dot(view, sun). size = (W, H, D, A); mapping 1 'nonlinear' (u = sqrt(h / Ha),
// w = (1 + cbrt(mu_s)) / 2), 0 'linear'; sun_range = (w_low, w_high) of the sun axis; rp, ra the planet
// and atmosphere radii [m]; incident_light I_I; mie_g the Cornette-Shanks g in the notes' sign convention
// (negative: forward); modified_rayleigh 1 for the notes' 0.8 (1.4 + c^2 / 2), else 3/4 (1 + c^2).
vec3 radiance4d(sampler3D t0, sampler3D t1, sampler3D t2, vec4 size, int mapping, vec2 sun_range, float rp,
                float ra, vec3 incident_light, float mie_g, int modified_rayleigh, float h, float mu_v, float mu_s,
                float nu)
{
    float c = clamp(nu, -1.0, 1.0);
    float hc = clamp(h / (ra - rp), 0.0, 1.0);
    float s = clamp(mu_s, -1.0, 1.0);
    float cbrt_s = s < 0.0 ? -pow(-s, 1.0 / 3.0) : pow(s, 1.0 / 3.0);
    float fx = (mapping == 1 ? sqrt(hc) : hc) * (size.x - 1.0);
    float w = 0.5 * (1.0 + (mapping == 1 ? cbrt_s : s));
    float fz = clamp((w - sun_range.x) / (sun_range.y - sun_range.x), 0.0, 1.0) * (size.z - 1.0);
    float fy = view4d(h, mu_v, size.y, rp, ra);
    float fa = azimuth4d(mu_v, s, c, size.w);
    float half_nodes = floor(size.y / 2.0);
    float x0 = lower4d(fx, size.x);
    float z0 = lower4d(fz, size.z);
    float a0 = lower4d(fa, size.w);
    float y0 = fy < half_nodes ? clamp(floor(fy), 0.0, half_nodes - 2.0) : clamp(floor(fy), half_nodes, size.y - 2.0);
    vec4 ibar0 = vec4(0.0, 0.0, 0.0, 0.0);
    vec4 ibar1 = vec4(0.0, 0.0, 0.0, 0.0);
    vec4 ibar2 = vec4(0.0, 0.0, 0.0, 0.0);
    for (float da = 0.0; da < 1.5; da += 1.0) {
        for (float dz = 0.0; dz < 1.5; dz += 1.0) {
            for (float dy = 0.0; dy < 1.5; dy += 1.0) {
                for (float dx = 0.0; dx < 1.5; dx += 1.0) {
                    float weight = (da > 0.5 ? fa - a0 : 1.0 - (fa - a0)) * (dz > 0.5 ? fz - z0 : 1.0 - (fz - z0))
                                 * (dy > 0.5 ? fy - y0 : 1.0 - (fy - y0)) * (dx > 0.5 ? fx - x0 : 1.0 - (fx - x0));
                    ivec3 texel = ivec3(x0 + dx, y0 + dy, z0 + dz + size.z * (a0 + da));
                    ibar0 += weight * texelFetch(t0, texel, 0);
                    ibar1 += weight * texelFetch(t1, texel, 0);
                    ibar2 += weight * texelFetch(t2, texel, 0);
                }
            }
        }
    }
    float f_r = modified_rayleigh == 1 ? 0.8 * (1.4 + 0.5 * c * c) : 0.75 * (1.0 + c * c);
    float g2 = mie_g * mie_g;
    // the base 1 + g^2 + 2gc is at least (1 - |g|)^2, but formed from terms of size ~2 it rounds to 0 or below
    // in float32 for |g| near 1 (an infinity or a NaN at the peak): below half its least value it is rounding
    // noise and replaced by the least value (as clsky's kernels/phase.cl)
    float least = min((1.0 - mie_g) * (1.0 - mie_g), (1.0 + mie_g) * (1.0 + mie_g));
    float formed = 1.0 + g2 + 2.0 * mie_g * c;
    float base = formed < 0.5 * least ? least : formed;
    float f_m = 1.5 * (1.0 - g2) / (2.0 + g2) * (1.0 + c * c) / (base * sqrt(base));
    return incident_light * vec3(f_r * ibar0.x + f_m * ibar0.w + ibar1.z,
                                 f_r * ibar0.y + f_m * ibar1.x + ibar1.w,
                                 f_r * ibar0.z + f_m * ibar1.y + ibar2.x);
}
