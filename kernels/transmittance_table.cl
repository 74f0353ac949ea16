/* transmittance_table.cl -- the 2D table of column densities to the top of the atmosphere.
 *
 * Axes (TW x TH nodes, index x + y TW, COLUMN_CHANNELS channels per node: C_R, C_M [m], and C_O [m]
 * (column of the ozone tent f_O, column.cl) with -DOZONE):
 *   altitude     u = sqrt(h / Ha)                                          (x = u (TW - 1))
 *   zenith cos   v = sqrt((mu - mu_h) / (1 - mu_h)), mu_h = horizon_cos(h)  (y = v (TH - 1))
 * so that nodes crowd near the ground and near the horizon, where the columns change fastest. Rays
 * below the horizon hit the planet and are never looked up (the caller decides the shadow first).
 * Replaces re-marching each sun ray (2 N_SUN exponentials per sample) by one bilinear lookup.
 * Works on realv (1 or 8 lanes). Requires real.cl, atmosphere_t, geometry.cl, column.cl.
 */

/* Altitude [m] and zenith cosine of node (x, y). */
inline void transmittance_table_node(__constant const atmosphere_t *atm, const int x, const int y,
                                     const int tw, const int th, realv *h, realv *mu)
{
    const real u = (real)x / (real)(tw - 1);
    const real v = (real)y / (real)(th - 1);
    *h = (realv)(u * u * (atm->top_radius - atm->planet_radius));
    const realv mu_h = horizon_cos(*h, atm->planet_radius);
    *mu = mu_h + (R(1.0) - mu_h) * (v * v);
}

/* Bilinear interpolation of one channel between the node values t00, t10 (x + 1), t01 (y + 1), t11, per lane. */
inline realv bilinear_channel(const realv t00, const realv t10, const realv t01, const realv t11, const realv ax,
                              const realv ay)
{
    return ((R(1.0) - ax) * t00 + ax * t10) * (R(1.0) - ay) + ((R(1.0) - ax) * t01 + ax * t11) * ay;
}

/* The columns of two nodes adjacent along x, per lane: left[c] at index i (an intv), right[c] at
 * i + COLUMN_CHANNELS. Their 2 COLUMN_CHANNELS values are contiguous in the table; with 8 lanes each
 * lane reads them as one real4 (and a real2 with ozone) and the lanes are put together in registers
 * (LOAD_LANES, LANES_OF), instead of 2 COLUMN_CHANNELS scalar reads per lane: the same values, the
 * ray march about 4 % faster (A/B, docs/speed-log.md). Reads exactly those values (no read past a node). */
inline void adjacent_columns(__global const real *table, const intv i, realv *left, realv *right)
{
#if VECTOR_WIDTH == 8
    LOAD_LANES(4, head, table, i, 0);
    left[0] = LANES_OF(head, s0);
    left[1] = LANES_OF(head, s1);
#if COLUMN_CHANNELS == 3
    LOAD_LANES(2, tail, table, i, 4);
    left[2] = LANES_OF(head, s2);
    right[0] = LANES_OF(head, s3);
    right[1] = LANES_OF(tail, s0);
    right[2] = LANES_OF(tail, s1);
#else
    right[0] = LANES_OF(head, s2);
    right[1] = LANES_OF(head, s3);
#endif
#else
    for (int c = 0; c < COLUMN_CHANNELS; ++c) {
        left[c] = table[i + c];
        right[c] = table[i + COLUMN_CHANNELS + c];
    }
#endif
}

/* What a lookup in the table takes from the altitude h alone: the horizon cosine mu_h there, the lower
 * altitude node x0 and the weight ax of the one above it. A ray node looks up several sun directions at
 * one altitude (the sun nodes of single scattering, the planet's shadow test): it computes these once. */
typedef struct {
    realv mu_h;
    intv x0;
    realv ax;
} sun_table_altitude_t;

inline sun_table_altitude_t sun_table_altitude(__constant const atmosphere_t *atm, const int tw, const realv h)
{
    const real ha = atm->top_radius - atm->planet_radius;
    sun_table_altitude_t a;
    a.mu_h = horizon_cos(h, atm->planet_radius);
    const realv fx = sqrt(clamp(h / ha, R(0.0), R(1.0))) * (real)(tw - 1);
    a.x0 = min(CONVERT_INTV(fx), tw - 2);
    a.ax = fx - CONVERT_REALV(a.x0);
    return a;
}

/* Bilinear lookup of the column densities (COLUMN_CHANNELS per node) from the altitude `at`
 * (sun_table_altitude) along mu to the top.
 * Only the reads of the 4 corner nodes are per lane (adjacent_columns); the indices, weights and
 * interpolation are computed in realv arithmetic: the same operations as lane by lane, so the same
 * values (checked bit for bit on frames and tables); the per-lane loop stored each lane's result to the
 * stack and read the vector back. The ray march's CPU time fell by about 2 % (A/B, docs/speed-log.md). */
inline column_t column_density_from_table(__global const real *table, const int tw, const int th,
                                          const sun_table_altitude_t *at, const realv mu)
{
    const realv fy = sqrt(clamp((mu - at->mu_h) / (R(1.0) - at->mu_h), R(0.0), R(1.0))) * (real)(th - 1);
    const intv y0 = min(CONVERT_INTV(fy), th - 2);
    const realv ay = fy - CONVERT_REALV(y0);
    const intv i00 = COLUMN_CHANNELS * (at->x0 + y0 * tw);
    realv c00[COLUMN_CHANNELS], c10[COLUMN_CHANNELS], c01[COLUMN_CHANNELS], c11[COLUMN_CHANNELS];
    adjacent_columns(table, i00, c00, c10);
    adjacent_columns(table, i00 + COLUMN_CHANNELS * tw, c01, c11);
    column_t c;
    c.r = bilinear_channel(c00[0], c10[0], c01[0], c11[0], at->ax, ay);
    c.m = bilinear_channel(c00[1], c10[1], c01[1], c11[1], at->ax, ay);
#ifdef OZONE
    c.o = bilinear_channel(c00[2], c10[2], c01[2], c11[2], at->ax, ay);
#endif
    return c;
}
