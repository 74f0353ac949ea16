/* mapping.cl -- texture coordinates of the 3D scattering table (Atmosphere Plus, after Elek 2009).
 *
 * mapping == 1 (non-linear, default):  u = sqrt(h / Ha);  v = (1 + sign(c) |c|^(1/3)) / 2
 * mapping == 0 (linear, Elek):         u = h / Ha;        v = (c + 1) / 2
 * with c the cosine of the view zenith (v) or of the sun zenith (w, same formula); inverses
 * h = u^2 Ha, c = (2v - 1)^3 (non-linear). Macros, so that they serve real and realv alike (the
 * argument is evaluated more than once: pass a variable). Requires real.cl.
 */

/* altitude [m] of texture coordinate u */
#define MAPPING_ALTITUDE(u, mapping, ha) (((mapping) ? (u) * (u) : (u)) * (ha))
/* cosine of texture coordinate v (or w) */
#define MAPPING_COS(v, mapping) \
    ((mapping) ? (R(2.0) * (v) - R(1.0)) * (R(2.0) * (v) - R(1.0)) * (R(2.0) * (v) - R(1.0)) \
               : (R(2.0) * (v) - R(1.0)))
/* texture coordinate u of altitude h [m], clamped to [0, 1] */
#define MAPPING_U(h, mapping, ha) \
    ((mapping) ? sqrt(clamp((h) / (ha), R(0.0), R(1.0))) : clamp((h) / (ha), R(0.0), R(1.0)))
/* The sun axis may cover a sub-range of w only (a scene's sun path, clsky/planner.py): its D nodes
 * span w in [range.x, range.y] (real2; (0, 1) for the whole axis). */
/* position in [0, 1] along that sub-range of the sun cosine c, clamped */
#define MAPPING_SUN_T(c, mapping, range) \
    clamp((MAPPING_V(c, mapping) - (range).x) / ((range).y - (range).x), R(0.0), R(1.0))
/* texture coordinate v (or w) of cosine c, clamped to [0, 1] */
#define MAPPING_V(c, mapping) \
    (R(0.5) * (R(1.0) + ((mapping) ? cbrt(clamp((c), R(-1.0), R(1.0))) : clamp((c), R(-1.0), R(1.0)))))
