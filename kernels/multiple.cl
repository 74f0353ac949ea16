/* multiple.cl -- kernels of clsky/multiple.py: one scattering order from the previous one.
 *
 * Gather (physics.md; Elek 2009, eq. 4.4), on the 3D grid, for each altitude x and sun node z:
 *   Gbar(h, mu_v, mu_s) = Integral_{4 pi} F(dot(omega, V)) Ibar(h, omega, mu_s) d omega
 * Since the table has no azimuth, Ibar depends on omega only through its zenith cosine, and the 2D
 * trapezoid over (Theta, Phi) collapses into one matrix per phase function acting on the view axis:
 *   Gbar[z, i, x] = sum_j M[i, j] Ibar[z, j, x]
 * (clsky/multiple.py builds M; `gather` applies it, accumulating when asked, so that the physical
 * mode's cross terms and per-sun-node matrices are sums of such products).
 *
 * Scatter (physics.md, order k >= 2): for each cell, along its view ray (as in single.cl),
 *   Ibar_s^(k)(lambda) = beta_s(lambda) / (4 pi) Integral_{Pa}^{Pb} Gbar_s^(k-1)(P, V, L) rho_s(h(P)) T(P, Pa) ds
 * with Gbar looked up trilinearly (texture space) at the altitude, view and sun cosines of each node
 * P. Channels of Gbar and of the result: Rayleigh r, g, b, Mie r, g, b, padded to 8 (one real8 per
 * cell: a trilinear lookup is 8 vector loads).
 * Requires real.cl, atmosphere_t, geometry.cl, mapping.cl (scatter also VECTOR_WIDTH, N_VIEW).
 */

/* out[z, i, p] (+)= sum_j M[c / 3][(z)][i][j] in[z, j, p] over the rows p = 8 x + c of a padded table
 * (D, H, W, 8): channel c (Rayleigh r, g, b, Mie r, g, b, then 2 unused) uses its species' matrix. matrices holds two
 * sets (Rayleigh, Mie) of H x H entries, per sun node when matrix_z_stride = H * H (else 0), the two
 * sets species_stride apart.
 * Blocking: a work-item computes GATHER_ROWS rows i and 8 consecutive p (one real8), so that each
 * loaded input vector serves GATHER_ROWS products. Global size (W, ceil(H / GATHER_ROWS), D). */
#define GATHER_ROWS 4
__kernel void gather(__global const real *matrices, const int species_stride, const int matrix_z_stride,
                     __global const real *table_in, __global real *table_out, const int accumulate,
                     const int width, const int height, const int depth)
{
    const int p0 = 8 * get_global_id(0);
    const int i0 = GATHER_ROWS * get_global_id(1);
    const int z = get_global_id(2);
    const int row_length = 8 * width;
    if (p0 >= row_length || i0 >= height || z >= depth)
        return;
    __global const real *rayleigh = matrices + (size_t)z * (size_t)matrix_z_stride;
    __global const real *mie = rayleigh + (size_t)species_stride;
    __global const real *slab = table_in + (size_t)z * (size_t)height * (size_t)row_length;
    /* lanes of the Mie channels 3, 4, 5 (lanes 6, 7 are padding) */
    const maskv8 is_mie = (maskv8)(0, 0, 0, -1, -1, -1, -1, -1);
    real8 sum[GATHER_ROWS];
    int rows[GATHER_ROWS];
    for (int r = 0; r < GATHER_ROWS; ++r) {
        sum[r] = (real8)(R(0.0));
        rows[r] = min(i0 + r, height - 1);
    }
    for (int j = 0; j < height; ++j) {
        const real8 column = vload8(0, slab + (size_t)j * (size_t)row_length + (size_t)p0);
        for (int r = 0; r < GATHER_ROWS; ++r) {
            const size_t entry = (size_t)rows[r] * (size_t)height + (size_t)j;
            sum[r] += select((real8)(rayleigh[entry]), (real8)(mie[entry]), is_mie) * column;
        }
    }
    for (int r = 0; r < GATHER_ROWS; ++r) {
        if (i0 + r >= height)
            break;
        __global real *target = table_out + ((size_t)z * (size_t)height + (size_t)(i0 + r)) * (size_t)row_length + (size_t)p0;
        vstore8((accumulate ? vload8(0, target) : (real8)(R(0.0))) + sum[r], 0, target);
    }
}

