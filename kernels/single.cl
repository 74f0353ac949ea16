/* single.cl -- kernel of clsky/single.py: the single-scattering 3D table.
 *
 * For each cell (altitude h, view-zenith cosine mu_v, sun-zenith cosine mu_s) in the canonical frame
 * (sun and view in one vertical plane, same side: cos theta = cos(phi - delta)), per species s and
 * wavelength lambda, without I_I and without the phase function (physics.md; Elek 2009, eq. 4.2):
 *
 *   Ibar_s^(1) = beta_s / (4 pi) Integral_{Pa}^{Pb} rho_s(h(P)) T(Pc, P) T(P, Pa) ds
 *
 * Pa = observer (inside the atmosphere), Pb = top of the atmosphere or the ground. Trapezoidal rule
 * over N_VIEW + 1 nodes s_i = L f(i / N_VIEW), f(x) = x, or x^3 with -DKELLER_BOHN_SAMPLING. T(P, Pa) is
 * accumulated by the same trapezoid along the view ray; T(Pc, P) is re-marched with N_SUN steps
 * (column.cl) or, with -DSUN_TRANSMITTANCE_TABLE, read from the 2D table (transmittance_table.cl).
 * A node whose sun ray hits the planet (mu below the local horizon, decided from its altitude and
 * mu, never from |P| - Rp rounding) is in the shadow and contributes nothing. The last node of a
 * ground-hitting view ray lies on the ground at altitude exactly 0.
 *
 * Each work-item computes VECTOR_WIDTH cells along the altitude axis (x = VECTOR_WIDTH gx + lane), all
 * branch-free in realv arithmetic. Global size (ceil(W / VECTOR_WIDTH), H, slab): a launch covers the
 * sun-zenith layers z_offset .. z_offset + slab - 1 (the host launches slabs to report progress).
 *
 * Output: 6 reals per cell at index i = x + y W + z W H: Rayleigh r, g, b, then Mie r, g, b [1/sr].
 * Requires real.cl, atmosphere_t, geometry.cl, column.cl, transmittance_table.cl, mapping.cl.
 */
#ifndef N_VIEW
#error "N_VIEW (number of trapezoid steps along a view ray) must be defined"
#endif

inline real view_node(const int i)
{
    const real x = (real)i / (real)N_VIEW;
#ifdef KELLER_BOHN_SAMPLING
    return x * x * x;
#else
    return x;
#endif
}

