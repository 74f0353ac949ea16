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

/* What sun_column takes from a node's altitude h alone, whatever the sun: the horizon cosine there and,
 * with -DSUN_TRANSMITTANCE_TABLE, the altitude's corner and weight in the 2D table (sun_table_altitude).
 * Computed once per ray node for all the suns it is lit by (two square roots and two divisions), not once a sun. */
inline sun_table_altitude_t sun_altitude(__constant const atmosphere_t *atm, const int tw, const realv h)
{
#ifdef SUN_TRANSMITTANCE_TABLE
    return sun_table_altitude(atm, tw, h);
#else
    sun_table_altitude_t a;
    a.mu_h = horizon_cos(h, atm->planet_radius);
    a.x0 = (intv)(0);
    a.ax = V(0.0);
    return a;
#endif
}

/* The mask of the lanes whose node (`at`: sun_altitude of its altitude) the sun of zenith cosine mu_sun
 * lights: not in the planet's shadow, decided from the local horizon (sun_column's test; a ray node whose
 * lanes are all unlit skips the sun's columns). A tie is lit: a sun cosine within SHADOW_TIE of the
 * horizon's, where the sun ray grazes the ground (the horizontal view away from a sun exactly on the
 * horizon: every node's, in exact arithmetic), the limit of the rays just above it; the sign of the
 * rounding noise decided such nodes, 11 % of that pixel, and differently in the twin. SHADOW_TIE is 8
 * float64 ulps of 1 in either precision: float32 rounds the cosines by ~1e-7, and 8 of its ulps lit
 * nodes truly in the shadow (8 % of a pixel against the float64 twin); its ties stay its rounding's. */
#define SHADOW_TIE R(1.7763568394002505e-15)
inline maskv sun_lit(const sun_table_altitude_t *at, const realv mu_sun)
{
    return isgreaterequal(mu_sun, at->mu_h - SHADOW_TIE);
}

/* Column densities *sun [m] from a node at altitude h (`at`: sun_altitude of h) toward the sun (zenith
 * cosine mu_sun), read from the 2D table (-DSUN_TRANSMITTANCE_TABLE) or re-marched; returns the mask of
 * nodes the sun lights (not in the planet's shadow, decided from h and mu_sun against the local
 * horizon). In the shadow the march would cross the planet: it is given zero length, and the
 * caller discards the result. */
