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

/* Bilinear lookup of the column densities (COLUMN_CHANNELS per node) from altitude h along mu to the top.
 * Only the reads of the 4 corner nodes are per lane (GATHER_REALV, built in registers); the indices,
 * weights and interpolation are computed in realv arithmetic: the same operations as lane by lane, so the
 * same values (checked bit for bit on frames and tables); the per-lane loop stored each lane's result to
 * the stack and read the vector back. The ray march's CPU time fell by about 2 % (A/B, README "Speed"). */
inline column_t column_density_from_table(__constant const atmosphere_t *atm, __global const real *table,
                                          const int tw, const int th, const realv h, const realv mu)
{
    const real ha = atm->top_radius - atm->planet_radius;
    const realv mu_h = horizon_cos(h, atm->planet_radius);
    const realv fx = sqrt(clamp(h / ha, R(0.0), R(1.0))) * (real)(tw - 1);
    const realv fy = sqrt(clamp((mu - mu_h) / (R(1.0) - mu_h), R(0.0), R(1.0))) * (real)(th - 1);
    const intv x0 = min(CONVERT_INTV(fx), tw - 2);
    const intv y0 = min(CONVERT_INTV(fy), th - 2);
    const realv ax = fx - CONVERT_REALV(x0);
    const realv ay = fy - CONVERT_REALV(y0);
    const intv i00 = COLUMN_CHANNELS * (x0 + y0 * tw), i10 = i00 + COLUMN_CHANNELS;
    const intv i01 = i00 + COLUMN_CHANNELS * tw, i11 = i01 + COLUMN_CHANNELS;
    realv corner[4][COLUMN_CHANNELS];
    for (int c = 0; c < COLUMN_CHANNELS; ++c) {
        corner[0][c] = GATHER_REALV(table, i00 + c);
        corner[1][c] = GATHER_REALV(table, i10 + c);
        corner[2][c] = GATHER_REALV(table, i01 + c);
        corner[3][c] = GATHER_REALV(table, i11 + c);
    }
    column_t c;
    c.r = bilinear_channel(corner[0][0], corner[1][0], corner[2][0], corner[3][0], ax, ay);
    c.m = bilinear_channel(corner[0][1], corner[1][1], corner[2][1], corner[3][1], ax, ay);
#ifdef OZONE
    c.o = bilinear_channel(corner[0][2], corner[1][2], corner[2][2], corner[3][2], ax, ay);
#endif
    return c;
}
