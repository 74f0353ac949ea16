/* render.cl -- kernels of clsky/render.py: HDR sky radiance per pixel, two ways.
 *
 * Per pixel a unit view direction V (observer's local frame, z = zenith), one sun direction S per
 * frame, one observer altitude h [m] (above Ha: seen from space, rays enter the atmosphere first).
 *   mu_v = V.z,  mu_s = S.z,  nu = dot(V, S) (cos theta, constant along the straight ray).
 *
 * render_table:    I = I_I (F_R(nu) Ibar_R + F_M(nu) Ibar_M [+ Lbar]) by trilinear lookup (lookup.cl).
 * render_raymarch: single scattering integrated along the pixel's actual ray with the true nu
 *                  (view_ray.cl: integrate_single), nothing tabulated but, optionally, the sun's
 *                  transmittance; higher orders from the gathered in-scatter table G along the ray
 *                  (integrate_gathered): physical mode I_I sum_s beta_s / (4 pi) Integral rho_s T G_s,
 *                  atmosphere-plus mode the same with F_s(nu) on each species (the notes' scheme).
 * Transmittances are those of column.cl (with -DOZONE, including ozone's absorption).
 * Both add the sun disc: sun_radiance (I_I T_sun / Omega_sun, from the host) where nu >= cos of the
 * sun's angular radius and the ray does not hit the planet. The ground is black, except with -DGROUND
 * (a Lambertian ground of albedo a): render_raymarch adds, for rays that end on the ground,
 *   I_I T(Pa, Pb) a / pi (mu_sun T_sun(Pb) + E_sky(mu_sun)),
 * the direct irradiance at the ground point's true sun cosine (view_ray.cl: ground_direct) and the
 * sky's from the table's 1D ground_irradiance (sum of the orders k >= 1, clsky/ground.py); the table
 * lookup's ground is in the table's higher orders (the scatter adds it, canonical geometry).
 * Each work-item renders VECTOR_WIDTH pixels; global size ceil(n / VECTOR_WIDTH). Pixels whose
 * valid[i] is 0 (outside a fisheye's circle) are written as 0.
 * Requires real.cl, atmosphere_t, geometry.cl, column.cl, transmittance_table.cl, mapping.cl,
 * phase.cl, view_ray.cl, lookup.cl.
 */

/* The pixels first .. first + VECTOR_WIDTH - 1: their view cosine at the observer (*mu_v_observer),
 * the observer's horizon cosine, and (h, mu_v, mu_s) moved to where each ray enters the atmosphere
 * (for observers above it); returns the mask of rays that see the atmosphere. */
inline maskv pixel_rays(__constant const atmosphere_t *atm, __global const real *directions, const int first,
                        const int n, const real4 sun, const real altitude, realv *mu_v_observer, realv *horizon,
                        realv *h, realv *mu_v, realv *mu_s, realv *nu);

/* Loads the directions of pixels first .. first + VECTOR_WIDTH - 1 (clamped to n - 1). */
inline void load_directions(__global const real *directions, const int first, const int n, const real4 sun,
                            realv *mu_v, realv *nu)
{
    for (int k = 0; k < VECTOR_WIDTH; ++k) {
        const size_t i = (size_t)min(first + k, n - 1);
        const real3 v = (real3)(directions[3 * i], directions[3 * i + 1], directions[3 * i + 2]);
        LANE(*mu_v, k) = clamp(v.z, R(-1.0), R(1.0));
        LANE(*nu, k) = clamp(dot(v, sun.xyz), R(-1.0), R(1.0));
    }
}

/* The sun disc's radiance in direction (nu, mu_v) seen from an observer whose horizon is at `horizon`. */
inline real3 sun_disc(const real nu, const real mu_v, const real horizon, const real4 sun_radiance,
                      const real cos_sun_radius)
{
    return (nu >= cos_sun_radius && mu_v >= horizon) ? sun_radiance.xyz : (real3)(R(0.0));
}

inline maskv pixel_rays(__constant const atmosphere_t *atm, __global const real *directions, const int first,
                        const int n, const real4 sun, const real altitude, realv *mu_v_observer, realv *horizon,
                        realv *h, realv *mu_v, realv *mu_s, realv *nu)
{
    load_directions(directions, first, n, sun, mu_v, nu);
    *mu_v_observer = *mu_v;
    *h = (realv)(altitude);
    *mu_s = (realv)(sun.z);
    *horizon = horizon_cos(*h, atm->planet_radius);
    return enter_atmosphere(atm->planet_radius, atm->top_radius, h, mu_v, mu_s, *nu);
}

/* 1 when none of pixels first .. first + VECTOR_WIDTH - 1 is valid: the work-item writes zeros and stops. */
inline int all_invalid(__global const uchar *valid, const int first, const int n, __global real *out)
{
    for (int k = 0; k < VECTOR_WIDTH && first + k < n; ++k)
        if (valid[first + k])
            return 0;
    for (int k = 0; k < VECTOR_WIDTH && first + k < n; ++k)
        for (int c = 0; c < 3; ++c)
            out[3 * (first + k) + c] = R(0.0);
    return 1;
}

