/* The view (pinhole camera in device coordinates) and the shading shared by the exact ray
 * tracer (raytrace.cl) and the splat resolve pass (resolve.cl), so both produce the same
 * pixels for the same hit.  Mirrored by view_dtype() in clcsg/host/raytracer.py.
 *
 * Camera contract (clcsg/camera.py): the un-normalized direction of pixel (i, j), row 0 at the
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
    float ambient;       /* Blinn-Phong weights; colors are linearized with gamma first */
    float diffuse;
    float specular;
    float shininess;
    float gamma;
} view_rec;

inline real3 view_eye(__global const view_rec *vw) { return vload3(0, vw->eye); }

/* Unit direction of the view ray of pixel (i, j). */
inline real3 view_ray(__global const view_rec *vw, int i, int j)
{
    real3 d = vload3(0, vw->d00) + (real)j * vload3(0, vw->dx) + (real)i * vload3(0, vw->dy);
    return normalize(d);
}

/* x^y for x >= 0 as exp2(y log2 x): several times faster than pow() on CPU devices, and
 * plenty for 8-bit output (x = 0 gives 0 for y > 0). */
inline float shade_pow(float x, float y) { return exp2(y * log2(x)); }
inline float3 shade_pow3(float3 x, float y) { return exp2(y * log2(x)); }

/* Blinn-Phong with two white lights: a headlight at the eye (direction -v) and a key light
 * (vw->key).  base: RGBA of the quadric in display (sRGB-like) space, linearized with gamma;
 * n: the solid's outward unit normal (sign * grad Q / |grad Q|, eq. 4); v: unit view ray.
 * The normal is flipped towards the viewer (two-sided), so a view from inside still shades.
 * Returns 8-bit RGBA, gamma encoded. */
inline uchar4 shade(__global const view_rec *vw, float4 base, float3 n, float3 v)
{
    if (dot(n, v) > 0.0f) n = -n;
    float g = vw->gamma;
    float3 albedo = shade_pow3(clamp(base.xyz, 0.0f, 1.0f), g);
    float3 key = vload3(0, vw->key);
    float3 head = -v;
    float d_head = fmax(dot(n, head), 0.0f);
    float d_key = fmax(dot(n, key), 0.0f);
    float3 h_key = normalize(key + head);
    float s_head = shade_pow(d_head, vw->shininess);            /* half vector of the headlight is -v */
    float s_key = d_key > 0.0f ? shade_pow(fmax(dot(n, h_key), 0.0f), vw->shininess) : 0.0f;
    float3 c = albedo * (vw->ambient + vw->diffuse * (0.45f * d_head + 0.75f * d_key))
             + vw->specular * (0.25f * s_head + 0.5f * s_key);
    c = shade_pow3(clamp(c, 0.0f, 1.0f), 1.0f / g);
    float4 out = (float4)(c, clamp(base.w, 0.0f, 1.0f)) * 255.0f + 0.5f;
    return convert_uchar4_sat(out);
}

inline uchar4 shade_background(__global const view_rec *vw)
{
    float4 b = vload4(0, vw->background);
    return convert_uchar4_sat(clamp(b, 0.0f, 1.0f) * 255.0f + 0.5f);
}

#endif
