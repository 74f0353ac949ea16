/* lookup4d.cl -- radiance from the 4D scattering table (clsky/lookup4d.py; twin clsky.reference.lookup4d).
 *
 *   I = I_I (F_R(nu) Ibar_R + F_M(nu) Ibar_M + Lbar)                      (physics.md, "Rendering")
 * with the 9 (or, single scattering only, 6) channels interpolated quadrilinearly at the node
 * coordinates (fx, fy, fz, fa): altitude and sun as the 3D table (mapping.cl), view zenith split at
 * the horizon and azimuth (mapping4d.cl). Along the view axis the lower node is kept on the query's
 * side of the horizon (nodes 0..H/2 - 1 see the ground, H/2..H - 1 space): a lookup never blends a
 * ray that hits the ground with one that does not (no horizon seam). Table layout (A, D, H, W, C):
 * cell index x + W (y + H (z + D a)); an axis of one node (the renderer's slice at one altitude and
 * sun, W = D = 1) is read without interpolation. The phase functions use the exact nu (phase.cl):
 * the sharp Mie peak never passes through the interpolation (Ibar carries no phase).
 * Requires real.cl, atmosphere_t, geometry.cl, mapping.cl, mapping4d.cl, phase.cl, lookup.cl.
 */

/* Lower node and weight along an axis of n nodes at coordinate f (one node: 0 and weight 0). */
inline int node4d(const real f, const int n, real *weight)
{
    if (n < 2) {
        *weight = R(0.0);
        return 0;
    }
    const int lower = lower_node(f, n);
    *weight = f - (real)lower;
    return lower;
}

/* Lower view node on the query's side of the horizon (see the header) and its weight. */
inline int view_node4d(const real fy, const int height, real *weight)
{
    const int half_nodes = height / 2;
    const int lower = fy < (real)half_nodes ? clamp((int)fy, 0, half_nodes - 2) : clamp((int)fy, half_nodes, height - 2);
    *weight = fy - (real)lower;
    return lower;
}

/* The quadrilinear interpolation of the table's channels at (fx, fy, fz, fa) into ibar[0..channels-1]. */
inline void interpolate4d(__global const real *table, const int width, const int height, const int depth,
                          const int azimuths, const int channels, const real fx, const real fy, const real fz,
                          const real fa, real *ibar)
{
    real ax, ay, az, aa;
    const int x0 = node4d(fx, width, &ax), z0 = node4d(fz, depth, &az), a0 = node4d(fa, azimuths, &aa);
    const int y0 = view_node4d(fy, height, &ay);
    for (int c = 0; c < channels; ++c)
        ibar[c] = R(0.0);
    for (int da = 0; da <= (azimuths > 1); ++da)
        for (int dz = 0; dz <= (depth > 1); ++dz)
            for (int dy = 0; dy <= 1; ++dy)
                for (int dx = 0; dx <= (width > 1); ++dx) {
                    const real weight = (da ? aa : R(1.0) - aa) * (dz ? az : R(1.0) - az)
                                        * (dy ? ay : R(1.0) - ay) * (dx ? ax : R(1.0) - ax);
                    const size_t cell = (size_t)(x0 + dx) + (size_t)width * ((size_t)(y0 + dy) + (size_t)height
                                        * ((size_t)(z0 + dz) + (size_t)depth * (size_t)(a0 + da)));
                    for (int c = 0; c < channels; ++c)
                        ibar[c] += weight * table[cell * channels + c];
                }
}

/* Node coordinates along the altitude and sun axes (0 on an axis of one node). */
inline real altitude4d_coordinate(__constant const atmosphere_t *atm, const int width, const int mapping, const real h)
{
    return width > 1 ? MAPPING_U(h, mapping, atm->top_radius - atm->planet_radius) * (real)(width - 1) : R(0.0);
}

inline real sun4d_coordinate(const int depth, const int mapping, const real2 sun_range, const real mu_s)
{
    return depth > 1 ? MAPPING_SUN_T(mu_s, mapping, sun_range) * (real)(depth - 1) : R(0.0);
}

#if VECTOR_WIDTH == 1   /* the render program (RenderEngine.program_sources) joins this file for interpolate4d */
__kernel void lookup4d(__constant const atmosphere_t *atm, __global const real *table,
                       const int width, const int height, const int depth, const int azimuths, const int channels,
                       const int mapping, const real2 sun_range, const int n,
                       __global const real *altitude, __global const real *cos_view,
                       __global const real *cos_sun, __global const real *cos_scatter,
                       __global real *radiance)
{
    const int i = get_global_id(0);
    if (i >= n)
        return;
    real h = altitude[i], mu_v = cos_view[i], mu_s = cos_sun[i];
    const real nu = clamp(cos_scatter[i], R(-1.0), R(1.0));
    const int inside = enter_atmosphere(atm->planet_radius, atm->top_radius, &h, &mu_v, &mu_s, nu);
    real3 value = (real3)(R(0.0));
    if (inside) {
        real ibar[9];
        interpolate4d(table, width, height, depth, azimuths, channels, altitude4d_coordinate(atm, width, mapping, h),
                      view4d_coordinate(h, mu_v, height, atm->planet_radius, atm->top_radius),
                      sun4d_coordinate(depth, mapping, sun_range, mu_s),
                      azimuth4d_coordinate(mu_v, mu_s, nu, azimuths), ibar);
        value = radiance_of_channels(atm, ibar, channels, nu);
    }
    radiance[3 * i] = value.x;
    radiance[3 * i + 1] = value.y;
    radiance[3 * i + 2] = value.z;
}
#endif
