/* Device buffer layout shared by every kernel; mirrored by numpy dtypes in
 * clcsg/host/buffers.py (a test reads the buffers back through kernels/layout_check.cl).
 *
 * Scalars are `real`: double when the host builds with -DCLCSG_DOUBLE (devices with fp64),
 * float otherwise.  All coordinates on the device are relative to the scene origin the host
 * chose (the center of the scene bound), which keeps float32 precise at millimetre scale.
 */
#ifndef CLCSG_LAYOUT_H
#define CLCSG_LAYOUT_H

#ifdef CLCSG_DOUBLE
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
typedef double real;
typedef double2 real2;
typedef double3 real3;
typedef double4 real4;
#define REAL_MAX DBL_MAX
#define REAL_EPS DBL_EPSILON
#else
typedef float real;
typedef float2 real2;
typedef float3 real3;
typedef float4 real4;
#define REAL_MAX FLT_MAX
#define REAL_EPS FLT_EPSILON
#endif

/* One unique quadric.  coef: the 10 coefficients of the symmetric 4x4 matrix in the order
 * xx xy xz xw yy yz yw zz zw ww (upper triangle, row-major), so that
 * Q(p) = xx x^2 + 2 xy x y + 2 xz x z + 2 xw x + yy y^2 + 2 yz y z + 2 yw y + zz z^2 + 2 zw z + ww.
 * lam_min / lam_max: extreme eigenvalues of the 3x3 part A (conservative distance, eqs. 10-12). */
typedef struct {
    real coef[10];
    real lam_min;
    real lam_max;
    float color[4];
} quadric_rec;

/* One literal of a DNF term: the solid sign * Q(p) <= 0. */
typedef struct {
    int quadric;
    int sign;
} literal_rec;

/* One DNF term: literals [first, first + count) of the literal buffer, and its bound. */
typedef struct {
    int first;
    int count;
    real lo[3];
    real hi[3];
} term_rec;

/* One surface sample (paper section 6): position and unit normal in device coordinates,
 * splat radius, the literal it lies on (quadric index and sign: the solid's outward normal is
 * sign * grad Q), its DNF term, and its clip set: clip_count literals starting at clip_first in
 * the clip buffer (an array of literal_rec): blocks of literals separated by an entry with
 * quadric -1; a splat fragment is kept if all literals of some block hold. */
typedef struct {
    real pos[3];
    real normal[3];
    real radius;
    int quadric;
    int sign;
    int term;
    int clip_first;
    int clip_count;
} sample_rec;

/* ---- sampler (clcsg/host/sampler.py, kernels/sampler.cl) ---------------------------------- */

/* Principal frame of a quadric (clcsg/host/analysis.py): x = center + U z and
 * Q = sum_m (lam_m z_m^2 + 2 beta_m z_m) + gamma.  U is row-major: U[3 * r + c], column c is
 * the principal axis u_c. */
typedef struct {
    real U[9];
    real center[3];
    real lam[3];
    real beta[3];
    real gamma;
} frame_rec;

/* One root of the subdivision: the literal (quadric `quadric`, polarity `sign`) sampled from
 * plane `plane` (normal u_plane) on sheet `sheet` (+1 / -1; 0 for a one-sheet heightfield).
 * The literal is sampled once for all DNF terms that hold it (its "group"): a point of the
 * quadric is on the CSG surface if some group term holds there and no other term contains it.
 * group_first / group_count: the group's other literals, as (term, literal) pairs in the
 * group-literal buffer (for clip sets).  Terms whose bound is disjoint from the group's bound
 * are left out of the distance queries; far_other stands in for them.  zlo / zhi: the union of the group terms' bounds as a
 * box in the quadric's local coordinates. */
typedef struct {
    int group_first;
    int group_count;
    int terms_first; /* the terms near the group's bound, in the task-term buffer: */
    int terms_count; /* index i for other terms, ~i for the group's own terms */
    int quadric;
    int sign;
    int plane;
    int sheet;
    real far_other; /* lower bound of the distance from the group's bound to every other term */
    real zlo[3];
    real zhi[3];
} task_rec;

/* A literal of a group term: term index and global literal index. */
typedef struct {
    int term;
    int literal;
} group_literal_rec;

/* An axis-aligned cell [x0, x1] x [y0, y1] of a task's sampling plane.  d: d_Q(S, p) at the
 * corners (x0,y0), (x1,y0), (x0,y1), (x1,y1), NaN where the heightfield is undefined; known
 * for children (level > 0), which inherit two corners from their parent and get the two new
 * ones evaluated once by the parent. */
typedef struct {
    real x0, y0, x1, y1;
    real d[4];
    int task;
    int level;
} cell_rec;

/* A sample as the subdivision emits it: position (device coordinates), splat radius, task. */
typedef struct {
    real pos[3];
    real radius;
    int task;
    int pad;
} raw_sample_rec;

#endif
