/* Clip programs stored once per run on the device (finish.h's clip_store uses this table; the
 * driver, clcsg/sampling/sampler.py, sizes it and zeroes it).
 *
 * Most samples' clip programs repeat: the level-3 Menger sponge at 0.1% of its diagonal had
 * 14.3M rows of programs for its 1.07M clipped samples, 204k rows once equal programs were
 * merged.  A program is built in private memory (tape_pruned_private), hashed, and looked up
 * first among the work-item's last CLIP_RECENT programs, then in an open-addressing table
 * (CLIP_TABLE_PROBES linear probes); only a program found in neither is written to the clip
 * buffer, and published in the first empty entry of its probes.  An entry is CLIP_ENTRY_WORDS
 * words: its state, the program's first row in the clip buffer, its rows, and its first
 * CLIP_TABLE_INLINE rows (a lookup compares a short program without reading the clip buffer).
 * The state word is 0 (empty), or 24 bits of the program's key above 8 bits of the launch that
 * published it (its number mod 255, plus 1; 0: claimed, not yet published).
 *
 * Only entries published by an earlier launch are read: their words and the rows they name were
 * written before the kernel that reads them started, so no work-item reads what another one
 * writes concurrently.  The state word is read and written with atomics only: an
 * atomic_cmpxchg that claims it if it is empty returns it, and an atomic_xchg publishes.  An
 * entry whose launch byte equals the current launch's is taken for the current launch's (one
 * 255 launches older only loses its use).  A sample is
 * never given a program that differs from its own: a program found is used only after it
 * compares equal, row for row, and the rows an entry names stay as they are for the rest of the
 * run (the clip buffer is only appended to, and a level that overran a buffer runs again and
 * writes its rows anew, after the host zeroed the table).  Equal programs may still be stored
 * more than once (first met in one launch by several work-items, a full probe sequence): the
 * host merges what is left (sampler.dedupe_programs).
 */
#ifndef CLCSG_CLIP_TABLE_H
#define CLCSG_CLIP_TABLE_H
#include "tape.h"

#if !defined(CLIP_TABLE_PROBES) || !defined(CLIP_ENTRY_WORDS) || !defined(CLIP_TABLE_INLINE) || !defined(CLIP_RECENT) \
    || !defined(CLIP_BUILD_ROWS)
#error "CLIP_TABLE_PROBES, CLIP_ENTRY_WORDS, CLIP_TABLE_INLINE, CLIP_RECENT, CLIP_BUILD_ROWS: from clcsg/cl/constants.py"
#endif

/* A 32-bit key of the program p[0..n) whose top 24 bits are not all 0: a row's four fields
 * packed into 64 bits (xor-shifted, so they need not fit), mixed in with one multiply per row,
 * then murmur3's 64-bit finalizer.  Its low bits pick the entry, its top 24 bits are kept in it. */
inline uint clip_program_key(const tape_op *p, int n)
{
    ulong h = 0x9E3779B97F4A7C15ul ^ (ulong)n;
    for (int m = 0; m < n; ++m) {
        tape_op o = p[m];
        ulong w = (ulong)(uint)o.op ^ ((ulong)(uint)o.out << 8) ^ ((ulong)(uint)o.a << 24) ^ ((ulong)(uint)o.b << 44);
        h = (h ^ w) * 0xFF51AFD7ED558CCDul;
    }
    h ^= h >> 33;
    h *= 0xC4CEB9FE1A85EC53ul;
    h ^= h >> 33;
    uint k = (uint)h;
    return k >> 8 ? k : k | 0x100u;
}

/* The launch byte of an entry's state word published by `launch` (never 0) */
inline uint clip_launch_byte(uint launch) { return launch % 255u + 1u; }

inline bool clip_rows_equal(tape_op x, tape_op y) { return x.op == y.op && x.out == y.out && x.a == y.a && x.b == y.b; }

/* Is the program q[0..n) in the clip buffer equal to p[0..n)? */
inline bool clip_stored_equal(__global const tape_op *q, const tape_op *p, int n)
{
    for (int m = 0; m < n; ++m)
        if (!clip_rows_equal(q[m], p[m])) return false;
    return true;
}

