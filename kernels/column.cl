/* column.cl -- column densities along a segment, the integrals inside the optical depth.
 *
 * For a segment of length d [m] leaving altitude h0 [m] along direction cosine mu:
 *   C_R = Integral_0^d rho_R(h(t)) dt,  C_M = Integral_0^d rho_M(h(t)) dt   [m],  rho_s = exp(-h / H_s)
 * by the trapezoidal rule over N_SUN + 1 nodes t_j = d f(j / N_SUN) (Bruneton & Neyret 2008 use
 * N = 30). f(x) = x (uniform) or, with -DKELLER_BOHN_SAMPLING, f(x) = x^2, the non-uniform
 * optical-depth sampling of Keller & Bohn that puts nodes where the density is high. Optical depth
 * per wavelength: tau = beta_R C_R + beta_M^e C_M (physics.md). Works on realv (1 or 8 lanes).
 * Requires real.cl, atmosphere_t, geometry.cl.
 */
#ifndef N_SUN
#error "N_SUN (number of trapezoid steps along a sun ray) must be defined"
#endif

inline real sun_node(const int j)
{
    const real x = (real)j / (real)N_SUN;
#ifdef KELLER_BOHN_SAMPLING
    return x * x;
#else
    return x;
#endif
}

inline void column_density(__constant const atmosphere_t *atm, const realv h0, const realv mu, const realv d,
                           realv *column_r, realv *column_m)
{
    const realv r0 = atm->planet_radius + h0;
    const real inv_hr = R(1.0) / atm->rayleigh_scale_height;
    const real inv_hm = R(1.0) / atm->mie_scale_height;
    realv sum_r = V(0.0), sum_m = V(0.0);
    realv previous_r = exp(-h0 * inv_hr), previous_m = exp(-h0 * inv_hm);
    real node_previous = R(0.0);
    for (int j = 1; j <= N_SUN; ++j) {
        const real node = sun_node(j);
        const realv h = altitude_along(h0, r0, mu, d * node, atm->planet_radius);
        const realv density_r = exp(-h * inv_hr), density_m = exp(-h * inv_hm);
        const realv half_step = R(0.5) * d * (node - node_previous);
        sum_r += (previous_r + density_r) * half_step;
        sum_m += (previous_m + density_m) * half_step;
        previous_r = density_r;
        previous_m = density_m;
        node_previous = node;
    }
    *column_r = sum_r;
    *column_m = sum_m;
}
