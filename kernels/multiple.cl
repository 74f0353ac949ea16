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
 * (T of every species, column.cl: with -DOZONE it includes ozone's absorption)
 * with Gbar looked up trilinearly (texture space) at the altitude, view and sun cosines of each node
 * P. With -DGROUND (physical mode only, combine_species) a ray that ends on the ground also sees the
 * ground's reflected radiance, I += T(Pa, Pb) L_g(mu_sun(Pb)), with L_g = a / pi E per sun node from the
 * host (clsky/ground.py: the ground irradiance not yet scattered) interpolated along the sun axis.
 * Channels of Gbar and of the result: Rayleigh r, g, b, Mie r, g, b, padded to 8 (one real8 per
 * cell: a trilinear lookup is 8 vector loads).
 * Requires real.cl, atmosphere_t, geometry.cl, column.cl, transmittance_table.cl, mapping.cl,
 * view_ray.cl.
 */

/* out[z, i, x] (+)= sum_j M[c / 3][(z)][i][j] in[z, j, x] for every channel c of the padded tables
 * (D, H, W, 8): one real8 per cell, channels Rayleigh r, g, b, Mie r, g, b (matrix M[0]), then 2 unused
 * (M[1] for channels 3..7). matrices holds the two sets (Rayleigh, Mie) of H x H entries, per sun node
 * when matrix_z_stride = H * H (else 0), the sets species_stride apart. The output table starts
 * out_offset reals into table_out (a slab of a stack of tables: clsky/azimuth.py's harmonics).
 * Register blocking: a work-item computes GATHER_ROWS rows i for GATHER_CELLS cells x; per j it forms
 * each row's per-channel coefficient vector once (select of the two species' entries) and applies it
 * to every cell's real8. Global size (ceil(W / GATHER_CELLS), ceil(H / GATHER_ROWS), D). */
#if !defined(GATHER_ROWS) || !defined(GATHER_CELLS)
#error "GATHER_ROWS and GATHER_CELLS (the register block of a gather work-item) must be defined"
#endif
__kernel void gather(__global const real *matrices, const int species_stride, const int matrix_z_stride,
                     __global const real *table_in, __global real *table_out, const ulong out_offset,
                     const int accumulate, const int width, const int height, const int depth)
{
    table_out += out_offset;
    const int x0 = GATHER_CELLS * get_global_id(0);
    const int i0 = GATHER_ROWS * get_global_id(1);
    const int z = get_global_id(2);
    if (x0 >= width || i0 >= height || z >= depth)
        return;
    __global const real *rayleigh = matrices + (size_t)z * (size_t)matrix_z_stride;
    __global const real *mie = rayleigh + (size_t)species_stride;
    const size_t slab = (size_t)z * (size_t)height * (size_t)width;       /* first cell of layer z */
    const maskv8 is_mie = (maskv8)(0, 0, 0, -1, -1, -1, -1, -1);
    const int cells = min(GATHER_CELLS, width - x0);
    int rows[GATHER_ROWS];
    real8 sum[GATHER_ROWS][GATHER_CELLS];
    #pragma unroll
    for (int r = 0; r < GATHER_ROWS; ++r) {
        rows[r] = min(i0 + r, height - 1);
        #pragma unroll
        for (int c = 0; c < GATHER_CELLS; ++c)
            sum[r][c] = (real8)(R(0.0));
    }
    for (int j = 0; j < height; ++j) {
        real8 column[GATHER_CELLS];
        #pragma unroll
        for (int c = 0; c < GATHER_CELLS; ++c)
            column[c] = vload8(slab + (size_t)j * (size_t)width + (size_t)(x0 + min(c, cells - 1)), table_in);
        #pragma unroll
        for (int r = 0; r < GATHER_ROWS; ++r) {
            const size_t entry = (size_t)rows[r] * (size_t)height + (size_t)j;
            const real8 coefficient = select((real8)(rayleigh[entry]), (real8)(mie[entry]), is_mie);
            #pragma unroll
            for (int c = 0; c < GATHER_CELLS; ++c)
                sum[r][c] += coefficient * column[c];
        }
    }
    #pragma unroll
    for (int r = 0; r < GATHER_ROWS; ++r) {
        #pragma unroll
        for (int c = 0; c < GATHER_CELLS; ++c) {
            if (i0 + r < height && c < cells) {
                const size_t cell = slab + (size_t)(i0 + r) * (size_t)width + (size_t)(x0 + c);
                vstore8((accumulate ? vload8(cell, table_out) : (real8)(R(0.0))) + sum[r][c], cell, table_out);
            }
        }
    }
}

/* Along one view ray (VECTOR_WIDTH cells x = VECTOR_WIDTH gx + lane of row y) for SCATTER_SUN_NODES sun
 * nodes z = z0 + b at once: the ray's geometry, densities and view transmittance (ray_step) and the
 * lookups' altitude and view parts (prepare_lookups) do not depend on the sun, so each node computes
 * them once and only the sun cosine there and the lookups per sun node (the same operations as
 * integrate_gathered: the same sums). A node computes the sun coordinates of all its sun nodes before
 * their lookups, so that their cube roots and divisions, independent of each other, overlap rather than
 * each waiting for the one before to finish its lookups (18 % less CPU for the scatter on PoCL at 4 sun
 * nodes per item, the same operations). sum[b][k] as integrate_gathered's sum[k] for sun node z0 + b;
 * mu_s[b], nu[b] that node's sun cosine and scattering cosine (table_cell: at the cells' azimuth; with
 * -DAZIMUTH_HARMONICS, add_lookups sums the harmonics at each lane's local azimuth for that sun).
 * With -DGROUND, ground_t[0..2] the view transmittance T(Pa, Pb) r, g, b of rays that end on the ground
 * (0 elsewhere) and ground_mu[b] the sun cosine at Pb.
 * With -DSOURCE_STRIDE=2 (TableSettings.source_stride) the source is looked up at the even nodes and the
 * last one, linear in distance between, by integrate_gathered's scheme: an odd node's shares of the lookups
 * on either side (shares_between), which do not depend on the sun, join those lookups' integrands; an even
 * node's lookups wait until the odd node after it has added f_i (1 - w_i), and f_i w_i waits for the next
 * even node's. Each sun node's lookups then cost half as many trilinear reads, for the same sums up to
 * rounding (the integrand of a lookup is summed before the product). */
inline void integrate_gathered_suns(__constant const atmosphere_t *atm, const realv h0, const real mu_v,
                                    const real *mu_s, const real *nu, __global const real *gathered,
                                    const int width, const int height, const int depth, const int mapping,
                                    const real2 sun_range, real8 sum[SCATTER_SUN_NODES][VECTOR_WIDTH],
                                    realv *ground_t, realv *ground_mu)
{
    const real ha = atm->top_radius - atm->planet_radius;
    view_march_t ray;
    ray_begin(atm, h0, (realv)(mu_v), &ray);
    for (int b = 0; b < SCATTER_SUN_NODES; ++b)
        for (int k = 0; k < VECTOR_WIDTH; ++k)
            sum[b][k] = (real8)(R(0.0));

    node_lookup_t node;                 /* with -DSOURCE_STRIDE=2, an even node's, kept for the odd node after it */
    realv fz[SCATTER_SUN_NODES];
#if SOURCE_STRIDE == 2
    real8 pending[VECTOR_WIDTH];        /* f_i w_i of the odd node i, for node i + 1's lookups */
    for (int k = 0; k < VECTOR_WIDTH; ++k)
        pending[k] = (real8)(R(0.0));
#endif
    for (int i = 0; i <= N_VIEW; ++i) {
        ray_step(atm, i, &ray);
#if SOURCE_STRIDE == 2
        if ((i & 1) && i < N_VIEW) {
            /* node i - 1's lookups waited for this node's share of them */
            real8 share[VECTOR_WIDTH];
            shares_between(&ray, i, share, pending);
            for (int k = 0; k < VECTOR_WIDTH; ++k)
                node.factor[k] += share[k];
            for (int b = 0; b < SCATTER_SUN_NODES; ++b)
                add_lookups(gathered, width, height, depth, &node, fz[b], &ray, (realv)(mu_s[b]), (realv)(nu[b]),
                            sum[b]);
            continue;
        }
#endif
        const realv fx = MAPPING_U(ray.h, mapping, ha) * (real)(width - 1);
        const realv fy = MAPPING_V(ray.mu_view_here, mapping) * (real)(height - 1);
        prepare_lookups(width, height, ray.f, ray.s, fx, fy, &node);
#if SOURCE_STRIDE == 2
        for (int k = 0; k < VECTOR_WIDTH; ++k) {
            node.factor[k] += pending[k];
            pending[k] = (real8)(R(0.0));
        }
#endif
        for (int b = 0; b < SCATTER_SUN_NODES; ++b) {
            const realv mu_sun_here = ray_sun_cos(&ray, (realv)(mu_s[b]), (realv)(nu[b]));
#ifdef GROUND
            if (i == N_VIEW) {
                realv seen[GROUND_VALUES];
                ground_view(atm, ray.view, ray.hits_ground, mu_sun_here, seen);
                ground_t[0] = seen[0]; ground_t[1] = seen[1]; ground_t[2] = seen[2];
                ground_mu[b] = seen[3];
            }
#endif
            fz[b] = MAPPING_SUN_T(mu_sun_here, mapping, sun_range) * (real)(depth - 1);
        }
#if SOURCE_STRIDE == 2
        if (i + 1 < N_VIEW)
            continue;                   /* node i + 1 is odd: its share joins these lookups first */
#endif
        for (int b = 0; b < SCATTER_SUN_NODES; ++b)
            add_lookups(gathered, width, height, depth, &node, fz[b], &ray, (realv)(mu_s[b]), (realv)(nu[b]), sum[b]);
    }
}

/* Global size (ceil(W / VECTOR_WIDTH), H, ceil(computed / SCATTER_SUN_NODES)): VECTOR_WIDTH cells along the
 * altitude axis and SCATTER_SUN_NODES of the computed sun nodes per item (integrate_gathered_suns; computed = D
 * with sun_stride 1, below).
 * gathered and table are padded (D, H, W, 8). combine_species != 0 (physical mode) writes
 * Rayleigh + Mie per wavelength into channels 0-2 and again 3-5 (the next gather's input).
 * ground_radiance: D x 4 reals, L_g r, g, b (and 0) per sun node, read only with -DGROUND, where it is
 * added to both channel sets of combine_species (the host refuses a ground without it).
 * cos_azimuth: the cells' view-sun azimuth (1: canonical frame); with -DAZIMUTH_HARMONICS=M, gathered
 * holds M + 1 harmonics (view_ray.cl: add_lookups; clsky/azimuth.py).
 * The result goes to table + 8 table_offset (table_offset in cells: an azimuth node's slab of a buffer
 * that holds every node, clsky/azimuth.py).
 * sun_stride 1 computes every sun node; 2 (TableSettings.orders_sun_stride) every other one and the last,
 * z = min(c sun_stride, D - 1) for c = 0 .. computed - 1, each as with sun_stride 1 (the same operations), and
 * leaves the nodes between to fill_between_suns; the global size's third axis then counts the computed nodes.
 * Requires view_ray.cl (and so N_VIEW). */
#ifndef SCATTER_SUN_NODES
#error "SCATTER_SUN_NODES (sun nodes per scatter work-item) must be defined"
#endif
/* The sun node of the c-th computed one of a scatter with sun_stride: every sun_stride-th, and the last. */
inline int computed_sun_node(const int c, const int sun_stride, const int depth)
{
    return min(c * sun_stride, depth - 1);
}

__kernel void scatter(__constant const atmosphere_t *atm, const int width, const int height,
                      const int depth, const int mapping, const real2 sun_range, const int combine_species,
                      const real cos_azimuth, __global const real *gathered, __global const real *ground_radiance,
                      __global real *table, const ulong table_offset, const int sun_stride)
{
    table += 8 * table_offset;
    const int gx = get_global_id(0);
    const int y = get_global_id(1);
    const int z0 = SCATTER_SUN_NODES * get_global_id(2);
    const int computed = (depth + sun_stride - 2) / sun_stride + 1;
    if (gx * VECTOR_WIDTH >= width || y >= height || z0 >= computed)
        return;

    realv h0;
    real mu_v, mu_s[SCATTER_SUN_NODES], nu[SCATTER_SUN_NODES];
    for (int b = 0; b < SCATTER_SUN_NODES; ++b)      /* nodes past the last one repeat it, unstored */
        table_cell(atm, gx, y, computed_sun_node(min(z0 + b, computed - 1), sun_stride, depth), width, height, depth,
                   mapping, sun_range, cos_azimuth, &h0, &mu_v, &mu_s[b], &nu[b]);
    real8 sum[SCATTER_SUN_NODES][VECTOR_WIDTH];
    realv ground_t[3], ground_mu[SCATTER_SUN_NODES];
    integrate_gathered_suns(atm, h0, mu_v, mu_s, nu, gathered, width, height, depth, mapping, sun_range, sum,
                            ground_t, ground_mu);

    const real4 beta = atm->beta_rayleigh;
    const real scale = R(1.0) / (R(4.0) * PI_REAL);
    const real4 beta_m = atm->beta_mie;
    const real8 coefficient = (real8)(beta.x, beta.y, beta.z, beta_m.x, beta_m.y, beta_m.z, R(0.0), R(0.0)) * scale;
    for (int b = 0; b < SCATTER_SUN_NODES && z0 + b < computed; ++b) {
        const int z = computed_sun_node(z0 + b, sun_stride, depth);
        for (int k = 0; k < VECTOR_WIDTH; ++k) {
            const int xk = gx * VECTOR_WIDTH + k;
            if (xk >= width)
                break;
            real8 value = coefficient * sum[b][k];
            if (combine_species)
                value = (real8)(value.s012 + value.s345, value.s012 + value.s345, R(0.0), R(0.0));
#ifdef GROUND
            if (combine_species) {
                const real4 seen = (real4)(LANE(ground_t[0], k), LANE(ground_t[1], k), LANE(ground_t[2], k), R(0.0))
                                   * sun_axis_lookup(ground_radiance, depth, mapping, sun_range, LANE(ground_mu[b], k));
                value += (real8)(seen.xyz, seen.xyz, R(0.0), R(0.0));
            }
#endif
            vstore8(value, (size_t)xk + (size_t)width * ((size_t)y + (size_t)height * (size_t)z), table);
        }
    }
}

/* The sun nodes a scatter with sun_stride 2 left between two computed ones (z odd, z < D - 1) of the padded
 * table (D, H, W, 8) at table + 8 table_offset, each channel the geometric mean of nodes z - 1 and z + 1, their
 * mean where either is not positive (TableSettings.orders_sun_stride; twin: clsky.reference.fill_between_sun_nodes).
 * layer_cells = H W. Global size: at least (D - 1) / 2 layer_cells, one cell a work-item. */
__kernel void fill_between_suns(__global real *table, const ulong table_offset, const int depth,
                                const ulong layer_cells)
{
    const size_t item = get_global_id(0);
    if (item >= (size_t)((depth - 1) / 2) * layer_cells)
        return;
    table += 8 * table_offset;
    const size_t z = 2 * (item / layer_cells) + 1, cell = item % layer_cells;
    const real8 below = vload8(cell + (z - 1) * layer_cells, table);
    const real8 above = vload8(cell + (z + 1) * layer_cells, table);
    const real8 mean = R(0.5) * (below + above);
    const real8 geometric = sqrt(below) * sqrt(above);
    vstore8(select(mean, geometric, (below > R(0.0)) & (above > R(0.0))), cell + z * layer_cells, table);
}

/* Elementwise steps of the orders with azimuth harmonics (clsky/azimuth.py), over padded tables of
 * `cells` real8 cells: what PyOpenCL's elementwise a * x + b and a * x + b * y kernels computed before
 * them, written as the same expressions (so with the same roundings: the compiler forms the same fused
 * multiply-adds; `one` and `zero` are arguments, 1 and 0, so that it cannot simplify them away) in one
 * pass with vector loads. Global size: at least `cells`. */

/* harmonic = sum_n weights[n] nodes[n] over the `count` slabs of `cells` cells of nodes (an order at its
 * azimuth nodes), as h = weights[0] L_0 + zero, then h = one h + weights[n] L_n for n = 1 .. count - 1. */
__kernel void combine_nodes(__global const real *nodes, __global const real *weights, const int count,
                            const ulong cells, const real one, const real zero, __global real *harmonic)
{
    const size_t cell = get_global_id(0);
    if (cell >= cells)
        return;
    real8 h = weights[0] * vload8(cell, nodes) + zero;
    for (int n = 1; n < count; ++n)
        h = one * h + weights[n] * vload8(cell + (size_t)n * (size_t)cells, nodes);
    vstore8(h, cell, harmonic);
}

/* total += scale addend per channel, as one * total + scale * addend (scale all ones: the sum, as PyOpenCL's
 * elementwise one * total + one * addend formed it; the orders' geometric tail scales per wavelength). */
__kernel void add_into(__global real *total, __global const real *addend, const ulong cells, const real one,
                       const real8 scale)
{
    const size_t cell = get_global_id(0);
    if (cell >= cells)
        return;
    vstore8(one * vload8(cell, total) + scale * vload8(cell, addend), cell, total);
}

/* packed[i * channels + c] = padded[i * 8 + c], c < channels: the first `channels` values of every row of a
 * padded table as one contiguous table, for one contiguous read: clsky.azimuth's downloads on devices whose
 * rectangular reads are slow (an H200 read rows of 3 of 8 doubles in 414 ms a node, all 8 contiguously in
 * 32 ms). A copy, bit for bit. */
__kernel void pack_channels(__global const real *padded, const ulong rows, const int channels,
                            __global real *packed)
{
    const size_t row = get_global_id(0);
    if (row >= rows)
        return;
    for (int c = 0; c < channels; ++c)
        packed[row * (size_t)channels + (size_t)c] = padded[row * 8 + (size_t)c];
}