inline void store_radiance(__global real *out, const int i, const real3 value)
{
    out[3 * i] = value.x;
    out[3 * i + 1] = value.y;
    out[3 * i + 2] = value.z;
}

/* For an observer inside the atmosphere, altitude and sun cosine are the same for every pixel of a
 * frame, so the host interpolates the table once at (h, mu_s) into a slice (H x channels) and each
 * pixel only interpolates linearly along the view axis (same result as the trilinear lookup, which
 * is linear in v). use_slice = 0 (observer above the atmosphere: h and mu_s change at each ray's entry
 * point) looks up the full table. */
__kernel void render_table(__constant const atmosphere_t *atm, __global const real *table, const int width,
                           const int height, const int depth, const int channels, const int mapping,
                           const real2 sun_range, __global const real *slice, const int use_slice,
                           const int n, __global const real *directions, __global const uchar *valid,
                           const real4 sun, const real altitude,
                           const real4 sun_radiance, const real cos_sun_radius, __global real *out)
{
    const int first = get_global_id(0) * VECTOR_WIDTH;
    if (first >= n || all_invalid(valid, first, n, out))
        return;
    realv mu_v_observer, horizon, h, mu_v, mu_s, nu;
    const maskv inside = pixel_rays(atm, directions, first, n, sun, altitude, &mu_v_observer, &horizon, &h, &mu_v,
                                    &mu_s, &nu);
    for (int k = 0; k < VECTOR_WIDTH && first + k < n; ++k) {
        real3 value = sun_disc(LANE(nu, k), LANE(mu_v_observer, k), LANE(horizon, 0), sun_radiance, cos_sun_radius);
        if (!valid[first + k]) {
        } else if (use_slice) {
            const real fy = MAPPING_V(LANE(mu_v, k), mapping) * (real)(height - 1);
            const int y0 = lower_node(fy, height);
            const real ay = fy - (real)y0;
            real ibar[9];
            for (int c = 0; c < channels; ++c)
                ibar[c] = (R(1.0) - ay) * slice[y0 * channels + c] + ay * slice[(y0 + 1) * channels + c];
            value += radiance_of_channels(atm, ibar, channels, LANE(nu, k));
        } else if (MASK_LANE(inside, k)) {
            value += table_radiance(atm, table, width, height, depth, channels, mapping, sun_range, LANE(h, k),
                                    LANE(mu_v, k), LANE(mu_s, k), LANE(nu, k));
        }
        store_radiance(out, first + k, valid[first + k] ? value : (real3)(R(0.0)));
    }
}

/* has_multiple: add the higher orders from `gathered` (padded (D, H, W, 8) on the table's grid, with
 * harmonics interleaved (D, H, W, M + 1, 8): view_ray.cl, add_lookups);
 * physical: 1 for the physical mode (phase inside G), 0 for atmosphere-plus (F_s(nu) applied here).
 * ground_irradiance: ground_depth x 4 reals, the sky's irradiance E_sky r, g, b (and 0) on the ground
 * per sun node of the table (mapping, sun_range), read only with -DGROUND.
 * RAY_SUNS frames at once (view_ray.cl: integrate_ray_suns; clsky.render.RAY_MARCH_SUNS): suns
 * holds 8 reals per sun, its direction (x, y, z, 0) and its disc's radiance (r, g, b, 0); out holds the
 * frames one after the other, n x 3 reals each. */