#ifdef N_VIEW
inline real view_node(const int i)
{
    const real x = (real)i / (real)N_VIEW;
#ifdef KELLER_BOHN_SAMPLING
    return x * x * x;
#else
    return x;
#endif
}

/* Trilinear lookup in a padded table (D, H, W, 8) at node coordinates (fx, fy, fz). */
inline real8 lookup8(__global const real *table, const int width, const int height, const int depth,
                     const real fx, const real fy, const real fz)
{
    const int x0 = clamp((int)fx, 0, width - 2), y0 = clamp((int)fy, 0, height - 2), z0 = clamp((int)fz, 0, depth - 2);
    const real ax = fx - (real)x0, ay = fy - (real)y0, az = fz - (real)z0;
    const size_t base = (size_t)x0 + (size_t)width * ((size_t)y0 + (size_t)height * (size_t)z0);
    const size_t dy = (size_t)width, dz = (size_t)width * (size_t)height;
    const real8 c00 = (R(1.0) - ax) * vload8(base, table) + ax * vload8(base + 1, table);
    const real8 c10 = (R(1.0) - ax) * vload8(base + dy, table) + ax * vload8(base + dy + 1, table);
    const real8 c01 = (R(1.0) - ax) * vload8(base + dz, table) + ax * vload8(base + dz + 1, table);
    const real8 c11 = (R(1.0) - ax) * vload8(base + dy + dz, table) + ax * vload8(base + dy + dz + 1, table);
    return (R(1.0) - az) * ((R(1.0) - ay) * c00 + ay * c10) + az * ((R(1.0) - ay) * c01 + ay * c11);
}

/* Global size (ceil(W / VECTOR_WIDTH), H, D): VECTOR_WIDTH cells along the altitude axis per item.
 * gathered and table are padded (D, H, W, 8). combine_species != 0 (physical mode) writes
 * Rayleigh + Mie per wavelength into channels 0-2 and again 3-5 (the next gather's input). */
