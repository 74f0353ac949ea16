/* transmittance_table.cl -- the 2D table of column densities to the top of the atmosphere.
 *
 * Axes (TW x TH nodes, index x + y TW, two channels (C_R, C_M) [m] per node):
 *   altitude     u = sqrt(h / Ha)                                          (x = u (TW - 1))
 *   zenith cos   v = sqrt((mu - mu_h) / (1 - mu_h)), mu_h = horizon_cos(h)  (y = v (TH - 1))
 * so that nodes crowd near the ground and near the horizon, where the columns change fastest. Rays
 * below the horizon hit the planet and are never looked up (the caller decides the shadow first).
 * Replaces re-marching each sun ray (2 N_SUN exponentials per sample) by one bilinear lookup.
 * Works on realv (1 or 8 lanes). Requires real.cl, atmosphere_t, geometry.cl.
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

/* Bilinear lookup of the column densities from altitude h along mu to the top. */
inline void column_density_from_table(__constant const atmosphere_t *atm, __global const real *table,
                                      const int tw, const int th, const realv h, const realv mu,
                                      realv *column_r, realv *column_m)
{
    const real ha = atm->top_radius - atm->planet_radius;
    const realv mu_h = horizon_cos(h, atm->planet_radius);
    const realv fx = sqrt(clamp(h / ha, R(0.0), R(1.0))) * (real)(tw - 1);
    const realv fy = sqrt(clamp((mu - mu_h) / (R(1.0) - mu_h), R(0.0), R(1.0))) * (real)(th - 1);
    realv c_r, c_m;
    for (int k = 0; k < VECTOR_WIDTH; ++k) {
        const int x0 = min((int)LANE(fx, k), tw - 2);
        const int y0 = min((int)LANE(fy, k), th - 2);
        const real ax = LANE(fx, k) - (real)x0;
        const real ay = LANE(fy, k) - (real)y0;
        const int i00 = 2 * (x0 + y0 * tw), i10 = i00 + 2, i01 = i00 + 2 * tw, i11 = i01 + 2;
        LANE(c_r, k) = ((R(1.0) - ax) * table[i00] + ax * table[i10]) * (R(1.0) - ay)
                     + ((R(1.0) - ax) * table[i01] + ax * table[i11]) * ay;
        LANE(c_m, k) = ((R(1.0) - ax) * table[i00 + 1] + ax * table[i10 + 1]) * (R(1.0) - ay)
                     + ((R(1.0) - ax) * table[i01 + 1] + ax * table[i11 + 1]) * ay;
    }
    *column_r = c_r;
    *column_m = c_m;
}