inline maskv sun_column(__constant const atmosphere_t *atm, const realv h, const sun_table_altitude_t *at,
                        const realv mu_sun, __global const real *sun_table, const int tw, const int th, column_t *sun)
{
    const maskv lit = sun_lit(at, mu_sun);
#ifdef SUN_TRANSMITTANCE_TABLE
    *sun = column_density_from_table(sun_table, tw, th, at, mu_sun);
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

/* Adds to *sky what lane k of a ray sees of a Lambertian ground, in units of I_I: T(Pa, Pb) a / pi (mu_sun
 * T_sun + E_sky(mu_sun)) at its last node (0 where it does not hit the ground), from ground[] of
 * integrate_single or integrate_gathered (with single) and E_sky the table's per-sun-node
 * ground_irradiance (sun_axis_lookup). One statement, so that its rounding (FMA contraction) is the
 * ray march's as it was written inline in render.cl. */
inline void add_ground_reflection(__constant const atmosphere_t *atm, const realv *ground, const int k,
                                  __global const real *ground_irradiance, const int ground_depth, const int mapping,
                                  const real2 sun_range, real3 *sky)
{
    const real3 irradiance = (real3)(LANE(ground[4], k), LANE(ground[5], k), LANE(ground[6], k))
        + sun_axis_lookup(ground_irradiance, ground_depth, mapping, sun_range, LANE(ground[3], k)).xyz;
    *sky += (real3)(LANE(ground[0], k), LANE(ground[1], k), LANE(ground[2], k))
            * (atm->ground_albedo / PI_REAL) * irradiance;
}
#endif

/* Suns per ray of the per-pixel ray march (render.cl: render_raymarch; clsky.render.RAY_MARCH_SUNS). */
#ifndef RAY_SUNS
#define RAY_SUNS 1
#endif

/* The ground values of several suns (integrate_single_suns, integrate_ray_suns): ground[b][0..6]
 * with -DGROUND, unused (0) without. */
#ifdef GROUND
#define GROUND_OF_SUNS realv (*ground)[GROUND_VALUES]
#else
#define GROUND_OF_SUNS realv *ground
#endif

/* Single scattering along the ray for `count` suns at once (count <= SINGLE_SUN_NODES), sun b of zenith
 * cosine mu_s[b] and nu[b] = dot(V, Sun_b) at the observer:
 *   sum[b][0..2] = Integral rho_R T dt (r, g, b), sum[b][3..5] the same with rho_M, T = T(Pc, P) T(P, Pa),
 * zero where P is in the planet's shadow (decided from P's altitude and sun cosine against the local horizon,
 * never from rounding). Multiply by beta_s / (4 pi) for Ibar. The ray's nodes, altitudes, densities and
 * view columns do not depend on the sun: each is computed once for every sun, and each sun's sums are
 * the same operations as for that sun alone (the single-scattering table marches a ray once for
 * SINGLE_SUN_NODES sun nodes: single.cl). With -DGROUND and ground != 0, also ground[b][0..GROUND_VALUES - 1]
 * of the last node for each sun (ground_view, ground_direct). */
#ifndef SINGLE_SUN_NODES
#define SINGLE_SUN_NODES RAY_SUNS
#endif
inline void integrate_single_suns(__constant const atmosphere_t *atm, const realv h0, const realv mu_v,
                                  const realv *mu_s, const realv *nu, const int count,
                                  __global const real *sun_table, const int tw, const int th,
                                  realv sum[][6], GROUND_OF_SUNS)
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
    realv last[SINGLE_SUN_NODES][6];
    for (int b = 0; b < count; ++b)
        for (int c = 0; c < 6; ++c) {
            last[b][c] = V(0.0);
            sum[b][c] = V(0.0);
        }
    view_node_t node_previous = (view_node_t)(R(0.0));

    for (int i = 0; i <= N_VIEW; ++i) {
        const view_node_t node = view_node_at(i, hits_ground);
        const realv s = length * node;
        realv h = altitude_along(h0, r0, mu_v, s, rp);
        if (i == N_VIEW)
            h = SELECT(h, V(0.0), hits_ground);
        const realv r = rp + h;
        const column_t density = densities_at(atm, h, inv_hr, inv_hm);
        const realv half_step = R(0.5) * length * (node - node_previous);
        if (i > 0)
            view = column_step(view, last_density, density, half_step);
        const sun_table_altitude_t at = sun_altitude(atm, tw, h);
        for (int b = 0; b < count; ++b) {
            const realv mu_sun_here = (r0 * mu_s[b] + s * nu[b]) / r;     /* dot(P, Sun) / |P| */
            realv t0 = V(0.0), t1 = V(0.0), t2 = V(0.0);
#ifdef GROUND
            if (ground && i == N_VIEW)
                ground_view(atm, view, hits_ground, mu_sun_here, ground[b]);
#endif
            /* where no lane is lit, the columns and exponentials would all be discarded: not computed */
            if (ANY_LANE(sun_lit(&at, mu_sun_here))) {
                column_t sun;
                const maskv lit = sun_column(atm, h, &at, mu_sun_here, sun_table, tw, th, &sun);
                const column_t column = column_sum(view, sun);
                t0 = SELECT(V(0.0), exp(-optical_depth_of(column, beta.x, beta_me.x, beta_o.x)), lit);
                t1 = SELECT(V(0.0), exp(-optical_depth_of(column, beta.y, beta_me.y, beta_o.y)), lit);
                t2 = SELECT(V(0.0), exp(-optical_depth_of(column, beta.z, beta_me.z, beta_o.z)), lit);
#ifdef GROUND
                if (ground && i == N_VIEW)
                    ground_direct(atm, sun, lit, ground[b]);
#endif
            }
            realv f[6];
            f[0] = density.r * t0; f[1] = density.r * t1; f[2] = density.r * t2;
            f[3] = density.m * t0; f[4] = density.m * t1; f[5] = density.m * t2;
            for (int c = 0; c < 6; ++c) {
                if (i > 0)
                    sum[b][c] += (last[b][c] + f[c]) * half_step;
                last[b][c] = f[c];
            }
        }
        last_density = density;
        node_previous = node;
    }
}

