/* vec.h - the one header every file may include: 3-vector math, struct ray, constants and the
 * error record that parsers fill in.  Geometry is float; pixel sums and statistics use double.
 * The ray-origin offset follows PBRT 4e, ch. 6, "Robust Spawned Ray Origins". */
#ifndef MCPT_VEC_H
#define MCPT_VEC_H

#include <math.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

/* Inlining where gcc's heuristics decline it on a hot path (the 8-wide traversal, the
 * triangle surface's double-precision helpers), and the rare paths kept out of the way. */
#if defined(__GNUC__)
#define ALWAYS_INLINE inline __attribute__((always_inline))
#define COLD __attribute__((noinline, cold))
#define NOINLINE __attribute__((noinline))
#else
#define ALWAYS_INLINE inline
#define COLD
#define NOINLINE
#endif

#define MCPT_PI 3.14159265358979323846f
#define MCPT_INV_PI 0.31830988618379067154f
#define MCPT_VERSION "0.1.0"

typedef struct vec3 {
    float x; /* components, in scene units or radiance units by context */
    float y;
    float z;
} vec3; /* 12 bytes */

typedef struct vec2 {
    float x;
    float y;
} vec2; /* 8 bytes */

/* A ray o + t d for t in [t_min, t_max].  d need not be unit length unless a caller says so. */
struct ray {
    vec3 o;      /* origin */
    float t_min; /* smallest accepted hit parameter */
    vec3 d;      /* direction */
    float t_max; /* largest accepted hit parameter; +INFINITY for an unbounded ray */
};               /* 32 bytes */

/* Every failure is reported here; main prints "file:line:col: error: msg" and exits with the
 * status its kind names.  line == 0 means the error has no line (e.g. the file cannot be
 * opened); col == 0 no column. */
enum mcpt_error_kind {
    MCPT_ERROR_INPUT = 0,   /* bad usage or input the user can fix: exit status 2 */
    MCPT_ERROR_RUNTIME = 1, /* out of memory, I/O or thread failure: exit status 1 */
};

struct mcpt_error {
    char file[4096]; /* PATH_MAX: a longer path's message named a file cut to 255 bytes */
    int line;
    int col;
    char msg[3 * 4096 + 1024]; /* the paths a message names, whole (a resume command: three) */
    enum mcpt_error_kind kind;
};
/* Room for mcpt_error_format's longest line: file, ":line:col: error: " and msg. */
#define MCPT_ERROR_LINE_BYTES                                                                      \
    (sizeof((struct mcpt_error *)0)->file + sizeof((struct mcpt_error *)0)->msg + 64)

static inline void mcpt_error_setv(struct mcpt_error *err, enum mcpt_error_kind kind,
                                   const char *file, int line, int col, const char *fmt, va_list ap)
{
    if (!err)
        return;
    snprintf(err->file, sizeof err->file, "%s", file ? file : "");
    err->line = line;
    err->col = col;
    err->kind = kind;
    vsnprintf(err->msg, sizeof err->msg, fmt, ap);
}

/* A bad-input error (exit status 2): what the user gave, at file:line:col. */
static inline void mcpt_error_set(struct mcpt_error *err, const char *file, int line, int col,
                                  const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    mcpt_error_setv(err, MCPT_ERROR_INPUT, file, line, col, fmt, ap);
    va_end(ap);
}

/* A runtime error (exit status 1): out of memory, I/O, threads; file may be NULL or a path. */
static inline void mcpt_error_runtime(struct mcpt_error *err, const char *file, const char *fmt,
                                      ...)
{
    va_list ap;
    va_start(ap, fmt);
    mcpt_error_setv(err, MCPT_ERROR_RUNTIME, file, 0, 0, fmt, ap);
    va_end(ap);
}

/* Formats the error as one line (no trailing newline): "file:line:col: error: msg",
 * "file:line: error: msg" when col == 0, "file: error: msg" when line == 0. */
