/* The floor of a frame: one work-item per pixel writes the four per-pixel outputs of the
 * renderers (depth, quadric id, primitive id, RGBA8) and nothing else (bench/render.py). */
__kernel void write_frame(__global float *depth, __global int *ids, __global int *prims, __global uchar4 *rgba,
                          int width, int height)
{
    int j = get_global_id(0), i = get_global_id(1);
    if (i >= height || j >= width) return;
    int p = i * width + j;
    depth[p] = INFINITY;
    ids[p] = -1;
    prims[p] = -1;
    rgba[p] = (uchar4)(255, 255, 255, 255);
}