/* Single scattering along the ray for one sun (integrate_single_suns): sum[0..5]. */
inline void integrate_single(__constant const atmosphere_t *atm, const realv h0, const realv mu_v,
                             const realv mu_s, const realv nu, __global const real *sun_table,
                             const int tw, const int th, realv *sum, realv *ground)
{
    realv sums[1][6];
#ifdef GROUND
    integrate_single_suns(atm, h0, mu_v, &mu_s, &nu, 1, sun_table, tw, th, sums, (realv (*)[GROUND_VALUES])ground);
#else
    integrate_single_suns(atm, h0, mu_v, &mu_s, &nu, 1, sun_table, tw, th, sums, ground);
#endif
    for (int c = 0; c < 6; ++c)
        sum[c] = sums[0][c];
}

/* The trilinear interpolation of a padded table's real8 cells between base, base + dx, base + dy,
 * base + dz, ... [real8] with weights ax, ay, az along x, y, z (the corner cell base: add_lookups). */
inline real8 trilinear8(__global const real *table, const size_t base, const size_t dx, const size_t dy,
                        const size_t dz, const real ax, const real ay, const real az)
{
    const real8 c00 = (R(1.0) - ax) * vload8(base, table) + ax * vload8(base + dx, table);
    const real8 c10 = (R(1.0) - ax) * vload8(base + dy, table) + ax * vload8(base + dy + dx, table);
    const real8 c01 = (R(1.0) - ax) * vload8(base + dz, table) + ax * vload8(base + dz + dx, table);
    const real8 c11 = (R(1.0) - ax) * vload8(base + dy + dz, table) + ax * vload8(base + dy + dz + dx, table);
    return (R(1.0) - az) * ((R(1.0) - ay) * c00 + ay * c10) + az * ((R(1.0) - ay) * c01 + ay * c11);
}

/* A view ray's march (integrate_gathered, integrate_gathered_suns): the ray, its quadrature state, and
 * what node i holds whatever the sun's direction. ray_begin sets the ray up; ray_step(i) moves to
 * node i: its distance s, altitude h (exactly 0 at a ground end), 1 / r, view cosine and densities
 * there, the view column from the observer (trapezoid), the node's trapezoid weight
 * (h_i + h_(i+1)) / 2 and the integrands f[c] = weight rho_s T(P, Pa) (Rayleigh r, g, b, Mie r, g, b).
 * Both integrals take their sun-independent work from here, so that it is written once. */
typedef struct {
    realv h0, r0, mu_v, length;
    realv sin_view;                 /* sqrt(1 - mu_v^2): the ray's, for the local azimuth (ray_azimuth_cos) */
    maskv hits_ground;
    real inv_hr, inv_hm;
    column_t view, last_density;
    view_node_t node_previous;
    /* node i */
    realv s, h, inv_r, mu_view_here;
    column_t density;
    realv f[6];
} view_march_t;

inline void ray_begin(__constant const atmosphere_t *atm, const realv h0, const realv mu_v, view_march_t *ray)
{
    ray->h0 = h0;
    ray->r0 = atm->planet_radius + h0;
    ray->mu_v = mu_v;
    ray->sin_view = sqrt(fmax(R(1.0) - mu_v * mu_v, V(0.0)));
    ray->length = view_ray_length(atm, h0, mu_v, &ray->hits_ground);
    ray->inv_hr = R(1.0) / atm->rayleigh_scale_height;
    ray->inv_hm = R(1.0) / atm->mie_scale_height;
    ray->view = column_zero();
    ray->last_density = column_zero();
    ray->node_previous = (view_node_t)(R(0.0));
}

