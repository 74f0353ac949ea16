/* lookup.cl -- kernel of clsky/lookup.py: radiance from the 3D scattering table.
 *
 *   I = I_I (F_R(cos theta) Ibar_R + F_M(cos theta) Ibar_M)            (physics.md, "Rendering")
 * with Ibar interpolated trilinearly in texture space (u, v, w) (mapping.cl) and the phase functions
 * evaluated at the true scattering angle cos theta = dot(Sun, V) (phase.cl).
 *
 * Inputs per query: observer altitude h [m] (>= 0; above Ha the observer looks from space: the view
 * ray is moved to where it enters the atmosphere, and a ray that misses it sees no sky), cosines of
 * the view zenith, sun zenith and scattering angle. Table: `channels` per cell, cell index
 * x + y W + z W H: 6 (Rayleigh r, g, b, Mie r, g, b) or 4 (the notes' Rayleigh r, g, b + one Mie),
 * factored (the phase is applied here); the physical mode appends 3 channels (9 or 7 in all) holding
 * the higher orders with their phase already applied, added as I_I Lbar.
 * Output: radiance r, g, b per query. The `lookup` kernel is built with VECTOR_WIDTH 1.
 * Requires real.cl, atmosphere_t, geometry.cl, mapping.cl, phase.cl.
 */

inline int lower_node(const real f, const int n)
{
    return clamp((int)f, 0, n - 2);
}

/* I = I_I (F_R(nu) Ibar_R + F_M(nu) Ibar_M [+ Lbar]) from interpolated channels ibar (see the header). */
inline real3 radiance_of_channels(__constant const atmosphere_t *atm, const real *ibar, const int channels,
                                  const real nu)
{
    const real f_r = phase_rayleigh(atm, nu);
    const real f_m = phase_mie(atm, nu);
    const int factored = (channels == 7 || channels == 9) ? channels - 3 : channels;
    const int mie = 3;                          /* first Mie channel */
    const int mie_stride = factored == 6;       /* Mie per wavelength, or the notes' one Mie channel */
    const int multiple = factored < channels;   /* the physical mode's phased higher orders follow */
    return atm->incident_light.xyz * (real3)(
        f_r * ibar[0] + f_m * ibar[mie] + (multiple ? ibar[factored] : R(0.0)),
        f_r * ibar[1] + f_m * ibar[mie + mie_stride] + (multiple ? ibar[factored + 1] : R(0.0)),
        f_r * ibar[2] + f_m * ibar[mie + 2 * mie_stride] + (multiple ? ibar[factored + 2] : R(0.0)));
}

/* Radiance r, g, b at (h, mu_v, mu_s, nu) for an observer inside the atmosphere (see the header). */
inline real3 table_radiance(__constant const atmosphere_t *atm, __global const real *table, const int width,
                            const int height, const int depth, const int channels, const int mapping,
                            const real2 sun_range, const real h, const real mu_v, const real mu_s, const real nu)
{
    real ibar[9] = {R(0.0), R(0.0), R(0.0), R(0.0), R(0.0), R(0.0), R(0.0), R(0.0), R(0.0)};
    const real ha = atm->top_radius - atm->planet_radius;
    const real fx = MAPPING_U(h, mapping, ha) * (real)(width - 1);
    const real fy = MAPPING_V(mu_v, mapping) * (real)(height - 1);
    const real fz = MAPPING_SUN_T(mu_s, mapping, sun_range) * (real)(depth - 1);
    const int x0 = lower_node(fx, width), y0 = lower_node(fy, height), z0 = lower_node(fz, depth);
    const real ax = fx - (real)x0, ay = fy - (real)y0, az = fz - (real)z0;
    for (int corner = 0; corner < 8; ++corner) {
        const int dx = corner & 1, dy = (corner >> 1) & 1, dz = corner >> 2;
        const real weight = (dx ? ax : R(1.0) - ax) * (dy ? ay : R(1.0) - ay) * (dz ? az : R(1.0) - az);
        const size_t cell = (size_t)(x0 + dx) + (size_t)width * ((size_t)(y0 + dy) + (size_t)height * (size_t)(z0 + dz));
        for (int c = 0; c < channels; ++c)
            ibar[c] += weight * table[cell * channels + c];
    }
    return radiance_of_channels(atm, ibar, channels, nu);
}

#if VECTOR_WIDTH == 1   /* the render program (RenderEngine.program_sources) joins this file for table_radiance */
__kernel void lookup(__constant const atmosphere_t *atm, __global const real *table,
                     const int width, const int height, const int depth, const int channels,
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
    const real3 value = inside ? table_radiance(atm, table, width, height, depth, channels, mapping, sun_range, h, mu_v,
                                                 mu_s, nu)
                               : (real3)(R(0.0));
    radiance[3 * i] = value.x;
    radiance[3 * i + 1] = value.y;
    radiance[3 * i + 2] = value.z;
}
#endif
