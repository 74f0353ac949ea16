/* geometry.cl -- rays in a spherical atmosphere, written to stay accurate at radii of 6.4e6 m.
 *
 * A point is given by its radius r [m] (or altitude h = r - Rp [m]) and the cosine mu of the zenith
 * angle of a direction there. Differences of squares of radii are always formed as (a - b)(a + b) and
 * ray lengths by the cancellation-free root of the quadratic (Press et al., Numerical Recipes, 3rd ed.,
 * sec. 5.6; Bruneton & Neyret 2008, sec. 4), so no result depends on the rounding noise of
 * |P|^2 - R^2. Both roots are finite for every input (denominators are kept >= REAL_TINY), so the
 * branch-free SELECT() of the callers never meets a NaN. Works on realv (1 or 8 lanes).
 * Requires real.cl.
 */

/* Cosine of the zenith angle of the horizon seen from radius r: rays with mu < horizon_cos hit the
 * planet. -sqrt(1 - (Rp/r)^2), written as -sqrt((r - Rp)(r + Rp)) / r. */
inline realv horizon_cos(const realv r, const real planet_radius)
{
    return -sqrt(fmax((r - planet_radius) * (r + planet_radius), R(0.0))) / r;
}

/* Length [m] from radius r <= Ra along mu to the top of the atmosphere Ra. */
inline realv distance_to_top(const realv r, const realv mu, const real top_radius)
{
    const realv inside = fmax((top_radius - r) * (top_radius + r), R(0.0));   /* Ra^2 - r^2 >= 0 */
    const realv root = sqrt(inside + r * mu * r * mu);
    /* mu > 0: -r mu + root would cancel; use the conjugate form instead. */
    return SELECT(root - r * mu, inside / fmax(r * mu + root, REAL_TINY), mu > R(0.0));
}

/* Length [m] from radius r along mu (< horizon_cos) to the ground. */
inline realv distance_to_ground(const realv r, const realv mu, const real planet_radius)
{
    const realv above = fmax((r - planet_radius) * (r + planet_radius), R(0.0));   /* r^2 - Rp^2 */
    const realv root = sqrt(fmax(r * mu * r * mu - above, R(0.0)));
    return above / fmax(root - r * mu, REAL_TINY);     /* = -r mu - root, without cancellation */
}

/* Altitude [m] at distance s [m] along mu from altitude h0 (radius r0): h = (r^2 - Rp^2) / (r + Rp)
 * with r^2 - Rp^2 = h0 (2 Rp + h0) + s (2 r0 mu + s), never negative. */
inline realv altitude_along(const realv h0, const realv r0, const realv mu, const realv s, const real planet_radius)
{
    const realv excess = fmax(h0 * (R(2.0) * planet_radius + h0) + s * (R(2.0) * r0 * mu + s), R(0.0));
    return excess / (sqrt(planet_radius * planet_radius + excess) + planet_radius);
}
