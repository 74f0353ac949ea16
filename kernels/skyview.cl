/* skyview.cl -- kernel of clsky/render.py's render_skyview: HDR radiance per pixel from a per-frame
 * sky-view map (Hillaire 2020, "A Scalable and Production Ready Sky and Atmosphere Rendering Technique",
 * EGSR, sec. 5.3; mapping: clsky/skyview.py).
 *
 * The map: (sky_rows + ground_rows) x width nodes of radiance r, g, b (I_I units, or W m^-2 sr^-1 nm^-1
 * for absolute tables), row-major, 3 reals per node, without the sun's disc. Per pixel of unit view
 * direction V (observer's local frame, z = zenith) and sun direction S:
 *   theta = atan2(|V_xy|, V_z) (view zenith angle [rad]),
 *   phi in [0, pi], the azimuth from the sun's vertical plane, from the chord between the unit horizontal
 *   directions V_h = V_xy / |V_xy| and S_h = S_xy / |S_xy| (S_h = x where the sun is at the zenith or
 *   nadir, V_h = S_h where V is): c = |V_h - S_h| = 2 sin(phi / 2), well conditioned at phi = 0 and pi,
 *   sky half (mu_v = V_z >= mu_H): row = (1 - sqrt(1 - theta / theta_H)) (sky_rows - 1),
 *   ground half (mu_v < mu_H):     row = sky_rows + sqrt((theta - theta_H) / (pi - theta_H)) (ground_rows - 1),
 *   column = u (width - 1), u = sin(phi / 2) = c / 2 ('sun', azimuth_mapping 1: Hillaire's
 *   sqrt((1 - cos phi) / 2), no trigonometry per pixel) or phi / pi = 2 atan2(c, |V_h + S_h|) / pi ('linear', 0).
 * Bilinear in (row, column) within the pixel's half only: nothing is interpolated across the horizon.
 * Then the sun's disc is added as render.cl does (sun_disc). Invalid pixels are written as 0.
 * Arguments: horizon_cos = mu_H and horizon_angle = theta_H [rad] of the observer's altitude (host);
 * view_zenith: theta of each pixel, from view_zenith_angles (a camera's directions are the same every frame:
 * the renderer computes their angles once, clsky.render.PreparedDirections, and every frame reads them).
 * Requires render.cl (all_invalid, sun_disc, store_radiance) and what it requires.
 */

/* The view zenith angle theta = atan2(|V_xy|, V_z) [rad] of directions[i] into out[i], for every pixel
 * (valid or not), VECTOR_WIDTH pixels a work-item, each lane by the scalar atan2 of a pixel's own, as
 * render_skyview computed it per frame before it read them from here (the same values; with a realv
 * atan2 instead, 0.5 % of a frame's radiances differed in their last bits). */
__kernel void view_zenith_angles(const int n, __global const real *directions, __global real *out)
{
    const int first = get_global_id(0) * VECTOR_WIDTH;
    for (int k = 0; k < VECTOR_WIDTH && first + k < n; ++k) {
        const int i = first + k;
        const real3 v = (real3)(directions[3 * i], directions[3 * i + 1], directions[3 * i + 2]);
        out[i] = atan2(sqrt(v.x * v.x + v.y * v.y), v.z);
    }
}

/* Lower node and weight of coordinate f in [0, n - 1] (clamped), n >= 2. */
inline int skyview_node(const real f, const int n, real *weight)
{
    const real g = fmin(fmax(f, R(0.0)), (real)(n - 1));
    const int i = clamp((int)g, 0, n - 2);
    *weight = g - (real)i;
    return i;
}

__kernel void render_skyview(__constant const atmosphere_t *atm, __global const real *sky_map, const int width,
                             const int sky_rows, const int ground_rows, const int azimuth_mapping,
                             const real horizon_cos, const real horizon_angle, __global const real *view_zenith,
                             const int n, __global const real *directions, __global const uchar *valid,
                             const real4 sun, const real altitude,
                             const real4 sun_radiance, const real cos_sun_radius, __global real *out)
{
    const int first = get_global_id(0) * VECTOR_WIDTH;
    if (first >= n || all_invalid(valid, first, n, out))
        return;
    const real below = PI_REAL - horizon_angle;
    const real sun_horizontal = sqrt(sun.x * sun.x + sun.y * sun.y);
    const real2 sun_unit = sun_horizontal > R(0.0) ? (real2)(sun.x, sun.y) / sun_horizontal : (real2)(R(1.0), R(0.0));
    for (int k = 0; k < VECTOR_WIDTH && first + k < n; ++k) {
        const int i = first + k;
        if (!valid[i]) {
            store_radiance(out, i, (real3)(R(0.0)));
            continue;
        }
        const real3 v = (real3)(directions[3 * i], directions[3 * i + 1], directions[3 * i + 2]);
        const real mu_v = clamp(v.z, R(-1.0), R(1.0));
        const real nu = clamp(dot(v, sun.xyz), R(-1.0), R(1.0));
        const real theta = view_zenith[i];
        const real horizontal = sqrt(v.x * v.x + v.y * v.y);
        const real2 view = horizontal > R(0.0) ? (real2)(v.x, v.y) / horizontal : sun_unit;
        const real chord = length(view - sun_unit);           /* |V_h - S_h| = 2 sin(phi / 2) */
        const real u = azimuth_mapping == 1 ? fmin(R(0.5) * chord, R(1.0))
                                            : R(2.0) * atan2(chord, length(view + sun_unit)) / PI_REAL;
        real ax, ay;
        const int x0 = skyview_node(u * (real)(width - 1), width, &ax);
        int y0;
        if (mu_v >= horizon_cos) {
            const real t = R(1.0) - sqrt(fmax(R(1.0) - theta / horizon_angle, R(0.0)));
            y0 = skyview_node(t * (real)(sky_rows - 1), sky_rows, &ay);
        } else {
            const real t = sqrt(fmax((theta - horizon_angle) / below, R(0.0)));
            y0 = sky_rows + skyview_node(t * (real)(ground_rows - 1), ground_rows, &ay);
        }
        const size_t c00 = 3 * ((size_t)y0 * (size_t)width + (size_t)x0);
        const size_t c10 = c00 + 3 * (size_t)width;
        real3 value = sun_disc(nu, mu_v, horizon_cos, sun_radiance, cos_sun_radius);
        value += (R(1.0) - ay) * ((R(1.0) - ax) * vload3(0, sky_map + c00) + ax * vload3(0, sky_map + c00 + 3))
                 + ay * ((R(1.0) - ax) * vload3(0, sky_map + c10) + ax * vload3(0, sky_map + c10 + 3));
        store_radiance(out, i, value);
    }
}
