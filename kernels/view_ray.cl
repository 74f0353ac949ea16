/* view_ray.cl -- integrals along view rays, shared by the table kernels (single.cl, multiple.cl) and
 * the per-pixel renderer (render.cl).
 *
 * A view ray leaves an observer at altitude h0 (inside the atmosphere) along a direction whose zenith
 * cosine is mu_v; the sun's zenith cosine there is mu_s and nu = dot(V, Sun). At distance s along the
 * ray (physics.md; Bruneton & Neyret 2008, sec. 4):
 *   r(s)^2 = r0^2 + 2 r0 mu_v s + s^2,   mu_view(s) = (r0 mu_v + s) / r,   mu_sun(s) = (r0 mu_s + s nu) / r,
 * so the integrals depend on (h0, mu_v, mu_s, nu) only: the 3D table uses the canonical
 * nu = cos(phi - delta), the renderer the true one.
 *
 * Trapezoidal rule over N_VIEW + 1 nodes s_i = L f(i / N_VIEW), f(x) = x, or x^3 with
 * -DKELLER_BOHN_SAMPLING (Keller & Bohn: clustered at the observer), or, with -DGROUND_END_SAMPLING,
 * x^3 on rays that leave the atmosphere and 1 - (1 - x)^3 on rays that hit the ground: there the
 * nodes cluster at the ground end, where the haze is, rather than at an observer far above it
 * (README, "Views from altitude"). The last node of a ground-hitting ray lies at altitude exactly 0.
 * Transmittances T = exp(-tau) take every species' column from column.cl (column_t, optical_depth_of):
 * with -DOZONE they include ozone's absorption, tau += sigma_O3 n_max C_O.
 * With -DGROUND (a Lambertian ground of albedo a, clsky/ground.py) both integrals can also report
 * what a ray sees of the ground (ground_view, ground_direct): T(Pa, Pb) where the ray ends on the ground, the sun
 * cosine there and, where the sun columns are computed, the direct irradiance mu_sun T_sun (units of
 * I_I) on the horizontal ground at Pb; the callers add T a / pi E(mu_sun) (physics.md).
 * Works on realv. Requires real.cl, atmosphere_t, geometry.cl, column.cl, transmittance_table.cl,
 * mapping.cl.
 */
#ifndef N_VIEW
#error "N_VIEW (number of trapezoid steps along a view ray) must be defined"
#endif

inline real view_node(const int i)
{
    const real x = (real)i / (real)N_VIEW;
#ifdef KELLER_BOHN_SAMPLING
    return x * x * x;
#else
    return x;
#endif
}

/* A node's place along the ray, f(i / N_VIEW): one value for every lane, or, with
 * -DGROUND_END_SAMPLING, one per lane (a select between the two placements, no search). */
#ifdef GROUND_END_SAMPLING
typedef realv view_node_t;
#else
typedef real view_node_t;
#endif

inline view_node_t view_node_at(const int i, const maskv hits_ground)
{
#ifdef GROUND_END_SAMPLING
    const real x = (real)i / (real)N_VIEW;
    const real y = R(1.0) - x;
    return SELECT((realv)(x * x * x), (realv)(R(1.0) - y * y * y), hits_ground);
#else
    return view_node(i);
#endif
}

/* The cells x = VECTOR_WIDTH gx + lane of row (y, z) of a table (W, H, D, mapping, sun nodes over
 * w in sun_range): altitudes h0, view and sun cosines, and the scattering cosine of a view at azimuth
 * phi from the sun's, nu = mu_v mu_s + sqrt(1 - mu_v^2) sqrt(1 - mu_s^2) cos_azimuth: cos_azimuth = 1
 * is the canonical frame's nu = cos(phi - delta) (clsky/azimuth.py: the nodes of the harmonic orders). */