inline void ray_step(__constant const atmosphere_t *atm, const int i, view_march_t *ray)
{
    const real rp = atm->planet_radius;
    const real4 beta = atm->beta_rayleigh;
    const real4 beta_me = atm->beta_mie_extinction;
    const real4 beta_o = atm->ozone_extinction;
    if (i > 0) {
        ray->last_density = ray->density;
        ray->node_previous = view_node_at(i - 1, ray->hits_ground);
    }
    const view_node_t node = view_node_at(i, ray->hits_ground);
    const view_node_t node_next = i < N_VIEW ? view_node_at(i + 1, ray->hits_ground) : node;
    const realv length = ray->length;
    ray->s = length * node;
    realv h = altitude_along(ray->h0, ray->r0, ray->mu_v, ray->s, rp);
    if (i == N_VIEW)
        h = SELECT(h, V(0.0), ray->hits_ground);
    ray->h = h;
    ray->inv_r = R(1.0) / (rp + h);
    ray->mu_view_here = clamp((ray->r0 * ray->mu_v + ray->s) * ray->inv_r, R(-1.0), R(1.0));
    const column_t density = densities_at(atm, h, ray->inv_hr, ray->inv_hm);
    if (i > 0) {
        const realv half_step = R(0.5) * length * (node - ray->node_previous);
        ray->view = column_step(ray->view, ray->last_density, density, half_step);
    }
    ray->density = density;
    const realv weight = R(0.5) * length * ((node - ray->node_previous) + (node_next - node));
    const realv t0 = exp(-optical_depth_of(ray->view, beta.x, beta_me.x, beta_o.x));
    const realv t1 = exp(-optical_depth_of(ray->view, beta.y, beta_me.y, beta_o.y));
    const realv t2 = exp(-optical_depth_of(ray->view, beta.z, beta_me.z, beta_o.z));
    const realv wr = weight * density.r, wm = weight * density.m;
    ray->f[0] = wr * t0; ray->f[1] = wr * t1; ray->f[2] = wr * t2;
    ray->f[3] = wm * t0; ray->f[4] = wm * t1; ray->f[5] = wm * t2;
}

/* The sun's zenith cosine at the current node of a ray, for a sun of zenith cosine mu_s at the observer
 * and scattering cosine nu (dot(P, Sun) / |P|). */
inline realv ray_sun_cos(const view_march_t *ray, const realv mu_s, const realv nu)
{
    return clamp((ray->r0 * mu_s + ray->s * nu) * ray->inv_r, R(-1.0), R(1.0));
}

/* Lane k's integrands f[0..5] (ray_step) as one real8, 2 zeros. */
inline real8 lane_integrands(const realv *f, const int k)
{
    return (real8)(LANE(f[0], k), LANE(f[1], k), LANE(f[2], k), LANE(f[3], k), LANE(f[4], k), LANE(f[5], k),
                   R(0.0), R(0.0));
}

/* What the lookups of one ray node share whatever the sun: each lane's integrands as one real8
 * (f[0..5], 2 zeros), the node's distance s along the ray (the local azimuth's, add_lookups) and the
 * table's altitude and view corner cells and weights at node coordinates (fx, fy); the coordinates are
 * clamped before the conversion (NaN-safe: fmax returns the other operand). */
typedef struct {
    real8 factor[VECTOR_WIDTH];
    realv s;
    intv ix, iy;
    realv ax, ay;
} node_lookup_t;

