/* The view (pinhole camera in device coordinates) and the shading shared by the exact ray
 * tracer (raytrace.cl) and the splat resolve pass (resolve.cl), so both produce the same
 * pixels for the same hit.  Mirrored by view_dtype() in clcsg/rendering/view.py.
 *
 * Camera contract (clcsg/rendering/camera.py): the un-normalized direction of pixel (i, j), row 0 at the
 * top, is d00 + j dx + i dy; the view ray is eye + t v with v = d / |d| and t the depth.  A point
 * p projects to continuous pixel coordinates x = W/2 + f (p - eye).right / z,
 * y = H/2 - f (p - eye).up / z with z = (p - eye).forward; pixel (i, j) covers
 * [j, j + 1) x [i, i + 1).
 */
#ifndef CLCSG_SHADE_H
#define CLCSG_SHADE_H
#include "layout.h"

typedef struct {
    real eye[3];     /* device coordinates (world - scene origin) */
    real d00[3];     /* direction of pixel (0, 0), un-normalized */
    real dx[3];      /* d(i, j + 1) - d(i, j) = right / f */
    real dy[3];      /* d(i + 1, j) - d(i, j) = -up / f */
    real forward[3]; /* unit view axis */
    real right[3];
    real up[3];
    real focal;      /* f = (H / 2) / tan(fov / 2), in pixels */
    int width;
    int height;
    float background[4]; /* RGBA in [0, 1], written as is (already display-encoded) */
    float key[3];        /* unit direction towards the key light (world) */
    float fill[3];       /* unit direction towards the fill light (world) */
    float sky[3];        /* unit world up: where the hemisphere light comes from */
    float ambient;       /* hemisphere light from the sky ... */
    float ground;        /* ... and from below, as a fraction of the sky's */
    float diffuse;       /* weight of the three directional lights: */
    float headlight;     /*   the headlight at the eye, */
    float key_light;     /*   the key light, */
    float fill_light;    /*   the fill light */
    float rim;           /* light along the silhouette (grazing view) */
    float specular;      /* Blinn-Phong highlight of the key light */
    float shininess;
    float gamma;         /* colors are linearized with gamma, lit, and encoded with 1 / gamma */
    float spec_cut;      /* highlights of n.h <= spec_cut are skipped: (n.h)^shininess <= 2^-64 */
} view_rec;

inline real3 view_eye(__global const view_rec *vw) { return vload3(0, vw->eye); }

/* Direction d of the view ray of pixel (i, j), not normalized (the camera contract). */
inline real3 view_dir(__global const view_rec *vw, int i, int j)
{
    return vload3(0, vw->d00) + (real)j * vload3(0, vw->dx) + (real)i * vload3(0, vw->dy);
}

/* view_dir of the eight pixels (i, j0) ... (i, j0 + 7), as real8 components. */
inline void view_dirs8(__global const view_rec *vw, int i, int j0, real8 *dx, real8 *dy, real8 *dz)
{
    real8 jj = (real8)(j0) + (real8)(0, 1, 2, 3, 4, 5, 6, 7);
    *dx = vw->d00[0] + jj * vw->dx[0] + (real)i * vw->dy[0];
    *dy = vw->d00[1] + jj * vw->dx[1] + (real)i * vw->dy[1];
    *dz = vw->d00[2] + jj * vw->dx[2] + (real)i * vw->dy[2];
}

/* Unit direction of the view ray of pixel (i, j). */
inline real3 view_ray(__global const view_rec *vw, int i, int j) { return normalize(view_dir(vw, i, j)); }

/* x^y for x >= 0 as exp2(y log2 x), for the colours of the primitives (once per view) and a
 * highlight exponent that is not a whole number (shade_powi): x = 0 gives 0 for y > 0. */
inline float shade_pow(float x, float y) { return exp2(y * log2(x)); }
inline float3 shade_pow3(float3 x, float y) { return exp2(y * log2(x)); }
inline float8 shade_pow8(float8 x, float y) { return exp2(y * log2(x)); }

/* x^y for x in [0, 1], y > 0, within 2e-5 relative: enough for the 8-bit encoding (5e-3 of a
 * level), at a fraction of exp2() and log2()'s cost on CPUs.  With x = (1 + m) 2^e, log2 x =
 * e + log2(1 + m) and 2^z = 2^n 2^f (n = floor(z)): log2(1 + m) (m in [0, 1)) and 2^f (f in
 * [0, 1)) are degree 5 and 4 polynomials fitted on Chebyshev nodes (errors 1.5e-5 absolute,
 * 3.6e-6 relative), on float types T (int type I): the same arithmetic for one pixel and for
 * eight. */