inline void table_cell(__constant const atmosphere_t *atm, const int gx, const int y, const int z, const int width,
                       const int height, const int depth, const int mapping, const real2 sun_range,
                       const real cos_azimuth, realv *h0, real *mu_v, real *mu_s, real *nu)
{
    const real ha = atm->top_radius - atm->planet_radius;
    const realv u = fmin((real)(gx * VECTOR_WIDTH) + LANE_INDEX, (real)(width - 1)) / (real)(width - 1);
    const real v = (real)y / (real)(height - 1);
    const real w = sun_range.x + (sun_range.y - sun_range.x) * ((real)z / (real)(depth - 1));
    *h0 = MAPPING_ALTITUDE(u, mapping, ha);
    *mu_v = MAPPING_COS(v, mapping);
    *mu_s = MAPPING_COS(w, mapping);
    *nu = *mu_v * *mu_s + sqrt(fmax(R(1.0) - *mu_v * *mu_v, R(0.0)) * fmax(R(1.0) - *mu_s * *mu_s, R(0.0))) * cos_azimuth;
}

/* Length [m] of the view ray to the top of the atmosphere or to the ground (*hits_ground). */
inline realv view_ray_length(__constant const atmosphere_t *atm, const realv h0, const realv mu_v, maskv *hits_ground)
{
    const real rp = atm->planet_radius;
    *hits_ground = isless(mu_v, horizon_cos(h0, rp));
    return SELECT(distance_to_top(h0, mu_v, rp, atm->top_radius), distance_to_ground(h0, mu_v, rp), *hits_ground);
}

/* Column densities *sun [m] from a node at altitude h toward the sun (zenith cosine
 * mu_sun), read from the 2D table (-DSUN_TRANSMITTANCE_TABLE) or re-marched; returns the mask of
 * nodes the sun lights (not in the planet's shadow, decided from h and mu_sun against the local
 * horizon). In the shadow the march would cross the planet: it is given zero length, and the
 * caller discards the result. */
inline maskv sun_column(__constant const atmosphere_t *atm, const realv h, const realv mu_sun,
                        __global const real *sun_table, const int tw, const int th, column_t *sun)
{
    const maskv lit = isgreaterequal(mu_sun, horizon_cos(h, atm->planet_radius));
#ifdef SUN_TRANSMITTANCE_TABLE
    *sun = column_density_from_table(atm, sun_table, tw, th, h, mu_sun);
#else
    const realv sun_length = SELECT(V(0.0), distance_to_top(h, mu_sun, atm->planet_radius, atm->top_radius), lit);
    *sun = column_density(atm, h, mu_sun, sun_length);
#endif
    return lit;
}

#ifdef GROUND
/* ground[0..6] of a ray's last node (GROUND_VALUES per ray): T(Pa, Pb) r, g, b (0 where the ray does not
 * hit the ground), the sun cosine at Pb, then the direct irradiance mu_sun T_sun r, g, b (0 in the
 * planet's shadow; set by ground_direct, 0 otherwise). */
#define GROUND_VALUES 7
inline void ground_view(__constant const atmosphere_t *atm, const column_t view, const maskv hits_ground,
                        const realv mu_sun, realv *ground)
{
    const real4 beta = atm->beta_rayleigh;
    const real4 beta_me = atm->beta_mie_extinction;
    const real4 beta_o = atm->ozone_extinction;
    ground[0] = SELECT(V(0.0), exp(-optical_depth_of(view, beta.x, beta_me.x, beta_o.x)), hits_ground);
    ground[1] = SELECT(V(0.0), exp(-optical_depth_of(view, beta.y, beta_me.y, beta_o.y)), hits_ground);
    ground[2] = SELECT(V(0.0), exp(-optical_depth_of(view, beta.z, beta_me.z, beta_o.z)), hits_ground);
    ground[3] = mu_sun;
    ground[4] = ground[5] = ground[6] = V(0.0);
}