inline void prepare_lookups(const int width, const int height, const realv *f, const realv s, const realv fx,
                            const realv fy, node_lookup_t *node)
{
    node->s = s;
    const realv x0 = fmin(fmax(fx, V(0.0)), (real)(width - 2)), y0 = fmin(fmax(fy, V(0.0)), (real)(height - 2));
    node->ix = CONVERT_INTV(x0);
    node->iy = CONVERT_INTV(y0);
    node->ax = fx - CONVERT_REALV(node->ix);
    node->ay = fy - CONVERT_REALV(node->iy);
    for (int k = 0; k < VECTOR_WIDTH; ++k)
        node->factor[k] = lane_integrands(f, k);
}

#ifndef AZIMUTH_HARMONICS
#define AZIMUTH_HARMONICS 0
#endif
#if AZIMUTH_HARMONICS > 0
/* cos phi per lane, phi the local azimuth between the view's and the sun's horizontal directions at the
 * ray's node at distance s (from radius r0, the ray's start mu_v, a sun of zenith cosine mu_s and
 * scattering cosine nu at the start), in a form free of cancellation near the vertical (P = r0 Z + s V;
 * r sin(view zenith) = r0 sqrt(1 - mu_v^2), r sin(sun zenith) = |P x Sun|,
 * r^2 (nu - mu_view mu_sun) = r0 (r0 (nu - mu_v mu_s) + s (mu_v nu - mu_s))):
 *   cos phi = (r0 (nu - mu_v mu_s) + s (mu_v nu - mu_s)) / (sqrt(1 - mu_v^2) |P x Sun|),
 *   |P x Sun|^2 = r0^2 (1 - mu_s^2) + 2 r0 s (mu_v - mu_s nu) + s^2 (1 - nu^2),
 * 1 where the denominator is 0 (view or sun vertical: no azimuth). */
inline realv ray_azimuth_cos(const view_march_t *ray, const realv s, const realv mu_s, const realv nu)
{
    const realv r0 = ray->r0, mu_v = ray->mu_v;
    const realv cross2 = r0 * r0 * fmax(R(1.0) - mu_s * mu_s, V(0.0)) + R(2.0) * r0 * s * (mu_v - mu_s * nu)
                         + s * s * fmax(R(1.0) - nu * nu, V(0.0));
    const realv denominator = ray->sin_view * sqrt(fmax(cross2, V(0.0)));
    const realv numerator = r0 * (nu - mu_v * mu_s) + s * (mu_v * nu - mu_s);
    return SELECT(V(1.0), clamp(numerator / denominator, R(-1.0), R(1.0)), isgreater(denominator, V(0.0)));
}
#endif

/* sum[k] += node->factor[k] x the gathered source at a node of the ray, for every lane k: the trilinear
 * lookup of the padded table (D, H, W, 8) at the node's altitude and view coordinates (prepare_lookups)
 * and sun coordinate fz. With -DAZIMUTH_HARMONICS=M > 0 (clsky/azimuth.py) `gathered` holds the M + 1
 * cosine harmonics G_m and the source is max(0, sum_m G_m cos(m phi)), each G_m looked up at the same
 * corner cells and weights, phi the local azimuth of the lane at the node (ray_azimuth_cos at node->s,
 * for the sun of zenith cosine mu_s and scattering cosine nu at the ray's start), cos(m phi) by the
 * Chebyshev recurrence. Without it (M = 0) ray, mu_s and nu are not read and the source is the one
 * table's lookup. The harmonics come in one of two layouts:
 *   the orders' stack (the scatter, multiple.cl): M + 1 padded tables (D, H, W, 8) one after the other,
 *     as the gathers write them;
 *   -DGATHERED_INTERLEAVED (render.cl, table4d.cl: clsky.transmittance.upload_gathered_source): the
 *     cells' harmonics side by side, (D, H, W, M + 1, 8), so that a corner's M + 1 rows of 8 reals are
 *     contiguous (192 bytes with M = 2), where the stack puts them 109 MB apart (the default animation's
 *     table): the same values; the default animation's ray march takes 3-8 % less CPU time, 10-20 % less
 *     at dusk, where its lookups spread over more of the table than the caches hold.
 * (Cells of 6 (M + 1) reals, without the padding, were up to 10 % faster than these at dusk and 5 %
 * slower by day: their rows of 8 reals cross cache lines.) */
