/* phase.cl -- phase functions, without 1/(4 pi) (docs/physics.md). c = cos(theta) = dot(Sun, V).
 *
 *   Rayleigh (0):                3/4 (1 + c^2)                    mean over the sphere 1
 *   modified Rayleigh (1):       0.8 (7/5 + c^2 / 2)              mean 1.2533 (Atmosphere Plus notes)
 *   Cornette-Shanks Mie (0):     3 (1 - g^2) / (2 (2 + g^2)) (1 + c^2) / (1 + g^2 + 2 g c)^(3/2)
 * with the notes' sign convention: g < 0 puts the forward lobe toward the sun (Cornette & Shanks
 * 1992, Applied Optics 31(16), eq. 4, with g -> -g). Requires real.cl, atmosphere_t.
 */

inline real phase_rayleigh(__constant const atmosphere_t *atm, const real c)
{
    return atm->rayleigh_phase ? R(0.8) * (R(1.4) + R(0.5) * c * c) : R(0.75) * (R(1.0) + c * c);
}

/* The base 1 + g^2 + 2gc is at least (1 - |g|)^2, its value at the peak (c = -sign(g)), but it is formed
 * from terms of size ~2: in float32 with |g| near 1 its rounding took it to 0 or below (an infinity or a
 * NaN). Below half that least value it is rounding noise and replaced by the least value; above, it
 * stays as formed, bit for bit (a few ulps below the least is common at c = +-1: 1.9e-15 relative for g = -0.85). */
inline real phase_mie(__constant const atmosphere_t *atm, const real c)
{
    const real g = atm->mie_g;
    const real g2 = g * g;
    const real least = (R(1.0) - fabs(g)) * (R(1.0) - fabs(g));
    const real formed = R(1.0) + g2 + R(2.0) * g * c;
    const real base = formed < R(0.5) * least ? least : formed;
    return R(1.5) * (R(1.0) - g2) / (R(2.0) + g2) * (R(1.0) + c * c) / (base * sqrt(base));
}