/* The direct irradiance at the ground node from its sun columns (lit: not in the planet's shadow). */
inline void ground_direct(__constant const atmosphere_t *atm, const column_t sun, const maskv lit, realv *ground)
{
    const real4 beta = atm->beta_rayleigh;
    const real4 beta_me = atm->beta_mie_extinction;
    const real4 beta_o = atm->ozone_extinction;
    const realv mu = fmax(ground[3], V(0.0));
    ground[4] = SELECT(V(0.0), mu * exp(-optical_depth_of(sun, beta.x, beta_me.x, beta_o.x)), lit);
    ground[5] = SELECT(V(0.0), mu * exp(-optical_depth_of(sun, beta.y, beta_me.y, beta_o.y)), lit);
    ground[6] = SELECT(V(0.0), mu * exp(-optical_depth_of(sun, beta.z, beta_me.z, beta_o.z)), lit);
}

/* A per-sun-node table values[z][0..3] (D nodes over w in sun_range, mapping) interpolated linearly in
 * the sun axis' texture coordinate at sun cosine mu_sun, as the 3D lookups do. */
inline real4 sun_axis_lookup(__global const real *values, const int depth, const int mapping, const real2 sun_range,
                             const real mu_sun)
{
    const real fz = MAPPING_SUN_T(mu_sun, mapping, sun_range) * (real)(depth - 1);
    /* the node index from a coordinate clamped first: a NaN (fmax returns the other operand) or a value
     * beyond int's range must never reach the conversion, whose result is then undefined */
    const int z0 = clamp((int)fmin(fmax(fz, R(0.0)), (real)(depth - 2)), 0, depth - 2);
    const real az = fz - (real)z0;
    return (R(1.0) - az) * vload4(z0, values) + az * vload4(z0 + 1, values);
}
#endif

/* Single scattering along the ray: sum[0..2] = Integral rho_R T dt (r, g, b), sum[3..5] the same with
 * rho_M, T = T(Pc, P) T(P, Pa), zero where P is in the planet's shadow (decided from P's altitude and
 * sun cosine against the local horizon, never from rounding). Multiply by beta_s / (4 pi) for Ibar.
 * With -DGROUND and ground != 0, also ground[0..GROUND_VALUES - 1] of the last node (ground_view,
 * ground_direct). */
inline void integrate_single(__constant const atmosphere_t *atm, const realv h0, const realv mu_v,
                             const realv mu_s, const realv nu, __global const real *sun_table,
                             const int tw, const int th, realv *sum, realv *ground)
{
    const real rp = atm->planet_radius;
    const realv r0 = rp + h0;
    maskv hits_ground;
    const realv length = view_ray_length(atm, h0, mu_v, &hits_ground);
    const real inv_hr = R(1.0) / atm->rayleigh_scale_height;
    const real inv_hm = R(1.0) / atm->mie_scale_height;
    const real4 beta = atm->beta_rayleigh;
    const real4 beta_me = atm->beta_mie_extinction;
    const real4 beta_o = atm->ozone_extinction;
    column_t view = column_zero();                          /* column densities from the observer */
    column_t last_density = column_zero();
    realv last[6];
    for (int c = 0; c < 6; ++c) {
        last[c] = V(0.0);
        sum[c] = V(0.0);
    }
    view_node_t node_previous = (view_node_t)(R(0.0));

    for (int i = 0; i <= N_VIEW; ++i) {
        const view_node_t node = view_node_at(i, hits_ground);
        const realv s = length * node;
        realv h = altitude_along(h0, r0, mu_v, s, rp);
        if (i == N_VIEW)
            h = SELECT(h, V(0.0), hits_ground);
        const realv r = rp + h;
        const realv mu_sun_here = (r0 * mu_s + s * nu) / r;     /* dot(P, Sun) / |P| */
        const column_t density = densities_at(atm, h, inv_hr, inv_hm);
        const realv half_step = R(0.5) * length * (node - node_previous);
        if (i > 0)
            view = column_step(view, last_density, density, half_step);
        column_t sun;
        const maskv lit = sun_column(atm, h, mu_sun_here, sun_table, tw, th, &sun);
        const column_t column = column_sum(view, sun);
        const realv t0 = SELECT(V(0.0), exp(-optical_depth_of(column, beta.x, beta_me.x, beta_o.x)), lit);
        const realv t1 = SELECT(V(0.0), exp(-optical_depth_of(column, beta.y, beta_me.y, beta_o.y)), lit);
        const realv t2 = SELECT(V(0.0), exp(-optical_depth_of(column, beta.z, beta_me.z, beta_o.z)), lit);
#ifdef GROUND
        if (ground && i == N_VIEW) {
            ground_view(atm, view, hits_ground, mu_sun_here, ground);
            ground_direct(atm, sun, lit, ground);
        }
#endif
        realv f[6];
        f[0] = density.r * t0; f[1] = density.r * t1; f[2] = density.r * t2;
        f[3] = density.m * t0; f[4] = density.m * t1; f[5] = density.m * t2;
        for (int c = 0; c < 6; ++c) {
            if (i > 0)
                sum[c] += (last[c] + f[c]) * half_step;
            last[c] = f[c];
        }
        last_density = density;
        node_previous = node;
    }
}

