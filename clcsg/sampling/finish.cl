/* Per sample, after the level that emitted it (while its cell's tape is still in the level's
 * arena; samples [first, first + n) of the raw buffer, outputs at the same indices): its clip
 * program, the side the solid is on, its outward normal and its primitive (driven by
 * clcsg/sampling/sampler.py).
 *
 * The clip program is the sample's cell tape pruned over the splat ball (s, r) with the
 * sample's quadric substituted.  If both sides come out constant (and, s being on the surface,
 * different) the splat needs no clipping; otherwise the pruned tape is written to the clip
 * buffer (exactly the rows pruning keeps, reserved with an atomic add, written only below the
 * capacity; the host grows the buffer and re-runs on overflow).  A sample that comes with its
 * sides (raw_sample_rec.sides: its filled cell's tape is decided over the cell's patch grown by
 * the radius, which holds the ball) needs neither.  The sign is +1 where the solid is on the
 * quadric's negative side at s (outward normal +grad Q), -1 otherwise.
 */
#include "tape.h"
#include "primitives.h"

#ifndef WORK_GROUP
#error "WORK_GROUP: the work-group size comes from the driver (sampler.py)"
#endif

/* The clip program of a sample at p on quadric q (its cell's tape pruned over the splat ball,
 * written to the clip buffer unless both sides are decided) into *first, *count; returns the
 * membership bits at p: from the decided root state, else from the (short) clip program,
 * which equals the tape over the ball; the full tape only if the clip buffer is full this
 * run. */
inline uint clip_program(__global const tape_op *tape, int nt, __global const quadric_rec *qs, int q, real3 p,
                         real radius, __global tape_op *clip, uint cap_clip, __global volatile uint *counters,
                         int *first, int *count, uint *evals)
{
    prune_region ball = {p, (real3)(0), (real3)(0), (real3)(0), radius};
    uchar state;
    prune_memo memo; /* the count's leaf states, replayed by the write */
    memo.mode = 1;
    int rows = tape_prune_rows_memo(tape, nt, qs, &ball, q, &state, evals, &memo);
    if (prune_decision(state) < 0) return prune_member_bits(state);
    uint base = atomic_add(&counters[0], (uint)rows);
    if (base + (uint)rows > cap_clip) return tape_member(tape, nt, qs, p, q);
    memo.mode = 2;
    tape_prune_write_memo(tape, nt, qs, &ball, q, state, clip + base, first, count, evals, &memo);
    *first += (int)base;
    return tape_member(clip + *first, *count, qs, p, q);
}

/* The clip program, sign, normal and primitive of sample o (see above); returns the prune
 * evaluations it took. */
inline uint finish_sample(__global const quadric_rec *qs, __global const frame_rec *frames,
                          __global const task_rec *tasks, __global const raw_sample_rec *raw, int o,
                          __global const tape_op *arena, __global tape_op *clip, uint cap_clip,
                          __global volatile uint *counters, PRIMITIVE_TABLE,
                          __global real *normals, __global int *signs, __global int *primitives,
                          __global int *clip_first, __global int *clip_count)
{
    raw_sample_rec s = raw[o];
    task_rec t = tasks[s.task];
    real3 p = (real3)(s.pos[0], s.pos[1], s.pos[2]);
    __global const tape_op *tape = arena + s.tape_first;
    int nt = s.tape_count;
    int first = 0, count = 0;
    uint evals = 0;
    uint bits = s.sides & SIDES_KNOWN ? (uint)(s.sides & 3)
                                      : clip_program(tape, nt, qs, t.quadric, p, s.radius, clip, cap_clip, counters,
                                                     &first, &count, &evals);
    clip_first[o] = first;
    clip_count[o] = count;
    int sign = (bits & 1) ? 1 : -1;
    real3 g = sign * quadric_gradient(quadric_load(qs, t.quadric), p);
    real gl = length(g);
    if (gl > 0) {
        g = g / gl;
    } else { /* a singular point (cone apex): the sampling direction stands in */
        __global const frame_rec *f = frames + t.quadric;
        real sh = t.sheet != 0 ? (real)t.sheet : (real)1;
        g = sh * (real3)(f->U[t.plane], f->U[3 + t.plane], f->U[6 + t.plane]);
    }
    normals[3 * o] = g.x;
    normals[3 * o + 1] = g.y;
    normals[3 * o + 2] = g.z;
    signs[o] = sign;
    primitives[o] = primitive_at(PRIMITIVE_TABLE_ARGS, qs, t.quadric, p);
    return evals;
}

/* One sample per work-item; the prune evaluations are summed over the work-group before one
 * atomic (an atomic per sample contends between the compute units). */
__kernel __attribute__((reqd_work_group_size(WORK_GROUP, 1, 1)))
void finish(__global const quadric_rec *qs, __global const frame_rec *frames,
            __global const task_rec *tasks, __global const raw_sample_rec *raw, int n,
            int first_sample, __global const tape_op *arena, __global tape_op *clip, uint cap_clip,
            __global volatile uint *counters,
            PRIMITIVE_TABLE,
            __global real *normals, __global int *signs, __global int *primitives,
            __global int *clip_first, __global int *clip_count)
{
    __local uint evals[WORK_GROUP];
    int gid = get_global_id(0), lid = get_local_id(0);
    evals[lid] = gid < n ? finish_sample(qs, frames, tasks, raw, first_sample + gid, arena, clip, cap_clip, counters,
                                         PRIMITIVE_TABLE_ARGS, normals, signs, primitives, clip_first, clip_count)
                         : 0;
    barrier(CLK_LOCAL_MEM_FENCE);
    if (lid == 0) {
        uint t = 0;
        for (int m = 0; m < WORK_GROUP; ++m) t += evals[m];
        atomic_add(&counters[1], t);
    }
}
