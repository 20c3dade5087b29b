/* A sample as it is emitted (sampler.cl): its position, splat radius and quadric, and what the
 * renderer needs of it besides: its clip program, the side the solid is on, its outward normal
 * and its primitive, all written by the emitting work-item while its cell's tape is at hand.
 * They go to the sample columns (sample_sink.reals / ints), one region per field (the SR_* /
 * SI_* offsets, in units of the capacity), so the host reads each field straight into its
 * array.
 *
 * The clip program is the cell's tape pruned over the splat ball (s, r) with the sample's
 * quadric substituted.  If both sides come out constant (and, s being on the surface,
 * different) the splat needs no clipping; otherwise the pruned tape is written to the clip
 * buffer (exactly the rows pruning keeps, reserved with an atomic add on SC_CLIP_ROWS, written
 * only below the capacity: the level's counters show the host an overflow, and it grows the
 * buffer and runs the level again).  A filled cell prunes its tape over its patch grown by
 * the radius, which holds every ball of its samples: where that decides both sides, its
 * samples get their sides at once (sample_src.sides), with no pruning per sample; otherwise
 * the pruned tape is written as a clip program, which its samples prune over their balls
 * (fewer leaves to test) and take as it is where that keeps all of it.  The sign is +1 where the solid is on the
 * quadric's negative side at s (outward normal +grad Q), -1 otherwise.
 */
#ifndef CLCSG_FINISH_H
#define CLCSG_FINISH_H
#include "tape.h"
#include "primitives.h"
#include "clip_table.h"

/* sample_src.sides: 0, or SIDES_KNOWN with the membership bits (bit 0 side -, bit 1 side +) */
#define SIDES_KNOWN 4

/* where a sample comes from: its task (quadric, plane, sheet), the tape of its cell (valid
 * over every splat ball of radius <= r around the cell's patch), the sides where that tape is
 * decided over them, and where the tape lies in the clip buffer if it was written there as a
 * clip program (clip_at >= 0; -1: it is the cell's tape in the arena) */
typedef struct {
    int task, quadric, plane, sheet;
    __global const tape_op *tape;
    int tape_count, sides, clip_at;
} sample_src;

/* Where a level's samples go: their columns (`cap` entries per region), the clip buffer, and
 * what the finish reads.  `counters` is the run's running totals (slots SC_SAMPLES and
 * SC_CLIP_ROWS: the next free sample slot and clip row); `evals` counts the prune evaluations
 * of the work-item's clip programs, `emitted` and `clip_rows` what it reserved (the level's
 * own counts: the host finds where a chain of levels first overflowed from them). */
typedef struct {
    __global real *reals;
    __global int *ints;
    uint cap;
    __global volatile uint *counters;
    __global tape_op *clip;
    uint cap_clip;
    __global const quadric_rec *qs;
    __global const frame_rec *frames;
    __global const owner_rec *owners;
    __global const int *owner_list;
    __global const prim_rec *prims;
    __global const int2 *prim_lits;
    __global const real4 *prim_box;
    __global const tape_op *inst_tape;
    int inst_rows;
    uint evals, emitted, clip_rows;
    __global volatile uint *table; /* the run's clip programs (clip_table.h) */
    uint table_mask, launch;
    clip_recent recent;
} sample_sink;

/* `n` consecutive sample slots: the first (the sample columns hold only those below the
 * capacity; the level runs again if any is past it) */
inline uint sink_slots(sample_sink *k, uint n)
{
    k->emitted += n;
    return atomic_add(&k->counters[SC_SAMPLES], n);
}

/* `rows` consecutive rows of the clip buffer: the first */
inline uint sink_clip_rows(sample_sink *k, uint rows)
{
    k->clip_rows += rows;
    return atomic_add(&k->counters[SC_CLIP_ROWS], rows);
}

/* Program p[0..n) (private) in the clip buffer: the first row of an equal one stored before
 * (clip_table.h), or of a new copy; -1 if the copy would end past the capacity (the level runs
 * again). */
inline int clip_store(sample_sink *k, const tape_op *p, int n)
{
    uint key = clip_program_key(p, n), claimed;
    int at = clip_recent_find(&k->recent, k->clip, key, p, n);
    if (at < 0) at = clip_table_find(k->table, k->table_mask, k->launch, k->clip, key, p, n, &claimed);
    if (at < 0) {
        uint base = sink_clip_rows(k, (uint)n);
        if (base + (uint)n > k->cap_clip) return -1;
        for (int m = 0; m < n; ++m) k->clip[base + m] = p[m];
        at = (int)base;
        if (claimed != ~0u) clip_table_publish(k->table, claimed, k->launch, key, at, p, n);
    }
    clip_recent_add(&k->recent, key, at, n);
    return at;
}