/* Trilinear lookup in a padded table (D, H, W, 8) at node coordinates (fx, fy, fz). */
inline real8 lookup8(__global const real *table, const int width, const int height, const int depth,
                     const real fx, const real fy, const real fz)
{
    const int x0 = (int)fmin(fmax(fx, R(0.0)), (real)(width - 2)), y0 = (int)fmin(fmax(fy, R(0.0)), (real)(height - 2)),
              z0 = (int)fmin(fmax(fz, R(0.0)), (real)(depth - 2));    /* clamped before the conversion (NaN-safe) */
    const real ax = fx - (real)x0, ay = fy - (real)y0, az = fz - (real)z0;
    const size_t base = (size_t)x0 + (size_t)width * ((size_t)y0 + (size_t)height * (size_t)z0);
    const size_t dy = (size_t)width, dz = (size_t)width * (size_t)height;
    const real8 c00 = (R(1.0) - ax) * vload8(base, table) + ax * vload8(base + 1, table);
    const real8 c10 = (R(1.0) - ax) * vload8(base + dy, table) + ax * vload8(base + dy + 1, table);
    const real8 c01 = (R(1.0) - ax) * vload8(base + dz, table) + ax * vload8(base + dz + 1, table);
    const real8 c11 = (R(1.0) - ax) * vload8(base + dy + dz, table) + ax * vload8(base + dy + dz + 1, table);
    return (R(1.0) - az) * ((R(1.0) - ay) * c00 + ay * c10) + az * ((R(1.0) - ay) * c01 + ay * c11);
}

#ifndef AZIMUTH_HARMONICS
#define AZIMUTH_HARMONICS 0
#endif
/* The gathered source at a node: with -DAZIMUTH_HARMONICS=M (clsky/azimuth.py) `gathered` holds the
 * M + 1 cosine harmonics G_m, each a padded (D, H, W, 8) table, one after the other, and the source is
 *   max(0, sum_m G_m(h, mu_view, mu_sun) cos(m phi)),
 * phi the local azimuth between the view's and the sun's horizontal directions at the node, distance s
 * along a ray from radius r0 with (mu_v, mu_s, nu) at its start, in a form free of cancellation near
 * the vertical (P = r0 Z + s V; r sin(view zenith) = r0 sqrt(1 - mu_v^2), r sin(sun zenith) = |P x Sun|,
 * r^2 (nu - mu_view mu_sun) = r0 (r0 (nu - mu_v mu_s) + s (mu_v nu - mu_s))):
 *   cos phi = (r0 (nu - mu_v mu_s) + s (mu_v nu - mu_s)) / (sqrt(1 - mu_v^2) |P x Sun|),
 *   |P x Sun|^2 = r0^2 (1 - mu_s^2) + 2 r0 s (mu_v - mu_s nu) + s^2 (1 - nu^2),
 * 1 where the denominator is 0 (view or sun vertical: no azimuth), cos(m phi) by the Chebyshev
 * recurrence. Without it (M = 0) the one table's trilinear lookup. */
