/* transmittance.cl -- kernels of clsky/transmittance.py: optical depth along segments and the 2D
 * column-density table.
 *
 *   tau_lambda(P1, P2) = beta_R(lambda) Integral rho_R ds + beta_M^e Integral rho_M ds     (physics.md)
 *   T = exp(-tau)
 * Inputs: altitude h0 [m] (0 <= h0 <= Ha), direction cosine mu, length d [m]. Output: tau for r, g, b.
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
    realv column_r, column_m;
    column_density(atm, altitude[i], mu[i], length[i], &column_r, &column_m);
    tau[3 * i] = atm->beta_rayleigh.x * column_r + atm->beta_mie_extinction * column_m;
    tau[3 * i + 1] = atm->beta_rayleigh.y * column_r + atm->beta_mie_extinction * column_m;
    tau[3 * i + 2] = atm->beta_rayleigh.z * column_r + atm->beta_mie_extinction * column_m;
}

__kernel void transmittance_table(__constant const atmosphere_t *atm, const int tw, const int th,
                                  __global real *table)
{
    const int x = get_global_id(0);
    const int y = get_global_id(1);
    if (x >= tw || y >= th)
        return;
    realv h, mu, column_r, column_m;
    transmittance_table_node(atm, x, y, tw, th, &h, &mu);
    column_density(atm, h, mu, distance_to_top(h, mu, atm->planet_radius, atm->top_radius),
                   &column_r, &column_m);
    table[2 * (x + y * tw)] = column_r;
    table[2 * (x + y * tw) + 1] = column_m;
}
