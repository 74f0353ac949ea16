/* column.cl -- column densities along a segment, the integrals inside the optical depth, and the one
 * place where the species' densities and extinctions meet.
 *
 * Densities (dimensionless, 1 at their reference): rho_R = exp(-h / H_R), rho_M = exp(-h / H_M) and,
 * with -DOZONE, Bruneton 2017's ozone tent f_O(h) = max(0, 1 - |h - h_peak| / w) (clsky/ozone.py).
 * For a segment of length d [m] leaving altitude h0 [m] along direction cosine mu:
 *   C_s = Integral_0^d rho_s(h(t)) dt   [m],  s in {R, M (, O)}
 * by the trapezoidal rule over N_SUN + 1 nodes t_j = d f(j / N_SUN) (Bruneton & Neyret 2008 use
 * N = 30). f(x) = x (uniform) or, with -DKELLER_BOHN_SAMPLING, f(x) = x^2, the non-uniform
 * optical-depth sampling of Keller & Bohn that puts nodes where the density is high. Optical depth
 * per wavelength (physics.md):
 *   tau = beta_R C_R + beta_M^e C_M (+ sigma_O3 n_max C_O with -DOZONE), every coefficient per wavelength
 * Ozone absorbs only: it enters tau and nothing else. Without -DOZONE, column_t has no ozone member
 * and every expression is the ozone-free one. Works on realv (1 or 8 lanes).
 * Requires real.cl, atmosphere_t, geometry.cl.
 */
#ifndef N_SUN
#error "N_SUN (number of trapezoid steps along a sun ray) must be defined"
#endif

#ifdef OZONE
#define COLUMN_CHANNELS 3   /* C_R, C_M, C_O per node of the 2D table */
#else
#define COLUMN_CHANNELS 2   /* C_R, C_M */
#endif

/* Column densities [m] (or, from densities_at, the densities themselves) of every species. */
typedef struct {
    realv r;
    realv m;
#ifdef OZONE
    realv o;
#endif
} column_t;

inline column_t column_zero(void)
{
    column_t c;
    c.r = V(0.0);
    c.m = V(0.0);
#ifdef OZONE
    c.o = V(0.0);
#endif
    return c;
}

/* a + b, per species. */
inline column_t column_sum(const column_t a, const column_t b)
{
    column_t c;
    c.r = a.r + b.r;
    c.m = a.m + b.m;
#ifdef OZONE
    c.o = a.o + b.o;
#endif
    return c;
}

/* One trapezoid step: sum + (a + b) half_step, per species. */
inline column_t column_step(const column_t sum, const column_t a, const column_t b, const realv half_step)
{
    column_t c;
    c.r = sum.r + (a.r + b.r) * half_step;
    c.m = sum.m + (a.m + b.m) * half_step;
#ifdef OZONE
    c.o = sum.o + (a.o + b.o) * half_step;
#endif
    return c;
}

#ifdef OZONE
/* The ozone tent f_O(h) = max(0, 1 - |h - h_peak| / w), 1 at the peak (n_O3 = n_max f_O). */
inline realv ozone_profile(__constant const atmosphere_t *atm, const realv h)
{
    return fmax(R(1.0) - fabs(h - atm->ozone_peak_altitude) / atm->ozone_half_width, R(0.0));
}
#endif

/* Densities at altitude h; inv_hr = 1 / H_R, inv_hm = 1 / H_M. */
inline column_t densities_at(__constant const atmosphere_t *atm, const realv h, const real inv_hr, const real inv_hm)
{
    column_t c;
    c.r = exp(-h * inv_hr);
    c.m = exp(-h * inv_hm);
#ifdef OZONE
    c.o = ozone_profile(atm, h);
#endif
    return c;
}

/* tau of one wavelength: beta_r C_R + beta_me C_M (+ beta_o C_O with -DOZONE), beta_o = sigma n_max. */
inline realv optical_depth_of(const column_t c, const real beta_r, const real beta_me, const real beta_o)
{
#ifdef OZONE
    return beta_r * c.r + beta_me * c.m + beta_o * c.o;
#else
    return beta_r * c.r + beta_me * c.m;
#endif
}

inline real sun_node(const int j)
{
    const real x = (real)j / (real)N_SUN;
#ifdef KELLER_BOHN_SAMPLING
    return x * x;
#else
    return x;
#endif
}

inline column_t column_density(__constant const atmosphere_t *atm, const realv h0, const realv mu, const realv d)
{
    const realv r0 = atm->planet_radius + h0;
    const real inv_hr = R(1.0) / atm->rayleigh_scale_height;
    const real inv_hm = R(1.0) / atm->mie_scale_height;
    column_t sum = column_zero();
    column_t previous = densities_at(atm, h0, inv_hr, inv_hm);
    real node_previous = R(0.0);
    for (int j = 1; j <= N_SUN; ++j) {
        const real node = sun_node(j);
        const realv h = altitude_along(h0, r0, mu, d * node, atm->planet_radius);
        const column_t density = densities_at(atm, h, inv_hr, inv_hm);
        const realv half_step = R(0.5) * d * (node - node_previous);
        sum = column_step(sum, previous, density, half_step);
        previous = density;
        node_previous = node;
    }
    return sum;
}