inline real8 gathered_source(__global const real *gathered, const int width, const int height, const int depth,
                             const real fx, const real fy, const real fz, const real r0, const real s,
                             const real mu_v, const real mu_s, const real nu)
{
    real8 g = lookup8(gathered, width, height, depth, fx, fy, fz);
#if AZIMUTH_HARMONICS > 0
    const size_t stride = (size_t)8 * (size_t)width * (size_t)height * (size_t)depth;
    const real cross2 = r0 * r0 * fmax(R(1.0) - mu_s * mu_s, R(0.0)) + R(2.0) * r0 * s * (mu_v - mu_s * nu)
                        + s * s * fmax(R(1.0) - nu * nu, R(0.0));
    const real denominator = sqrt(fmax(R(1.0) - mu_v * mu_v, R(0.0))) * sqrt(fmax(cross2, R(0.0)));
    const real numerator = r0 * (nu - mu_v * mu_s) + s * (mu_v * nu - mu_s);
    const real c = denominator > R(0.0) ? clamp(numerator / denominator, R(-1.0), R(1.0)) : R(1.0);
    real previous = R(1.0), current = c;
    for (int m = 1; m <= AZIMUTH_HARMONICS; ++m) {
        g += current * lookup8(gathered + (size_t)m * stride, width, height, depth, fx, fy, fz);
        const real next = R(2.0) * c * current - previous;
        previous = current;
        current = next;
    }
    g = fmax(g, (real8)(R(0.0)));
#endif
    return g;
}

/* In-scattering of a gathered table along the ray, per lane k:
 *   sum[k].s012 = Integral rho_R T(P, Pa) Gbar_R dt (r, g, b), sum[k].s345 the same with rho_M, Gbar_M
 * with Gbar (padded (D, H, W, 8), the table's grid, mapping and sun_range) looked up trilinearly at each node's
 * altitude, view and sun cosines (and, with -DAZIMUTH_HARMONICS, summed over its harmonics at the local
 * azimuth: gathered_source). The trapezoid sum_i (f_(i-1) + f_i) h_i / 2 is accumulated as
 * sum_i f_i (h_i + h_(i+1)) / 2, so that each lane's 6 channels are one real8 FMA per node.
 * With single != 0 (the per-pixel ray march), the same pass also accumulates single scattering into
 * single[0..5] as integrate_single does (sun columns from sun_table or re-marched), sharing the
 * geometry, densities and view transmittance of each node. With -DGROUND and ground != 0, also
 * ground[0..GROUND_VALUES - 1] of the last node (the direct irradiance only with single != 0). */