#define SHADE_POW_ENCODE_BODY(T, I)                                                                  \
    {                                                                                                \
        I xi = as_##I(x);                                                                            \
        T m = as_##T((xi & 0x007fffff) | 0x3f800000) - 1.0f;                                         \
        T lg = 1.43909300e-05f + m * (1.44159208f + m * (-0.707253434f + m * (0.411561482f           \
               + m * (-0.189832447f + m * 0.0439286278f))));                                         \
        T z = fmax(y * (convert_##T(((xi >> 23) & 0xff) - 127) + lg), -127.0f);                      \
        T n = floor(z), f = z - n;                                                                   \
        T p = 1.0000036f + f * (0.692969551f + f * (0.241621323f + f * (0.0517177355f                \
                                                                    + f * 0.0136839829f)));          \
        T r = p * as_##T((convert_##I(n) + 127) << 23);                                             \
        return select(select(r, (T)(0.0f), convert_##I(n) < -126), (T)(0.0f), x < FLT_MIN);          \
    }
inline float3 shade_pow_encode3(float3 x, float y) SHADE_POW_ENCODE_BODY(float3, int3)
inline float8 shade_pow_encode8(float8 x, float y) SHADE_POW_ENCODE_BODY(float8, int8)

/* x^y for the highlight's exponent y (the same for every pixel): by squaring where y is a
 * whole number up to 1024 (the default 32: five products), else shade_pow. */
#define SHADE_POWI_BODY(T, POW)                                                                      \
    {                                                                                                \
        if (!(y >= 0.0f && y <= 1024.0f && y == floor(y))) return POW(x, y);                        \
        T r = (T)(1.0f), b = x;                                                                      \
        for (int n = (int)y; n; n >>= 1) {                                                           \
            if (n & 1) r *= b;                                                                       \
            b *= b;                                                                                  \
        }                                                                                            \
        return r;                                                                                    \
    }
inline float shade_powi(float x, float y) SHADE_POWI_BODY(float, shade_pow)
inline float8 shade_powi8(float8 x, float y) SHADE_POWI_BODY(float8, shade_pow8)

/* The default look (clcsg.rendering.view.Shading), in linear light:
 *
 *   albedo * (hemisphere + diffuse * (headlight d_head + key_light d_key + fill_light d_fill)
 *             + rim (1 - |n.v|)^3) + specular * highlight(key)
 *
 * The hemisphere term, ambient * lerp(ground, 1, (1 + n.sky) / 2), lights every face by its
 * orientation alone, so faces that no directional light reaches (the inside of a hollow box,
 * the underside of a lip) still differ from each other: floors brighter than walls, walls
 * brighter than ceilings.  The headlight keeps faces seen head-on brighter than grazing ones;
 * the key light (upper left, camera frame) and the weaker fill (lower right) separate faces of
 * equal view angle.  The lights are white, so shading scales a primitive's colour without
 * shifting its hue.  base: RGBA of the primitive in display (sRGB-like) space; n: the solid's
 * outward unit normal (sign * grad Q / |grad Q|, eq. 4); v: unit view ray.  The normal is
 * flipped towards the viewer (two-sided), so a view from inside still shades.  Returns 8-bit
 * RGBA, gamma encoded. */
/* The albedo of display colour base in linear light, and its alpha (shade_lit's input). */
inline float4 shade_albedo(__global const view_rec *vw, float4 base)
{
    return (float4)(shade_pow3(clamp(base.xyz, 0.0f, 1.0f), vw->gamma), clamp(base.w, 0.0f, 1.0f));
}

/* The lit colour in linear light, clamped to [0, 1], from the linear albedo (ax, ay, az) of
 * shade_albedo, on separate components: T is float (one pixel) or float8 (RESOLVE_LANES pixels of
 * the resolve pass), and both widths expand this one body, so a pixel gets the same arithmetic
 * in either.  The highlight (n.h)^shininess counts only where n.h > spec_cut (pack_view: at
 * most 2^-64, under the rounding of any lit colour) and the key light reaches the face;
 * selects instead of branches keep the body straight-line for the vector width. */
#define SHADE_LIGHT_BODY(T)                                                                          \
    {                                                                                                \
        T flip = select((T)1.0f, (T)-1.0f, nx * vx + ny * vy + nz * vz > 0.0f);                     \
        nx *= flip; ny *= flip; nz *= flip;                                                          \
        T hx = -vx, hy = -vy, hz = -vz; /* towards the eye: the headlight */                        \
        T facing = fmax(nx * hx + ny * hy + nz * hz, 0.0f);                                          \
        T up = 0.5f + 0.5f * (nx * vw->sky[0] + ny * vw->sky[1] + nz * vw->sky[2]);                 \
        T hemi = vw->ambient * (vw->ground + (1.0f - vw->ground) * up);                              \
        T d_key = fmax(nx * vw->key[0] + ny * vw->key[1] + nz * vw->key[2], 0.0f);                  \
        T d_fill = fmax(nx * vw->fill[0] + ny * vw->fill[1] + nz * vw->fill[2], 0.0f);              \
        T edge = 1.0f - facing;                                                                      \
        T light = hemi + vw->diffuse * (vw->headlight * facing + vw->key_light * d_key              \
                                        + vw->fill_light * d_fill) + vw->rim * edge * edge * edge;   \
        T kx = vw->key[0] + hx, ky = vw->key[1] + hy, kz = vw->key[2] + hz; /* half vector */       \
        T nh = fmax((nx * kx + ny * ky + nz * kz) / sqrt(kx * kx + ky * ky + kz * kz), 0.0f);      \
        T s_key = select((T)0.0f, SHADE_POW_T(nh, vw->shininess), (d_key > 0.0f) & (nh > vw->spec_cut)); \
        *cx = clamp(ax * light + vw->specular * s_key, 0.0f, 1.0f);                                  \
        *cy = clamp(ay * light + vw->specular * s_key, 0.0f, 1.0f);                                  \
        *cz = clamp(az * light + vw->specular * s_key, 0.0f, 1.0f);                                  \
    }

#define SHADE_POW_T shade_powi
inline void shade_light1(__global const view_rec *vw, float ax, float ay, float az, float nx, float ny, float nz,
                         float vx, float vy, float vz, float *cx, float *cy, float *cz)
SHADE_LIGHT_BODY(float)
#undef SHADE_POW_T

#define SHADE_POW_T shade_powi8
/* inlined: ten float8 arguments passed to a call go through memory */
__attribute__((always_inline)) inline void shade_light8(__global const view_rec *vw, float8 ax, float8 ay, float8 az,
                                                        float8 nx, float8 ny, float8 nz, float8 vx, float8 vy,
                                                        float8 vz, float8 *cx, float8 *cy, float8 *cz)
SHADE_LIGHT_BODY(float8)
#undef SHADE_POW_T

/* The channel bytes of shade_encode for RESOLVE_LANES linear channel values c in [0, 1]. */
inline uchar8 shade_encode8(__global const view_rec *vw, float8 c)
{
    return convert_uchar8_sat(shade_pow_encode8(c, 1.0f / vw->gamma) * 255.0f + 0.5f);
}

/* Eight pixels' channel bytes as the words of their uchar4 RGBA (r in the lowest byte: the
 * first in memory on the little-endian devices OpenCL runs on). */
inline uint8 shade_pack_rgba8(uchar8 r, uchar8 g, uchar8 b, uchar8 a)
{
    return convert_uint8(r) | (convert_uint8(g) << 8) | (convert_uint8(b) << 16) | (convert_uint8(a) << 24);
}

/* shade_light1 on vectors: the lit colour of one pixel (n: the unit normal, v: the unit view ray). */
inline float3 shade_light(__global const view_rec *vw, float4 albedo, float3 n, float3 v)
{
    float cx, cy, cz;
    shade_light1(vw, albedo.x, albedo.y, albedo.z, n.x, n.y, n.z, v.x, v.y, v.z, &cx, &cy, &cz);
    return (float3)(cx, cy, cz);
}

/* 8-bit RGBA of linear colour c in [0, 1] and alpha: c^(1 / gamma) and alpha, rounded. */
inline uchar4 shade_encode(__global const view_rec *vw, float3 c, float alpha)
{
    c = shade_pow_encode3(c, 1.0f / vw->gamma);
    float4 out = (float4)(c, alpha) * 255.0f + 0.5f;
    return convert_uchar4_sat(out);
}

/* shade() from the linear albedo and alpha of shade_albedo (the resolve pass looks them up per
 * primitive instead of linearizing at every pixel). */
inline uchar4 shade_lit(__global const view_rec *vw, float4 albedo, float3 n, float3 v)
{
    return shade_encode(vw, shade_light(vw, albedo, n, v), albedo.w);
}

inline uchar4 shade(__global const view_rec *vw, float4 base, float3 n, float3 v)
{
    return shade_lit(vw, shade_albedo(vw, base), n, v);
}

inline uchar4 shade_background(__global const view_rec *vw)
{
    float4 b = vload4(0, vw->background);
    return convert_uchar4_sat(clamp(b, 0.0f, 1.0f) * 255.0f + 0.5f);
}

#endif