inline void add_lookups(__global const real *gathered, const int width, const int height, const int depth,
                        const node_lookup_t *node, const realv fz, const view_march_t *ray, const realv mu_s,
                        const realv nu, real8 *sum)
{
    const realv z0 = fmin(fmax(fz, V(0.0)), (real)(depth - 2));
    const intv iz = CONVERT_INTV(z0);
    const realv az = fz - CONVERT_REALV(iz);
#ifdef GATHERED_INTERLEAVED
    const size_t cell = AZIMUTH_HARMONICS + 1, harmonic = 1;                  /* [real8] */
#else
    const size_t cell = 1, harmonic = (size_t)width * (size_t)height * (size_t)depth;
#endif
    const size_t dy = cell * (size_t)width, dz = dy * (size_t)height;
#if AZIMUTH_HARMONICS > 0
    const realv cos_phi = ray_azimuth_cos(ray, node->s, mu_s, nu);
#endif
    for (int k = 0; k < VECTOR_WIDTH; ++k) {
        const size_t base = cell * ((size_t)INT_LANE(node->ix, k)
                                    + (size_t)width * ((size_t)INT_LANE(node->iy, k)
                                                       + (size_t)height * (size_t)INT_LANE(iz, k)));
        const real ax = LANE(node->ax, k), ay = LANE(node->ay, k), azk = LANE(az, k);
        real8 g = trilinear8(gathered, base, cell, dy, dz, ax, ay, azk);
#if AZIMUTH_HARMONICS > 0
        const real c = LANE(cos_phi, k);
        real previous = R(1.0), current = c;
        for (int m = 1; m <= AZIMUTH_HARMONICS; ++m) {
            g += current * trilinear8(gathered, base + (size_t)m * harmonic, cell, dy, dz, ax, ay, azk);
            const real next = R(2.0) * c * current - previous;
            previous = current;
            current = next;
        }
        g = fmax(g, (real8)(R(0.0)));
#endif
        sum[k] += node->factor[k] * g;
    }
}

/* The higher orders' source on every SOURCE_STRIDE-th view node (integrate_gathered). */
#ifndef SOURCE_STRIDE
#define SOURCE_STRIDE 1
#endif
#if SOURCE_STRIDE != 1 && SOURCE_STRIDE != 2
#error "SOURCE_STRIDE must be 1 or 2"
#endif
#if SOURCE_STRIDE == 2
/* The current node i of a ray, odd and i < N_VIEW, with -DSOURCE_STRIDE=2: its source is
 * (1 - w_i) Gbar_(i-1) + w_i Gbar_(i+1), w_i = (s_i - s_(i-1)) / (s_(i+1) - s_(i-1)), so its integrands
 * f_i go to the lookups on either side: before[k] = f_i (1 - w_i) to node i - 1's, after[k] = f_i w_i to
 * node i + 1's (lane k). */
inline void shares_between(const view_march_t *ray, const int i, real8 *before, real8 *after)
{
    const view_node_t previous = view_node_at(i - 1, ray->hits_ground), here = view_node_at(i, ray->hits_ground),
                      next = view_node_at(i + 1, ray->hits_ground);
    const realv w = V(0.0) + (here - previous) / (next - previous);
    for (int k = 0; k < VECTOR_WIDTH; ++k) {
        const real8 f = lane_integrands(ray->f, k);
        before[k] = f * (R(1.0) - LANE(w, k));
        after[k] = f * LANE(w, k);
    }
}
#endif

