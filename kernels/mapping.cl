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
    (R(0.5) * (R(1.0) + ((mapping) ? CUBE_ROOT_UNIT(clamp((c), R(-1.0), R(1.0))) \
                                   : clamp((c), R(-1.0), R(1.0)))))

/* CUBE_ROOT_UNIT(x): the real cube root of x in [-1, 1], for real and real8 x.
 *
 * In double precision, cube_root_unit() below: OpenCL's cbrt() costs PoCL here about 2.5x the
 * arithmetic below (400 M against 900-950 M double8 roots per CPU-second), and the non-linear
 * mapping takes one per view and sun coordinate of every ray node (the scatter, the ray march).
 * -DCUBE_ROOT_LIBRARY=1 (clsky._cl.CUBE_ROOT = "library") keeps cbrt(), as in float32 and on
 * compilers without clang's overloadable functions. */
#if defined(REAL_IS_DOUBLE) && defined(__clang__) && !defined(CUBE_ROOT_LIBRARY)
#define CUBE_ROOT_UNIT(x) cube_root_unit(x)
#define CUBE_ROOT_HALLEY 1

/* The body of cube_root_unit, for a scalar or vector type T (AS_T, AS_U: the reinterpretations of
 * T as itself and as its unsigned 64-bit integer type; SELECT_IF(a, b, m): b where m, else a).
 *
 * Seed: a third of the bit pattern of |x| plus a constant (the exponent divided by 3, the mantissa
 * roughly so: within 3.3 % of the root; W. Kahan's bit trick, the constant's high word being B1 =
 * 715094163 of FreeBSD's s_cbrt.c), then three Halley steps y <- y (y^3 + 2|x|) / (2 y^3 + |x|), each
 * cubing the relative error: within 3 ulp of the exact root for DBL_MIN <= |x| <= 1 (2.9 ulp at
 * most over the 2^20 + 2^18 arguments of tests/test_cube_root.py, against an 80-bit reference). The quotient of each step is formed first, so
 * that no product falls to a subnormal (PoCL here flushes those to zero). Subnormal x (|x| <
 * DBL_MIN) get a value of their sign below 3e-103 in magnitude, as their roots are, but not their
 * root: the seed's bit trick assumes a normal number, and rescaling them cost a quarter of the
 * speed; MAPPING_V does not see it (0.5 (1 + y) is 0.5 for every |y| < 2^-54). Zero gives x itself
 * (its sign kept). */
#define CUBE_ROOT_UNIT_BODY(x, T, AS_T, AS_U, SELECT_IF)                                             \
    const T a = fabs(x);                                                                            \
    T y = AS_T(AS_U(a) / 3UL + 0x2A9F7893782DA1CEUL);                                                \
    for (int step = 0; step < 3; ++step) {                                                          \
        const T y3 = y * y * y;                                                                     \
        y = y * ((y3 + R(2.0) * a) / (R(2.0) * y3 + a));                                            \
    }                                                                                               \
    return SELECT_IF(x, copysign(y, x), a > R(0.0));

#define CUBE_ROOT_SCALAR_IF(a, b, m) ((m) ? (b) : (a))
inline double __attribute__((overloadable)) cube_root_unit(const double x)
{
    CUBE_ROOT_UNIT_BODY(x, double, as_double, as_ulong, CUBE_ROOT_SCALAR_IF)
}

inline double8 __attribute__((overloadable)) cube_root_unit(const double8 x)
{
    CUBE_ROOT_UNIT_BODY(x, double8, as_double8, as_ulong8, select)
}
#else
#define CUBE_ROOT_UNIT(x) cbrt(x)
#define CUBE_ROOT_HALLEY 0
#endif