/* Tape t (n rows) pruned over g with q substituted, as a clip program: `rows` and `state` come
 * from its count pass, whose leaf states and rows' fates `memo` holds (leaves tested again are
 * counted in *evals).  Returns its first row in the clip buffer and its rows in *count, or -1 if
 * the buffer is full (the level runs again).  Up to CLIP_BUILD_ROWS rows it is built in private
 * memory and stored once per run where it can be (clip_store); a longer one is written into the
 * buffer as it is. */
inline int sink_clip_program(sample_sink *k, __global const tape_op *t, int n, int rows, const prune_region *g,
                             int q, uchar state, prune_memo *memo, uint *evals, int *count)
{
    int first;
    if (rows <= CLIP_BUILD_ROWS && n <= PRUNE_MEMO_ROWS) {
        tape_op built[CLIP_BUILD_ROWS];
        tape_pruned_private(t, n, rows, state, memo, built, &first, count);
        return clip_store(k, built + first, *count);
    }
    uint base = sink_clip_rows(k, (uint)rows);
    if (base + (uint)rows > k->cap_clip) return -1;
    tape_write_pruned(t, n, rows, k->qs, g, q, state, k->clip + base, &first, count, evals, memo);
    return (int)base + first;
}

/* The clip program of a sample at p on quadric q (the tape pruned over the splat ball,
 * written to the clip buffer unless both sides are decided) into *first, *count; returns the
 * membership bits at p: from the decided root state, else from the (short) clip program,
 * which equals the tape over the ball; the full tape only if the clip buffer is full this
 * run (the level runs again).  Where the tape is a clip program already (clip_at >= 0) and
 * pruning would not shorten it (tape_write_pruned), the sample takes it as it is. */
inline uint clip_program(sample_sink *k, __global const tape_op *tape, int nt, int clip_at, int q, real3 p,
                         real radius, int *first, int *count)
{
    prune_region ball = {p, (real3)(0), (real3)(0), (real3)(0), radius};
    uchar state;
    prune_memo memo; /* the count's leaf states and rows' fates, for the write */
    memo.mode = 3;
    int rows = tape_prune_rows_memo(tape, nt, k->qs, &ball, q, &state, &k->evals, &memo);
    if (prune_decision(state) < 0) return prune_member_bits(state);
    if (clip_at >= 0 && rows == nt) {
        *first = clip_at;
        *count = nt;
        return tape_member(tape, nt, k->qs, p, q);
    }
    int n;
    int at = sink_clip_program(k, tape, nt, rows, &ball, q, state, &memo, &k->evals, &n);
    if (at < 0) return tape_member(tape, nt, k->qs, p, q);
    *first = at;
    *count = n;
    return tape_member(k->clip + at, n, k->qs, p, q);
}

/* Entry `slot` of the real column region at `offset` (SR_*), `width` reals wide. */
#define SAMPLE_REAL(k, offset, width, slot) ((k)->reals + (size_t)(offset) * (k)->cap + (size_t)(width) * (slot))
/* Entry `slot` of the int column region at `offset` (SI_*). */
#define SAMPLE_INT(k, offset, slot) ((k)->ints[(size_t)(offset) * (k)->cap + (slot)])

/* The clip program, sign, normal and primitive of sample `slot` at p (see above). */
inline void finish_sample(sample_sink *k, uint slot, real3 p, real radius, sample_src src)
{
    __global const owner_rec *owners = k->owners;
    __global const int *owner_list = k->owner_list;
    __global const prim_rec *prims = k->prims;
    __global const int2 *prim_lits = k->prim_lits;
    __global const real4 *prim_box = k->prim_box;
    __global const tape_op *inst_tape = k->inst_tape;
    int inst_rows = k->inst_rows;
    int first = 0, count = 0;
    uint bits = src.sides & SIDES_KNOWN ? (uint)(src.sides & 3)
                                        : clip_program(k, src.tape, src.tape_count, src.clip_at, src.quadric, p,
                                                       radius, &first, &count);
    SAMPLE_INT(k, SI_CLIP_FIRST, slot) = first;
    SAMPLE_INT(k, SI_CLIP_COUNT, slot) = count;
    int sign = (bits & 1) ? 1 : -1;
    real3 g = sign * quadric_gradient(quadric_load(k->qs, src.quadric), p);
    real gl = length(g);
    if (gl > 0) {
        g = g / gl;
    } else { /* a singular point (cone apex): the sampling direction stands in */
        __global const frame_rec *f = k->frames + src.quadric;
        real sh = src.sheet != 0 ? (real)src.sheet : (real)1;
        g = sh * (real3)(f->U[src.plane], f->U[3 + src.plane], f->U[6 + src.plane]);
    }
    __global real *normal = SAMPLE_REAL(k, SR_NORMAL, 3, slot);
    normal[0] = g.x;
    normal[1] = g.y;
    normal[2] = g.z;
    SAMPLE_INT(k, SI_SIGN, slot) = sign;
    SAMPLE_INT(k, SI_PRIMITIVE, slot) = primitive_at(PRIMITIVE_TABLE_ARGS, k->qs, src.quadric, p);
}

