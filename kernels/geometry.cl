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

/* Every helper takes the altitude h = r - Rp [m] rather than the radius: in float32, r = Rp + h rounds
 * h to 0.5 m at 6.4e6 m, so differences of squared radii are formed from h directly:
 * r^2 - Rp^2 = h (2 Rp + h) and Ra^2 - r^2 = (Ha - h)(Ra + r). */

/* Cosine of the zenith angle of the horizon seen from altitude h: rays with mu < horizon_cos hit the
 * planet. -sqrt(1 - (Rp/r)^2) = -sqrt(h (2 Rp + h)) / (Rp + h). */
inline realv horizon_cos(const realv h, const real planet_radius)
{
    return -sqrt(fmax(h * (R(2.0) * planet_radius + h), R(0.0))) / (planet_radius + h);
}

/* Length [m] from altitude h <= Ha along mu to the top of the atmosphere Ra. */
inline realv distance_to_top(const realv h, const realv mu, const real planet_radius, const real top_radius)
{
    const realv r = planet_radius + h;
    const realv inside = fmax(((top_radius - planet_radius) - h) * (top_radius + r), R(0.0));   /* Ra^2 - r^2 */
    const realv root = sqrt(inside + r * mu * r * mu);
    /* mu > 0: -r mu + root would cancel; use the conjugate form instead. */
    return SELECT(root - r * mu, inside / fmax(r * mu + root, REAL_TINY), mu > R(0.0));
}

/* Length [m] from altitude h along mu (< horizon_cos) to the ground. */
inline realv distance_to_ground(const realv h, const realv mu, const real planet_radius)
{
    const realv r = planet_radius + h;
    const realv above = fmax(h * (R(2.0) * planet_radius + h), R(0.0));   /* r^2 - Rp^2 */
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

/* Moves observers above the atmosphere (h > Ha) to the entry point of their view ray, in place: h,
 * mu_v and mu_s at the entry (nu = dot(V, Sun) does not change along a ray). Returns the mask of rays
 * that see the atmosphere (every ray of an observer inside it). Branch-free; logical operators give
 * 1 / 0 on scalars and -1 / 0 on vectors, as select() expects. */
inline maskv enter_atmosphere(const real planet_radius, const real top_radius, realv *h, realv *mu_v,
                              realv *mu_s, const realv nu)
{
    const realv r = planet_radius + *h;
    const maskv above = isgreater(*h, top_radius - planet_radius);
    const realv outside = fmax((r - top_radius) * (r + top_radius), R(0.0));        /* r^2 - Ra^2 */
    const realv discriminant = r * *mu_v * r * *mu_v - outside;
    const maskv enters = isless(*mu_v, R(0.0)) && isgreaterequal(discriminant, R(0.0));
    const realv d = outside / fmax(sqrt(fmax(discriminant, R(0.0))) - r * *mu_v, REAL_TINY);   /* near root */
    *mu_s = SELECT(*mu_s, clamp((r * *mu_s + d * nu) / top_radius, R(-1.0), R(1.0)), above);
    *mu_v = SELECT(*mu_v, clamp((r * *mu_v + d) / top_radius, R(-1.0), R(1.0)), above);
    *h = SELECT(*h, (realv)(top_radius - planet_radius), above);
    return !above || enters;
}