inline void integrate_gathered(__constant const atmosphere_t *atm, const realv h0, const realv mu_v,
                               const realv mu_s, const realv nu, __global const real *gathered,
                               const int width, const int height, const int depth, const int mapping,
                               const real2 sun_range, real8 *sum, __global const real *sun_table, const int tw, const int th,
                               realv *single, realv *ground)
{
    const real rp = atm->planet_radius;
    const real ha = atm->top_radius - rp;
    const realv r0 = rp + h0;
    maskv hits_ground;
    const realv length = view_ray_length(atm, h0, mu_v, &hits_ground);
    const real inv_hr = R(1.0) / atm->rayleigh_scale_height;
    const real inv_hm = R(1.0) / atm->mie_scale_height;
    const real4 beta = atm->beta_rayleigh;
    const real4 beta_me = atm->beta_mie_extinction;
    const real4 beta_o = atm->ozone_extinction;
    column_t view = column_zero();
    column_t last_density = column_zero();
    for (int k = 0; k < VECTOR_WIDTH; ++k)
        sum[k] = (real8)(R(0.0));
    if (single)
        for (int c = 0; c < 6; ++c)
            single[c] = V(0.0);
    view_node_t node_previous = (view_node_t)(R(0.0));

    for (int i = 0; i <= N_VIEW; ++i) {
        const view_node_t node = view_node_at(i, hits_ground);
        const view_node_t node_next = i < N_VIEW ? view_node_at(i + 1, hits_ground) : node;
        const realv s = length * node;
        realv h = altitude_along(h0, r0, mu_v, s, rp);
        if (i == N_VIEW)
            h = SELECT(h, V(0.0), hits_ground);
        const realv inv_r = R(1.0) / (rp + h);
        const realv mu_view_here = clamp((r0 * mu_v + s) * inv_r, R(-1.0), R(1.0));
        const realv mu_sun_here = clamp((r0 * mu_s + s * nu) * inv_r, R(-1.0), R(1.0));
        const column_t density = densities_at(atm, h, inv_hr, inv_hm);
        if (i > 0) {
            const realv half_step = R(0.5) * length * (node - node_previous);
            view = column_step(view, last_density, density, half_step);
        }
        const realv weight = R(0.5) * length * ((node - node_previous) + (node_next - node));
        const realv t0 = exp(-optical_depth_of(view, beta.x, beta_me.x, beta_o.x));
        const realv t1 = exp(-optical_depth_of(view, beta.y, beta_me.y, beta_o.y));
        const realv t2 = exp(-optical_depth_of(view, beta.z, beta_me.z, beta_o.z));
        const realv wr = weight * density.r, wm = weight * density.m;
        const realv fr0 = wr * t0, fr1 = wr * t1, fr2 = wr * t2, fm0 = wm * t0, fm1 = wm * t1, fm2 = wm * t2;
#ifdef GROUND
        if (ground && i == N_VIEW)
            ground_view(atm, view, hits_ground, mu_sun_here, ground);
#endif
        if (single) {
            column_t sun;
            const maskv lit = sun_column(atm, h, mu_sun_here, sun_table, tw, th, &sun);
            const realv s0 = SELECT(V(0.0), exp(-optical_depth_of(sun, beta.x, beta_me.x, beta_o.x)), lit);
            const realv s1 = SELECT(V(0.0), exp(-optical_depth_of(sun, beta.y, beta_me.y, beta_o.y)), lit);
            const realv s2 = SELECT(V(0.0), exp(-optical_depth_of(sun, beta.z, beta_me.z, beta_o.z)), lit);
            single[0] += fr0 * s0; single[1] += fr1 * s1; single[2] += fr2 * s2;
            single[3] += fm0 * s0; single[4] += fm1 * s1; single[5] += fm2 * s2;
#ifdef GROUND
            if (ground && i == N_VIEW)
                ground_direct(atm, sun, lit, ground);
#endif
        }
        const realv fx = MAPPING_U(h, mapping, ha) * (real)(width - 1);
        const realv fy = MAPPING_V(mu_view_here, mapping) * (real)(height - 1);
        const realv fz = MAPPING_SUN_T(mu_sun_here, mapping, sun_range) * (real)(depth - 1);
        for (int k = 0; k < VECTOR_WIDTH; ++k) {
            const real8 factor = (real8)(LANE(fr0, k), LANE(fr1, k), LANE(fr2, k), LANE(fm0, k), LANE(fm1, k),
                                         LANE(fm2, k), R(0.0), R(0.0));
            sum[k] += factor * gathered_source(gathered, width, height, depth, LANE(fx, k), LANE(fy, k), LANE(fz, k),
                                               LANE(r0, k), LANE(s, k), LANE(mu_v, k), LANE(mu_s, k), LANE(nu, k));
        }
        last_density = density;
        node_previous = node;
    }
}