/* In-scattering of a gathered table along the ray for RAY_SUNS suns at once, per sun b and lane k:
 *   sum[b][k].s012 = Integral rho_R T(P, Pa) Gbar_R dt (r, g, b), sum[b][k].s345 the same with rho_M, Gbar_M
 * with Gbar (padded (D, H, W, 8), the table's grid, mapping and sun_range) looked up trilinearly at each node's
 * altitude, view and sun cosines (and, with -DAZIMUTH_HARMONICS, summed over its harmonics at the local
 * azimuth: add_lookups); sun b of zenith cosine mu_s[b] and scattering cosine nu[b] at the ray's start.
 * The trapezoid sum_i (f_(i-1) + f_i) h_i / 2 is accumulated as sum_i f_i (h_i + h_(i+1)) / 2, so that each
 * lane's 6 channels are one real8 FMA per node.
 * With single != 0 (the per-pixel ray march), the same pass also accumulates single scattering into
 * single[b][0..5] as integrate_single does (sun columns from sun_table or re-marched), sharing the
 * geometry, densities and view transmittance of each node. With -DGROUND and ground != 0, also
 * ground[b][0..GROUND_VALUES - 1] of the last node (the direct irradiance only with single != 0).
 * A ray's geometry, densities, view transmittance and the lookups' altitude and view parts (ray_step,
 * prepare_lookups) do not depend on the sun: each node computes them once for its RAY_SUNS suns, and each
 * sun's sums are the operations of the ray marched for it alone (the scatter's integrate_gathered_suns
 * does the same for a table's sun nodes, kernels/multiple.cl).
 * With -DSOURCE_STRIDE=2 (TableSettings.source_stride) Gbar is looked up at the even nodes and the last
 * one only, and taken linear in distance between two of them at the odd node i between:
 * Gbar_i = (1 - w_i) Gbar_(i-1) + w_i Gbar_(i+1), w_i = (s_i - s_(i-1)) / (s_(i+1) - s_(i-1)); node i's
 * integrand goes to the lookups on either side (shares_between): f_i (1 - w_i) joins node i - 1's, whose
 * lookup waits for it, and f_i w_i node i + 1's (the scatter's scheme, kernels/multiple.cl).
 * Gbar is a smooth field of the higher orders: about half the lookups' cost for a change of the
 * radiance of about 2e-4 by day (docs/speed-log.md). */
