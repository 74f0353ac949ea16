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

/* Bilinear interpolation of one channel between the nodes i00, i10 (x + 1), i01 (y + 1), i11. */
inline real bilinear_channel(__global const real *table, const int i00, const int i10, const int i01, const int i11,
                             const real ax, const real ay)
{
    return ((R(1.0) - ax) * table[i00] + ax * table[i10]) * (R(1.0) - ay)
         + ((R(1.0) - ax) * table[i01] + ax * table[i11]) * ay;
}

/* Bilinear lookup of the column densities (COLUMN_CHANNELS per node) from altitude h along mu to the top. */
inline column_t column_density_from_table(__constant const atmosphere_t *atm, __global const real *table,
                                          const int tw, const int th, const realv h, const realv mu)
{
    const real ha = atm->top_radius - atm->planet_radius;
    const realv mu_h = horizon_cos(h, atm->planet_radius);
    const realv fx = sqrt(clamp(h / ha, R(0.0), R(1.0))) * (real)(tw - 1);
    const realv fy = sqrt(clamp((mu - mu_h) / (R(1.0) - mu_h), R(0.0), R(1.0))) * (real)(th - 1);
    column_t c;
    for (int k = 0; k < VECTOR_WIDTH; ++k) {
        const int x0 = min((int)LANE(fx, k), tw - 2);
        const int y0 = min((int)LANE(fy, k), th - 2);
        const real ax = LANE(fx, k) - (real)x0;
        const real ay = LANE(fy, k) - (real)y0;
        const int i00 = COLUMN_CHANNELS * (x0 + y0 * tw), i10 = i00 + COLUMN_CHANNELS;
        const int i01 = i00 + COLUMN_CHANNELS * tw, i11 = i01 + COLUMN_CHANNELS;
        LANE(c.r, k) = bilinear_channel(table, i00, i10, i01, i11, ax, ay);
        LANE(c.m, k) = bilinear_channel(table, i00 + 1, i10 + 1, i01 + 1, i11 + 1, ax, ay);
#ifdef OZONE
        LANE(c.o, k) = bilinear_channel(table, i00 + 2, i10 + 2, i01 + 2, i11 + 2, ax, ay);
#endif
    }
    return c;
}
