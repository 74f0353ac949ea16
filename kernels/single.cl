/* single.cl -- kernel of clsky/single.py: the single-scattering 3D table.
 *
 * For each cell (altitude h, view-zenith cosine mu_v, sun-zenith cosine mu_s) in the canonical frame
 * (sun and view in one vertical plane, same side: cos theta = cos(phi - delta)), per species s and
 * wavelength lambda, without I_I and without the phase function (physics.md; Elek 2009, eq. 4.2):
 *
 *   Ibar_s^(1) = beta_s / (4 pi) Integral_{Pa}^{Pb} rho_s(h(P)) T(Pc, P) T(P, Pa) ds
 *
 * Pa = observer (inside the atmosphere), Pb = top of the atmosphere or the ground. Trapezoidal rule
 * over N_VIEW + 1 nodes s_i = L f(i / N_VIEW), f(x) = x, or x^3 with -DKELLER_BOHN_SAMPLING, or with
 * -DGROUND_END_SAMPLING 1 - (1 - x)^3 on rays that hit the ground (view_ray.cl: view_node_at). T(P, Pa) is
 * accumulated by the same trapezoid along the view ray; T(Pc, P) is re-marched with N_SUN steps
 * (column.cl) or, with -DSUN_TRANSMITTANCE_TABLE, read from the 2D table (transmittance_table.cl).
 * T = exp(-tau) of every species (column.cl): with -DOZONE, tau includes ozone's absorption
 * sigma_O3 n_max C_O on both legs (the 2D table then has a third channel, C_O).
 * A node whose sun ray hits the planet (mu below the local horizon, decided from its altitude and
 * mu, never from |P| - Rp rounding) is in the shadow and contributes nothing. The last node of a
 * ground-hitting view ray lies on the ground at altitude exactly 0.
 *
 * Each work-item computes VECTOR_WIDTH cells along the altitude axis (x = VECTOR_WIDTH gx + lane), all
 * branch-free in realv arithmetic, for SINGLE_SUN_NODES sun nodes at once (view_ray.cl:
 * integrate_single_suns marches each view ray once for all of them). Global size (ceil(W / VECTOR_WIDTH),
 * H padded to the work-group's rows, ceil(slab / SINGLE_SUN_NODES)): a launch covers the sun-zenith layers
 * z_offset .. z_end - 1 (the host launches slabs to report progress); rows past H are skipped.
 *
 * cos_azimuth: cosine of the azimuth between view and sun (1: the canonical frame; other values are the
 * azimuth nodes of clsky/azimuth.py).
 * Output: 6 reals per cell at index i = x + y W + z W H: Rayleigh r, g, b, then Mie r, g, b [1/sr].
 * Requires real.cl, atmosphere_t, geometry.cl, column.cl, transmittance_table.cl, mapping.cl,
 * view_ray.cl.
 */
__kernel void single_scattering(__constant const atmosphere_t *atm, const int width, const int height,
                                const int depth, const int z_offset, const int z_end, const int mapping,
                                const real2 sun_range, __global const real *sun_table, const int tw, const int th,
                                const real cos_azimuth, __global real *table)
{
    const int gx = get_global_id(0);
    const int y = get_global_id(1);
    const int z0 = z_offset + SINGLE_SUN_NODES * get_global_id(2);
    if (gx * VECTOR_WIDTH >= width || y >= height || z0 >= z_end)
        return;

    realv h0, mu_s[SINGLE_SUN_NODES], nu[SINGLE_SUN_NODES];
    real mu_v;
    for (int b = 0; b < SINGLE_SUN_NODES; ++b) {     /* nodes past the slab's end repeat its last, unstored */
        real mu_s_b, nu_b;
        table_cell(atm, gx, y, min(z0 + b, z_end - 1), width, height, depth, mapping, sun_range, cos_azimuth, &h0,
                   &mu_v, &mu_s_b, &nu_b);
        mu_s[b] = (realv)(mu_s_b);
        nu[b] = (realv)(nu_b);
    }
    realv sum[SINGLE_SUN_NODES][6];
    integrate_single_suns(atm, h0, (realv)(mu_v), mu_s, nu, SINGLE_SUN_NODES, sun_table, tw, th, sum, 0);

    const real4 beta = atm->beta_rayleigh;
    const real scale_r = R(1.0) / (R(4.0) * PI_REAL);
    const real4 scale_m = atm->beta_mie / (R(4.0) * PI_REAL);
    for (int b = 0; b < SINGLE_SUN_NODES && z0 + b < z_end; ++b) {
        const int z = z0 + b;
        for (int k = 0; k < VECTOR_WIDTH; ++k) {
            const int xk = gx * VECTOR_WIDTH + k;
            if (xk >= width)
                break;
            const size_t cell = 6 * ((size_t)xk + (size_t)width * ((size_t)y + (size_t)height * (size_t)z));
            table[cell] = beta.x * scale_r * LANE(sum[b][0], k);
            table[cell + 1] = beta.y * scale_r * LANE(sum[b][1], k);
            table[cell + 2] = beta.z * scale_r * LANE(sum[b][2], k);
            table[cell + 3] = scale_m.x * LANE(sum[b][3], k);
            table[cell + 4] = scale_m.y * LANE(sum[b][4], k);
            table[cell + 5] = scale_m.z * LANE(sum[b][5], k);
        }
    }
}