/* The work-item's last CLIP_RECENT programs stored or found (key, first row, rows; key 0: none)
 * and the next one to replace. */
typedef struct {
    uint key[CLIP_RECENT];
    int first[CLIP_RECENT], rows[CLIP_RECENT];
    uint next;
} clip_recent;

inline void clip_recent_add(clip_recent *r, uint key, int first, int n)
{
    uint k = r->next++ % CLIP_RECENT;
    r->key[k] = key;
    r->first[k] = first;
    r->rows[k] = n;
}

/* The first row of a program equal to p[0..n) (key `key`) among the work-item's recent ones;
 * -1 if none. */
inline int clip_recent_find(const clip_recent *r, __global const tape_op *clip, uint key, const tape_op *p, int n)
{
    for (int k = 0; k < CLIP_RECENT; ++k)
        if (r->key[k] == key && r->rows[k] == n && clip_stored_equal(clip + r->first[k], p, n)) return r->first[k];
    return -1;
}

/* An entry e: e[0] the state (see above), e[1] the program's first row in the clip buffer, e[2]
 * its rows, e[3..) its first CLIP_TABLE_INLINE rows (four words each). */
inline tape_op clip_entry_row(__global volatile uint *e, int m)
{
    return (tape_op){(int)e[3 + 4 * m], (int)e[4 + 4 * m], (int)e[5 + 4 * m], (int)e[6 + 4 * m]};
}

/* Does entry e (published by an earlier launch) name a program equal to p[0..n)? */
inline bool clip_entry_holds(__global volatile uint *e, __global const tape_op *clip, const tape_op *p, int n)
{
    if ((int)e[2] != n) return false;
    int inl = min(n, CLIP_TABLE_INLINE);
    for (int m = 0; m < inl; ++m)
        if (!clip_rows_equal(clip_entry_row(e, m), p[m])) return false;
    return clip_stored_equal(clip + (int)e[1] + inl, p + inl, n - inl);
}

/* The first row of a program equal to p[0..n) (key `key`) that an earlier launch than `launch`
 * published in the table; -1 if none was found, and then *claimed is an entry this work-item
 * claimed for it (~0u: none), which clip_table_publish publishes. */
inline int clip_table_find(__global volatile uint *table, uint mask, uint launch, __global const tape_op *clip,
                           uint key, const tape_op *p, int n, uint *claimed)
{
    *claimed = ~0u;
    uint mine = key & ~0xFFu, now = clip_launch_byte(launch);
    for (uint probe = 0; probe < CLIP_TABLE_PROBES; ++probe) {
        uint s = (key + probe) & mask;
        __global volatile uint *e = table + CLIP_ENTRY_WORDS * s;
        uint state = atomic_cmpxchg(&e[0], 0u, mine);
        if (state == 0) {
            *claimed = s;
            return -1;
        }
        if ((state & ~0xFFu) != mine) continue;
        uint by = state & 0xFFu;
        if (by == 0 || by == now) return -1; /* this launch's: its words may still be written */
        if (clip_entry_holds(e, clip, p, n)) return (int)e[1];
    }
    return -1;
}

/* Publish program p[0..n) (key `key`), stored at row `at` of the clip buffer, in the entry
 * `claimed`: its words first, the state word last. */
inline void clip_table_publish(__global volatile uint *table, uint claimed, uint launch, uint key, int at,
                               const tape_op *p, int n)
{
    __global volatile uint *e = table + CLIP_ENTRY_WORDS * claimed;
    e[1] = (uint)at;
    e[2] = (uint)n;
    for (int m = 0; m < min(n, CLIP_TABLE_INLINE); ++m) {
        e[3 + 4 * m] = (uint)p[m].op;
        e[4 + 4 * m] = (uint)p[m].out;
        e[5 + 4 * m] = (uint)p[m].a;
        e[6 + 4 * m] = (uint)p[m].b;
    }
    atomic_xchg(&e[0], (key & ~0xFFu) | clip_launch_byte(launch));
}

#endif
