/* power_law.cl -- kernel of clsky/colorimetry_cl.py: the tabulated solar power law's XYZ (colorimetry.py,
 * _solar_power_law_tabulated_xyz, its NumPy twin), for the lit pixels of a frame, written into the frame's
 * XYZ (the unlit pixels 0).
 *
 *   XYZ = r_0 (B_0(q_0) + O_0(clip(q_0 / Delta_0))) + r_1 (B_1(q_1) + O_1(clip(q_1 / Delta_1))),
 *   q_k = log r_(k+1) - log r_k,
 * B_k and O_k interpolated linearly on their tables (nodes (i - half) step, clamped to the end nodes).
 *
 * Bit for bit the twin's values: the host computes the ratios r_k and their logarithms (NumPy's log; an
 * OpenCL log may differ in the last bit), and every operation here is one of the twin's, in its order:
 * IEEE +, -, *, / of doubles (correctly rounded in OpenCL), fmin / fmax for its clips, truncation for its
 * node indices, with no contraction into fused multiply-adds (the pragma below). VECTOR_WIDTH lit pixels a
 * work-item. Built with -DREAL_IS_DOUBLE=1 only (the twin is float64).
 * Requires real.cl.
 */

#pragma OPENCL FP_CONTRACT OFF

/* The three columns (X, Y, Z; each n_nodes values, one after the other at table) at x of the table on nodes
 * (i - half) step: out[c] = column[i] (1 - t) + column[i + 1] t, position = clip(x / step + half, 0,
 * 2 half), i = min(trunc(position), n_nodes - 2), t = position - i. */
inline void interpolate_columns(__global const real *table, const int n_nodes, const realv x, const real step,
                                const real half_nodes, realv *out)
{
    const realv position = fmin(fmax(x / step + half_nodes, V(0.0)), (realv)(R(2.0) * half_nodes));
    const intv index = min(CONVERT_INTV(position), (intv)(n_nodes - 2));
    const realv t = position - CONVERT_REALV(index);
    const realv below = V(1.0) - t;
    for (int c = 0; c < 3; ++c) {
        __global const real *column = table + c * n_nodes;
#if VECTOR_WIDTH == 8
        LOAD_LANES(2, node, column, index, 0);
        const realv low = LANES_OF(node, s0) * below;
        const realv high = LANES_OF(node, s1) * t;
#else
        const real2 node = vload2(0, column + index);
        const realv low = node.s0 * below;
        const realv high = node.s1 * t;
#endif
        out[c] = low + high;
    }
}

/* lit: rows of `stride` values: r_0, r_1, r_2 (the floored ratios, wavelengths ascending), then their
 * logarithms; lit pixel j at column j (j < n_lit; the rows are padded to a multiple of VECTOR_WIDTH).
 * pixels[j]: its pixel's index in xyz (n_pixels rows of X, Y, Z), ascending; every other pixel is unlit
 * and gets 0. inner_k / outer_k: B_k on n_inner nodes of step step_inner, O_k on n_outer nodes of step
 * step_outer (X, Y, Z columns one after the other). */
__kernel void power_law_xyz(__global const real *lit, const int stride, const int n_lit, __global const int *pixels,
                            __global const real *inner_0, __global const real *outer_0,
                            __global const real *inner_1, __global const real *outer_1,
                            const int n_inner, const int n_outer, const real step_inner, const real step_outer,
                            const real delta_0, const real delta_1, const real max_exponent,
                            const int n_pixels, __global real *xyz)
{
    const int first = get_global_id(0) * VECTOR_WIDTH;
    if (first >= n_lit)
        return;
    realv pair[2][3];
    for (int k = 0; k < 2; ++k) {
#if VECTOR_WIDTH == 8
        const realv log_low = vload8(0, lit + (size_t)(3 + k) * stride + first);
        const realv log_high = vload8(0, lit + (size_t)(4 + k) * stride + first);
        const realv ratio = vload8(0, lit + (size_t)k * stride + first);
#else
        const realv log_low = lit[(size_t)(3 + k) * stride + first];
        const realv log_high = lit[(size_t)(4 + k) * stride + first];
        const realv ratio = lit[(size_t)k * stride + first];
#endif
        const realv q = log_high - log_low;
        const real delta = k ? delta_1 : delta_0;
        const realv exponent = fmin(fmax(q / delta, (realv)(-max_exponent)), (realv)(max_exponent));
        realv between[3], beyond[3];
        interpolate_columns(k ? inner_1 : inner_0, n_inner, q, step_inner, (real)(n_inner / 2), between);
        interpolate_columns(k ? outer_1 : outer_0, n_outer, exponent, step_outer, (real)(n_outer / 2), beyond);
        for (int c = 0; c < 3; ++c)
            pair[k][c] = ratio * (between[c] + beyond[c]);
    }
    for (int lane = 0; lane < VECTOR_WIDTH && first + lane < n_lit; ++lane) {
        const int j = first + lane;
        const size_t pixel = (size_t)pixels[j];
        for (int c = 0; c < 3; ++c)
            xyz[3 * pixel + c] = LANE(pair[0][c], lane) + LANE(pair[1][c], lane);
        /* the unlit pixels, each written once: those between the previous lit pixel (pixels ascend) and
         * this one, and after the last lit one */
        for (size_t unlit = j ? (size_t)pixels[j - 1] + 1 : 0; unlit < pixel; ++unlit)
            xyz[3 * unlit] = xyz[3 * unlit + 1] = xyz[3 * unlit + 2] = R(0.0);
        if (j + 1 == n_lit)
            for (size_t unlit = pixel + 1; unlit < (size_t)n_pixels; ++unlit)
                xyz[3 * unlit] = xyz[3 * unlit + 1] = xyz[3 * unlit + 2] = R(0.0);
    }
}
