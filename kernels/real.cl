/* real.cl -- precision prelude shared by every clsky program.
 *
 * -DREAL_IS_DOUBLE=1 selects double precision (clsky's default); otherwise float32. Shared code uses
 * only `real`, `real2`, `real3`, `real4`, `real8` and the R(x) literal macro, never `float` or `1.0f`.
 */
#ifdef REAL_IS_DOUBLE
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
typedef double real;
typedef double2 real2;
typedef double3 real3;
typedef double4 real4;
typedef double8 real8;
#define R(x) ((real)(x))
#define CONVERT_REAL8(v) convert_double8(v)
#define REAL_TINY DBL_MIN
#else
typedef float real;
typedef float2 real2;
typedef float3 real3;
typedef float4 real4;
typedef float8 real8;
#define R(x) ((real)(x##f))
#define CONVERT_REAL8(v) convert_float8(v)
#define REAL_TINY FLT_MIN
#endif

#define PI_REAL R(3.14159265358979323846)

/* realv: the type the geometry and column helpers compute in. -DVECTOR_WIDTH=8 makes every work-item
 * handle 8 cells at once in real8 arithmetic, which PoCL maps onto AVX-512, or two AVX2 registers (it
 * does not vectorise the scalar loops across work-items by itself: docs/speed-log.md). maskv holds comparison results
 * (-1 true in vectors, 1 true in scalars); select() accepts both. */
#ifndef VECTOR_WIDTH
#define VECTOR_WIDTH 1
#endif
#if VECTOR_WIDTH == 8
typedef real8 realv;
#define LANE_INDEX ((realv)(R(0.0), R(1.0), R(2.0), R(3.0), R(4.0), R(5.0), R(6.0), R(7.0)))
#ifdef REAL_IS_DOUBLE
typedef long8 maskv;
#else
typedef int8 maskv;
#endif
#elif VECTOR_WIDTH == 1
typedef real realv;
typedef int maskv;
#define LANE_INDEX R(0.0)
#else
#error "VECTOR_WIDTH must be 1 or 8"
#endif
#define V(x) ((realv)(R(x)))
/* intv: integer node indices of a realv (CONVERT_INTV truncates toward zero, as a (int) cast does;
 * CONVERT_REALV converts back), INT_LANE(v, k) lane k of one */
#if VECTOR_WIDTH == 8
typedef int8 intv;
#define CONVERT_INTV(v) convert_int8(v)
#define CONVERT_REALV(v) CONVERT_REAL8(v)
#define INT_LANE(v, k) (((int *)&(v))[k])
/* LOAD_LANES(n, v, p, i, offset): declares v##0 .. v##7, the real##n (n = 2, 4, 8) at p + offset +
 * i.sk of each lane k (i an intv); LANES_OF(v, s): the realv of component s of v##0 .. v##7, built in
 * registers. Together they gather n contiguous values per lane with one vector load each (a transpose),
 * rather than n scalar loads per lane. */
#define LOAD_LANES(n, v, p, i, offset)                                                                     \
    const real##n v##0 = vload##n(0, (p) + (i).s0 + (offset)), v##1 = vload##n(0, (p) + (i).s1 + (offset)), \
                  v##2 = vload##n(0, (p) + (i).s2 + (offset)), v##3 = vload##n(0, (p) + (i).s3 + (offset)), \
                  v##4 = vload##n(0, (p) + (i).s4 + (offset)), v##5 = vload##n(0, (p) + (i).s5 + (offset)), \
                  v##6 = vload##n(0, (p) + (i).s6 + (offset)), v##7 = vload##n(0, (p) + (i).s7 + (offset))
#define LANES_OF(v, s) ((realv)((v##0).s, (v##1).s, (v##2).s, (v##3).s, (v##4).s, (v##5).s, (v##6).s, (v##7).s))
#else
typedef int intv;
#define CONVERT_INTV(v) ((int)(v))
#define CONVERT_REALV(v) ((real)(v))
#define INT_LANE(v, k) (v)
#endif
/* mask type of real8 comparisons */
#ifdef REAL_IS_DOUBLE
typedef long8 maskv8;
#else
typedef int8 maskv8;
#endif
/* SELECT(a, b, m): b where mask m is true, else a (select() is ambiguous for scalar double); ANY_LANE(m):
 * whether mask m is true in any lane */
#if VECTOR_WIDTH == 1
#define SELECT(a, b, m) ((m) ? (b) : (a))
#define ANY_LANE(m) ((m) != 0)
#else
#define SELECT(a, b, m) select((a), (b), (m))
#define ANY_LANE(m) any(m)
#endif
/* lane k of a realv, and of a maskv */
#define LANE(v, k) (((real *)&(v))[k])
#if VECTOR_WIDTH == 8 && defined(REAL_IS_DOUBLE)
#define MASK_LANE(m, k) (((long *)&(m))[k])
#else
#define MASK_LANE(m, k) (((int *)&(m))[k])
#endif