/* Samples 0..n-1 (n <= 8) of the lanes (px, py, pz), slots slot..slot+n-1 (below the capacity),
 * whose sides src knows: emit_sample's columns with their arithmetic in lanes (the primitive of
 * a quadric that several own is looked up per sample).  False (nothing written) where a
 * sample's gradient vanishes or overflows (emit_sample's fallback for it). */
inline bool emit_known8(sample_sink *k, uint slot, int n, real8 px, real8 py, real8 pz, real radius, sample_src src)
{
    owner_rec o = k->owners[src.quadric];
    quadric Q = quadric_load(k->qs, src.quadric);
    real s = (src.sides & 1) ? 2 : -2; /* the sign times grad Q's 2 */
    real8 gx = s * (Q.xx * px + Q.xy * py + Q.xz * pz + Q.xw);
    real8 gy = s * (Q.xy * px + Q.yy * py + Q.yz * pz + Q.yw);
    real8 gz = s * (Q.xz * px + Q.yz * py + Q.zz * pz + Q.zw);
    real8 g2 = gx * gx + gy * gy + gz * gz;
    realmask8 used = convert_realmask8((int8)(0, 1, 2, 3, 4, 5, 6, 7) < (int8)(n));
    if (any(used & (!(g2 >= (real8)REAL_MIN) | isinf(g2)))) return false;
    real8 inv = 1 / sqrt(g2);
    real lane[6][8];
    vstore8(px, 0, lane[0]);
    vstore8(py, 0, lane[1]);
    vstore8(pz, 0, lane[2]);
    vstore8(gx * inv, 0, lane[3]);
    vstore8(gy * inv, 0, lane[4]);
    vstore8(gz * inv, 0, lane[5]);
    __global real *pos = SAMPLE_REAL(k, SR_POS, 3, slot), *normal = SAMPLE_REAL(k, SR_NORMAL, 3, slot);
    __global real *radii = SAMPLE_REAL(k, SR_RADIUS, 1, slot);
    int sign = (src.sides & 1) ? 1 : -1, prim = o.count ? k->owner_list[o.first] : -1;
    for (int l = 0; l < n; ++l) {
        if (o.count > 1)
            prim = primitive_at(k->owners, k->owner_list, k->prims, k->prim_lits, k->prim_box, k->inst_tape,
                                k->inst_rows, k->qs, src.quadric, (real3)(lane[0][l], lane[1][l], lane[2][l]));
        for (int c = 0; c < 3; ++c) {
            pos[3 * l + c] = lane[c][l];
            normal[3 * l + c] = lane[3 + c][l];
        }
        radii[l] = radius;
        SAMPLE_INT(k, SI_QUADRIC, slot + l) = src.quadric;
        SAMPLE_INT(k, SI_CLIP_FIRST, slot + l) = 0;
        SAMPLE_INT(k, SI_CLIP_COUNT, slot + l) = 0;
        SAMPLE_INT(k, SI_SIGN, slot + l) = sign;
        SAMPLE_INT(k, SI_PRIMITIVE, slot + l) = prim;
    }
    return true;
}

/* Sample `slot` at p with splat radius `radius`: its columns, finished (nothing past the
 * capacity: the level runs again). */
inline void emit_sample(sample_sink *k, uint slot, real3 p, real radius, sample_src src)
{
    if (slot >= k->cap) return;
    __global real *pos = SAMPLE_REAL(k, SR_POS, 3, slot);
    pos[0] = p.x;
    pos[1] = p.y;
    pos[2] = p.z;
    *SAMPLE_REAL(k, SR_RADIUS, 1, slot) = radius;
    SAMPLE_INT(k, SI_QUADRIC, slot) = src.quadric;
    finish_sample(k, slot, p, radius, src);
}

#endif