__kernel void scatter(__constant const atmosphere_t *atm, const int width, const int height,
                      const int depth, const int mapping, const int combine_species,
                      __global const real *gathered, __global real *table)
{
    const int gx = get_global_id(0);
    const int y = get_global_id(1);
    const int z = get_global_id(2);
    if (gx * VECTOR_WIDTH >= width || y >= height || z >= depth)
        return;

    const real rp = atm->planet_radius;
    const real ha = atm->top_radius - rp;
    const realv u = fmin((real)(gx * VECTOR_WIDTH) + LANE_INDEX, (real)(width - 1)) / (real)(width - 1);
    const real v = (real)y / (real)(height - 1);
    const real w = (real)z / (real)(depth - 1);
    const realv h0 = MAPPING_ALTITUDE(u, mapping, ha);
    const real mu_v = MAPPING_COS(v, mapping);
    const real mu_s = MAPPING_COS(w, mapping);
    const realv r0 = rp + h0;
    const real nu = mu_v * mu_s + sqrt(fmax(R(1.0) - mu_v * mu_v, R(0.0)) * fmax(R(1.0) - mu_s * mu_s, R(0.0)));

    const maskv hits_ground = isless((realv)(mu_v), horizon_cos(h0, rp));
    const realv length = SELECT(distance_to_top(h0, (realv)(mu_v), rp, atm->top_radius),
                                distance_to_ground(h0, (realv)(mu_v), rp), hits_ground);

    const real inv_hr = R(1.0) / atm->rayleigh_scale_height;
    const real inv_hm = R(1.0) / atm->mie_scale_height;
    const real4 beta = atm->beta_rayleigh;
    const real beta_me = atm->beta_mie_extinction;
    realv view_r = V(0.0), view_m = V(0.0);
    realv last_density_r = V(0.0), last_density_m = V(0.0);
    /* The trapezoid sum_i (f_(i-1) + f_i) h_i / 2 is accumulated as sum_i f_i (h_i + h_(i+1)) / 2, so that
     * each lane's 6 channels (Rayleigh r, g, b, Mie r, g, b) are one real8 FMA per node. */
    real8 sum[VECTOR_WIDTH];
    for (int k = 0; k < VECTOR_WIDTH; ++k)
        sum[k] = (real8)(R(0.0));
    real node_previous = R(0.0);

    for (int i = 0; i <= N_VIEW; ++i) {
        const real node = view_node(i);
        const real node_next = i < N_VIEW ? view_node(i + 1) : node;
        const realv s = length * node;
        realv h = altitude_along(h0, r0, (realv)(mu_v), s, rp);
        if (i == N_VIEW)
            h = SELECT(h, V(0.0), hits_ground);
        const realv inv_r = R(1.0) / (rp + h);
        const realv mu_view_here = clamp((r0 * mu_v + s) * inv_r, R(-1.0), R(1.0));
        const realv mu_sun_here = clamp((r0 * mu_s + s * nu) * inv_r, R(-1.0), R(1.0));
        const realv density_r = exp(-h * inv_hr), density_m = exp(-h * inv_hm);
        if (i > 0) {
            const realv half_step = R(0.5) * length * (node - node_previous);
            view_r += (last_density_r + density_r) * half_step;
            view_m += (last_density_m + density_m) * half_step;
        }
        const realv weight = R(0.5) * length * ((node - node_previous) + (node_next - node));
        const realv t0 = exp(-(beta.x * view_r + beta_me * view_m));
        const realv t1 = exp(-(beta.y * view_r + beta_me * view_m));
        const realv t2 = exp(-(beta.z * view_r + beta_me * view_m));
        const realv wr = weight * density_r, wm = weight * density_m;
        const realv fr0 = wr * t0, fr1 = wr * t1, fr2 = wr * t2, fm0 = wm * t0, fm1 = wm * t1, fm2 = wm * t2;
        const realv fx = MAPPING_U(h, mapping, ha) * (real)(width - 1);
        const realv fy = MAPPING_V(mu_view_here, mapping) * (real)(height - 1);
        const realv fz = MAPPING_V(mu_sun_here, mapping) * (real)(depth - 1);
        for (int k = 0; k < VECTOR_WIDTH; ++k) {
            const real8 factor = (real8)(LANE(fr0, k), LANE(fr1, k), LANE(fr2, k), LANE(fm0, k), LANE(fm1, k),
                                         LANE(fm2, k), R(0.0), R(0.0));
            sum[k] += factor * lookup8(gathered, width, height, depth, LANE(fx, k), LANE(fy, k), LANE(fz, k));
        }
        last_density_r = density_r;
        last_density_m = density_m;
        node_previous = node;
    }

    const real scale = R(1.0) / (R(4.0) * PI_REAL);
    const real8 coefficient = (real8)(beta.x, beta.y, beta.z, atm->beta_mie, atm->beta_mie, atm->beta_mie,
                                      R(0.0), R(0.0)) * scale;
    for (int k = 0; k < VECTOR_WIDTH; ++k) {
        const int xk = gx * VECTOR_WIDTH + k;
        if (xk >= width)
            break;
        real8 value = coefficient * sum[k];
        if (combine_species)
            value = (real8)(value.s012 + value.s345, value.s012 + value.s345, R(0.0), R(0.0));
        vstore8(value, (size_t)xk + (size_t)width * ((size_t)y + (size_t)height * (size_t)z), table);
    }
}
#endif