__kernel void render_raymarch(__constant const atmosphere_t *atm, __global const real *gathered, const int width,
                              const int height, const int depth, const int mapping, const real2 sun_range,
                              const int has_multiple,
                              const int physical, __global const real *sun_table, const int tw, const int th,
                              __global const real *ground_irradiance, const int ground_depth,
                              const int n, __global const real *directions, __global const uchar *valid,
                              __global const real *suns, const real altitude,
                              const real cos_sun_radius, __global real *out)
{
    const int first = get_global_id(0) * VECTOR_WIDTH;
    if (first >= n)
        return;
    int invalid = 1;
    for (int b = 0; b < RAY_SUNS; ++b)
        invalid = all_invalid(valid, first, n, out + (size_t)b * (size_t)3 * (size_t)n);
    if (invalid)
        return;
    realv mu_v_observer, horizon, h, mu_v, mu_s[RAY_SUNS], nu[RAY_SUNS];
    maskv inside;
    for (int b = 0; b < RAY_SUNS; ++b)          /* the same h, mu_v, horizon and inside for every sun */
        inside = pixel_rays(atm, directions, first, n, vload4(2 * b, suns), altitude, &mu_v_observer, &horizon, &h,
                            &mu_v, &mu_s[b], &nu[b]);

    realv single[RAY_SUNS][6];
    real8 multiple[RAY_SUNS][VECTOR_WIDTH];
#ifdef GROUND
    realv ground[RAY_SUNS][GROUND_VALUES];
#else
    realv *ground = 0;
#endif
    if (has_multiple)   /* one pass along the ray for both */
        integrate_ray_suns(atm, h, mu_v, mu_s, nu, gathered, width, height, depth, mapping, sun_range, multiple,
                           sun_table, tw, th, single, ground);
    else
        integrate_single_suns(atm, h, mu_v, mu_s, nu, RAY_SUNS, sun_table, tw, th, single, ground);

    const real scale = R(1.0) / (R(4.0) * PI_REAL);
    const real3 beta_r = atm->beta_rayleigh.xyz * scale;
    const real3 beta_m = atm->beta_mie.xyz * scale;
    const real3 light = atm->incident_light.xyz;
    for (int b = 0; b < RAY_SUNS; ++b) {
        const real4 sun_radiance = vload4(2 * b + 1, suns);
        for (int k = 0; k < VECTOR_WIDTH && first + k < n; ++k) {
            const real nu_k = LANE(nu[b], k);
            real3 value = sun_disc(nu_k, LANE(mu_v_observer, k), LANE(horizon, 0), sun_radiance, cos_sun_radius);
            if (MASK_LANE(inside, k)) {
                const real f_r = phase_rayleigh(atm, nu_k), f_m = phase_mie(atm, nu_k);
                const real3 ibar_r = beta_r * (real3)(LANE(single[b][0], k), LANE(single[b][1], k), LANE(single[b][2], k));
                const real3 ibar_m = beta_m * (real3)(LANE(single[b][3], k), LANE(single[b][4], k), LANE(single[b][5], k));
                real3 sky = f_r * ibar_r + f_m * ibar_m;
                if (has_multiple) {
                    const real3 g_r = beta_r * multiple[b][k].s012, g_m = beta_m * multiple[b][k].s345;
                    sky += physical ? g_r + g_m : f_r * g_r + f_m * g_m;
                }
#ifdef GROUND
                add_ground_reflection(atm, ground[b], k, ground_irradiance, ground_depth, mapping, sun_range, &sky);
#endif
                value += light * sky;
            }
            store_radiance(out + (size_t)b * (size_t)3 * (size_t)n, first + k, valid[first + k] ? value : (real3)(R(0.0)));
        }
    }
}

/* render_table4d: I = I_I (F_R(nu) Ibar_R + F_M(nu) Ibar_M + Lbar) from the 4D table (lookup4d.cl:
 * quadrilinear in altitude, view (split at the horizon), sun and azimuth; the phase at the exact nu).
 * For an observer inside the atmosphere the host interpolates the table at (h, mu_s) into a slice
 * (A, 1, H, 1, C), passed as `table` with width = depth = 1: each pixel then interpolates bilinearly
 * in (view, azimuth), the quadrilinear result up to the association of its weights. Above the
 * atmosphere (h and mu_s change at each ray's entry point) `table` is the whole table. */
__kernel void render_table4d(__constant const atmosphere_t *atm, __global const real *table, const int width,
                             const int height, const int depth, const int azimuths, const int channels,
                             const int mapping, const real2 sun_range, const int n,
                             __global const real *directions, __global const uchar *valid, const real4 sun,
                             const real altitude, const real4 sun_radiance, const real cos_sun_radius,
                             __global real *out)
{
    const int first = get_global_id(0) * VECTOR_WIDTH;
    if (first >= n || all_invalid(valid, first, n, out))
        return;
    realv mu_v_observer, horizon, h, mu_v, mu_s, nu;
    const maskv inside = pixel_rays(atm, directions, first, n, sun, altitude, &mu_v_observer, &horizon, &h, &mu_v,
                                    &mu_s, &nu);
    const realv fy = view4d_coordinate(h, mu_v, height, atm->planet_radius, atm->top_radius);
    const realv fa = azimuth4d_coordinate(mu_v, mu_s, nu, azimuths);
    for (int k = 0; k < VECTOR_WIDTH && first + k < n; ++k) {
        real3 value = sun_disc(LANE(nu, k), LANE(mu_v_observer, k), LANE(horizon, 0), sun_radiance, cos_sun_radius);
        if (valid[first + k] && MASK_LANE(inside, k)) {
            real ibar[9];
            interpolate4d(table, width, height, depth, azimuths, channels,
                          altitude4d_coordinate(atm, width, mapping, LANE(h, k)), LANE(fy, k),
                          sun4d_coordinate(depth, mapping, sun_range, LANE(mu_s, k)), LANE(fa, k), ibar);
            value += radiance_of_channels(atm, ibar, channels, LANE(nu, k));
        }
        store_radiance(out, first + k, valid[first + k] ? value : (real3)(R(0.0)));
    }
}
