/* mapping4d.cl -- node coordinates of the 4D scattering table (clsky/table4d.py); twin of the *4d*
 * functions of clsky/mapping.py, whose comment gives the equations.
 *
 * View zenith, split at the horizon (after Bruneton 2017, "precomputed_atmospheric_scattering",
 * atmosphere/functions.glsl, GetScatteringTextureUvwzFromRMuMuSNu; node-centred here): from altitude
 * h [m], rho = sqrt(h (2 Rp + h)), K = sqrt(Ha (2 Rp + Ha)),
 *   mu < horizon_cos(h):  x = (d_ground - h) / (rho - h),                fy = (H/2 - 1) x
 *   otherwise:            x = (d_top - (Ha - h)) / (rho + K - (Ha - h)), fy = H/2 + (H/2 - 1)(1 - x)
 * Azimuth: fa = acos(cos phi) (A - 1) / pi, cos phi = (nu - mu_v mu_s) / sqrt((1 - mu_v^2)(1 - mu_s^2))
 * (1 where view or sun is vertical). Works on realv. Requires real.cl, geometry.cl.
 */

/* Node coordinate fy in [0, H - 1] of view cosine mu at altitude h [m] (clamped to [0, Ha]). */
inline realv view4d_coordinate(const realv altitude, const realv mu, const int height, const real planet_radius,
                               const real top_radius)
{
    const real ha = top_radius - planet_radius;
    const realv h = clamp(altitude, R(0.0), ha);
    const realv rho = sqrt(h * (R(2.0) * planet_radius + h));
    const real k = sqrt(ha * (R(2.0) * planet_radius + ha));
    const realv to_top = ha - h;
    const real half_nodes = (real)(height / 2);
    const realv x_ground = clamp((distance_to_ground(h, mu, planet_radius) - h) / fmax(rho - h, REAL_TINY),
                                 R(0.0), R(1.0));
    const realv x_sky = clamp((distance_to_top(h, mu, planet_radius, top_radius) - to_top)
                              / fmax(rho + k - to_top, REAL_TINY), R(0.0), R(1.0));
    return SELECT(half_nodes + (half_nodes - R(1.0)) * (R(1.0) - x_sky), (half_nodes - R(1.0)) * x_ground,
                  isless(mu, horizon_cos(h, planet_radius)));
}

/* Node coordinate fa in [0, A - 1] of the view-sun azimuth of (mu_v, mu_s, nu). */
inline realv azimuth4d_coordinate(const realv mu_v, const realv mu_s, const realv nu, const int size)
{
    const realv denominator = sqrt(fmax(R(1.0) - mu_v * mu_v, R(0.0)) * fmax(R(1.0) - mu_s * mu_s, R(0.0)));
    const realv cos_phi = SELECT(V(1.0), clamp((nu - mu_v * mu_s) / fmax(denominator, REAL_TINY), R(-1.0), R(1.0)),
                                 isgreater(denominator, REAL_TINY));
    return acos(cos_phi) * ((real)(size - 1) / PI_REAL);
}