__kernel void single_scattering(__constant const atmosphere_t *atm, const int width, const int height,
                                const int depth, const int z_offset, const int mapping,
                                __global const real *sun_table, const int tw, const int th,
                                __global real *table)
{
    const int gx = get_global_id(0);
    const int y = get_global_id(1);
    const int z = get_global_id(2) + z_offset;
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
    /* cos(phi - delta), the scattering-angle cosine of the canonical frame */
    const real nu = mu_v * mu_s + sqrt(fmax(R(1.0) - mu_v * mu_v, R(0.0)) * fmax(R(1.0) - mu_s * mu_s, R(0.0)));

    const maskv hits_ground = isless((realv)(mu_v), horizon_cos(h0, rp));
    const realv length = SELECT(distance_to_top(h0, (realv)(mu_v), rp, atm->top_radius),
                                distance_to_ground(h0, (realv)(mu_v), rp), hits_ground);

    const real inv_hr = R(1.0) / atm->rayleigh_scale_height;
    const real inv_hm = R(1.0) / atm->mie_scale_height;
    const real4 beta = atm->beta_rayleigh;
    const real beta_me = atm->beta_mie_extinction;
    realv view_r = V(0.0), view_m = V(0.0);                 /* column densities from the observer */
    realv last_density_r = V(0.0), last_density_m = V(0.0);
    realv last_fr0 = V(0.0), last_fr1 = V(0.0), last_fr2 = V(0.0);
    realv last_fm0 = V(0.0), last_fm1 = V(0.0), last_fm2 = V(0.0);
    realv sum_r0 = V(0.0), sum_r1 = V(0.0), sum_r2 = V(0.0);
    realv sum_m0 = V(0.0), sum_m1 = V(0.0), sum_m2 = V(0.0);
    real node_previous = R(0.0);

    for (int i = 0; i <= N_VIEW; ++i) {
        const real node = view_node(i);
        const realv s = length * node;
        realv h = altitude_along(h0, r0, (realv)(mu_v), s, rp);
        if (i == N_VIEW)
            h = SELECT(h, V(0.0), hits_ground);
        const realv r = rp + h;
        const realv mu_sun_here = (r0 * mu_s + s * nu) / r;     /* dot(P, Sun) / |P| */
        const maskv lit = isgreaterequal(mu_sun_here, horizon_cos(h, rp));
        const realv density_r = exp(-h * inv_hr), density_m = exp(-h * inv_hm);
        const realv half_step = R(0.5) * length * (node - node_previous);
        if (i > 0) {
            view_r += (last_density_r + density_r) * half_step;
            view_m += (last_density_m + density_m) * half_step;
        }
        realv sun_r, sun_m;
#ifdef SUN_TRANSMITTANCE_TABLE
        column_density_from_table(atm, sun_table, tw, th, h, mu_sun_here, &sun_r, &sun_m);
#else
        /* in the shadow the march would cross the planet: give it zero length, then discard */
        const realv sun_length = SELECT(V(0.0), distance_to_top(h, mu_sun_here, rp, atm->top_radius), lit);
        column_density(atm, h, mu_sun_here, sun_length, &sun_r, &sun_m);
#endif
        const realv column_r = view_r + sun_r, column_m = view_m + sun_m;
        const realv t0 = SELECT(V(0.0), exp(-(beta.x * column_r + beta_me * column_m)), lit);
        const realv t1 = SELECT(V(0.0), exp(-(beta.y * column_r + beta_me * column_m)), lit);
        const realv t2 = SELECT(V(0.0), exp(-(beta.z * column_r + beta_me * column_m)), lit);
        const realv fr0 = density_r * t0, fr1 = density_r * t1, fr2 = density_r * t2;
        const realv fm0 = density_m * t0, fm1 = density_m * t1, fm2 = density_m * t2;
        if (i > 0) {
            sum_r0 += (last_fr0 + fr0) * half_step;
            sum_r1 += (last_fr1 + fr1) * half_step;
            sum_r2 += (last_fr2 + fr2) * half_step;
            sum_m0 += (last_fm0 + fm0) * half_step;
            sum_m1 += (last_fm1 + fm1) * half_step;
            sum_m2 += (last_fm2 + fm2) * half_step;
        }
        last_density_r = density_r;
        last_density_m = density_m;
        last_fr0 = fr0; last_fr1 = fr1; last_fr2 = fr2;
        last_fm0 = fm0; last_fm1 = fm1; last_fm2 = fm2;
        node_previous = node;
    }

    const real scale_r = R(1.0) / (R(4.0) * PI_REAL);
    const real scale_m = atm->beta_mie / (R(4.0) * PI_REAL);
    for (int k = 0; k < VECTOR_WIDTH; ++k) {
        const int xk = gx * VECTOR_WIDTH + k;
        if (xk >= width)
            break;
        const size_t cell = 6 * ((size_t)xk + (size_t)width * ((size_t)y + (size_t)height * (size_t)z));
        table[cell] = beta.x * scale_r * LANE(sum_r0, k);
        table[cell + 1] = beta.y * scale_r * LANE(sum_r1, k);
        table[cell + 2] = beta.z * scale_r * LANE(sum_r2, k);
        table[cell + 3] = scale_m * LANE(sum_m0, k);
        table[cell + 4] = scale_m * LANE(sum_m1, k);
        table[cell + 5] = scale_m * LANE(sum_m2, k);
    }
}
