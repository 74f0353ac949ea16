/* stopping.cl -- the orders' stopping test on the device (clsky/stopping.py: DeviceStoppingTest): the
 * numbers of the host's clsky.orders.relative_addition, bit for bit.
 *
 * An order's values are channels 0-2 of a padded device table (cells, 8) of type NODE (float or double,
 * the table's precision: -DNODE=float or -DNODE=double); the running sum S and the order before, P, are
 * (cells, 3) in double, as the host keeps them (float32 values convert exactly). Every operation is the
 * one NumPy does, rounded once: no fused multiply-add (FP_CONTRACT OFF below; the program is never built
 * with -cl-fast-relaxed-math) and double division, which OpenCL rounds correctly. Maxima are exact in
 * any order, so that each work-item's maximum over its chunk of cells, and the host's maximum over the
 * work-items, are the host's maximum over the table.
 *
 * Each work-item takes `chunk` consecutive cells (the launch: ceil(cells / chunk) work-items, any
 * work-group size): no local memory, no barrier. The three kernels run one after the other on the
 * orders' queue, with no trip to the host between them: the host reads the ratios' maxima when it
 * needs them. */
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

#ifndef NODE
#error "build with -DNODE=float or -DNODE=double"
#endif

/* The cells [first, last) of work-item `item`: `chunk` consecutive cells, fewer at the end; false past it. */
inline bool chunk_of(const size_t item, const ulong cells, const uint chunk, ulong *first, ulong *last)
{
    *first = (ulong)item * chunk;
    *last = min(*first + (ulong)chunk, cells);
    return *first < cells;
}

/* S += the order, per value; maxima[3 item + c] = channel c's maximum of the new S over the item's cells. */
__kernel void running_sum(__global const NODE *order, __global double *running, const ulong cells,
                          const uint chunk, __global double *maxima)
{
    const size_t item = get_global_id(0);
    ulong first, last;
    if (!chunk_of(item, cells, chunk, &first, &last))
        return;
    double peak[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (ulong cell = first; cell < last; ++cell)
        for (int c = 0; c < 3; ++c) {
            const double sum = running[3 * cell + c] + (double)order[8 * cell + c];
            running[3 * cell + c] = sum;
            peak[c] = fmax(peak[c], sum);
        }
    for (int c = 0; c < 3; ++c)
        maxima[3 * item + c] = peak[c];
}

/* threshold[c] = fraction x channel c's maximum of S over the table, from running_sum's maxima of `items`
 * work-items (one work-item: the bright part's bound, without a trip to the host). */
__kernel void bright_threshold(__global const double *maxima, const uint items, const double fraction,
                               __global double *threshold)
{
    if (get_global_id(0) != 0)
        return;
    for (int c = 0; c < 3; ++c) {
        double peak = -INFINITY;
        for (uint item = 0; item < items; ++item)
            peak = fmax(peak, maxima[3 * item + c]);
        threshold[c] = fraction * peak;
    }
}

/* Over the item's bright values (S >= threshold[c] and S > 0, channel c of a cell):
 *   ratios[2 item]     = max of order / S (0 if none),
 *   ratios[2 item + 1] = with `estimate`, max of |order - ratio[c] P| / squared_complement[c] / S (the
 *                        estimated error of the sum with its geometric tail, clsky.orders), else 0;
 * with `keep`, P = the order afterwards (for the next order's estimate). The host's maxima start from the
 * zeros of the cells that are not bright (relative_addition): the same for orders >= 0. */
__kernel void order_ratios(__global const NODE *order, __global const double *running, __global double *previous,
                           const ulong cells, const uint chunk, __global const double *threshold,
                           const double4 ratio, const double4 squared_complement, const int estimate,
                           const int keep, __global double *ratios)
{
    const size_t item = get_global_id(0);
    ulong first, last;
    if (!chunk_of(item, cells, chunk, &first, &last))
        return;
    const double bound[3] = {threshold[0], threshold[1], threshold[2]};
    const double r[3] = {ratio.x, ratio.y, ratio.z};
    const double complement[3] = {squared_complement.x, squared_complement.y, squared_complement.z};
    double addition = 0.0, error = 0.0;
    for (ulong cell = first; cell < last; ++cell)
        for (int c = 0; c < 3; ++c) {
            const double added = (double)order[8 * cell + c], sum = running[3 * cell + c];
            if (sum >= bound[c] && sum > 0.0) {
                addition = fmax(addition, added / sum);
                if (estimate) {
                    const double extrapolated = r[c] * previous[3 * cell + c];
                    error = fmax(error, fabs(added - extrapolated) / complement[c] / sum);
                }
            }
            if (keep)
                previous[3 * cell + c] = added;
        }
    ratios[2 * item] = addition;
    ratios[2 * item + 1] = error;
}
