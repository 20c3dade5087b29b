/* Device records shared by every kernel.  Each struct has a numpy dtype in
 * clcsg/cl/records.py, and tests/test_records.py checks size and field offsets of every one
 * on the device.
 *
 * Scalars are `real`: double when the host builds with -DCLCSG_DOUBLE (devices with fp64),
 * float otherwise.  All coordinates on the device are relative to the scene origin the host
 * chose (the center of the scene bound), which keeps float32 precise at millimetre scale.
 */
#ifndef CLCSG_LAYOUT_H
#define CLCSG_LAYOUT_H

/* Small helpers of the per-cell and per-leaf paths that LLVM would leave as calls, their
 * structs passed through memory.  Oclgrind's interpreter has no implementation of the scope
 * intrinsic the inliner emits for struct arguments and results (CLCSG_PLAIN_INLINE, set by
 * clcsg/cl/programs.py there): plain inline. */
#ifdef CLCSG_PLAIN_INLINE
#define CLCSG_INLINE inline
#else
#define CLCSG_INLINE __attribute__((always_inline)) inline
#endif

#ifdef CLCSG_DOUBLE
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
typedef double real;
typedef double2 real2;
typedef double3 real3;
typedef double4 real4;
typedef double8 real8;
typedef long4 realmask4; /* the mask types of select() on real4, real8 */
typedef long8 realmask8;
#define convert_real4 convert_double4
#define convert_real8 convert_double8
#define convert_realmask4 convert_long4
#define convert_realmask8 convert_long8
#define REAL_MAX DBL_MAX
#define REAL_MIN DBL_MIN
#define REAL_EPS DBL_EPSILON
#else
typedef float real;
typedef float2 real2;
typedef float3 real3;
typedef float4 real4;
typedef float8 real8;
typedef int4 realmask4;
#define convert_real4 convert_float4
#define convert_real8 convert_float8
#define convert_realmask4 convert_int4
#define convert_realmask8 convert_int8
typedef int8 realmask8;
#define REAL_MAX FLT_MAX
#define REAL_MIN FLT_MIN
#define REAL_EPS FLT_EPSILON
#endif

/* One unique canonical quadric.  coef: the 10 coefficients of the symmetric 4x4 matrix in the
 * order xx xy xz xw yy yz yw zz zw ww (upper triangle, row-major), so that
 * Q(p) = xx x^2 + 2 xy x y + 2 xz x z + 2 xw x + yy y^2 + 2 yz y z + 2 yw y + zz z^2 + 2 zw z + ww.
 * lam_min / lam_max: extreme eigenvalues of the 3x3 part A (conservative distance, eqs. 10-12). */
typedef struct {
    real coef[10];
    real lam_min;
    real lam_max;
} quadric_rec;

/* A primitive instance (a Primitive node under one world transform, in tree order): its
 * literals (quadric, sign) are rows [lit_first, lit_first + lit_count) of the primitive-literal
 * buffer (int2), and its color. */
typedef struct {
    int lit_first;
    int lit_count;
    float color[4];
} prim_rec;

/* Per quadric: the primitive instances that have it as a literal, rows [first, first + count)
 * of the owner buffer (int), in tree order. */
typedef struct {
    int first;
    int count;
} owner_rec;

/* One surface sample (paper section 6): position and the solid's outward unit normal in device
 * coordinates, splat radius, its quadric and the side the solid is on (sign +1: on the
 * negative side, outward normal +grad Q), the primitive instance whose boundary holds it, and
 * its clip program: clip_count tape rows from clip_first of the clip buffer (0: no clipping);
 * a fragment on the quadric is kept iff the program's membership differs between the
 * quadric's two sides.  splat_primitive: the primitive every point of the splat takes (the
 * colour rule, primitives.h), -1 where it may vary over the splat (clcsg/sampling/samples.py). */
typedef struct {
    real pos[3];
    real normal[3];
    real radius;
    int quadric;
    int sign;
    int primitive;
    int clip_first;
    int clip_count;
    int splat_primitive;
} sample_rec;

/* ---- sampler (clcsg/sampling) -------------------------------------------------------------- */

/* Principal frame of a quadric (clcsg/compile/frames.py): x = center + U z and
 * Q = sum_m (lam_m z_m^2 + 2 beta_m z_m) + gamma.  U is row-major: U[3 * r + c], column c is
 * the principal axis u_c.  Per axis m, divisions the sampler's cells would repeat
 * (sampling/heightfield.h): height_factor[m] = -1 / lam_m (the heightfield of plane m has
 * t^2 = R height_factor), or -1 / (2 beta_m) where lam_m = 0 (t = R height_factor), 0 if both
 * are 0; vertex[m] = -beta_m / lam_m, where lam_m z^2 + 2 beta_m z has its extremum, and
 * vertex_value[m] that extremum (0, 0 where lam_m = 0). */
typedef struct {
    real U[9];
    real center[3];
    real lam[3];
    real beta[3];
    real gamma;
    real height_factor[3];
    real vertex[3];
    real vertex_value[3];
} frame_rec;

/* One root of the subdivision: quadric `quadric` sampled from plane `plane` (normal u_plane) on
 * sheet `sheet` (+1 / -1; 0 for a one-sheet heightfield).  zlo / zhi: the box, in the
 * quadric's local coordinates, that holds every point of the quadric that can be CSG surface. */
typedef struct {
    int quadric;
    int plane;
    int sheet;
    int pad;
    real zlo[3];
    real zhi[3];
} task_rec;

/* An axis-aligned cell [x0, x1] x [y0, y1] of a task's sampling plane.  d: d_q(p) at the
 * corners (x0,y0), (x1,y0), (x0,y1), (x1,y1), NaN where unknown or the heightfield is
 * undefined (children inherit two corners and get the two new ones from their parent).
 * Its tape: rows [tape_first, tape_first + tape_count) of the tape arena, pruned over the
 * parent's patch grown by the sampling radius. */
typedef struct {
    real x0, y0, x1, y1;
    real d[4];
    int task;
    int level;
    int tape_first;
    int tape_count;
} cell_rec;

#endif