static inline void mcpt_error_format(const struct mcpt_error *err, char *out, size_t out_bytes)
{
    if (err->line > 0 && err->col > 0)
        snprintf(out, out_bytes, "%s:%d:%d: error: %s", err->file, err->line, err->col, err->msg);
    else if (err->line > 0)
        snprintf(out, out_bytes, "%s:%d: error: %s", err->file, err->line, err->msg);
    else if (err->file[0])
        snprintf(out, out_bytes, "%s: error: %s", err->file, err->msg);
    else
        snprintf(out, out_bytes, "error: %s", err->msg);
}

static inline vec3 v3(float x, float y, float z) { return (vec3){x, y, z}; }
/* A 3-vector of doubles: shape.c computes points and normals in double (docs/theory.md,
 * "Self-intersection"), and struct triangle_plane (shape.h) keeps some. */
struct dvec3 {
    double x;
    double y;
    double z;
}; /* 24 bytes */
static inline struct dvec3 d3(vec3 a) { return (struct dvec3){a.x, a.y, a.z}; }
/* rounded to float, each component to nearest */
static inline vec3 d3_to_float(struct dvec3 a)
{
    return (vec3){(float)a.x, (float)a.y, (float)a.z};
}
static inline struct dvec3 d3_add(struct dvec3 a, struct dvec3 b)
{
    return (struct dvec3){a.x + b.x, a.y + b.y, a.z + b.z};
}
static inline struct dvec3 d3_sub(struct dvec3 a, struct dvec3 b)
{
    return (struct dvec3){a.x - b.x, a.y - b.y, a.z - b.z};
}
static inline struct dvec3 d3_scale(struct dvec3 a, double s)
{
    return (struct dvec3){a.x * s, a.y * s, a.z * s};
}
static inline struct dvec3 d3_abs(struct dvec3 a)
{
    return (struct dvec3){fabs(a.x), fabs(a.y), fabs(a.z)};
}
static inline double d3_dot(struct dvec3 a, struct dvec3 b)
{
    return a.x * b.x + a.y * b.y + a.z * b.z;
}
static inline struct dvec3 d3_cross(struct dvec3 a, struct dvec3 b)
{
    return (struct dvec3){a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
static inline double d3_length(struct dvec3 a) { return sqrt(d3_dot(a, a)); }

/* fmaxf and fminf written out: gcc calls libm for them (their NaN rule, a NaN operand gives the
 * other, has no one-instruction form on x86), and they sit in the path loop.  Same results. */
static inline float max_f(float a, float b) { return a > b || b != b ? a : b; }
static inline float min_f(float a, float b) { return a < b || b != b ? a : b; }
static inline vec3 v3_splat(float s) { return (vec3){s, s, s}; }
static inline vec3 v3_add(vec3 a, vec3 b) { return (vec3){a.x + b.x, a.y + b.y, a.z + b.z}; }
static inline vec3 v3_sub(vec3 a, vec3 b) { return (vec3){a.x - b.x, a.y - b.y, a.z - b.z}; }
static inline vec3 v3_mul(vec3 a, vec3 b) { return (vec3){a.x * b.x, a.y * b.y, a.z * b.z}; }
static inline vec3 v3_scale(vec3 a, float s) { return (vec3){a.x * s, a.y * s, a.z * s}; }
static inline vec3 v3_neg(vec3 a) { return (vec3){-a.x, -a.y, -a.z}; }
static inline float v3_dot(vec3 a, vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline vec3 v3_cross(vec3 a, vec3 b)
{
    return (vec3){a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
static inline float v3_length(vec3 a) { return sqrtf(v3_dot(a, a)); }
static inline vec3 v3_normalize(vec3 a) { return v3_scale(a, 1.0f / v3_length(a)); }
static inline vec3 v3_min(vec3 a, vec3 b)
{
    return (vec3){min_f(a.x, b.x), min_f(a.y, b.y), min_f(a.z, b.z)};
}
static inline vec3 v3_max(vec3 a, vec3 b)
{
    return (vec3){max_f(a.x, b.x), max_f(a.y, b.y), max_f(a.z, b.z)};
}
static inline float v3_get(vec3 a, int axis) { return axis == 0 ? a.x : axis == 1 ? a.y : a.z; }
static inline float v3_max_comp(vec3 a) { return max_f(a.x, max_f(a.y, a.z)); }
static inline bool v3_is_zero(vec3 a) { return a.x == 0.0f && a.y == 0.0f && a.z == 0.0f; }
static inline bool v3_is_finite(vec3 a) { return isfinite(a.x) && isfinite(a.y) && isfinite(a.z); }
/* Rec. 709 luminance of linear RGB. */
static inline float v3_luminance(vec3 c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }

/* Orthonormal basis around unit n: Duff et al. 2017, "Building an Orthonormal Basis, Revisited",
 * listing 3.  Returns t, b with (t, b, n) right-handed. */
static inline void v3_basis(vec3 n, vec3 *t, vec3 *b)
{
    float sign = copysignf(1.0f, n.z);
    float a = -1.0f / (sign + n.z);
    float c = n.x * n.y * a;
    *t = (vec3){1.0f + sign * n.x * n.x * a, sign * c, -sign * n.x};
    *b = (vec3){c, sign + n.y * n.y * a, -n.y};
}

/* Local (tangent-space, z = n) vector to world space. */
static inline vec3 v3_from_local(vec3 l, vec3 t, vec3 b, vec3 n)
{
    return v3_add(v3_add(v3_scale(t, l.x), v3_scale(b, l.y)), v3_scale(n, l.z));
}
/* World-space vector to the local frame (t, b, n): the inverse of v3_from_local. */
static inline vec3 v3_to_local(vec3 w, vec3 t, vec3 b, vec3 n)
{
    return (vec3){v3_dot(w, t), v3_dot(w, b), v3_dot(w, n)};
}

/* Floating-point error bounds, PBRT 4e, ch. 6, "Managing Rounding Error":
 * gamma(n) = n eps / (1 - n eps), eps = 2^-24 (half an ulp of 1). */
static inline float mcpt_gamma(int n)
{
    const float eps = 0x1p-24f;
    return ((float)n * eps) / (1.0f - (float)n * eps);
}
/* The neighbouring floats, nextafterf(v, +-INFINITY) to the bit, without the library call (a
 * spawned ray makes three): PBRT 4e, ch. 6, "Managing Rounding Error", NextFloatUp/Down, which
 * step the bit pattern; -0 and +0 both step to the smallest denormal, infinities towards the
 * finite range stay put, and NaN stays NaN. */
static inline float next_float_up(float v)
{
    if (isnan(v) || (isinf(v) && v > 0.0f))
        return v;
    if (v == 0.0f)
        return 0x1p-149f;
    uint32_t bits;
    memcpy(&bits, &v, sizeof bits);
    bits = v > 0.0f ? bits + 1u : bits - 1u;
    memcpy(&v, &bits, sizeof v);
    return v;
}
static inline float next_float_down(float v) { return -next_float_up(-v); }

/* PBRT 4e, ch. 6, "Robust Spawned Ray Origins": p carries the absolute error bound p_error of
 * its computation; push it along the geometric normal n by the error projected on n, to the side
 * of w (the new ray's direction), then round away from p.  Scale-free: no scene-tuned epsilon. */
static inline vec3 offset_ray_origin(vec3 p, vec3 p_error, vec3 n, vec3 w)
{
    float d = fabsf(n.x) * p_error.x + fabsf(n.y) * p_error.y + fabsf(n.z) * p_error.z;
    vec3 offset = v3_scale(n, d);
    if (v3_dot(w, n) < 0.0f)
        offset = v3_neg(offset);
    vec3 po = v3_add(p, offset);
    po.x = offset.x > 0.0f ? next_float_up(po.x) : offset.x < 0.0f ? next_float_down(po.x) : po.x;
    po.y = offset.y > 0.0f ? next_float_up(po.y) : offset.y < 0.0f ? next_float_down(po.y) : po.y;
    po.z = offset.z > 0.0f ? next_float_up(po.z) : offset.z < 0.0f ? next_float_down(po.z) : po.z;
    return po;
}

#endif
