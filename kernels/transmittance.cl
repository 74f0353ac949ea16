/* transmittance.cl -- kernels of clsky/transmittance.py: optical depth along segments and the 2D
 * column-density table.
 *
 *   tau_lambda(P1, P2) = beta_R(lambda) Integral rho_R ds + beta_M^e(lambda) Integral rho_M ds
 *                        (+ sigma_O3(lambda) n_max Integral f_O ds with -DOZONE)        (physics.md)
 *   T = exp(-tau)
 * Inputs: altitude h0 [m] (0 <= h0 <= Ha), direction cosine mu, length d [m]. Output: tau for r, g, b.
 * The table holds COLUMN_CHANNELS columns [m] per node (C_R, C_M, and C_O with -DOZONE).
 * Built with VECTOR_WIDTH 1. Requires real.cl, atmosphere_t, geometry.cl, column.cl,
 * transmittance_table.cl.
 */

__kernel void optical_depth(__constant const atmosphere_t *atm, const int n,
                            __global const real *altitude, __global const real *mu,
                            __global const real *length, __global real *tau)
{
    const int i = get_global_id(0);
    if (i >= n)
        return;
    const column_t column = column_density(atm, altitude[i], mu[i], length[i]);
    tau[3 * i] = optical_depth_of(column, atm->beta_rayleigh.x, atm->beta_mie_extinction.x,
                                          atm->ozone_extinction.x);
    tau[3 * i + 1] = optical_depth_of(column, atm->beta_rayleigh.y, atm->beta_mie_extinction.y,
                                              atm->ozone_extinction.y);
    tau[3 * i + 2] = optical_depth_of(column, atm->beta_rayleigh.z, atm->beta_mie_extinction.z,
                                              atm->ozone_extinction.z);
}

__kernel void transmittance_table(__constant const atmosphere_t *atm, const int tw, const int th,
                                  __global real *table)
{
    const int x = get_global_id(0);
    const int y = get_global_id(1);
    if (x >= tw || y >= th)
        return;
    realv h, mu;
    transmittance_table_node(atm, x, y, tw, th, &h, &mu);
    const column_t column = column_density(atm, h, mu, distance_to_top(h, mu, atm->planet_radius, atm->top_radius));
    const size_t node = COLUMN_CHANNELS * (size_t)(x + y * tw);
    table[node] = column.r;
    table[node + 1] = column.m;
#ifdef OZONE
    table[node + 2] = column.o;
#endif
}
