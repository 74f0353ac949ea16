/* table4d.cl -- kernel of clsky/table4d.py: the channels of the 4D table along arbitrary rays.
 *
 * Each cell is a ray (h0 [m], mu_v, mu_s, nu) (the 4D table's nodes, clsky/mapping.py); per cell
 *   out[0..5] = beta_s / (4 pi) Integral rho_s T(Pc, P) T(P, Pa) ds   (Ibar_R r, g, b, Ibar_M r, g, b:
 *               single scattering without phase, physics.md), and with has_multiple
 *   out[6..8] = sum_s beta_s / (4 pi) Integral rho_s T(P, Pa) G_s(P) ds  (the higher orders, phase
 *               inside G: the gathered table (padded (D, H, W, 8), or its M + 1 cosine harmonics with
 *               -DAZIMUTH_HARMONICS, interleaved (D, H, W, M + 1, 8): view_ray.cl, add_lookups) on the 3D
 *               grid (width, height, depth, mapping, sun_range)),
 * the integrals of the per-pixel ray march (view_ray.cl: integrate_single, integrate_gathered; render.cl
 * render_raymarch applies the phase and I_I to the same sums). With -DGROUND (a Lambertian ground),
 * out[6..8] also holds what the ray sees of the ground, T a / pi (mu_sun T_sun + E_sky(mu_sun))
 * (view_ray.cl: add_ground_reflection; ground_irradiance (D, 4) per sun node of the 3D grid), as the ray
 * march adds it. VECTOR_WIDTH cells per work-item; cells beyond n repeat the last one and are not
 * written. Requires real.cl, atmosphere_t, geometry.cl, column.cl, transmittance_table.cl,
 * mapping.cl, view_ray.cl.
 */

__kernel void table4d_cells(__constant const atmosphere_t *atm, __global const real *gathered, const int width,
                            const int height, const int depth, const int mapping, const real2 sun_range,
                            const int has_multiple, __global const real *sun_table, const int tw, const int th,
                            __global const real *ground_irradiance, const int n, __global const real *cells,
                            const int channels, __global real *out)
{
    const int first = get_global_id(0) * VECTOR_WIDTH;
    if (first >= n)
        return;
    realv h0, mu_v, mu_s, nu;
    for (int k = 0; k < VECTOR_WIDTH; ++k) {
        const size_t i = (size_t)min(first + k, n - 1);
        LANE(h0, k) = cells[4 * i];
        LANE(mu_v, k) = cells[4 * i + 1];
        LANE(mu_s, k) = cells[4 * i + 2];
        LANE(nu, k) = cells[4 * i + 3];
    }
    realv single[6];
    real8 multiple[VECTOR_WIDTH];
#ifdef GROUND
    realv ground[GROUND_VALUES];
#else
    realv *ground = 0;
#endif
    if (has_multiple)
        integrate_gathered(atm, h0, mu_v, mu_s, nu, gathered, width, height, depth, mapping, sun_range, multiple,
                           sun_table, tw, th, single, ground);
    else
        integrate_single(atm, h0, mu_v, mu_s, nu, sun_table, tw, th, single, ground);
    const real scale = R(1.0) / (R(4.0) * PI_REAL);
    const real3 beta_r = atm->beta_rayleigh.xyz * scale;
    const real3 beta_m = atm->beta_mie.xyz * scale;
    for (int k = 0; k < VECTOR_WIDTH && first + k < n; ++k) {
        __global real *cell = out + (size_t)(first + k) * (size_t)channels;
        const real3 ibar_r = beta_r * (real3)(LANE(single[0], k), LANE(single[1], k), LANE(single[2], k));
        const real3 ibar_m = beta_m * (real3)(LANE(single[3], k), LANE(single[4], k), LANE(single[5], k));
        cell[0] = ibar_r.x; cell[1] = ibar_r.y; cell[2] = ibar_r.z;
        cell[3] = ibar_m.x; cell[4] = ibar_m.y; cell[5] = ibar_m.z;
        if (has_multiple) {
            real3 g = beta_r * multiple[k].s012 + beta_m * multiple[k].s345;
#ifdef GROUND
            add_ground_reflection(atm, ground, k, ground_irradiance, depth, mapping, sun_range, &g);
#endif
            cell[6] = g.x; cell[7] = g.y; cell[8] = g.z;
        }
    }
}
