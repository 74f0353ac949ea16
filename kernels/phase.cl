/* phase.cl -- phase functions, without 1/(4 pi) (physics.md). c = cos(theta) = dot(Sun, V).
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

inline real phase_mie(__constant const atmosphere_t *atm, const real c)
{
    const real g = atm->mie_g;
    const real g2 = g * g;
    const real base = R(1.0) + g2 + R(2.0) * g * c;
    return R(1.5) * (R(1.0) - g2) / (R(2.0) + g2) * (R(1.0) + c * c) / (base * sqrt(base));
}