inline void integrate_ray_suns(__constant const atmosphere_t *atm, const realv h0, const realv mu_v,
                               const realv *mu_s, const realv *nu, __global const real *gathered,
                               const int width, const int height, const int depth, const int mapping,
                               const real2 sun_range, real8 sum[RAY_SUNS][VECTOR_WIDTH],
                               __global const real *sun_table, const int tw, const int th,
                               realv (*single)[6], GROUND_OF_SUNS)
{
    const real ha = atm->top_radius - atm->planet_radius;
    const real4 beta = atm->beta_rayleigh;
    const real4 beta_me = atm->beta_mie_extinction;
    const real4 beta_o = atm->ozone_extinction;
    view_march_t ray;
    ray_begin(atm, h0, mu_v, &ray);
    for (int b = 0; b < RAY_SUNS; ++b) {
        for (int k = 0; k < VECTOR_WIDTH; ++k)
            sum[b][k] = (real8)(R(0.0));
        if (single)
            for (int c = 0; c < 6; ++c)
                single[b][c] = V(0.0);
    }
    node_lookup_t node;                 /* with -DSOURCE_STRIDE=2, an even node's, kept for the odd node after it */
    realv fz[RAY_SUNS];
#if SOURCE_STRIDE == 2
    real8 pending[VECTOR_WIDTH];        /* f_i w_i of the odd node i, for node i + 1's lookups */
    for (int k = 0; k < VECTOR_WIDTH; ++k)
        pending[k] = (real8)(R(0.0));
#endif

    for (int i = 0; i <= N_VIEW; ++i) {
        ray_step(atm, i, &ray);
        realv mu_sun_here[RAY_SUNS];
        for (int b = 0; b < RAY_SUNS; ++b)
            mu_sun_here[b] = ray_sun_cos(&ray, mu_s[b], nu[b]);
#ifdef GROUND
        if (ground && i == N_VIEW)
            for (int b = 0; b < RAY_SUNS; ++b)
                ground_view(atm, ray.view, ray.hits_ground, mu_sun_here[b], ground[b]);
#endif
        if (single) {
            const sun_table_altitude_t at = sun_altitude(atm, tw, ray.h);
            for (int b = 0; b < RAY_SUNS; ++b) {
                if (!ANY_LANE(sun_lit(&at, mu_sun_here[b])))
                    continue;           /* no lane lit: nothing to add, not computed */
                column_t sun;
                const maskv lit = sun_column(atm, ray.h, &at, mu_sun_here[b], sun_table, tw, th, &sun);
                const realv s0 = SELECT(V(0.0), exp(-optical_depth_of(sun, beta.x, beta_me.x, beta_o.x)), lit);
                const realv s1 = SELECT(V(0.0), exp(-optical_depth_of(sun, beta.y, beta_me.y, beta_o.y)), lit);
                const realv s2 = SELECT(V(0.0), exp(-optical_depth_of(sun, beta.z, beta_me.z, beta_o.z)), lit);
                single[b][0] += ray.f[0] * s0; single[b][1] += ray.f[1] * s1; single[b][2] += ray.f[2] * s2;
                single[b][3] += ray.f[3] * s0; single[b][4] += ray.f[4] * s1; single[b][5] += ray.f[5] * s2;
#ifdef GROUND
                if (ground && i == N_VIEW)
                    ground_direct(atm, sun, lit, ground[b]);
#endif
            }
        }
#if SOURCE_STRIDE == 2
        if ((i & 1) && i < N_VIEW) {
            /* node i - 1's lookups waited for this node's share of them */
            real8 share[VECTOR_WIDTH];
            shares_between(&ray, i, share, pending);
            for (int k = 0; k < VECTOR_WIDTH; ++k)
                node.factor[k] += share[k];
            for (int b = 0; b < RAY_SUNS; ++b)
                add_lookups(gathered, width, height, depth, &node, fz[b], &ray, mu_s[b], nu[b], sum[b]);
            continue;
        }
#endif
        const realv fx = MAPPING_U(ray.h, mapping, ha) * (real)(width - 1);
        const realv fy = MAPPING_V(ray.mu_view_here, mapping) * (real)(height - 1);
        for (int b = 0; b < RAY_SUNS; ++b)
            fz[b] = MAPPING_SUN_T(mu_sun_here[b], mapping, sun_range) * (real)(depth - 1);
        prepare_lookups(width, height, ray.f, ray.s, fx, fy, &node);
#if SOURCE_STRIDE == 2
        for (int k = 0; k < VECTOR_WIDTH; ++k) {
            node.factor[k] += pending[k];
            pending[k] = (real8)(R(0.0));
        }
        if (i + 1 < N_VIEW)
            continue;                   /* node i + 1 is odd: its share joins these lookups first */
#endif
        for (int b = 0; b < RAY_SUNS; ++b)
            add_lookups(gathered, width, height, depth, &node, fz[b], &ray, mu_s[b], nu[b], sum[b]);
    }
}

#if RAY_SUNS == 1
/* integrate_ray_suns for one sun (table4d.cl): sum[k], single[0..5], ground[0..GROUND_VALUES - 1]. */
inline void integrate_gathered(__constant const atmosphere_t *atm, const realv h0, const realv mu_v,
                               const realv mu_s, const realv nu, __global const real *gathered,
                               const int width, const int height, const int depth, const int mapping,
                               const real2 sun_range, real8 *sum, __global const real *sun_table, const int tw, const int th,
                               realv *single, realv *ground)
{
#ifdef GROUND
    realv (*ground_of_suns)[GROUND_VALUES] = (realv (*)[GROUND_VALUES])ground;
#else
    realv *ground_of_suns = ground;
#endif
    integrate_ray_suns(atm, h0, mu_v, &mu_s, &nu, gathered, width, height, depth, mapping, sun_range,
                       (real8 (*)[VECTOR_WIDTH])sum, sun_table, tw, th, (realv (*)[6])single, ground_of_suns);
}
#endif
