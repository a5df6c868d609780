/* scene.c - the scene-file parser.  Reads a line-based text file into struct scene: camera,
 * film, render defaults, materials, OBJ meshes flattened into world-space triangles, analytic
 * shapes, point lights and sky.  Each line is split into a keyword and key=value words, checked
 * against a table of statements, then applied.  Transforms are scale, then rotation (Rodrigues'
 * formula), then translation; normals go through the inverse transpose (PBRT 4e, ch. 3,
 * "Applying Transformations").  The light list is built last: emissive triangles, quads and
 * spheres, then point lights.  Full reference: docs/scene-format.md. */
#include "scene.h"

#include "obj.h"

#include <assert.h>
#include <errno.h>
#include <float.h>
#include <stdlib.h>
#include <unistd.h>

#include "file.h"

/* A small scene in the grammar this file reads:
 *
 *   # Cornell box lit by its ceiling quad
 *   camera eye=0,1,3.9 look-at=0,1,0 up=0,1,0 fov=40
 *   film width=512 height=512
 *   render spp=256 max-depth=inf
 *   material name=white type=diffuse albedo=0.73,0.73,0.73
 *   material name=lamp type=diffuse albedo=0,0,0 emission=17,12,4
 *   material name=glass type=dielectric ior=1.5
 *   mesh file=models/bunny.obj material=white scale=4 translate=0,0.3,0
 *   quad corner=-0.25,1.98,-0.25 edge1=0.5,0,0 edge2=0,0,0.5 material=lamp
 *   sphere center=0.4,0.3,0.3 radius=0.3 material=glass
 *   plane point=0,0,0 normal=0,1,0 material=white
 *   light type=point position=0,1.5,0 intensity=1,1,1
 *   sky type=gradient horizon=1,1,1 zenith=0.3,0.5,1
 */

#define SCENE_MAX_LINE_BYTES 4096 /* longest accepted line, bytes, without its line ending */
#define SCENE_READ_BYTES 65536    /* bytes read from the file at a time */
#define MAX_PARAMS 20             /* most distinct parameters any statement accepts */
#define SHOW_BYTES 40             /* longest piece of user text quoted in a message, bytes */
#define SHOW_OUT_BYTES (4 * SHOW_BYTES + 4) /* show()'s output: every byte as \xNN, "..." */
#define PARALLEL_SIN 1e-6 /* |sin angle| below which two directions count as parallel */
/* Largest |coordinate| of any point of the scene (scene units).  Two such points differ by at
 * most 2e18 per component, so a squared distance, or the area two such differences span, is at
 * most 1.2e37: finite in single precision (largest 3.4e38), with room for the products of the
 * ray-triangle test.  The Cornell box scaled by 1e15 reaches 4e15. */
#define SCENE_MAX_COORD 1e18
#define COORD_WHY "squared distances and areas must stay finite in single precision"
#define UNDERFLOW_WHY                                                                              \
    " (it rounds to 0 in single precision, whose smallest positive number is "                     \
    "1.4e-45)"

/* ---- the statement table ---------------------------------------------------------------- */

enum value_kind {
    VAL_NUMBER,         /* one number */
    VAL_VEC3,           /* x,y,z */
    VAL_ROTATION,       /* ax,ay,az,deg: axis and angle in degrees */
    VAL_SCALE,          /* s (uniform) or sx,sy,sz */
    VAL_INT,            /* unsigned integer, bounds from the range */
    VAL_DEPTH,          /* unsigned integer or "inf" */
    VAL_BOOL,           /* true or false */
    VAL_NAME,           /* a new material name */
    VAL_MATERIAL,       /* the name of a material defined on an earlier line */
    VAL_PATH,           /* a file path, relative to the scene file's folder */
    VAL_TYPE,           /* one of the statement's type words */
    VAL_SAMPLER,        /* a sampler name: independent, stratified, sobol */
    VAL_DIRECT,         /* a direct-lighting estimator: mis, light, bsdf, cosine, hemisphere */
    VAL_SPLIT,          /* full, direct or indirect */
    VAL_ADAPTIVE_RULE,  /* pilot, stop or budget */
    VAL_LIGHT_SAMPLING, /* area or solid-angle */
    VAL_NORMALS,        /* a mesh's shading normals: file or smooth */
    VAL_RR,             /* 'throughput' (stored as 0) or a probability in (0, 1] */
    VAL_CHECKER,        /* true, false, or a colour (the checker's second albedo) */
};

enum value_range {
    RANGE_ANY,
    RANGE_POSITIVE, /* > 0 */
    RANGE_NONNEG,   /* every component >= 0 */
    RANGE_UNIT,     /* every component in [0, 1] */
    RANGE_NONZERO,  /* VAL_VEC3: not the zero vector; VAL_SCALE: no zero component */
    RANGE_POINT,    /* VAL_VEC3: a point, every |component| <= SCENE_MAX_COORD */
    RANGE_FOV,      /* (0, 180) degrees */
    RANGE_FILM,     /* 1..65535 pixels */
    RANGE_SPP,      /* 1..4294967295 */
    RANGE_SPREAD,   /* 2..4294967295: sample counts that estimate a spread (min-spp, pilot-spp) */
    RANGE_1K,       /* 1..1024 */
};

#define ALL_TYPES                                                                                  \
    0xffu /* allowed_mask / required_mask bit t stands for type t; bit 0 when the
                           statement has no 'type' parameter */

struct param_spec {
    const char *key;
    enum value_kind kind;
    enum value_range range;
    unsigned allowed_mask;  /* the types this parameter may be given with */
    unsigned required_mask; /* the types this parameter must be given with */
};

enum stmt_kind {
    STMT_CAMERA,
    STMT_FILM,
    STMT_RENDER,
    STMT_MATERIAL,
    STMT_MESH,
    STMT_SPHERE,
    STMT_QUAD,
    STMT_PLANE,
    STMT_LIGHT,
    STMT_SKY,
    STMT_COUNT
};

struct stmt_spec {
    const char *keyword;
    bool is_once;                         /* may appear at most once */
    const char *types[8];                 /* words of the 'type' parameter; none: no 'type' */
    struct param_spec params[MAX_PARAMS]; /* in the order the reference lists them */
};

/* type bits: material */
#define T_DIFFUSE 1u
#define T_MIRROR 2u
#define T_DIELECTRIC 4u
#define T_DIFFUSE_UNIFORM 8u
#define T_CONDUCTOR 16u
#define T_PLASTIC 32u
#define T_UNITY 64u
#define T_ALBEDO (T_DIFFUSE | T_DIFFUSE_UNIFORM | T_PLASTIC | T_UNITY) /* textured by 'checker' */
/* type bits: sky */
#define T_CONSTANT 1u
#define T_GRADIENT 2u

static const struct stmt_spec stmt_specs[STMT_COUNT] = {
    [STMT_CAMERA] = {"camera",
                     true,
                     {NULL},
                     {
                         {"eye", VAL_VEC3, RANGE_POINT, ALL_TYPES, ALL_TYPES},
                         {"look-at", VAL_VEC3, RANGE_POINT, ALL_TYPES, ALL_TYPES},
                         {"up", VAL_VEC3, RANGE_NONZERO, ALL_TYPES, ALL_TYPES},
                         {"fov", VAL_NUMBER, RANGE_FOV, ALL_TYPES, ALL_TYPES},
                         {"aperture", VAL_NUMBER, RANGE_NONNEG, ALL_TYPES, 0},
                         {"focus-dist", VAL_NUMBER, RANGE_NONNEG, ALL_TYPES, 0},
                     }},
    [STMT_FILM] = {"film",
                   true,
                   {NULL},
                   {
                       {"width", VAL_INT, RANGE_FILM, ALL_TYPES, ALL_TYPES},
                       {"height", VAL_INT, RANGE_FILM, ALL_TYPES, ALL_TYPES},
                   }},
    [STMT_RENDER] = {"render",
                     true,
                     {NULL},
                     {
                         {"spp", VAL_INT, RANGE_SPP, ALL_TYPES, 0},
                         {"max-depth", VAL_DEPTH, RANGE_ANY, ALL_TYPES, 0},
                         {"sampler", VAL_SAMPLER, RANGE_ANY, ALL_TYPES, 0},
                         {"adaptive", VAL_BOOL, RANGE_ANY, ALL_TYPES, 0},
                         {"adaptive-rule", VAL_ADAPTIVE_RULE, RANGE_ANY, ALL_TYPES, 0},
                         {"pilot-spp", VAL_INT, RANGE_SPREAD, ALL_TYPES, 0},
                         {"tolerance", VAL_NUMBER, RANGE_POSITIVE, ALL_TYPES, 0},
                         {"adaptive-floor", VAL_NUMBER, RANGE_NONNEG, ALL_TYPES, 0},
                         {"batch", VAL_INT, RANGE_SPP, ALL_TYPES, 0},
                         {"min-spp", VAL_INT, RANGE_SPREAD, ALL_TYPES, 0},
                         {"max-spp", VAL_INT, RANGE_SPP, ALL_TYPES, 0},
                         {"direct", VAL_DIRECT, RANGE_ANY, ALL_TYPES, 0},
                         {"light-samples", VAL_INT, RANGE_1K, ALL_TYPES, 0},
                         {"split", VAL_SPLIT, RANGE_ANY, ALL_TYPES, 0},
                         {"light-sampling", VAL_LIGHT_SAMPLING, RANGE_ANY, ALL_TYPES, 0},
                         {"rr", VAL_RR, RANGE_ANY, ALL_TYPES, 0},
                         {"rr-depth", VAL_INT, RANGE_1K, ALL_TYPES, 0},
                         {"rr-threshold", VAL_NUMBER, RANGE_POSITIVE, ALL_TYPES, 0},
                     }},
    [STMT_MATERIAL] = {"material",
                       false,
                       {"diffuse", "mirror", "dielectric", "diffuse-uniform", "conductor",
                        "plastic", "unity", NULL},
                       {
                           {"name", VAL_NAME, RANGE_ANY, ALL_TYPES, ALL_TYPES},
                           {"type", VAL_TYPE, RANGE_ANY, ALL_TYPES, ALL_TYPES},
                           {"albedo", VAL_VEC3, RANGE_UNIT, T_ALBEDO, T_ALBEDO},
                           {"specular", VAL_VEC3, RANGE_UNIT,
                            T_MIRROR | T_DIELECTRIC | T_CONDUCTOR | T_UNITY, 0},
                           {"ior", VAL_NUMBER, RANGE_POSITIVE, T_DIELECTRIC | T_UNITY, 0},
                           {"emission", VAL_VEC3, RANGE_NONNEG, ALL_TYPES, 0},
                           {"two-sided", VAL_BOOL, RANGE_ANY, ALL_TYPES, 0},
                           {"roughness", VAL_NUMBER, RANGE_UNIT, T_CONDUCTOR | T_PLASTIC, 0},
                           {"metallic", VAL_NUMBER, RANGE_UNIT, T_PLASTIC, 0},
                           {"reflectance", VAL_NUMBER, RANGE_UNIT, T_PLASTIC, 0},
                           {"smoothness", VAL_NUMBER, RANGE_UNIT, T_UNITY, 0},
                           {"specular-prob", VAL_NUMBER, RANGE_UNIT, T_UNITY, 0},
                           {"glass", VAL_BOOL, RANGE_ANY, T_UNITY, 0},
                           {"checker", VAL_CHECKER, RANGE_UNIT, T_ALBEDO, 0},
                           {"checker-scale", VAL_NUMBER, RANGE_POSITIVE, T_ALBEDO, 0},
                           {"checker-uv", VAL_BOOL, RANGE_ANY, T_ALBEDO, 0},
                       }},
    [STMT_MESH] = {"mesh",
                   false,
                   {NULL},
                   {
                       {"file", VAL_PATH, RANGE_ANY, ALL_TYPES, ALL_TYPES},
                       {"material", VAL_MATERIAL, RANGE_ANY, ALL_TYPES, 0},
                       {"translate", VAL_VEC3, RANGE_ANY, ALL_TYPES, 0},
                       {"rotate", VAL_ROTATION, RANGE_ANY, ALL_TYPES, 0},
                       {"scale", VAL_SCALE, RANGE_NONZERO, ALL_TYPES, 0},
                       {"normals", VAL_NORMALS, RANGE_ANY, ALL_TYPES, 0},
                   }},
    [STMT_SPHERE] = {"sphere",
                     false,
                     {NULL},
                     {
                         {"center", VAL_VEC3, RANGE_POINT, ALL_TYPES, ALL_TYPES},
                         {"radius", VAL_NUMBER, RANGE_POSITIVE, ALL_TYPES, ALL_TYPES},
                         {"material", VAL_MATERIAL, RANGE_ANY, ALL_TYPES, ALL_TYPES},
                         {"translate", VAL_VEC3, RANGE_ANY, ALL_TYPES, 0},
                         {"scale", VAL_SCALE, RANGE_NONZERO, ALL_TYPES, 0},
                     }},
    [STMT_QUAD] = {"quad",
                   false,
                   {NULL},
                   {
                       {"corner", VAL_VEC3, RANGE_POINT, ALL_TYPES, ALL_TYPES},
                       {"edge1", VAL_VEC3, RANGE_NONZERO, ALL_TYPES, ALL_TYPES},
                       {"edge2", VAL_VEC3, RANGE_NONZERO, ALL_TYPES, ALL_TYPES},
                       {"material", VAL_MATERIAL, RANGE_ANY, ALL_TYPES, ALL_TYPES},
                       {"translate", VAL_VEC3, RANGE_ANY, ALL_TYPES, 0},
                       {"rotate", VAL_ROTATION, RANGE_ANY, ALL_TYPES, 0},
                       {"scale", VAL_SCALE, RANGE_NONZERO, ALL_TYPES, 0},
                   }},
    [STMT_PLANE] = {"plane",
                    false,
                    {NULL},
                    {
                        {"point", VAL_VEC3, RANGE_POINT, ALL_TYPES, ALL_TYPES},
                        {"normal", VAL_VEC3, RANGE_NONZERO, ALL_TYPES, ALL_TYPES},
                        {"material", VAL_MATERIAL, RANGE_ANY, ALL_TYPES, ALL_TYPES},
                    }},
    [STMT_LIGHT] = {"light",
                    false,
                    {"point", NULL},
                    {
                        {"type", VAL_TYPE, RANGE_ANY, ALL_TYPES, ALL_TYPES},
                        {"position", VAL_VEC3, RANGE_POINT, ALL_TYPES, ALL_TYPES},
                        {"intensity", VAL_VEC3, RANGE_NONNEG, ALL_TYPES, ALL_TYPES},
                    }},
    [STMT_SKY] = {"sky",
                  true,
                  {"constant", "gradient", NULL},
                  {
                      {"type", VAL_TYPE, RANGE_ANY, ALL_TYPES, ALL_TYPES},
                      {"radiance", VAL_VEC3, RANGE_NONNEG, T_CONSTANT, T_CONSTANT},
                      {"horizon", VAL_VEC3, RANGE_NONNEG, T_GRADIENT, T_GRADIENT},
                      {"zenith", VAL_VEC3, RANGE_NONNEG, T_GRADIENT, T_GRADIENT},
                  }},
};

/* One parameter of the statement being read; key == NULL when the line does not give it. */
struct param {
    const char *key;
    const char *text; /* the value as written */
    int key_col;      /* 1-based byte columns */
    int val_col;
    float f[4];        /* the numbers of VAL_NUMBER, VAL_VEC3, VAL_ROTATION, VAL_SCALE */
    double d[4];       /* the same numbers in double (0 where f underflowed to 0) */
    int n_f;           /* how many numbers were written */
    bool is_underflow; /* a number written nonzero was read as 0 (below 1.4e-45) */
    uint32_t u;        /* VAL_INT, VAL_DEPTH; type index; material index of VAL_MATERIAL */
    bool b;            /* VAL_BOOL */
};

struct stmt {
    enum stmt_kind kind;
    const struct stmt_spec *spec;
    int kw_col;
    uint32_t type_idx;          /* index into spec->types; 0 without types */
    struct param p[MAX_PARAMS]; /* parallel to spec->params */
};

struct parser {
    const char *path; /* the scene path as given, for messages */
    char *dir;        /* the scene file's folder with its trailing '/', or "" */
    struct scene *scene;
    struct mcpt_error *err;
    int line; /* 1-based line being read */
    int fd;   /* the scene file */
    char *in; /* SCENE_READ_BYTES read from it; in_pos..in_len not yet used */
    size_t in_pos, in_len;
    bool at_eof;
    int pending[3]; /* bytes read ahead and given back (a BOM that was not one) */
    int n_pending;
    int seen_line[STMT_COUNT]; /* line of the first statement of each kind, 0 = none */
    int *mat_def_line; /* per material: the scene-file line defining it, 0 = not referable */
    struct obj_names mat_names; /* referable material name -> index into materials */
    int64_t default_mat_idx;    /* the meshes' "default" material, -1 until needed */
    struct light *points;       /* point lights, in file order */
    uint32_t n_points;
    uint32_t cap_materials, cap_def_lines, cap_positions, cap_normals, cap_uvs, cap_tris;
    uint32_t cap_spheres, cap_quads, cap_planes, cap_points;
};

/* ---- errors ------------------------------------------------------------------------------- */

/* Fills the error at (current line, col) and returns false. */
static bool fail(struct parser *ps, int col, const char *fmt, ...)
{
    char msg[sizeof ps->err->msg];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    mcpt_error_set(ps->err, ps->path, ps->line, col, "%s", msg);
    return false;
}

/* Length of the valid UTF-8 sequence at s (1 to 4 bytes) that is not a control character,
 * or 0 (Unicode 15, table 3-7, "Well-Formed UTF-8 Byte Sequences"). */
static size_t utf8_char_bytes(const unsigned char *s)
{
    if (s[0] >= 0x20 && s[0] < 0x7f)
        return 1;
    unsigned char lo = 0x80, hi = 0xbf;
    size_t n;
    if (s[0] == 0xc2)
        lo = 0xa0, n = 2; /* C2 80..9F are the C1 controls */
    else if (s[0] > 0xc2 && s[0] <= 0xdf)
        n = 2;
    else if (s[0] >= 0xe0 && s[0] <= 0xef)
        n = 3, lo = s[0] == 0xe0 ? 0xa0 : 0x80, hi = s[0] == 0xed ? 0x9f : 0xbf;
    else if (s[0] >= 0xf0 && s[0] <= 0xf4)
        n = 4, lo = s[0] == 0xf0 ? 0x90 : 0x80, hi = s[0] == 0xf4 ? 0x8f : 0xbf;
    else
        return 0;
    if (s[1] < lo || s[1] > hi)
        return 0;
    for (size_t i = 2; i < n; i++)
        if (s[i] < 0x80 || s[i] > 0xbf)
            return 0;
    return n;
}

/* Out of memory: a runtime error (exit status 1), reported at the current line. */
static bool fail_oom(struct parser *ps, int col)
{
    fail(ps, col, "out of memory");
    ps->err->kind = MCPT_ERROR_RUNTIME;
    return false;
}

/* User text for a message: valid UTF-8 as it is, any other byte as \xNN (so a message is
 * always valid UTF-8 without control bytes), cut after SHOW_BYTES input bytes with "..." so a
 * long word cannot crowd out the rest of the message.  out must hold SHOW_OUT_BYTES. */
static const char *show(const char *s, char *out)
{
    const unsigned char *u = (const unsigned char *)s;
    size_t n = 0, i = 0;
    while (u[i]) {
        size_t k = utf8_char_bytes(u + i);
        if (i + (k ? k : 1) > SHOW_BYTES) {
            memcpy(out + n, "...", 3);
            n += 3;
            break;
        }
        if (k) {
            memcpy(out + n, u + i, k);
            n += k;
            i += k;
        } else {
            snprintf(out + n, 5, "\\x%02x", u[i++]);
            n += 4;
        }
    }
    out[n] = '\0';
    return out;
}

/* "a, b, c": the statement keywords, or the parameters a statement of type bit type_bit takes. */
static void list_words(char *out, size_t out_bytes, const struct stmt_spec *spec, unsigned type_bit)
{
    size_t used = 0;
    out[0] = '\0';
    for (int i = 0; i < (spec ? MAX_PARAMS : STMT_COUNT); i++) {
        const char *w;
        if (spec) {
            w = spec->params[i].key;
            if (!w || !(spec->params[i].allowed_mask & type_bit))
                continue;
        } else {
            w = stmt_specs[i].keyword;
        }
        int n = snprintf(out + used, out_bytes - used, "%s%s", used ? ", " : "", w);
        if (n < 0 || (size_t)n >= out_bytes - used)
            return;
        used += (size_t)n;
    }
}

/* Keeps a warning line for main to print (NULL: counts one that was not kept). */
static void add_warning(struct parser *ps, const char *line)
{
    struct scene *sc = ps->scene;
    if (line && sc->n_warnings < SCENE_MAX_WARNINGS)
        snprintf(sc->warnings[sc->n_warnings], sizeof sc->warnings[0], "%s", line);
    if (sc->n_warnings < UINT32_MAX)
        sc->n_warnings++;
}

/* ---- memory ------------------------------------------------------------------------------- */

/* Returns arr grown to hold at least need >= 1 elements of elem_bytes (arr itself when *cap
 * already does).  On overflow or out of memory: frees arr, fills the error, returns NULL.
 * Capacity doubles, so n appends cost O(n). */
static void *grow(struct parser *ps, void *arr, uint32_t *cap, uint64_t need, size_t elem_bytes)
{
    assert(need >= 1);
    if (need <= *cap)
        return arr;
    uint64_t new_cap = *cap ? *cap : 8;
    while (new_cap < need)
        new_cap *= 2;
    if (new_cap > UINT32_MAX)
        new_cap = UINT32_MAX;
    void *p = NULL;
    if (need > new_cap || new_cap > SIZE_MAX / elem_bytes)
        fail(ps, 0, "expected at most %u elements of %zu bytes, got %llu", UINT32_MAX, elem_bytes,
             (unsigned long long)need);
    else if (!(p = realloc(arr, (size_t)new_cap * elem_bytes)))
        fail_oom(ps, 0);
    if (!p) {
        free(arr);
        *cap = 0;
        return NULL;
    }
    *cap = (uint32_t)new_cap;
    return p;
}

/* Grows the array arr (an lvalue) of capacity cap; false (array freed, error filled) on failure. */
#define RESERVE(ps, arr, cap, need)                                                                \
    (((arr) = grow((ps), (arr), &(cap), (need), sizeof *(arr))) != NULL)

/* Appends m to the material table; def_line > 0 makes it referable by name. */
static bool add_material(struct parser *ps, const struct material *m, int def_line)
{
    struct scene *sc = ps->scene;
    uint64_t need = (uint64_t)sc->n_materials + 1;
    if (!RESERVE(ps, sc->materials, ps->cap_materials, need) ||
        !RESERVE(ps, ps->mat_def_line, ps->cap_def_lines, need))
        return false;
    if (def_line > 0 && !obj_names_add(&ps->mat_names, m->name, strlen(m->name), sc->n_materials))
        return fail_oom(ps, 0);
    ps->mat_def_line[sc->n_materials] = def_line;
    sc->materials[sc->n_materials++] = *m;
    return true;
}

/* ---- values ------------------------------------------------------------------------------- */

enum number_status { NUMBER_OK, NUMBER_SYNTAX, NUMBER_NONFINITE };

static bool is_digit(char c) { return c >= '0' && c <= '9'; }

/* Case-insensitive: does s start with the lower-case word w? */
static bool starts_with_word(const char *s, size_t len, const char *w)
{
    size_t n = strlen(w);
    if (len < n)
        return false;
    for (size_t i = 0; i < n; i++)
        if ((s[i] | 0x20) != w[i])
            return false;
    return true;
}

/* Reads the decimal number s[0..len): [+-] (digits [. digits] | . digits) [e [+-] digits].
 * NaN, infinities and values beyond float range are NUMBER_NONFINITE; hex floats are syntax
 * errors. */
static enum number_status parse_number(const char *s, size_t len, float *out, double *out_d)
{
    size_t i = 0;
    if (i < len && (s[i] == '+' || s[i] == '-'))
        i++;
    if (starts_with_word(s + i, len - i, "nan") || starts_with_word(s + i, len - i, "inf"))
        return NUMBER_NONFINITE;
    size_t n_digits = 0;
    while (i < len && is_digit(s[i]))
        i++, n_digits++;
    if (i < len && s[i] == '.') {
        i++;
        while (i < len && is_digit(s[i]))
            i++, n_digits++;
    }
    if (n_digits == 0)
        return NUMBER_SYNTAX;
    if (i < len && (s[i] == 'e' || s[i] == 'E')) {
        i++;
        if (i < len && (s[i] == '+' || s[i] == '-'))
            i++;
        if (i == len || !is_digit(s[i]))
            return NUMBER_SYNTAX;
        while (i < len && is_digit(s[i]))
            i++;
    }
    if (i != len)
        return NUMBER_SYNTAX;
    char *end;
    float f = strtof(s, &end); /* correctly rounded; the checked syntax is a subset of strtof's,
                                  so it stops at len */
    assert(end == s + len);
    if (!isfinite(f))
        return NUMBER_NONFINITE;
    *out = f;
    *out_d = f == 0.0f ? 0.0 : strtod(s, &end); /* the same digits, correctly rounded */
    return NUMBER_OK;
}

/* Reads [+-]digits; *is_negative is set for a '-' sign with a nonzero value.  Magnitudes above
 * UINT32_MAX come back as UINT32_MAX + 1. */
static bool parse_integer(const char *s, uint64_t *magnitude, bool *is_negative)
{
    bool minus = false;
    if (*s == '+' || *s == '-')
        minus = *s++ == '-';
    if (!is_digit(*s))
        return false;
    uint64_t v = 0;
    for (; is_digit(*s); s++)
        if (v <= UINT32_MAX)
            v = v * 10 + (uint64_t)(*s - '0');
    if (*s)
        return false;
    *magnitude = v > UINT32_MAX ? (uint64_t)UINT32_MAX + 1 : v;
    *is_negative = minus && v != 0;
    return true;
}

/* Material names: letters, digits, '_', '-', '.'; so the "<objfile>:<mtlname>" names of MTL
 * materials can never be written in a scene file. */
static bool parse_name(struct parser *ps, const struct param *p)
{
    char buf[SHOW_OUT_BYTES];
    size_t n = strlen(p->text);
    for (size_t i = 0; i < n; i++) {
        char c = p->text[i];
        bool ok = is_digit(c) || (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || c == '_' ||
                  c == '-' || c == '.';
        if (!ok)
            return fail(ps, p->val_col,
                        "expected a material name of letters, digits, '_', '-' "
                        "and '.', got '%s'",
                        show(p->text, buf));
    }
    if (n >= sizeof ps->scene->materials[0].name)
        return fail(ps, p->val_col, "expected a material name of at most %zu bytes, got %zu",
                    sizeof ps->scene->materials[0].name - 1, n);
    return true;
}

/* The referable material named name, or -1: a hash lookup, so n materials and n references
 * cost O(n), not O(n^2). */
static int64_t find_material(struct parser *ps, const char *name)
{
    return obj_names_find(&ps->mat_names, name, strlen(name));
}

/* Checks the numbers of p against its range. */
static bool check_range(struct parser *ps, const struct param_spec *sp, const struct param *p)
{
    char buf[SHOW_OUT_BYTES];
    const char *v = show(p->text, buf);
    bool all_nonneg = true, all_unit = true, any_zero = false, all_zero = true;
    for (int i = 0; i < p->n_f; i++) {
        all_nonneg &= p->f[i] >= 0.0f;
        all_unit &= p->f[i] >= 0.0f && p->f[i] <= 1.0f;
        any_zero |= p->f[i] == 0.0f;
        all_zero &= p->f[i] == 0.0f;
    }
    bool is_vector = sp->kind != VAL_NUMBER;
    const char *why_zero = p->is_underflow ? UNDERFLOW_WHY : "";
    switch (sp->range) {
    case RANGE_POSITIVE:
        if (!(p->f[0] > 0.0f))
            return fail(ps, p->val_col, "expected '%s' > 0, got %s%s", sp->key, v, why_zero);
        break;
    case RANGE_NONNEG:
        if (!all_nonneg)
            return fail(ps, p->val_col, "expected '%s'%s >= 0, got %s", sp->key,
                        is_vector ? " components" : "", v);
        break;
    case RANGE_UNIT:
        if (!all_unit)
            return fail(ps, p->val_col, "expected '%s'%s in [0, 1], got %s", sp->key,
                        is_vector ? " components" : "", v);
        break;
    case RANGE_NONZERO:
        if (sp->kind == VAL_SCALE && any_zero)
            return fail(ps, p->val_col, "expected nonzero '%s' components, got %s%s", sp->key, v,
                        why_zero);
        if (sp->kind == VAL_VEC3 && all_zero)
            return fail(ps, p->val_col, "expected a nonzero '%s', got %s%s", sp->key, v, why_zero);
        break;
    case RANGE_POINT:
        for (int i = 0; i < 3; i++)
            if (!(fabsf(p->f[i]) <= SCENE_MAX_COORD))
                return fail(ps, p->val_col,
                            "expected '%s' components in [-1e18, 1e18] (" COORD_WHY "), got %s",
                            sp->key, v);
        break;
    case RANGE_FOV:
        if (!(p->f[0] > 0.0f && p->f[0] < 180.0f))
            return fail(ps, p->val_col, "expected '%s' in (0, 180) degrees, got %s", sp->key, v);
        break;
    default:
        break;
    }
    return true;
}

/* Reads p->text as the numbers of a VAL_NUMBER, VAL_VEC3, VAL_ROTATION or VAL_SCALE. */
static bool parse_numbers(struct parser *ps, const struct param_spec *sp, struct param *p)
{
    char buf[SHOW_OUT_BYTES];
    const char *v = show(p->text, buf);
    const char *what = sp->kind == VAL_NUMBER     ? "a number"
                       : sp->kind == VAL_VEC3     ? "3 comma-separated numbers"
                       : sp->kind == VAL_ROTATION ? "4 comma-separated numbers (axis x,y,z, "
                                                    "angle in degrees)"
                                                  : "1 or 3 comma-separated numbers";
    int n_commas = 0;
    for (const char *c = p->text; *c; c++)
        n_commas += *c == ',';
    int n = n_commas + 1;
    bool arity_ok = sp->kind == VAL_NUMBER     ? n == 1
                    : sp->kind == VAL_VEC3     ? n == 3
                    : sp->kind == VAL_ROTATION ? n == 4
                                               : n == 1 || n == 3;
    if (!arity_ok)
        return fail(ps, p->val_col, "expected %s for '%s', got '%s'", what, sp->key, v);
    const char *s = p->text;
    for (int i = 0; i < n; i++) {
        const char *end = strchr(s, ',');
        size_t len = end ? (size_t)(end - s) : strlen(s);
        enum number_status st = parse_number(s, len, &p->f[i], &p->d[i]);
        if (st == NUMBER_OK && p->f[i] == 0.0f) /* a nonzero digit before any exponent? */
            for (size_t k = 0; k < len && s[k] != 'e' && s[k] != 'E'; k++)
                p->is_underflow |= s[k] >= '1' && s[k] <= '9';
        if (st == NUMBER_SYNTAX)
            return fail(ps, p->val_col, "expected %s for '%s', got '%s'", what, sp->key, v);
        if (st == NUMBER_NONFINITE)
            return fail(ps, p->val_col, "expected %s for '%s', got '%s'",
                        n == 1 ? "a finite number" : "finite numbers", sp->key, v);
        s += len + 1;
    }
    p->n_f = n;
    if (sp->kind == VAL_SCALE && n == 1) {
        p->f[1] = p->f[2] = p->f[0];
        p->d[1] = p->d[2] = p->d[0];
    }
    if (sp->kind == VAL_ROTATION && p->f[0] == 0.0f && p->f[1] == 0.0f && p->f[2] == 0.0f)
        return fail(ps, p->val_col, "expected a nonzero axis for '%s', got %s%s", sp->key, v,
                    p->is_underflow ? UNDERFLOW_WHY : "");
    return check_range(ps, sp, p);
}

/* Reads and checks the value of parameter p (anything but the type, read earlier). */
static bool parse_value(struct parser *ps, const struct param_spec *sp, struct param *p)
{
    char buf[SHOW_OUT_BYTES];
    const char *v = show(p->text, buf);
    uint64_t u;
    bool is_negative;
    switch (sp->kind) {
    case VAL_NUMBER:
    case VAL_VEC3:
    case VAL_ROTATION:
    case VAL_SCALE:
        return parse_numbers(ps, sp, p);
    case VAL_INT: {
        if (!parse_integer(p->text, &u, &is_negative))
            return fail(ps, p->val_col, "expected an integer for '%s', got '%s'", sp->key, v);
        uint64_t hi = sp->range == RANGE_FILM ? 65535 : sp->range == RANGE_1K ? 1024 : UINT32_MAX;
        uint64_t lo = sp->range == RANGE_SPREAD ? 2 : 1; /* one sample has no spread */
        if (is_negative || u < lo || u > hi)
            return fail(ps, p->val_col, "expected '%s' in %llu..%llu, got %s", sp->key,
                        (unsigned long long)lo, (unsigned long long)hi, v);
        p->u = (uint32_t)u;
        return true;
    }
    case VAL_DEPTH:
        if (strcmp(p->text, "inf") == 0) {
            p->u = UINT32_MAX;
            return true;
        }
        if (!parse_integer(p->text, &u, &is_negative))
            return fail(ps, p->val_col, "expected an integer or 'inf' for '%s', got '%s'", sp->key,
                        v);
        if (is_negative || u > UINT32_MAX)
            return fail(ps, p->val_col, "expected '%s' in 0..%u or 'inf', got %s", sp->key,
                        UINT32_MAX, v);
        p->u = (uint32_t)u;
        return true;
    case VAL_BOOL:
        if (strcmp(p->text, "true") != 0 && strcmp(p->text, "false") != 0)
            return fail(ps, p->val_col, "expected true or false for '%s', got '%s'", sp->key, v);
        p->b = p->text[0] == 't';
        return true;
    case VAL_NAME: {
        if (!parse_name(ps, p))
            return false;
        int64_t idx = find_material(ps, p->text);
        if (idx >= 0)
            return fail(ps, p->val_col,
                        "expected a new material name, got '%s' (defined on "
                        "line %d)",
                        v, ps->mat_def_line[idx]);
        return true;
    }
    case VAL_MATERIAL: {
        if (!parse_name(ps, p))
            return false;
        int64_t idx = find_material(ps, p->text);
        if (idx < 0)
            return fail(ps, p->val_col,
                        "expected a material defined on an earlier line, got "
                        "'%s'",
                        v);
        p->u = (uint32_t)idx;
        return true;
    }
    case VAL_SAMPLER: {
        enum sampler_kind kind;
        if (!sample_sampler_parse(p->text, &kind))
            return fail(ps, p->val_col,
                        "expected independent, stratified or sobol for '%s', "
                        "got '%s'",
                        sp->key, v);
        p->u = (uint32_t)kind;
        return true;
    }
    case VAL_DIRECT: {
        enum render_direct direct;
        if (!scene_direct_parse(p->text, &direct))
            return fail(ps, p->val_col,
                        "expected mis, light, bsdf, cosine or hemisphere for "
                        "'%s', got '%s'",
                        sp->key, v);
        p->u = (uint32_t)direct;
        return true;
    }
    case VAL_ADAPTIVE_RULE: {
        enum render_adaptive_rule rule;
        if (!scene_adaptive_rule_parse(p->text, &rule))
            return fail(ps, p->val_col, "expected pilot, stop or budget for '%s', got '%s'",
                        sp->key, v);
        p->u = (uint32_t)rule;
        return true;
    }
    case VAL_LIGHT_SAMPLING: {
        enum render_light_sampling mode;
        if (!scene_light_sampling_parse(p->text, &mode))
            return fail(ps, p->val_col, "expected area or solid-angle for '%s', got '%s'", sp->key,
                        v);
        p->u = (uint32_t)mode;
        return true;
    }
    case VAL_SPLIT: {
        enum render_split split;
        if (!scene_split_parse(p->text, &split))
            return fail(ps, p->val_col, "expected full, direct or indirect for '%s', got '%s'",
                        sp->key, v);
        p->u = (uint32_t)split;
        return true;
    }
    case VAL_NORMALS:
        if (strcmp(p->text, "file") != 0 && strcmp(p->text, "smooth") != 0)
            return fail(ps, p->val_col, "expected file or smooth for '%s', got '%s'", sp->key, v);
        p->b = p->text[0] == 's';
        return true;
    case VAL_RR: {
        float prob = 0.0f;
        double prob_d;
        if (strcmp(p->text, "throughput") != 0 &&
            (parse_number(p->text, strlen(p->text), &prob, &prob_d) != NUMBER_OK ||
             !(prob > 0.0f && prob <= 1.0f)))
            return fail(ps, p->val_col,
                        "expected 'throughput' or a probability in (0, 1] for "
                        "'%s', got '%s'",
                        sp->key, v);
        p->f[0] = prob;
        p->n_f = 1;
        return true;
    }
    case VAL_CHECKER: {
        p->n_f = 0;
        if (strcmp(p->text, "true") == 0 || strcmp(p->text, "false") == 0) {
            p->b = p->text[0] == 't';
            return true;
        }
        int n_commas = 0;
        for (const char *c = p->text; *c; c++)
            n_commas += *c == ',';
        if (n_commas != 2)
            return fail(ps, p->val_col,
                        "expected true, false or 3 comma-separated numbers for "
                        "'%s', got '%s'",
                        sp->key, v);
        struct param_spec colour = *sp;
        colour.kind = VAL_VEC3;
        p->b = true;
        return parse_numbers(ps, &colour, p);
    }
    case VAL_PATH:
    case VAL_TYPE:
        return true;
    }
    return true;
}

/* ---- the line reader and tokenizer ---------------------------------------------------------- */

/* The next byte of the scene file, -1 at its end, or -2 after a read error (error filled). */
static int next_byte(struct parser *ps)
{
    if (ps->n_pending > 0)
        return ps->pending[--ps->n_pending];
    if (ps->in_pos == ps->in_len) {
        if (ps->at_eof)
            return -1;
        ssize_t got;
        do
            got = read(ps->fd, ps->in, SCENE_READ_BYTES);
        while (got < 0 && errno == EINTR);
        if (got < 0 && errno == EISDIR) { /* standard input redirected from a folder */
            mcpt_error_set(ps->err, ps->path, 0, 0, "expected a scene, got a directory");
            return -2;
        }
        if (got < 0) {
            mcpt_error_runtime(ps->err, ps->path, "cannot read: %s", strerror(errno));
            return -2;
        }
        if (got == 0) {
            ps->at_eof = true;
            return -1;
        }
        ps->scene->file_hash = file_fnv1a64(ps->scene->file_hash, ps->in, (size_t)got);
        ps->in_pos = 0;
        ps->in_len = (size_t)got;
    }
    return (unsigned char)ps->in[ps->in_pos++];
}

/* Gives byte c back to next_byte (at most 3, last in first out). */
static void unread_byte(struct parser *ps, int c)
{
    assert(ps->n_pending < 3);
    ps->pending[ps->n_pending++] = c;
}

/* At the start of the file: skips a UTF-8 byte order mark (EF BB BF, which editors on Windows
 * write) and refuses UTF-16 (FF FE or FE FF).  Returns false with the error filled. */
static bool skip_byte_order_mark(struct parser *ps)
{
    int b[3];
    int n = 0;
    while (n < 3 && (b[n] = next_byte(ps)) >= 0)
        n++;
    if (n < 3 && b[n] == -2)
        return false;
    if (n == 3 && b[0] == 0xef && b[1] == 0xbb && b[2] == 0xbf)
        return true;
    if (n >= 2 && ((b[0] == 0xff && b[1] == 0xfe) || (b[0] == 0xfe && b[1] == 0xff)))
        return fail(ps, 1, "expected UTF-8 text, got UTF-16 (byte order mark 0x%02x 0x%02x)",
                    (unsigned)b[0], (unsigned)b[1]);
    while (n > 0)
        unread_byte(ps, b[--n]);
    return true;
}

/* Reads one line into buf (SCENE_MAX_LINE_BYTES + 1 bytes), without its "\n" or "\r\n", and
 * NUL-terminates it.  Returns 1 for a line, 0 at the end of the file, -1 on an error. */
static int read_line(struct parser *ps, char *buf)
{
    size_t len = 0;
    bool got_any = false;
    int c;
    while ((c = next_byte(ps)) >= 0 && c != '\n') {
        got_any = true;
        if (c == '\r') { /* CRLF (or a CR at the end of the file) ends the line */
            int next = next_byte(ps);
            if (next == '\n' || next == -1)
                break;
            if (next == -2)
                return -1;
            unread_byte(ps, next);
        }
        bool is_text = c >= 0x20 ? c != 0x7f : c == '\t';
        if (!is_text) {
            fail(ps, (int)len + 1, "expected text, got the byte 0x%02x", (unsigned)c);
            return -1;
        }
        if (len == SCENE_MAX_LINE_BYTES) {
            fail(ps, SCENE_MAX_LINE_BYTES + 1,
                 "expected a line of at most %d bytes, got a "
                 "longer one",
                 SCENE_MAX_LINE_BYTES);
            return -1;
        }
        buf[len++] = (char)c;
    }
    if (c == -2)
        return -1;
    if (c == -1 && !got_any)
        return 0;
    buf[len] = '\0';
    return 1;
}

/* The next word at *cur, NUL-terminated in place, or NULL at the end of the line or at a word
 * starting with '#' (a comment runs to the end of the line). */
static char *next_word(char **cur)
{
    char *s = *cur;
    while (*s == ' ' || *s == '\t')
        s++;
    if (*s == '\0' || *s == '#')
        return NULL;
    char *w = s;
    while (*s && *s != ' ' && *s != '\t')
        s++;
    if (*s)
        *s++ = '\0';
    *cur = s;
    return w;
}

/* ---- transforms --------------------------------------------------------------------------- */

/* p' = L p + t with L = R S: scale, then rotate, then translate.  Normals map by the inverse
 * transpose, (R S)^-T = R S^-1 since R is orthonormal (PBRT 4e, ch. 3, "Applying
 * Transformations").  Computed in double, rounded once to float. */
struct xform {
    double L[3][3]; /* linear part R S */
    double N[3][3]; /* normal matrix R S^-1 */
    double t[3];    /* translation */
    bool is_mirror; /* det L < 0: the winding is reversed to keep each face's front side */
};

/* sin and cos of an angle in degrees, exact at multiples of 90 so axis-aligned turns map
 * coordinates exactly. */
static void sincos_deg(double deg, double *s, double *c)
{
    double r = fmod(deg, 360.0);
    if (r < 0.0)
        r += 360.0;
    if (r == 0.0 || r == 90.0 || r == 180.0 || r == 270.0) {
        int q = (int)(r / 90.0);
        const double sin_q[4] = {0.0, 1.0, 0.0, -1.0};
        *s = sin_q[q];
        *c = sin_q[(q + 1) % 4];
        return;
    }
    double rad = r * (3.14159265358979323846 / 180.0);
    *s = sin(rad);
    *c = cos(rad);
}

/* Builds the transform from a statement's optional translate, rotate and scale. */
static void xform_from(struct xform *xf, const struct stmt *st, int i_translate, int i_rotate,
                       int i_scale)
{
    double R[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    if (i_rotate >= 0 && st->p[i_rotate].key) {
        /* Rodrigues: R = cos(a) I + sin(a) [k]x + (1 - cos(a)) k k^T, k the unit axis */
        const double *f = st->p[i_rotate].d;
        double len = sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]);
        double k[3] = {f[0] / len, f[1] / len, f[2] / len};
        double s, c;
        sincos_deg(f[3], &s, &c);
        double K[3][3] = {{0, -k[2], k[1]}, {k[2], 0, -k[0]}, {-k[1], k[0], 0}};
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                R[i][j] = (i == j ? c : 0.0) + s * K[i][j] + (1.0 - c) * k[i] * k[j];
    }
    double sc[3] = {1, 1, 1};
    if (i_scale >= 0 && st->p[i_scale].key)
        for (int j = 0; j < 3; j++)
            sc[j] = st->p[i_scale].d[j];
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++) {
            xf->L[i][j] = R[i][j] * sc[j];
            xf->N[i][j] = R[i][j] / sc[j];
        }
        xf->t[i] = i_translate >= 0 && st->p[i_translate].key ? st->p[i_translate].d[i] : 0.0;
    }
    xf->is_mirror = ((sc[0] < 0) ^ (sc[1] < 0) ^ (sc[2] < 0)) != 0; /* det L = sx sy sz */
}

/* r = M v + t (t may be NULL), in double. */
static void mat3_apply_dd(const double M[3][3], const double *t, const double v[3], double r[3])
{
    for (int i = 0; i < 3; i++)
        r[i] = M[i][0] * v[0] + M[i][1] * v[1] + M[i][2] * v[2] + (t ? t[i] : 0.0);
}
static void mat3_apply_d(const double M[3][3], const double *t, vec3 v, double r[3])
{
    const double vd[3] = {v.x, v.y, v.z};
    mat3_apply_dd(M, t, vd, r);
}

/* M v + t rounded once to float; a component beyond float range becomes +-infinity. */
static vec3 mat3_apply(const double M[3][3], const double *t, vec3 v)
{
    double r[3];
    mat3_apply_d(M, t, v, r);
    for (int i = 0; i < 3; i++)
        if (!(fabs(r[i]) <= FLT_MAX))
            r[i] = copysign(INFINITY, r[i]);
    return v3((float)r[0], (float)r[1], (float)r[2]);
}

static vec3 xform_point(const struct xform *xf, vec3 p) { return mat3_apply(xf->L, xf->t, p); }

/* xform_point before the rounding to float */
static void xform_point_d(const struct xform *xf, vec3 p, double r[3])
{
    mat3_apply_d(xf->L, xf->t, p, r);
}

/* Is every |component| of v, in double, at most SCENE_MAX_COORD? */
static bool in_scene_range_d(const double v[3])
{
    return fabs(v[0]) <= SCENE_MAX_COORD && fabs(v[1]) <= SCENE_MAX_COORD &&
           fabs(v[2]) <= SCENE_MAX_COORD;
}

/* Unit transformed normal; the zero vector when n is zero (or too small to normalise). */
static vec3 xform_normal(const struct xform *xf, vec3 n)
{
    double r[3];
    for (int i = 0; i < 3; i++)
        r[i] = xf->N[i][0] * n.x + xf->N[i][1] * n.y + xf->N[i][2] * n.z;
    double len = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
    if (!(len > 0.0) || !isfinite(len))
        return v3(0.0f, 0.0f, 0.0f);
    return v3((float)(r[0] / len), (float)(r[1] / len), (float)(r[2] / len));
}

/* ---- statements --------------------------------------------------------------------------- */

/* Index of key in the statement's table (the key must exist: a programming error otherwise). */
static int param_idx(const struct stmt *st, const char *key)
{
    for (int i = 0; i < MAX_PARAMS && st->spec->params[i].key; i++)
        if (strcmp(st->spec->params[i].key, key) == 0)
            return i;
    assert(!"unknown parameter key");
    return -1;
}

static const struct param *get(const struct stmt *st, const char *key)
{
    return &st->p[param_idx(st, key)];
}

static vec3 get_vec3(const struct stmt *st, const char *key, vec3 dflt)
{
    const struct param *p = get(st, key);
    return p->key ? v3(p->f[0], p->f[1], p->f[2]) : dflt;
}

/* A VAL_VEC3 parameter in double, as written; 0 where absent. */
static void get_vec3_d(const struct stmt *st, const char *key, double out[3])
{
    const struct param *p = get(st, key);
    for (int i = 0; i < 3; i++)
        out[i] = p->key ? p->d[i] : 0.0;
}

static float get_number(const struct stmt *st, const char *key, float dflt)
{
    const struct param *p = get(st, key);
    return p->key ? p->f[0] : dflt;
}

/* Are a and b parallel (or either zero)?  |a x b| <= PARALLEL_SIN |a| |b|, in double. */
static bool is_parallel(const double a[3], const double b[3])
{
    double cx = a[1] * b[2] - a[2] * b[1];
    double cy = a[2] * b[0] - a[0] * b[2];
    double cz = a[0] * b[1] - a[1] * b[0];
    double cross2 = cx * cx + cy * cy + cz * cz;
    double a2 = a[0] * a[0] + a[1] * a[1] + a[2] * a[2];
    double b2 = b[0] * b[0] + b[1] * b[1] + b[2] * b[2];
    return cross2 <= PARALLEL_SIN * PARALLEL_SIN * a2 * b2;
}

static bool is_emissive(const struct material *m) { return v3_max_comp(m->Le) > 0.0f; }

/* camera: the frame camera_init will build (camera_frame: the same function, so a loaded
 * scene's camera always builds), a lens inside the scene, and a plane of focus the lens can
 * tell apart from itself. */
static bool do_camera(struct parser *ps, const struct stmt *st)
{
    char buf[SHOW_OUT_BYTES];
    struct camera_params *c = &ps->scene->camera;
    c->eye = get_vec3(st, "eye", v3_splat(0));
    c->look_at = get_vec3(st, "look-at", v3_splat(0));
    c->up = get_vec3(st, "up", v3_splat(0));
    c->fov_deg = get_number(st, "fov", 0);
    c->aperture = get_number(st, "aperture", 0.0f);
    c->focus_dist = get_number(st, "focus-dist", 0.0f);
    const struct param *eye = get(st, "eye");
    const struct param *look_at = get(st, "look-at");
    const struct param *up = get(st, "up");
    const struct param *aperture = get(st, "aperture");
    const struct param *focus = get(st, "focus-dist");
    vec3 forward, right, up_unit;
    float view_len = 0.0f;
    switch (camera_frame(c, &forward, &right, &up_unit, &view_len)) {
    case CAMERA_OK:
        break;
    case CAMERA_SAME_POINT:
        return fail(ps, look_at->val_col,
                    "expected 'look-at' different from 'eye', got %s for "
                    "both%s",
                    show(look_at->text, buf),
                    strcmp(eye->text, look_at->text) != 0 ? " (the same point in single precision)"
                                                          : "");
    case CAMERA_UP_PARALLEL:
        return fail(ps, up->val_col, "expected 'up' not parallel to the view direction, got %s",
                    show(up->text, buf));
    default: /* eye and look-at lie within SCENE_MAX_COORD and up is nonzero: unreachable */
        return fail(ps, st->kw_col, "expected a camera frame, got none");
    }
    /* the lens and the plane of focus are places in the scene */
    if (aperture->key && !(c->aperture <= SCENE_MAX_COORD))
        return fail(ps, aperture->val_col,
                    "expected 'aperture' <= 1e18 (the lens lies in the "
                    "scene: " COORD_WHY "), got %s",
                    show(aperture->text, buf));
    if (focus->key && !(c->focus_dist <= SCENE_MAX_COORD))
        return fail(ps, focus->val_col,
                    "expected 'focus-dist' <= 1e18 (the plane of focus lies "
                    "in the scene: " COORD_WHY "), got %s",
                    show(focus->text, buf));
    if (c->aperture > 0.0f) {
        /* a lens ray aims at eye + focus_dist d from a lens point; both are rounded to a few
         * ulps of the eye's coordinates and the aperture (2^-23 relative), so focus_dist must
         * exceed those, with margin, or the aim point can round onto the lens point */
        double m = fmax(fmax(fabs((double)c->eye.x), fabs((double)c->eye.y)),
                        fmax(fabs((double)c->eye.z), (double)c->aperture));
        double fd_min = ldexp(m, -20);
        double fd = c->focus_dist > 0.0f ? c->focus_dist : view_len;
        if (fd < fd_min && c->focus_dist > 0.0f)
            return fail(ps, focus->val_col,
                        "expected 'focus-dist' >= %g (2^-20 of the largest "
                        "'eye' component or 'aperture': a plane of focus nearer the lens rounds "
                        "onto it in single precision), got %s",
                        fd_min, show(focus->text, buf));
        if (fd < fd_min)
            return fail(ps, look_at->val_col,
                        "expected 'look-at' at least %g from 'eye' (the "
                        "plane of focus when 'aperture' > 0 and no 'focus-dist' is given: 2^-20 "
                        "of the largest 'eye' component or 'aperture'), got %g",
                        fd_min, fd);
    }
    return true;
}

/* The MTL record om as an mcpt material (docs/scene-format.md, "MTL materials"). */
static struct material material_from_mtl(const struct obj_material *om, const char *obj_name)
{
    struct material m = {0};
    /* "<objfile>:<mtlname>", cut to fit: it only labels messages */
    const char *parts[3] = {obj_name, ":", om->name};
    size_t used = 0;
    for (int i = 0; i < 3; i++)
        for (const char *c = parts[i]; *c && used + 1 < sizeof m.name; c++)
            m.name[used++] = *c;
    vec3 zero = v3_splat(0.0f), one = v3_splat(1.0f);
    switch (om->illum) {
    case 5:
        m.kind = MAT_MIRROR;
        m.specular = v3_min(v3_max(om->Ks, zero), one);
        m.ior = 1.0f;
        break;
    case 4:
    case 6:
    case 7:
    case 9:
        m.kind = MAT_DIELECTRIC;
        m.specular = v3_min(v3_max(om->Tf, zero), one);
        m.ior = om->Ni > 0.0f && om->Ni != 1.0f ? om->Ni : 1.5f; /* 1 or less: crown glass */
        break;
    default:
        m.kind = MAT_DIFFUSE;
        m.albedo = v3_min(v3_max(om->Kd, zero), one);
        m.ior = 1.0f;
        break;
    }
    m.Le = v3_max(om->Ke, zero);
    return m;
}

/* Joins the scene folder and a path from the scene file; absolute paths stay as they are. */
static char *resolve_path(const char *dir, const char *file)
{
    if (file[0] == '/')
        dir = "";
    size_t n_dir = strlen(dir), n_file = strlen(file);
    char *p = malloc(n_dir + n_file + 1);
    if (p) {
        memcpy(p, dir, n_dir);
        memcpy(p + n_dir, file, n_file + 1);
    }
    return p;
}

/* Angle-weighted vertex normals (Thürmer & Wüthrich 1998, "Computing Vertex Normals from
 * Polygonal Facets", J. Graphics Tools 3(1)): n_v = sum over the faces at vertex v of alpha_f n_f,
 * alpha_f the face's angle at v and n_f its unit normal, so the result does not depend on how a
 * surface is cut into triangles.  In double, from the world-space positions of the n_tris faces
 * tris (wound as stored), whose vertices lie in [v_base, v_base + n_v); normals[i] gets vertex
 * v_base + i's unit normal, or 0 where the sum is 0 (no face with area).  False when out of
 * memory. */
static bool angle_weighted_normals(const vec3 *positions, const struct scene_tri *tris,
                                   uint32_t n_tris, uint32_t v_base, uint32_t n_v, vec3 *normals)
{
    double(*sum)[3] = calloc(n_v > 0 ? n_v : 1, sizeof *sum);
    if (!sum)
        return false;
    for (uint32_t i = 0; i < n_tris; i++) {
        double p[3][3];
        for (int k = 0; k < 3; k++) {
            vec3 q = positions[tris[i].v[k]];
            p[k][0] = q.x;
            p[k][1] = q.y;
            p[k][2] = q.z;
        }
        double e1[3], e2[3];
        for (int a = 0; a < 3; a++) {
            e1[a] = p[1][a] - p[0][a];
            e2[a] = p[2][a] - p[0][a];
        }
        double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                       e1[0] * e2[1] - e1[1] * e2[0]};
        double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        if (!(len > 0.0) || !isfinite(len))
            continue; /* no area: no normal, no angle */
        for (int k = 0; k < 3; k++) {
            /* the angle at corner k between the edges to the other two corners */
            const double *c = p[k], *a = p[(k + 1) % 3], *b = p[(k + 2) % 3];
            double u[3] = {a[0] - c[0], a[1] - c[1], a[2] - c[2]};
            double w[3] = {b[0] - c[0], b[1] - c[1], b[2] - c[2]};
            double uxw[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2],
                             u[0] * w[1] - u[1] * w[0]};
            double alpha = atan2(sqrt(uxw[0] * uxw[0] + uxw[1] * uxw[1] + uxw[2] * uxw[2]),
                                 u[0] * w[0] + u[1] * w[1] + u[2] * w[2]);
            uint32_t idx = tris[i].v[k] - v_base;
            for (int ax = 0; ax < 3; ax++)
                sum[idx][ax] += alpha * n[ax] / len;
        }
    }
    for (uint32_t i = 0; i < n_v; i++) {
        double len = sqrt(sum[i][0] * sum[i][0] + sum[i][1] * sum[i][1] + sum[i][2] * sum[i][2]);
        normals[i] = len > 0.0 ? (vec3){(float)(sum[i][0] / len), (float)(sum[i][1] / len),
                                        (float)(sum[i][2] / len)}
                               : v3_splat(0.0f);
    }
    free(sum);
    return true;
}

/* Adds *path (malloc'ed; the scene takes it, *path becomes NULL) to the files the scene
 * loaded, which no output of a render may overwrite (main.c). */
static bool add_loaded(struct parser *ps, char **path)
{
    struct scene *sc = ps->scene;
    char **grown = realloc(sc->loaded_paths, sizeof *grown * ((size_t)sc->n_loaded + 1));
    if (!grown) {
        mcpt_error_runtime(ps->err, ps->path, "out of memory");
        return false;
    }
    sc->loaded_paths = grown;
    sc->loaded_paths[sc->n_loaded++] = *path;
    *path = NULL;
    return true;
}

static bool do_mesh(struct parser *ps, const struct stmt *st)
{
    struct scene *sc = ps->scene;
    const struct param *file = get(st, "file");
    const struct param *mat = get(st, "material");
    bool is_smooth = get(st, "normals")->key && get(st, "normals")->b;
    struct obj_mesh mesh = {0};
    bool ok = false;
    char buf[SHOW_OUT_BYTES], buf2[SHOW_OUT_BYTES];

    char *full = resolve_path(ps->dir, file->text);
    if (!full) {
        fail_oom(ps, file->val_col);
        goto done;
    }
    /* a mesh that cannot be opened is an error of this line; what is inside is the OBJ's */
    const char *not_regular = NULL;
    int fd = file_open_input(full, false, &not_regular);
    if (fd < 0) {
        char where[SHOW_OUT_BYTES + 8] = "";
        if (strcmp(full, file->text) != 0)
            snprintf(where, sizeof where, " (%s)", show(full, buf));
        if (not_regular)
            fail(ps, file->val_col, "expected a regular file for mesh '%s'%s, got %s",
                 show(file->text, buf2), where, not_regular);
        else
            fail(ps, file->val_col, "cannot open mesh '%s'%s: %s", show(file->text, buf2), where,
                 strerror(errno));
        goto done;
    }
    if (!obj_load_fd(fd, full, &mesh, ps->err)) /* its message names the OBJ/MTL file and line */
        goto done;
    for (uint32_t i = 0; i < mesh.n_warnings; i++)
        add_warning(ps, i < OBJ_MAX_WARNINGS ? mesh.warnings[i] : NULL);
    if (mesh.n_tris == 0) {
        fail(ps, file->val_col, "expected at least one face in '%s', got none",
             show(file->text, buf));
        goto done;
    }
    /* normals=smooth appends one computed normal per vertex after the file's */
    uint32_t n_normals_new = mesh.n_normals + (is_smooth ? mesh.n_positions : 0);
    if ((uint64_t)sc->n_positions + mesh.n_positions > UINT32_MAX ||
        (uint64_t)sc->n_normals + mesh.n_normals + (is_smooth ? mesh.n_positions : 0) > INT32_MAX ||
        (uint64_t)sc->n_uvs + mesh.n_uvs > INT32_MAX) {
        fail(ps, file->val_col,
             "expected at most %u vertices and %d normals and uvs in the "
             "scene, got more with '%s'",
             UINT32_MAX, INT32_MAX, show(file->text, buf));
        goto done;
    }
    if (!RESERVE(ps, sc->positions, ps->cap_positions,
                 (uint64_t)sc->n_positions + mesh.n_positions) ||
        !RESERVE(ps, sc->tris, ps->cap_tris, (uint64_t)sc->n_tris + mesh.n_tris) ||
        (n_normals_new > 0 &&
         !RESERVE(ps, sc->normals, ps->cap_normals, (uint64_t)sc->n_normals + n_normals_new)) ||
        (mesh.n_uvs > 0 && !RESERVE(ps, sc->uvs, ps->cap_uvs, (uint64_t)sc->n_uvs + mesh.n_uvs)))
        goto done;

    /* materials: the one named on the line, or the MTL records plus "default" if needed */
    uint32_t mtl_base = sc->n_materials;
    if (!mat->key) {
        const char *slash = strrchr(file->text, '/');
        const char *obj_name = slash ? slash + 1 : file->text;
        for (uint32_t i = 0; i < mesh.n_materials; i++) {
            struct material m = material_from_mtl(&mesh.materials[i], obj_name);
            if (!add_material(ps, &m, 0))
                goto done;
        }
        bool needs_default = false;
        for (uint32_t i = 0; i < mesh.n_tris; i++)
            needs_default |= mesh.tris[i].mat_idx < 0;
        if (needs_default && ps->default_mat_idx < 0) {
            struct material m = {.name = "default",
                                 .kind = MAT_DIFFUSE,
                                 .albedo = v3_splat(0.8f),
                                 .ior = 1.0f};
            ps->default_mat_idx = sc->n_materials;
            if (!add_material(ps, &m, 0))
                goto done;
        }
    }

    /* vertices, normals and uvs, transformed into world space */
    struct xform xf;
    xform_from(&xf, st, param_idx(st, "translate"), param_idx(st, "rotate"),
               param_idx(st, "scale"));
    bool is_moved = get(st, "translate")->key || get(st, "rotate")->key || get(st, "scale")->key;
    for (uint32_t i = 0; i < mesh.n_positions; i++) {
        double p[3];
        xform_point_d(&xf, mesh.positions[i], p);
        if (!in_scene_range_d(p)) {
            fail(ps, st->kw_col,
                 "expected vertices of '%s' inside [-1e18, 1e18]%s (" COORD_WHY
                 "), got %g,%g,%g (vertex %u)",
                 show(file->text, buf), is_moved ? " after the transform" : "", p[0], p[1], p[2],
                 i + 1);
            goto done;
        }
        sc->positions[sc->n_positions + i] = xform_point(&xf, mesh.positions[i]);
    }
    for (uint32_t i = 0; i < mesh.n_normals; i++)
        sc->normals[sc->n_normals + i] = xform_normal(&xf, mesh.normals[i]);
    if (mesh.n_uvs > 0)
        memcpy(sc->uvs + sc->n_uvs, mesh.uvs, (size_t)mesh.n_uvs * sizeof *mesh.uvs);

    /* triangles; a mirroring transform swaps two corners to keep each face's front side */
    const int order[3] = {0, xf.is_mirror ? 2 : 1, xf.is_mirror ? 1 : 2};
    for (uint32_t i = 0; i < mesh.n_tris; i++) {
        const struct obj_tri *t = &mesh.tris[i];
        struct scene_tri *out = &sc->tris[sc->n_tris + i];
        bool has_vn = true, has_vt = true;
        for (int k = 0; k < 3; k++) {
            assert(t->v[k] < mesh.n_positions);
            has_vn &= t->vn[k] >= 0 && !v3_is_zero(sc->normals[sc->n_normals + (uint32_t)t->vn[k]]);
            has_vt &= t->vt[k] >= 0;
        }
        for (int k = 0; k < 3; k++) {
            int j = order[k];
            out->v[k] = sc->n_positions + t->v[j];
            out->vn[k] = has_vn ? (int32_t)sc->n_normals + t->vn[j] : -1;
            out->vt[k] = has_vt ? (int32_t)sc->n_uvs + t->vt[j] : -1;
        }
        assert(t->mat_idx < (int32_t)mesh.n_materials);
        out->mat_idx = mat->key          ? mat->u
                       : t->mat_idx >= 0 ? mtl_base + (uint32_t)t->mat_idx
                                         : (uint32_t)ps->default_mat_idx;
    }
    /* normals=smooth: faces without normals from the file take the vertices' angle-weighted
     * normals, stored after the file's (a face with a vertex that has none stays flat) */
    if (is_smooth) {
        uint32_t base = sc->n_normals + mesh.n_normals;
        if (!angle_weighted_normals(sc->positions, sc->tris + sc->n_tris, mesh.n_tris,
                                    sc->n_positions, mesh.n_positions, sc->normals + base)) {
            fail_oom(ps, st->kw_col);
            goto done;
        }
        for (uint32_t i = 0; i < mesh.n_tris; i++) {
            struct scene_tri *out = &sc->tris[sc->n_tris + i];
            bool has_all = out->vn[0] < 0;
            for (int k = 0; k < 3; k++)
                has_all &= !v3_is_zero(sc->normals[base + out->v[k] - sc->n_positions]);
            for (int k = 0; has_all && k < 3; k++)
                out->vn[k] = (int32_t)(base + out->v[k] - sc->n_positions);
        }
    }
    sc->n_positions += mesh.n_positions;
    sc->n_normals += n_normals_new;
    sc->n_uvs += mesh.n_uvs;
    sc->n_tris += mesh.n_tris;
    ok = add_loaded(ps, &full);
    for (uint32_t i = 0; ok && i < mesh.n_mtl_paths; i++)
        ok = add_loaded(ps, &mesh.mtl_paths[i]);
done:
    obj_free(&mesh);
    free(full);
    return ok;
}

/* sphere: inside [-SCENE_MAX_COORD, SCENE_MAX_COORD] after its transform, radius > 0 in float */
static bool do_sphere(struct parser *ps, const struct stmt *st)
{
    char buf[SHOW_OUT_BYTES];
    const struct param *scale = get(st, "scale");
    if (scale->key && (scale->f[1] != scale->f[0] || scale->f[2] != scale->f[0]))
        return fail(ps, scale->val_col, "expected a uniform 'scale' for 'sphere', got %s",
                    show(scale->text, buf));
    struct xform xf;
    xform_from(&xf, st, param_idx(st, "translate"), -1, param_idx(st, "scale"));
    vec3 center = get_vec3(st, "center", v3_splat(0));
    float radius = get_number(st, "radius", 0);
    float s_abs = fabsf(scale->key ? scale->f[0] : 1.0f);
    struct sphere s = {
        .center = xform_point(&xf, center),
        .radius = radius * s_abs,
        .mat_idx = get(st, "material")->u,
    };
    double c[3], r = (double)radius * s_abs;
    xform_point_d(&xf, center, c);
    double extent[3] = {fabs(c[0]) + r, fabs(c[1]) + r, fabs(c[2]) + r};
    if (!in_scene_range_d(extent))
        return fail(ps, st->kw_col,
                    "expected the sphere inside [-1e18, 1e18]%s (" COORD_WHY
                    "), got center %g,%g,%g and radius %g",
                    scale->key || get(st, "translate")->key ? " after its transform" : "", c[0],
                    c[1], c[2], r);
    if (!(s.radius > 0.0f))
        return fail(ps, scale->val_col, "expected 'radius' times 'scale' > 0, got %g" UNDERFLOW_WHY,
                    r);
    /* a surface point is rounded to float at the centre's magnitude, and a ray spawned from it
     * is pushed off by its error and the surface's curvature (shape.c, sphere_point); below
     * 2^-20 of the largest coordinate (16 float steps across) that push can cross the sphere.
     * Seen from outside it renders (a tiny lamp, a distant ball); a path inside it may escape */
    double r_min = ldexp(fmax(fmax(fabs((double)s.center.x), fabs((double)s.center.y)),
                              fabs((double)s.center.z)),
                         -20);
    if ((double)s.radius < r_min) {
        char line[SCENE_WARNING_BYTES];
        snprintf(line, sizeof line,
                 "%s:%d:%d: warning: sphere of radius %g at center %g,%g,%g is under 16 "
                 "single-precision steps across (radius < 2^-20 of the centre's largest "
                 "coordinate, %g): it renders from outside, but a path inside it may escape",
                 ps->path, ps->line, get(st, "radius")->val_col, (double)s.radius,
                 (double)s.center.x, (double)s.center.y, (double)s.center.z, r_min);
        add_warning(ps, line);
    }
    struct scene *sc = ps->scene;
    if (!RESERVE(ps, sc->spheres, ps->cap_spheres, (uint64_t)sc->n_spheres + 1))
        return false;
    sc->spheres[sc->n_spheres++] = s;
    return true;
}

/* quad: edges not parallel, before and after the transform, and all four corners inside
 * [-SCENE_MAX_COORD, SCENE_MAX_COORD].  Kept in double as written (struct quad): the corners
 * of quads that close a box agree to double precision, not only to float's. */
static bool do_quad(struct parser *ps, const struct stmt *st)
{
    char buf[SHOW_OUT_BYTES];
    double corner[3], e1[3], e2[3];
    get_vec3_d(st, "corner", corner);
    get_vec3_d(st, "edge1", e1);
    get_vec3_d(st, "edge2", e2);
    const struct param *edge2 = get(st, "edge2");
    if (is_parallel(e1, e2))
        return fail(ps, edge2->val_col, "expected 'edge2' not parallel to 'edge1', got %s",
                    show(edge2->text, buf));
    struct xform xf;
    xform_from(&xf, st, param_idx(st, "translate"), param_idx(st, "rotate"),
               param_idx(st, "scale"));
    /* a mirroring transform swaps the edges so e1 x e2 stays the transformed front normal */
    const struct xform *x = &xf;
    double c[3], a[3], b[3];
    mat3_apply_dd(x->L, x->t, corner, c);
    mat3_apply_dd(x->L, NULL, x->is_mirror ? e2 : e1, a);
    mat3_apply_dd(x->L, NULL, x->is_mirror ? e1 : e2, b);
    double extent[3];
    for (int i = 0; i < 3; i++)
        extent[i] = fabs(c[i]) + fabs(a[i]) + fabs(b[i]);
    bool is_moved = get(st, "translate")->key || get(st, "rotate")->key || get(st, "scale")->key;
    if (!in_scene_range_d(extent))
        return fail(ps, st->kw_col,
                    "expected the quad's corners inside [-1e18, 1e18]%s (" COORD_WHY
                    "), got corner %g,%g,%g and edges %g,%g,%g and %g,%g,%g",
                    is_moved ? " after its transform" : "", c[0], c[1], c[2], a[0], a[1], a[2],
                    b[0], b[1], b[2]);
    /* its area and light sampling are in float: the edges must not be parallel there either.
     * Rounded through vec3: written as a loop of (float) casts into double arrays, gcc 12.2 -O2
     * dropped the casts (its SLP vectoriser; -fno-tree-slp-vectorize restores them) */
    vec3 af = d3_to_float((struct dvec3){a[0], a[1], a[2]});
    vec3 bf = d3_to_float((struct dvec3){b[0], b[1], b[2]});
    double a_f[3] = {af.x, af.y, af.z}, b_f[3] = {bf.x, bf.y, bf.z};
    if (is_parallel(a_f, b_f)) /* only a 'scale' can make them so */
        return fail(ps, get(st, "scale")->val_col,
                    "expected the quad's edges not parallel after 'scale', got %g,%g,%g and "
                    "%g,%g,%g (rounded to single precision)",
                    a_f[0], a_f[1], a_f[2], b_f[0], b_f[1], b_f[2]);
    struct quad q = {
        .corner = {c[0], c[1], c[2]},
        .e1 = {a[0], a[1], a[2]},
        .e2 = {b[0], b[1], b[2]},
        .mat_idx = get(st, "material")->u,
    };
    struct scene *sc = ps->scene;
    if (!RESERVE(ps, sc->quads, ps->cap_quads, (uint64_t)sc->n_quads + 1))
        return false;
    sc->quads[sc->n_quads++] = q;
    return true;
}

static bool do_plane(struct parser *ps, const struct stmt *st)
{
    struct scene *sc = ps->scene;
    const struct param *mat = get(st, "material");
    if (is_emissive(&sc->materials[mat->u]))
        return fail(ps, mat->val_col,
                    "expected a non-emissive material for 'plane' (an "
                    "infinite emitter), got '%s'",
                    mat->text);
    /* normalise in double: a tiny or huge float normal has no float-safe length */
    vec3 n = get_vec3(st, "normal", v3_splat(0));
    double len = sqrt((double)n.x * n.x + (double)n.y * n.y + (double)n.z * n.z);
    struct plane pl = {
        .point = get_vec3(st, "point", v3_splat(0)),
        .n = v3((float)(n.x / len), (float)(n.y / len), (float)(n.z / len)),
        .mat_idx = mat->u,
    };
    if (!RESERVE(ps, sc->planes, ps->cap_planes, (uint64_t)sc->n_planes + 1))
        return false;
    sc->planes[sc->n_planes++] = pl;
    return true;
}

/* material: the kinds of material.h; 'plastic' takes the metallic/roughness parametrisation
 * of real-time PBR (Burley 2012; Karis 2013; Filament's reflectance: F0 = 0.16 reflectance^2),
 * 'unity' the Unity tracer's parameters, mapped as docs/scene-format.md, "Unity-style
 * materials", describes. */
static bool do_material(struct parser *ps, const struct stmt *st)
{
    struct material m = {0};
    snprintf(m.name, sizeof m.name, "%s", get(st, "name")->text); /* length checked */
    m.Le = get_vec3(st, "emission", v3_splat(0.0f));
    m.two_sided_emission = get(st, "two-sided")->key && get(st, "two-sided")->b;
    m.ior = 1.0f;
    vec3 albedo = get_vec3(st, "albedo", v3_splat(0.0f));
    bool is_glass = false;
    switch (st->type_idx) {
    case 0:
        m.kind = MAT_DIFFUSE;
        m.albedo = albedo;
        break;
    case 1:
        m.kind = MAT_MIRROR;
        m.specular = get_vec3(st, "specular", v3_splat(1.0f));
        break;
    case 2:
        m.kind = MAT_DIELECTRIC;
        m.specular = get_vec3(st, "specular", v3_splat(1.0f));
        m.ior = get_number(st, "ior", 1.5f);
        break;
    case 3:
        m.kind = MAT_DIFFUSE_UNIFORM;
        m.albedo = albedo;
        break;
    case 4:
        m.kind = MAT_CONDUCTOR;
        m.specular = get_vec3(st, "specular", v3_splat(1.0f));
        m.roughness = get_number(st, "roughness", 0.5f);
        break;
    case 5: {
        /* diffuse = (1 - metallic) base, F0 = lerp(0.16 reflectance^2, base, metallic) */
        float metallic = get_number(st, "metallic", 0.0f);
        float reflectance = get_number(st, "reflectance", 0.5f);
        vec3 F0_dielectric = v3_splat(0.16f * reflectance * reflectance);
        m.kind = MAT_PLASTIC;
        m.albedo = v3_scale(albedo, 1.0f - metallic);
        m.specular = v3_add(v3_scale(F0_dielectric, 1.0f - metallic), v3_scale(albedo, metallic));
        m.roughness = get_number(st, "roughness", 0.5f);
        break;
    }
    default: {
        /* unity: glass, else a diffuse base under a coat of F0 = specular-prob * specular and
         * roughness 1 - smoothness (a plain diffuse when specular-prob is 0) */
        is_glass = get(st, "glass")->key && get(st, "glass")->b;
        float prob = get_number(st, "specular-prob", 0.0f);
        if (is_glass) {
            m.kind = MAT_DIELECTRIC;
            m.specular = albedo;
            m.ior = get_number(st, "ior", 1.5f);
        } else if (prob == 0.0f) {
            m.kind = MAT_DIFFUSE;
            m.albedo = albedo;
        } else {
            m.kind = MAT_PLASTIC;
            m.albedo = albedo;
            m.specular = v3_scale(get_vec3(st, "specular", v3_splat(1.0f)), prob);
            m.roughness = 1.0f - get_number(st, "smoothness", 0.0f);
        }
        break;
    }
    }
    /* the checker texture alternates the diffuse albedo with a second colour (true: half the
     * first) */
    const struct param *ck = get(st, "checker");
    const struct param *ck_scale = get(st, "checker-scale");
    const struct param *ck_uv = get(st, "checker-uv");
    if (ck->key && ck->b) {
        if (is_glass)
            return fail(ps, ck->key_col,
                        "expected no 'checker' with 'glass=true' (glass has no "
                        "albedo), got 'checker=%s'",
                        ck->text);
        vec3 second = ck->n_f == 3 ? v3(ck->f[0], ck->f[1], ck->f[2]) : v3_scale(albedo, 0.5f);
        /* a plastic's texture is its base colour, of which the diffuse keeps 1 - metallic */
        float diffuse_share = st->type_idx == 5 ? 1.0f - get_number(st, "metallic", 0.0f) : 1.0f;
        m.checker_albedo = v3_scale(second, diffuse_share);
        m.checker_scale = get_number(st, "checker-scale", 1.0f);
        m.checker_uv = ck_uv->key && ck_uv->b;
    } else if (!ck->key && (ck_scale->key || ck_uv->key)) {
        const struct param *p = ck_scale->key ? ck_scale : ck_uv;
        return fail(ps, p->key_col, "expected 'checker' for '%s' to apply to, got none", p->key);
    }
    return add_material(ps, &m, ps->line);
}

static const char *const DIRECT_NAMES[RENDER_DIRECT_COUNT] = {"mis", "light", "bsdf", "cosine",
                                                              "hemisphere"};
static const char *const SPLIT_NAMES[RENDER_SPLIT_COUNT] = {"full", "direct", "indirect"};
static const char *const ADAPTIVE_RULE_NAMES[RENDER_ADAPTIVE_RULE_COUNT] = {"pilot", "stop",
                                                                            "budget"};
static const char *const LIGHT_SAMPLING_NAMES[RENDER_LIGHT_SAMPLING_COUNT] = {"area",
                                                                              "solid-angle"};

/* names[k] of an enum of n values, or "?" outside it. */
static const char *enum_name(const char *const *names, int n, int k)
{
    return k >= 0 && k < n ? names[k] : "?";
}

/* The k with names[k] equal to name, or -1. */
static int enum_parse(const char *const *names, int n, const char *name)
{
    for (int k = 0; k < n; k++)
        if (strcmp(name, names[k]) == 0)
            return k;
    return -1;
}

const char *scene_direct_name(enum render_direct direct)
{
    return enum_name(DIRECT_NAMES, RENDER_DIRECT_COUNT, (int)direct);
}

bool scene_direct_parse(const char *name, enum render_direct *direct)
{
    int k = enum_parse(DIRECT_NAMES, RENDER_DIRECT_COUNT, name);
    if (k >= 0)
        *direct = (enum render_direct)k;
    return k >= 0;
}

const char *scene_split_name(enum render_split split)
{
    return enum_name(SPLIT_NAMES, RENDER_SPLIT_COUNT, (int)split);
}

bool scene_split_parse(const char *name, enum render_split *split)
{
    int k = enum_parse(SPLIT_NAMES, RENDER_SPLIT_COUNT, name);
    if (k >= 0)
        *split = (enum render_split)k;
    return k >= 0;
}

const char *scene_adaptive_rule_name(enum render_adaptive_rule rule)
{
    return enum_name(ADAPTIVE_RULE_NAMES, RENDER_ADAPTIVE_RULE_COUNT, (int)rule);
}

bool scene_adaptive_rule_parse(const char *name, enum render_adaptive_rule *rule)
{
    int k = enum_parse(ADAPTIVE_RULE_NAMES, RENDER_ADAPTIVE_RULE_COUNT, name);
    if (k >= 0)
        *rule = (enum render_adaptive_rule)k;
    return k >= 0;
}

const char *scene_light_sampling_name(enum render_light_sampling mode)
{
    return enum_name(LIGHT_SAMPLING_NAMES, RENDER_LIGHT_SAMPLING_COUNT, (int)mode);
}

bool scene_light_sampling_parse(const char *name, enum render_light_sampling *mode)
{
    int k = enum_parse(LIGHT_SAMPLING_NAMES, RENDER_LIGHT_SAMPLING_COUNT, name);
    if (k >= 0)
        *mode = (enum render_light_sampling)k;
    return k >= 0;
}

/* render: spp, depth, sampler, the adaptive-sampling settings (docs/sampling.md) and the light
 * transport settings (direct, light-samples, split, rr, rr-depth). */
static bool do_render(struct parser *ps, const struct stmt *st)
{
    struct render_settings *r = &ps->scene->render;
    const struct param *p;
    if ((p = get(st, "spp"))->key)
        r->spp = p->u;
    if ((p = get(st, "max-depth"))->key)
        r->max_depth = p->u;
    if ((p = get(st, "sampler"))->key)
        r->sampler = (enum sampler_kind)p->u;
    if ((p = get(st, "adaptive"))->key)
        r->adaptive = p->b;
    if ((p = get(st, "adaptive-rule"))->key) {
        r->has_adaptive_rule = true;
        r->adaptive_rule = (enum render_adaptive_rule)p->u;
        r->adaptive_rule_line = ps->line;
        r->adaptive_rule_col = p->val_col;
    }
    if ((p = get(st, "pilot-spp"))->key)
        r->pilot_spp = p->u; /* >= 2 (RANGE_SPREAD) */
    /* the command line's bounds (--tolerance, --adaptive-floor), so the two accept the same */
    if ((p = get(st, "tolerance"))->key) {
        if (p->f[0] > SCENE_MAX_TOLERANCE)
            return fail(ps, p->val_col, "expected 'tolerance' in (0, 1e6], got %s", p->text);
        r->tolerance = p->f[0];
    }
    if ((p = get(st, "adaptive-floor"))->key) {
        if (p->f[0] > SCENE_MAX_ADAPTIVE_FLOOR)
            return fail(ps, p->val_col, "expected 'adaptive-floor' in [0, 1e30], got %s",
                        p->text);
        r->adaptive_floor = p->f[0];
    }
    if ((p = get(st, "batch"))->key)
        r->batch = p->u;
    if ((p = get(st, "max-spp"))->key)
        r->max_spp = p->u;
    if ((p = get(st, "direct"))->key)
        r->direct = (enum render_direct)p->u;
    if ((p = get(st, "light-samples"))->key)
        r->light_samples = p->u;
    if ((p = get(st, "split"))->key)
        r->split = (enum render_split)p->u;
    if ((p = get(st, "light-sampling"))->key)
        r->light_sampling = (enum render_light_sampling)p->u;
    if ((p = get(st, "rr"))->key)
        r->rr_prob = p->f[0];
    if ((p = get(st, "rr-depth"))->key)
        r->rr_depth = p->u;
    if ((p = get(st, "rr-threshold"))->key)
        r->rr_threshold = p->f[0];
    if ((p = get(st, "min-spp"))->key) {
        /* >= 2 (RANGE_SPREAD): with one sample sigma = 0 would stop every lit pixel at once */
        if (r->max_spp && p->u > r->max_spp)
            return fail(ps, p->val_col, "expected 'min-spp' <= 'max-spp' (%u), got %s", r->max_spp,
                        p->text);
        r->min_spp = p->u;
        r->min_spp_line = ps->line;
        r->min_spp_col = p->val_col;
    }
    return true;
}

static bool do_statement(struct parser *ps, const struct stmt *st)
{
    struct scene *sc = ps->scene;
    switch (st->kind) {
    case STMT_CAMERA:
        return do_camera(ps, st);
    case STMT_FILM:
        sc->width = (int)get(st, "width")->u;
        sc->height = (int)get(st, "height")->u;
        return true;
    case STMT_RENDER:
        return do_render(ps, st);
    case STMT_MATERIAL:
        return do_material(ps, st);
    case STMT_MESH:
        return do_mesh(ps, st);
    case STMT_SPHERE:
        return do_sphere(ps, st);
    case STMT_QUAD:
        return do_quad(ps, st);
    case STMT_PLANE:
        return do_plane(ps, st);
    case STMT_LIGHT: {
        struct light l = {.kind = LIGHT_POINT,
                          .prim_idx = ps->n_points,
                          .position = get_vec3(st, "position", v3_splat(0)),
                          .intensity = get_vec3(st, "intensity", v3_splat(0))};
        if (!RESERVE(ps, ps->points, ps->cap_points, (uint64_t)ps->n_points + 1))
            return false;
        ps->points[ps->n_points++] = l;
        return true;
    }
    case STMT_SKY:
        sc->sky.kind = st->type_idx == 0 ? SKY_CONSTANT : SKY_GRADIENT;
        sc->sky.radiance = get_vec3(st, "radiance", v3_splat(0));
        sc->sky.horizon = get_vec3(st, "horizon", v3_splat(0));
        sc->sky.zenith = get_vec3(st, "zenith", v3_splat(0));
        return true;
    case STMT_COUNT:
        break;
    }
    return true;
}

/* Reads one line's statement, checked in this order: the keyword; each word's key=value form,
 * key and uniqueness; the type; each value, left to right; missing parameters; then what
 * relates parameters to each other (in do_statement). */
static bool parse_line(struct parser *ps, char *line)
{
    char list[200], buf[SHOW_OUT_BYTES];
    char *cur = line;
    char *kw = next_word(&cur);
    if (!kw)
        return true;
    struct stmt st = {.kw_col = (int)(kw - line) + 1};
    int kind = 0;
    while (kind < STMT_COUNT && strcmp(stmt_specs[kind].keyword, kw) != 0)
        kind++;
    if (kind == STMT_COUNT) {
        list_words(list, sizeof list, NULL, 0);
        return fail(ps, st.kw_col, "expected a statement (%s), got '%s'", list, show(kw, buf));
    }
    st.kind = (enum stmt_kind)kind;
    st.spec = &stmt_specs[kind];
    if (st.spec->is_once && ps->seen_line[kind])
        return fail(ps, st.kw_col,
                    "expected at most one '%s' statement, got a second (the "
                    "first is on line %d)",
                    kw, ps->seen_line[kind]);
    ps->seen_line[kind] = ps->line;

    /* every word: key=value, a key of this statement, given once */
    int order[MAX_PARAMS], n_given = 0;
    for (char *w; (w = next_word(&cur));) {
        int col = (int)(w - line) + 1;
        char *eq = strchr(w, '=');
        if (!eq)
            return fail(ps, col, "expected 'key=value', got '%s'", show(w, buf));
        *eq = '\0';
        int i = 0;
        while (i < MAX_PARAMS && st.spec->params[i].key && strcmp(st.spec->params[i].key, w) != 0)
            i++;
        if (i == MAX_PARAMS || !st.spec->params[i].key) {
            list_words(list, sizeof list, st.spec, ALL_TYPES);
            return fail(ps, col, "expected a parameter of '%s' (%s), got '%s'", kw, list,
                        show(w, buf));
        }
        if (st.p[i].key)
            return fail(ps, col, "expected '%s' at most once, got it twice", w);
        st.p[i] = (struct param){.key = w,
                                 .text = eq + 1,
                                 .key_col = col,
                                 .val_col = col + (int)(eq - w) + 1};
        order[n_given++] = i;
    }

    /* the type, which decides the other parameters */
    char stmt_name[48];
    snprintf(stmt_name, sizeof stmt_name, "%s", kw);
    unsigned type_bit = 1;
    if (st.spec->types[0]) {
        const struct param *t = get(&st, "type");
        if (!t->key)
            return fail(ps, st.kw_col, "expected parameter 'type' for '%s', got none", kw);
        uint32_t ti = 0;
        while (st.spec->types[ti] && strcmp(st.spec->types[ti], t->text) != 0)
            ti++;
        if (!st.spec->types[ti]) {
            int used = 0;
            list[0] = '\0';
            for (int i = 0; st.spec->types[i]; i++)
                used += snprintf(list + used, sizeof list - (size_t)used, "%s%s", i ? ", " : "",
                                 st.spec->types[i]);
            return fail(ps, t->val_col, "expected a %s type (%s), got '%s'", kw, list,
                        show(t->text, buf));
        }
        st.type_idx = ti;
        type_bit = 1u << ti;
        snprintf(stmt_name, sizeof stmt_name, "%s type=%s", kw, st.spec->types[ti]);
    }

    /* each value, left to right */
    for (int g = 0; g < n_given; g++) {
        const struct param_spec *sp = &st.spec->params[order[g]];
        struct param *p = &st.p[order[g]];
        if (!(sp->allowed_mask & type_bit)) {
            list_words(list, sizeof list, st.spec, type_bit);
            return fail(ps, p->key_col, "expected a parameter of '%s' (%s), got '%s'", stmt_name,
                        list, p->key);
        }
        if (p->text[0] == '\0')
            return fail(ps, p->val_col, "expected a value after '%s=', got nothing", p->key);
        if (!parse_value(ps, sp, p))
            return false;
    }

    /* missing parameters */
    for (int i = 0; i < MAX_PARAMS && st.spec->params[i].key; i++)
        if ((st.spec->params[i].required_mask & type_bit) && !st.p[i].key)
            return fail(ps, st.kw_col, "expected parameter '%s' for '%s', got none",
                        st.spec->params[i].key, stmt_name);
    return do_statement(ps, &st);
}

/* ---- grooves: the margins of edges at acute concave angles ---------------------------------- */

/* A point near an edge is pulled inside its triangle by a margin (shape.c, edge_margin_groove)
 * that keeps the spawned origin in front of a neighbour meeting the edge at 80 to 100 degrees;
 * at a sharper groove the origin's push along the normal heads into the neighbour, and a closed
 * wedge of 30 degrees let sky in (docs/theory.md, "Self-intersection").  The margin's normal
 * term needs a factor g > 5 cot(phi) there; an edge shared by two triangles (the same two
 * corners) knows its angle, so the load gives each such edge g = 6 cot(phi), at most
 * GROOVE_MAX_FACTOR.  Faces folded onto each other (phi below GROOVE_MIN_ANGLE) close no
 * groove. */
#define GROOVE_MAX_FACTOR 1e4
#define GROOVE_MIN_ANGLE 1e-7 /* radians */

/* The factor for a groove of angle phi (radians); 1 from a right angle on, where there is no
 * groove to cover (a gap beyond pi between two faces is the outside of an edge). */
static double groove_factor(double phi)
{
    if (!(phi > GROOVE_MIN_ANGLE && phi < 0.5 * M_PI))
        return 1.0;
    double g = 6.0 / tan(phi);
    return g > GROOVE_MAX_FACTOR ? GROOVE_MAX_FACTOR : g > 1.0 ? g : 1.0;
}

/* The part of q perpendicular to the line of direction d (both from a point on the line). */
static struct dvec3 groove_arm(struct dvec3 q, struct dvec3 d)
{
    return d3_sub(q, d3_scale(d, d3_dot(q, d) / d3_dot(d, d)));
}

/* The angle between two arms, in [0, pi]. */
static double arm_angle(struct dvec3 u, struct dvec3 w)
{
    return atan2(d3_length(d3_cross(u, w)), d3_dot(u, w));
}

static bool set_groove(struct scene *sc, uint32_t e, double g)
{
    if (!(g > 1.0))
        return true;
    if (!sc->tri_groove) {
        sc->tri_groove = malloc((size_t)sc->n_tris * sizeof *sc->tri_groove);
        if (!sc->tri_groove)
            return false;
        for (uint32_t i = 0; i < sc->n_tris; i++)
            sc->tri_groove[i][0] = sc->tri_groove[i][1] = sc->tri_groove[i][2] = 1.0f;
    }
    float *slot = &sc->tri_groove[e / 3][e % 3];
    float gf = (float)g * (1.0f + 0x1p-20f); /* not below g after the rounding */
    if (gf > *slot)
        *slot = gf;
    return true;
}

struct groove_arm {
    double angle; /* about the edge, from the first arm */
    uint32_t e;   /* triangle * 3 + the corner opposite the edge */
};

static int groove_arm_cmp(const void *x, const void *y)
{
    double a = ((const struct groove_arm *)x)->angle, b = ((const struct groove_arm *)y)->angle;
    return (a > b) - (a < b);
}

/* An edge's other vertex and the triangle edge it is (triangle * 3 + the opposite corner). */
struct groove_ent {
    uint32_t hi;
    uint32_t e;
};

static int groove_ent_cmp(const void *x, const void *y)
{
    uint32_t a = ((const struct groove_ent *)x)->hi, b = ((const struct groove_ent *)y)->hi;
    return (a > b) - (a < b);
}

/* The faces around one edge (lo, ent[0].hi), ent[0 .. n_ent): each pair of faces that are
 * neighbours in angle about the edge closes a groove of the angle between them. */
static bool edge_grooves(struct scene *sc, uint32_t lo, const struct groove_ent *ent, size_t n_ent,
                         struct groove_arm **arms, size_t *cap)
{
    const vec3 *pos = sc->positions;
    struct dvec3 a = d3(pos[lo]), d = d3_sub(d3(pos[ent[0].hi]), a);
    if (n_ent == 2) { /* the usual edge: one angle, no frame, no sort */
        struct dvec3 w1 = groove_arm(d3_sub(d3(pos[sc->tris[ent[0].e / 3].v[ent[0].e % 3]]), a), d);
        struct dvec3 w2 = groove_arm(d3_sub(d3(pos[sc->tris[ent[1].e / 3].v[ent[1].e % 3]]), a), d);
        double g = groove_factor(arm_angle(w1, w2));
        return set_groove(sc, ent[0].e, g) && set_groove(sc, ent[1].e, g);
    }
    size_t n = 0;
    struct dvec3 u = {0.0, 0.0, 0.0}, v = {0.0, 0.0, 0.0};
    for (size_t j = 0; j < n_ent; j++) {
        uint32_t e = ent[j].e;
        struct dvec3 w = groove_arm(d3_sub(d3(pos[sc->tris[e / 3].v[e % 3]]), a), d);
        double len = d3_length(w);
        if (!(len > 0.0) || !isfinite(len))
            continue; /* a face without area along this edge */
        if (n == 0) { /* the frame about the edge: u along the first arm, v = (d / |d|) x u */
            u = d3_scale(w, 1.0 / len);
            v = d3_cross(d3_scale(d, 1.0 / d3_length(d)), u);
        }
        if (n == *cap) {
            size_t c = *cap ? 2 * *cap : 8;
            struct groove_arm *grown = realloc(*arms, c * sizeof *grown);
            if (!grown)
                return false;
            *arms = grown;
            *cap = c;
        }
        (*arms)[n++] = (struct groove_arm){atan2(d3_dot(w, v), d3_dot(w, u)), e};
    }
    if (n < 2)
        return true;
    qsort(*arms, n, sizeof **arms, groove_arm_cmp);
    for (size_t k = 0; k < n; k++) {
        /* the gap to the next arm counter-clockwise (the last one's wraps round) */
        const struct groove_arm *p = &(*arms)[k], *q = &(*arms)[(k + 1) % n];
        double gap = k + 1 < n ? q->angle - p->angle : q->angle + 2.0 * M_PI - p->angle;
        double g = groove_factor(gap);
        if (!set_groove(sc, p->e, g) || !set_groove(sc, q->e, g))
            return false;
    }
    return true;
}

/* Quads are separate statements, so no index says which meet: the pairs whose boxes meet are
 * found by sweep and prune (the boxes sorted by their low end along the axis their centres
 * spread most on, each compared with those that start before it ends), and each is tested both
 * ways.  The sweep compares at most GROOVE_MAX_COMPARES pairs of boxes and tests at most
 * GROOVE_MAX_MEETS pairs that meet (four edges each way): a scene of quads that nearly all
 * overlap stops there, its remaining factors 1, so that no input makes the load quadratic.
 * Quad b meets an edge of quad a where both of the edge's ends lie in b, within
 * GROOVE_QUAD_TOL of the ends' coordinates and the edge's length (the file writes each quad's
 * corner and edges apart, to the digits it prints); the groove's angle is that between the two
 * quads' arms away from the edge (the acute one of the two, where the edge crosses b's inside
 * rather than lying on its border).  A quad takes the largest factor of its four edges for all
 * of them. */
#define GROOVE_MAX_COMPARES (1u << 26)
#define GROOVE_MAX_MEETS (1u << 19)
#define GROOVE_QUAD_TOL 1e-6

/* Where p lies in quad q: its coordinates (alpha along e1, beta along e2) and distance from the
 * plane, in double. */
static void quad_locate(const struct quad *q, struct dvec3 p, double *alpha, double *beta,
                        double *dist)
{
    struct dvec3 c = d3_cross(q->e1, q->e2), d = d3_sub(p, q->corner);
    double cc = d3_dot(c, c);
    *alpha = d3_dot(d3_cross(d, q->e2), c) / cc;
    *beta = d3_dot(d3_cross(q->e1, d), c) / cc;
    *dist = fabs(d3_dot(d, c)) / sqrt(cc);
}

static double d3_max_abs(struct dvec3 v) { return fmax(fabs(v.x), fmax(fabs(v.y), fabs(v.z))); }

/* The factor quad b's meeting edge k of quad a (0: corner to + e1, 1: + e1 to + e1 + e2, 2: + e2
 * to + e1 + e2, 3: corner to + e2) calls for, 1 where it does not meet it. */
static double quad_edge_groove(const struct quad *a, int k, const struct quad *b)
{
    struct dvec3 p0 = k == 1   ? d3_add(a->corner, a->e1)
                      : k == 2 ? d3_add(a->corner, a->e2)
                               : a->corner;
    struct dvec3 p1 = k == 0   ? d3_add(a->corner, a->e1)
                      : k == 3 ? d3_add(a->corner, a->e2)
                               : d3_add(d3_add(a->corner, a->e1), a->e2);
    struct dvec3 u = d3_sub(p1, p0);
    double len = d3_length(u);
    if (!(len > 0.0))
        return 1.0;
    double tol = GROOVE_QUAD_TOL * (fmax(d3_max_abs(p0), d3_max_abs(p1)) + len);
    double t = tol / fmax(d3_length(b->e1), d3_length(b->e2)); /* in b's coordinates, about */
    double al[2], be[2], dist[2];
    quad_locate(b, p0, &al[0], &be[0], &dist[0]);
    quad_locate(b, p1, &al[1], &be[1], &dist[1]);
    for (int j = 0; j < 2; j++)
        if (!(dist[j] <= tol && al[j] >= -t && al[j] <= 1.0 + t && be[j] >= -t && be[j] <= 1.0 + t))
            return 1.0;
    bool on_border = (fabs(al[0]) <= t && fabs(al[1]) <= t) ||
                     (fabs(al[0] - 1.0) <= t && fabs(al[1] - 1.0) <= t) ||
                     (fabs(be[0]) <= t && fabs(be[1]) <= t) ||
                     (fabs(be[0] - 1.0) <= t && fabs(be[1] - 1.0) <= t);
    /* the arms: each centre's part perpendicular to the edge */
    struct dvec3 ca = d3_add(a->corner, d3_scale(d3_add(a->e1, a->e2), 0.5));
    struct dvec3 cb = d3_add(b->corner, d3_scale(d3_add(b->e1, b->e2), 0.5));
    double phi = arm_angle(groove_arm(d3_sub(ca, p0), u), groove_arm(d3_sub(cb, p0), u));
    if (!on_border && phi > 0.5 * M_PI)
        phi = M_PI - phi; /* b goes on past the edge: the other side's groove */
    return groove_factor(phi);
}

/* Quad q's box, grown by a millionth of its coordinates and size: pairs whose boxes do not
 * overlap cannot share an edge. */
static void quad_span(double c, double u, double v, double *lo, double *hi)
{
    double l = c + fmin(0.0, u) + fmin(0.0, v), h = c + fmax(0.0, u) + fmax(0.0, v);
    double pad = 2.0 * GROOVE_QUAD_TOL * (fmax(fabs(l), fabs(h)) + (h - l) + fabs(u) + fabs(v));
    *lo = l - pad;
    *hi = h + pad;
}

static void quad_box(const struct quad *q, double lo[3], double hi[3])
{
    quad_span(q->corner.x, q->e1.x, q->e2.x, &lo[0], &hi[0]);
    quad_span(q->corner.y, q->e1.y, q->e2.y, &lo[1], &hi[1]);
    quad_span(q->corner.z, q->e1.z, q->e2.z, &lo[2], &hi[2]);
}

/* A quad's box along the sweep axis, and its index (quad_grooves). */
struct sweep_ent {
    double lo, hi;
    uint32_t idx;
};

static int sweep_ent_cmp(const void *x, const void *y)
{
    const struct sweep_ent *a = x, *b = y;
    if (a->lo != b->lo)
        return a->lo < b->lo ? -1 : 1;
    return a->idx < b->idx ? -1 : a->idx > b->idx; /* a total order: the same on every libc */
}

/* Raises quad i's factor to what its edges lying in quad j call for. */
static void quad_pair_groove(struct scene *sc, uint32_t i, uint32_t j)
{
    for (int k = 0; k < 4; k++) {
        double g = quad_edge_groove(&sc->quads[i], k, &sc->quads[j]);
        float gf = (float)g * (1.0f + 0x1p-20f);
        if (g > 1.0 && gf > sc->quads[i].groove)
            sc->quads[i].groove = gf;
    }
}

static bool quad_grooves(struct scene *sc)
{
    uint32_t n = sc->n_quads;
    if (n < 2)
        return true;
    double(*box)[2][3] = malloc((size_t)n * sizeof *box);
    struct sweep_ent *ent = malloc((size_t)n * sizeof *ent);
    if (!box || !ent) {
        free(box);
        free(ent);
        return false;
    }
    double c_lo[3] = {INFINITY, INFINITY, INFINITY}, c_hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t i = 0; i < n; i++) {
        quad_box(&sc->quads[i], box[i][0], box[i][1]);
        for (int a = 0; a < 3; a++) {
            double c = 0.5 * box[i][0][a] + 0.5 * box[i][1][a];
            c_lo[a] = fmin(c_lo[a], c);
            c_hi[a] = fmax(c_hi[a], c);
        }
    }
    int axis = 0;
    for (int a = 1; a < 3; a++)
        if (c_hi[a] - c_lo[a] > c_hi[axis] - c_lo[axis])
            axis = a;
    for (uint32_t i = 0; i < n; i++)
        ent[i] = (struct sweep_ent){box[i][0][axis], box[i][1][axis], i};
    qsort(ent, n, sizeof *ent, sweep_ent_cmp);
    uint32_t compares = 0, meets = 0;
    for (uint32_t p = 0; p < n; p++)
        for (uint32_t q = p + 1; q < n && ent[q].lo <= ent[p].hi; q++) {
            if (++compares > GROOVE_MAX_COMPARES)
                goto done;
            uint32_t i = ent[p].idx, j = ent[q].idx;
            bool meet = true;
            for (int a = 0; meet && a < 3; a++)
                meet = box[i][0][a] <= box[j][1][a] && box[j][0][a] <= box[i][1][a];
            if (!meet)
                continue;
            if (++meets > GROOVE_MAX_MEETS)
                goto done;
            quad_pair_groove(sc, i, j);
            quad_pair_groove(sc, j, i);
        }
done:
    free(box);
    free(ent);
    return true;
}

/* A position's coordinates as bits, -0 as +0: equal keys, equal positions (the weld, and the
 * quads that meet meshes). */
static void corner_key(vec3 p, uint32_t key[3])
{
    const float c[3] = {p.x + 0.0f, p.y + 0.0f, p.z + 0.0f}; /* -0 + 0 = +0 */
    memcpy(key, c, 3 * sizeof *key);
}

/* SplitMix64's finaliser (Steele, Lea and Flood 2014): every input bit reaches every output
 * bit, so coordinates on a grid, whose low mantissa bits are zero, spread over the table. */
static uint64_t weld_mix(uint64_t z)
{
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

/* The lowest index of a vertex at each vertex's position (exactly equal coordinates, -0 as +0):
 * meshes keep their vertices apart, and a triangle soup (STL, some exporters) gives each
 * triangle its own, yet faces that meet at a groove share their corners' coordinates.  An open
 * hash of the positions, in a table of twice their number or more.  NULL where out of memory. */
static uint32_t *weld_positions(const struct scene *sc)
{
    uint32_t n_v = sc->n_positions;
    uint32_t *canon = malloc(((size_t)n_v + 1) * sizeof *canon);
    size_t cap = 16;
    while (cap < 2 * (size_t)n_v)
        cap *= 2;
    uint32_t *table = malloc(cap * sizeof *table);
    if (!canon || !table) {
        free(canon);
        free(table);
        return NULL;
    }
    memset(table, 0xff, cap * sizeof *table); /* UINT32_MAX: empty */
    for (uint32_t v = 0; v < n_v; v++) {
        const vec3 p = sc->positions[v];
        uint32_t bits[3];
        corner_key(p, bits);
        uint64_t h = weld_mix(weld_mix((uint64_t)bits[0] << 32 | bits[1]) ^ bits[2]);
        size_t slot = (size_t)h & (cap - 1);
        for (;; slot = (slot + 1) & (cap - 1)) {
            uint32_t w = table[slot];
            if (w == UINT32_MAX) {
                table[slot] = v;
                canon[v] = v;
                break;
            }
            const vec3 q = sc->positions[w];
            if (q.x == p.x && q.y == p.y && q.z == p.z) {
                canon[v] = w;
                break;
            }
        }
    }
    free(table);
    return canon;
}

/* The scene's edges (corners weld_positions apart) listed under their lower corner: on
 * success *start (n_positions + 1 entries) and *ent, vertex v's edges being ent[start[v] ..
 * start[v + 1]) sorted by the other corner (a counting sort, then each list by insertion sort
 * or qsort).  False where out of memory (nothing to free). */
static bool edge_lists(const struct scene *sc, const uint32_t *canon, uint32_t **start_out,
                       struct groove_ent **ent_out)
{
    uint32_t n_e = 3 * sc->n_tris, n_v = sc->n_positions;
    uint32_t *start = calloc((size_t)n_v + 2, sizeof *start);
    struct groove_ent *ent = malloc(((size_t)n_e + 1) * sizeof *ent);
    if (!start || !ent) {
        free(start);
        free(ent);
        return false;
    }
    for (uint32_t e = 0; e < n_e; e++) {
        const struct scene_tri *t = &sc->tris[e / 3];
        uint32_t a = canon[t->v[(e % 3 + 1) % 3]], b = canon[t->v[(e % 3 + 2) % 3]];
        if (a != b)
            start[(a < b ? a : b) + 2]++;
    }
    for (uint32_t v = 0; v < n_v; v++)
        start[v + 2] += start[v + 1];
    for (uint32_t e = 0; e < n_e; e++) {
        const struct scene_tri *t = &sc->tris[e / 3];
        uint32_t a = canon[t->v[(e % 3 + 1) % 3]], b = canon[t->v[(e % 3 + 2) % 3]];
        if (a != b) /* start[lo + 1] counts up to the next list's start as it fills */
            ent[start[(a < b ? a : b) + 1]++] = (struct groove_ent){a < b ? b : a, e};
    }
    for (uint32_t v = 0; v < n_v; v++) {
        uint32_t begin = start[v], end = start[v + 1];
        if (end - begin <= 16) { /* the usual handful: insertion sort */
            for (uint32_t j = begin + 1; j < end; j++)
                for (uint32_t k = j; k > begin && ent[k - 1].hi > ent[k].hi; k--) {
                    struct groove_ent tmp = ent[k];
                    ent[k] = ent[k - 1];
                    ent[k - 1] = tmp;
                }
        } else {
            qsort(ent + begin, end - begin, sizeof *ent, groove_ent_cmp);
        }
    }
    *start_out = start;
    *ent_out = ent;
    return true;
}

/* sc->tri_groove from the edges the scene's triangles share: edges with the same two corners
 * (vertices at the same coordinates, weld_positions, so triangles of two meshes or of a soup
 * meet as those of one mesh do), edge_lists. */
static bool grooves(struct parser *ps, const uint32_t *canon, const uint32_t *start,
                    const struct groove_ent *ent)
{
    struct scene *sc = ps->scene;
    if (!quad_grooves(sc))
        return fail_oom(ps, 0);
    uint64_t n_e = 3 * (uint64_t)sc->n_tris;
    if (n_e == 0 || !canon)
        return true;
    uint32_t n_v = sc->n_positions;
    struct groove_arm *arms = NULL;
    size_t arms_cap = 0;
    bool ok = true;
    for (uint32_t v = 0; ok && v < n_v; v++) {
        uint32_t begin = start[v], end = start[v + 1];
        for (uint32_t j = begin; ok && j < end;) {
            uint32_t k = j + 1;
            while (k < end && ent[k].hi == ent[j].hi)
                k++;
            if (k - j >= 2)
                ok = edge_grooves(sc, v, ent + j, k - j, &arms, &arms_cap);
            j = k;
        }
    }
    free(arms);
    if (ok && sc->tri_groove) {
        /* a groove's factor also for the other edges at its two vertices: a triangle that only
         * touches the groove's edge at a corner (a quad's other half) has points as near the
         * neighbour's plane there, and its own edges are the ones that keep them away */
        float *at_v = calloc(sc->n_positions, sizeof *at_v);
        ok = at_v != NULL;
        for (uint32_t e = 0; ok && e < (uint32_t)n_e; e++) {
            const struct scene_tri *t = &sc->tris[e / 3];
            float g = sc->tri_groove[e / 3][e % 3];
            for (int k = 1; k <= 2; k++) {
                uint32_t v = canon[t->v[(e % 3 + k) % 3]];
                at_v[v] = at_v[v] > g ? at_v[v] : g;
            }
        }
        for (uint32_t e = 0; ok && e < (uint32_t)n_e; e++) {
            const struct scene_tri *t = &sc->tris[e / 3];
            float *g = &sc->tri_groove[e / 3][e % 3];
            for (int k = 1; k <= 2; k++) {
                float g_v = at_v[canon[t->v[(e % 3 + k) % 3]]];
                *g = g_v > *g ? g_v : *g;
            }
        }
        free(at_v);
    }
    if (!ok)
        return fail_oom(ps, 0);
    return true;
}

/* ---- T-junctions: triangles split where a neighbour's corners lie on their edge ----------- */

/* A vertex on a neighbour's edge without being its corner (a T-junction: a face cut into strips
 * that end on the next face's single edge) is exact in the file, but a rotation or a move rounds
 * it off the edge, and a ray passes through the crack between them (docs/theory.md,
 * "Self-intersection").  The load closes such cracks: an edge that no other triangle shares
 * (edge_lists) whose line is covered from end to end by a chain of other unshared edges, each
 * corner within TJ_TOL of the line's coordinates, has its triangle fanned from the opposite
 * corner through the chain's corners, which the two sides then share.  A triangle with chains
 * along two or three edges is split along one a pass, up to TJ_PASSES passes. */
#define TJ_PASSES 3
#define TJ_TOL 0x1p-20   /* of the largest coordinate of the edge's ends and the corner */
#define TJ_WORK 32       /* list entries the passes may look at, per edge (and 2^20 more) */
#define TJ_MAX_DEGREE 16 /* unshared edges at a corner of a chain (T-junctions have 2 to 4) */

/* The unshared edges (those whose corners no other triangle's edge has) at each vertex, both
 * ends: at[first[v] .. first[v + 1]) are edge ids (triangle * 3 + the opposite corner); lone[e]
 * says whether edge e is one. */
struct tj_lists {
    uint32_t *first;
    uint32_t *at;
    bool *lone;
};

static bool tj_lists(const struct scene *sc, const uint32_t *start, const struct groove_ent *ent,
                     struct tj_lists *l)
{
    uint32_t n_v = sc->n_positions;
    l->first = calloc((size_t)n_v + 2, sizeof *l->first);
    l->lone = calloc((size_t)sc->n_tris * 3, sizeof *l->lone);
    l->at = NULL;
    if (!l->first || !l->lone)
        return false;
    uint32_t n = 0;
    for (int pass = 0; pass < 2; pass++) {
        for (uint32_t v = 0; v < n_v; v++)
            for (uint32_t j = start[v]; j < start[v + 1]; j++) {
                bool alone = (j == start[v] || ent[j - 1].hi != ent[j].hi) &&
                             (j + 1 == start[v + 1] || ent[j + 1].hi != ent[j].hi);
                if (!alone)
                    continue;
                uint32_t ends[2] = {v, ent[j].hi};
                if (pass == 0) {
                    l->first[ends[0] + 2]++;
                    l->first[ends[1] + 2]++;
                    l->lone[ent[j].e] = true;
                    n += 2;
                } else {
                    l->at[l->first[ends[0] + 1]++] = ent[j].e;
                    l->at[l->first[ends[1] + 1]++] = ent[j].e;
                }
            }
        if (pass == 0) {
            for (uint32_t v = 0; v < n_v; v++)
                l->first[v + 2] += l->first[v + 1];
            l->at = malloc(((size_t)n + 1) * sizeof *l->at);
            if (!l->at)
                return false;
        }
    }
    return true;
}

/* The corner of edge e's triangle (of tris) at end k (1 or 2 from the opposite corner), welded. */
static uint32_t tj_corner(const struct scene_tri *tris, const uint32_t *canon, uint32_t e, int k)
{
    return canon[tris[e / 3].v[(e % 3 + k) % 3]];
}

/* A chain's inner corners and their parameters along the edge, grown as needed. */
struct tj_chain {
    uint32_t *v;
    double *t;
    uint32_t n, cap;
};

/* The chain of unshared edges from corner a to corner b of edge e along its line, its inner
 * corners in order into *ch; false where there is none (or the triangle is flat, or the pass's
 * *work, the list entries it may still look at, runs out).  *oom where memory did. */
static bool tj_find_chain(const struct scene *sc, const struct scene_tri *tris,
                          const uint32_t *canon, const struct tj_lists *l, uint32_t e, uint32_t a,
                          uint32_t b, struct tj_chain *ch, uint64_t *work, bool *oom)
{
    struct dvec3 pa = d3(sc->positions[a]), pb = d3(sc->positions[b]), d = d3_sub(pb, pa);
    struct dvec3 pc = d3(sc->positions[canon[tris[e / 3].v[e % 3]]]);
    double big = fmax(d3_max_abs(pa), fmax(d3_max_abs(pb), d3_max_abs(pc)));
    double tol2 = (TJ_TOL * big) * (TJ_TOL * big);
    double len2 = d3_dot(d, d);
    if (!(len2 > 0.0))
        return false;
    /* the opposite corner off the line: the triangle is not flat */
    struct dvec3 qc = d3_sub(pc, pa);
    struct dvec3 oc = d3_sub(qc, d3_scale(d, d3_dot(qc, d) / len2));
    if (!(d3_dot(oc, oc) > 0.0))
        return false;
    ch->n = 0;
    uint32_t cur = a;
    double t_cur = 0.0;
    for (;;) {
        uint32_t degree = l->first[cur + 1] - l->first[cur];
        if (degree > TJ_MAX_DEGREE || degree > *work)
            return false;
        *work -= degree;
        uint32_t best = UINT32_MAX;
        double best_t = 2.0;
        for (uint32_t j = l->first[cur]; j < l->first[cur + 1]; j++) {
            uint32_t f = l->at[j];
            uint32_t p = tj_corner(tris, canon, f, 1), q = tj_corner(tris, canon, f, 2);
            if (f / 3 == e / 3 || (p != cur && q != cur))
                continue; /* the triangle's own edges are not its neighbours' */
            uint32_t w = p == cur ? q : p;
            double t = 1.0; /* b itself */
            if (w != b) {
                struct dvec3 qw = d3_sub(d3(sc->positions[w]), pa);
                t = d3_dot(qw, d) / len2;
                struct dvec3 o = d3_sub(qw, d3_scale(d, t));
                if (!(t > t_cur && t < 1.0) || !(d3_dot(o, o) <= tol2))
                    continue;
            }
            if (t < best_t) {
                best_t = t;
                best = w;
            }
        }
        if (best == UINT32_MAX)
            return false;
        if (best == b)
            return ch->n > 0;
        if (ch->n == ch->cap) {
            uint32_t cap = ch->cap ? 2 * ch->cap : 64;
            uint32_t *v = realloc(ch->v, (size_t)cap * sizeof *v);
            if (v)
                ch->v = v;
            double *t = v ? realloc(ch->t, (size_t)cap * sizeof *t) : NULL;
            if (!t) {
                *oom = true;
                return false;
            }
            ch->t = t;
            ch->cap = cap;
        }
        ch->v[ch->n] = best;
        ch->t[ch->n++] = best_t;
        cur = best;
        t_cur = best_t;
    }
}

/* The attributes of a new corner at t along triangle tr's corners p -> q, appended to the
 * scene's normals and uvs: *vn, *vt (-1 where either corner has none). */
static bool tj_attributes(struct parser *ps, const struct scene_tri *tr, int p, int q, double t,
                          int32_t *vn, int32_t *vt)
{
    struct scene *sc = ps->scene;
    *vn = *vt = -1;
    if (tr->vn[p] >= 0 && tr->vn[q] >= 0) {
        if (!RESERVE(ps, sc->normals, ps->cap_normals, (uint64_t)sc->n_normals + 1))
            return false;
        vec3 na = sc->normals[tr->vn[p]];
        struct dvec3 n = d3_add(d3_scale(d3(na), 1.0 - t), d3_scale(d3(sc->normals[tr->vn[q]]), t));
        double len = d3_length(n);
        sc->normals[sc->n_normals] = len > 0.0 ? d3_to_float(d3_scale(n, 1.0 / len)) : na;
        *vn = (int32_t)sc->n_normals++;
    }
    if (tr->vt[p] >= 0 && tr->vt[q] >= 0) {
        if (!RESERVE(ps, sc->uvs, ps->cap_uvs, (uint64_t)sc->n_uvs + 1))
            return false;
        vec2 u = sc->uvs[tr->vt[p]], w = sc->uvs[tr->vt[q]];
        sc->uvs[sc->n_uvs] = (vec2){(float)((1.0 - t) * u.x + t * w.x),
                                    (float)((1.0 - t) * u.y + t * w.y)};
        *vt = (int32_t)sc->n_uvs++;
    }
    return true;
}

/* A budget the passes share: list entries to look at, triangles to add. */
struct tj_budget {
    uint64_t work;
    uint64_t tris;
};

/* One pass: every triangle with a chain along one of its edges fanned through it, while the
 * budget lasts.  *split says whether any was. */
static bool tj_pass(struct parser *ps, const uint32_t *canon, const uint32_t *start,
                    const struct groove_ent *ent, struct tj_budget *budget, bool *split)
{
    struct scene *sc = ps->scene;
    *split = false;
    struct tj_lists l = {NULL, NULL, NULL};
    bool listed = tj_lists(sc, start, ent, &l);
    /* the chains are found in the triangles as the pass began, whatever it splits first */
    uint32_t n_tris = sc->n_tris;
    struct scene_tri *tris = listed ? malloc((size_t)n_tris * sizeof *tris) : NULL;
    if (!tris) {
        free(l.first);
        free(l.at);
        free(l.lone);
        return fail_oom(ps, 0);
    }
    memcpy(tris, sc->tris, (size_t)n_tris * sizeof *tris);
    bool ok = true; /* false: RESERVE failed and filled the error */
    struct tj_chain ch = {NULL, NULL, 0, 0};
    bool oom = false;
    for (uint32_t i = 0; ok && !oom && budget->work > 0 && i < n_tris; i++) {
        for (int o = 0; o < 3; o++) {
            uint32_t e = 3 * i + (uint32_t)o;
            if (!l.lone[e])
                continue;
            uint32_t a = tj_corner(tris, canon, e, 1), b = tj_corner(tris, canon, e, 2);
            if (l.first[a + 1] - l.first[a] < 2)
                continue; /* a's only unshared edge is e: no chain starts there */
            if (!tj_find_chain(sc, tris, canon, &l, e, a, b, &ch, &budget->work, &oom))
                continue;
            uint32_t n = ch.n;
            if (n > budget->tris || (uint64_t)sc->n_tris + (uint64_t)n >= UINT32_MAX / 8) {
                budget->work = 0; /* the rest stays as it is */
                break;
            }
            budget->tris -= n;
            if (!RESERVE(ps, sc->tris, ps->cap_tris, (uint64_t)sc->n_tris + (uint64_t)n)) {
                ok = false;
                break;
            }
            /* the fan from corner o: (o, w_k, w_k+1) for w_0 = corner p, ..., w_n+1 = corner q,
             * wound as (o, p, q); the first keeps slot i */
            const struct scene_tri t = tris[i];
            int p = (o + 1) % 3, q = (o + 2) % 3;
            uint32_t prev_v = t.v[p];
            int32_t prev_n = t.vn[p], prev_t = t.vt[p];
            for (uint32_t k = 0; k <= n && ok; k++) {
                uint32_t next_v = k < n ? ch.v[k] : t.v[q];
                int32_t next_n = t.vn[q], next_t = t.vt[q];
                if (k < n)
                    ok = tj_attributes(ps, &t, p, q, ch.t[k], &next_n, &next_t);
                struct scene_tri s = t;
                s.v[p] = prev_v;
                s.vn[p] = prev_n;
                s.vt[p] = prev_t;
                s.v[q] = next_v;
                s.vn[q] = next_n;
                s.vt[q] = next_t;
                if (k == 0)
                    sc->tris[i] = s;
                else
                    sc->tris[sc->n_tris++] = s;
                prev_v = next_v;
                prev_n = next_n;
                prev_t = next_t;
            }
            *split = true;
            break; /* this triangle's other edges: the next pass */
        }
    }
    free(ch.v);
    free(ch.t);
    free(tris);
    free(l.first);
    free(l.at);
    free(l.lone);
    if (ok && oom)
        return fail_oom(ps, 0);
    return ok;
}

/* ---- quads that meet meshes ---------------------------------------------------------------- */

/* A quad keeps its corner and edges in double, a mesh its vertices in float, so where the two
 * share an edge the quad's runs up to half a float ulp beside the mesh's, and rays pass through
 * the crack (a box of quads and mesh faces, camera inside, let sky in in 11 of 30 random
 * placements at right angles; `python3 scripts/probe_leaks.py sheared --mixed --degrees 90`).
 * A quad with an edge whose two ends are mesh vertices (the corners rounded to float, exactly
 * equal), and every quad that shares an edge with it so, becomes two triangles of the meshes
 * with those float corners: the faces then meet by coordinates as a mesh's do, and the weld, the
 * T-junction pass and the grooves treat them so.  Uvs (0, 0), (1, 0), (1, 1), (0, 1) keep the
 * quad's (alpha, beta); the front normal e1 x e2 and the area are the quad's.  Quads that meet
 * only quads stay as they are. */
struct corner_rec {
    uint32_t key[3]; /* the float corner's bits, -0 as +0 */
    uint32_t at;     /* 4 quad + corner */
};

static int corner_key_cmp(const uint32_t a[3], const uint32_t b[3])
{
    for (int i = 0; i < 3; i++)
        if (a[i] != b[i])
            return a[i] < b[i] ? -1 : 1;
    return 0;
}

static int corner_rec_cmp(const void *x, const void *y)
{
    const struct corner_rec *a = x, *b = y;
    return corner_key_cmp(a->key, b->key);
}

/* The quad's four corners in double, then rounded to float: corner, + e1, + e1 + e2, + e2. */
static void quad_corners_f(const struct quad *q, vec3 p[4])
{
    struct dvec3 a = d3_add(q->corner, q->e1);
    p[0] = d3_to_float(q->corner);
    p[1] = d3_to_float(a);
    p[2] = d3_to_float(d3_add(a, q->e2));
    p[3] = d3_to_float(d3_add(q->corner, q->e2));
}

/* The corners at key are at a vertex of the meshes: each quad whose edge has both ends there
 * now is queued to become triangles. */
struct corner_marks {
    const struct corner_rec *recs;
    size_t n_recs;
    uint8_t *bits;   /* per quad, its corners at mesh vertices */
    uint32_t *queue; /* quads to become triangles, in the order found */
    uint32_t n_queue;
};

static void corner_mark(struct corner_marks *m, const uint32_t key[3])
{
    size_t lo = 0, hi = m->n_recs; /* the first record with key */
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (corner_key_cmp(m->recs[mid].key, key) < 0)
            lo = mid + 1;
        else
            hi = mid;
    }
    for (size_t r = lo; r < m->n_recs && corner_key_cmp(m->recs[r].key, key) == 0; r++) {
        uint32_t q = m->recs[r].at / 4, k = m->recs[r].at % 4;
        uint8_t b = m->bits[q];
        if (b & 0x10)
            continue; /* queued already */
        b |= (uint8_t)(1u << k);
        uint8_t edges = b & (uint8_t)((b >> 1) | (b << 3)) & 0xf; /* corners k and k + 1 */
        if (edges) {
            b |= 0x10;
            m->queue[m->n_queue++] = q;
        }
        m->bits[q] = b;
    }
}

static bool quads_to_triangles(struct parser *ps)
{
    struct scene *sc = ps->scene;
    uint32_t n_q = sc->n_quads;
    if (n_q == 0 || sc->n_tris == 0 || n_q > UINT32_MAX / 8)
        return true;
    struct corner_marks m = {NULL, 4 * (size_t)n_q, NULL, NULL, 0};
    struct corner_rec *recs = malloc(m.n_recs * sizeof *recs);
    m.bits = calloc(n_q, 1);
    m.queue = malloc((size_t)n_q * sizeof *m.queue);
    m.recs = recs;
    if (!recs || !m.bits || !m.queue) {
        free(recs);
        free(m.bits);
        free(m.queue);
        return fail_oom(ps, 0);
    }
    for (uint32_t i = 0; i < n_q; i++) {
        vec3 p[4];
        quad_corners_f(&sc->quads[i], p);
        for (uint32_t k = 0; k < 4; k++) {
            corner_key(p[k], recs[4 * i + k].key);
            recs[4 * i + k].at = 4 * i + k;
        }
    }
    qsort(recs, m.n_recs, sizeof *recs, corner_rec_cmp);
    uint32_t key[3];
    for (uint32_t v = 0; v < sc->n_positions; v++) { /* quads along the meshes' edges */
        corner_key(sc->positions[v], key);
        corner_mark(&m, key);
    }
    for (uint32_t h = 0; h < m.n_queue; h++) { /* and the quads that share an edge with them */
        vec3 p[4];
        quad_corners_f(&sc->quads[m.queue[h]], p);
        for (int k = 0; k < 4; k++) {
            corner_key(p[k], key);
            corner_mark(&m, key);
        }
    }
    free(recs);
    free(m.queue);
    bool ok = true;
    if (m.n_queue > 0) {
        uint64_t n_pos = (uint64_t)sc->n_positions + 4 * (uint64_t)m.n_queue;
        uint64_t n_tri = (uint64_t)sc->n_tris + 2 * (uint64_t)m.n_queue;
        ok = RESERVE(ps, sc->positions, ps->cap_positions, n_pos) &&
             RESERVE(ps, sc->tris, ps->cap_tris, n_tri) &&
             RESERVE(ps, sc->uvs, ps->cap_uvs, (uint64_t)sc->n_uvs + 4);
    }
    if (ok && m.n_queue > 0) {
        int32_t uv0 = (int32_t)sc->n_uvs;
        static const vec2 uv[4] = {{0.0f, 0.0f}, {1.0f, 0.0f}, {1.0f, 1.0f}, {0.0f, 1.0f}};
        for (int k = 0; k < 4; k++)
            sc->uvs[sc->n_uvs++] = uv[k];
        static const int fan[2][3] = {{0, 1, 2}, {0, 2, 3}};
        uint32_t kept = 0;
        for (uint32_t i = 0; i < n_q; i++) {
            const struct quad q = sc->quads[i];
            if (!(m.bits[i] & 0x10)) {
                sc->quads[kept++] = q;
                continue;
            }
            uint32_t v0 = sc->n_positions;
            quad_corners_f(&q, &sc->positions[v0]);
            sc->n_positions += 4;
            for (int t = 0; t < 2; t++) {
                struct scene_tri *tr = &sc->tris[sc->n_tris++];
                for (int k = 0; k < 3; k++) {
                    tr->v[k] = v0 + (uint32_t)fan[t][k];
                    tr->vn[k] = -1;
                    tr->vt[k] = uv0 + fan[t][k];
                }
                tr->mat_idx = q.mat_idx;
            }
        }
        sc->n_quads = kept;
    }
    free(m.bits);
    return ok;
}

/* ---- where meshes stand on planes, quads and other meshes -------------------------------- */

/* A mesh wall standing on a plane, a quad or another mesh's triangle (a room's walls on a floor,
 * a box on the ground) shares no edge with it.  Two things let rays through there: the wall's
 * bottom corners, on the floor in the file, round to float up to half a float step above it, a
 * crack under the wall; and no margin keeps the floor's points near the wall in front of it, so
 * that a point of the floor within a float step of the wall spawns rays past it.  Open boxes
 * standing on a plane or a quad, turned and moved, camera inside, let sky in in 7 of 40 cases,
 * on two triangles of another mesh in 6 of 40.  So the load finds, per plane, quad and
 * triangle, the mesh vertices on it (within CONTACT_ULPS float steps of its plane, and inside
 * it to that distance; for a triangle, only vertices of edges that one triangle alone has, as an
 * open wall's bottom corners are, and not its own) whose triangles' other corners off it lie
 * all on one side, and moves each onto it or the least way past it (stand_seat), so that the
 * wall reaches it (the floor hides any overlap); a vertex with corners on both sides (a mesh
 * that crosses the floor) or none off it (a mesh lying in it) stays.  And it lists the edges
 * with both corners on the surface and the third corner off it, the lines where something
 * stands: shape_pull_from_contacts keeps the floor's hits a triangle edge's margin away from
 * them.  A surface with more than CONTACT_MAX lines keeps none of them (each of its hits would
 * test them all; its vertices are still seated), and the search stops after CONTACT_MAX_WORK
 * vertex and triangle visits. */
#define CONTACT_ULPS 8.0
#define SEAT_ULPS 4.0
#define CONTACT_MAX 64
#define CONTACT_MAX_WORK (1u << 26)

/* A surface that meshes may stand on: the plane through o with unit normal n; q its quad, or
 * tri its triangle's corners, or neither for a plane. */
struct stand_surface {
    struct dvec3 o, n;
    const struct quad *q;
    const struct dvec3 *tri;
};

/* ulps float steps of p's and s's largest coordinate. */
static double stand_tol(const struct stand_surface *s, struct dvec3 p, double ulps)
{
    return ulps * 0x1p-24 * (d3_max_abs(p) + d3_max_abs(s->o));
}

/* Whether p lies on s: within CONTACT_ULPS of its plane, and inside its quad or triangle to
 * that distance. */
static bool stand_on(const struct stand_surface *s, struct dvec3 p)
{
    double tol = stand_tol(s, p, CONTACT_ULPS);
    if (!(fabs(d3_dot(d3_sub(p, s->o), s->n)) <= tol))
        return false;
    if (s->tri) { /* within tol of each edge's line, on the inner side */
        for (int k = 0; k < 3; k++) {
            struct dvec3 a = s->tri[k], ab = d3_sub(s->tri[(k + 1) % 3], a);
            double len = d3_length(ab);
            if (!(d3_dot(d3_cross(ab, d3_sub(p, a)), s->n) >= -tol * len))
                return false;
        }
        return true;
    }
    if (!s->q)
        return true;
    double alpha, beta, unused;
    quad_locate(s->q, p, &alpha, &beta, &unused);
    double ta = tol / d3_length(s->q->e1), tb = tol / d3_length(s->q->e2);
    return alpha >= -ta && alpha <= 1.0 + ta && beta >= -tb && beta <= 1.0 + tb;
}

enum { STAND_ON = 1, STAND_ABOVE = 2, STAND_BELOW = 4 };

/* Moves vertex i, on s with its triangles' other corners on one side (flags), onto s or the
 * least way past it: the float point nearest its projection on s, or, where that lies on the
 * wall's side, the first of the points 1/8, 1/4, ... SEAT_ULPS float steps past s that does
 * not.  The least way, so that the margin of the wall's own edge (triangle_point) still keeps
 * the wall's points above s by about what it did. */
static void stand_seat(struct scene *sc, const struct stand_surface *s, uint32_t i, uint8_t flags)
{
    double sgn = flags & STAND_ABOVE ? 1.0 : -1.0; /* the wall's side */
    struct dvec3 p = d3(sc->positions[i]);
    double step = stand_tol(s, p, 1.0), dist = d3_dot(d3_sub(p, s->o), s->n);
    if (sgn * dist <= 0.0)
        return; /* on s or past it already */
    for (double depth = 0.0; depth <= SEAT_ULPS * step;
         depth = depth > 0.0 ? 2.0 * depth : step / 8) {
        vec3 moved = d3_to_float(d3_sub(p, d3_scale(s->n, dist + sgn * depth)));
        if (sgn * d3_dot(d3_sub(d3(moved), s->o), s->n) <= 0.0) {
            sc->positions[i] = moved;
            return;
        }
    }
}

/* What the search shares: the triangles at each vertex (adj[adj_start[v] .. adj_start[v + 1])),
 * a flag byte per vertex (0 between surfaces), the vertices flagged for the current surface,
 * the contacts found so far, and the work left. */
struct stand_state {
    struct scene *sc;
    uint32_t *adj_start, *adj;
    uint8_t *flags;
    uint32_t *marked, n_marked;
    struct contact *out;
    uint32_t n_out, cap;
    uint64_t work;
};

/* Marks vertex i when it lies on s. */
static void stand_mark(struct stand_state *st, const struct stand_surface *s, uint32_t i)
{
    st->work++;
    if (!st->flags[i] && stand_on(s, d3(st->sc->positions[i]))) {
        st->flags[i] = STAND_ON;
        st->marked[st->n_marked++] = i;
    }
}

/* Seats the marked vertices that stand on s, appends its contacts (up to CONTACT_MAX + 1) and
 * clears the marks.  False where out of memory. */
static bool stand_finish(struct stand_state *st, const struct stand_surface *s)
{
    struct scene *sc = st->sc;
    bool ok = true;
    for (uint32_t m = 0; m < st->n_marked; m++) { /* the sides of the corners off s */
        uint32_t i = st->marked[m];
        for (uint32_t a = st->adj_start[i]; a < st->adj_start[i + 1]; a++) {
            const uint32_t *v = sc->tris[st->adj[a]].v;
            for (int k = 0; k < 3; k++)
                if (!(st->flags[v[k]] & STAND_ON)) {
                    double d = d3_dot(d3_sub(d3(sc->positions[v[k]]), s->o), s->n);
                    st->flags[i] |= d > 0.0 ? STAND_ABOVE : STAND_BELOW;
                }
        }
        st->work += st->adj_start[i + 1] - st->adj_start[i];
    }
    for (uint32_t m = 0; m < st->n_marked; m++) {
        uint32_t i = st->marked[m];
        if (st->flags[i] == (STAND_ON | STAND_ABOVE) || st->flags[i] == (STAND_ON | STAND_BELOW))
            stand_seat(sc, s, i, st->flags[i]);
    }
    /* the lines: edges with both corners on s, the third off it (seated corners as moved),
     * each found from its triangle's first corner on s */
    uint32_t found = 0;
    for (uint32_t m = 0; ok && m < st->n_marked && found <= CONTACT_MAX; m++) {
        uint32_t i = st->marked[m];
        for (uint32_t a = st->adj_start[i]; a < st->adj_start[i + 1]; a++) {
            const uint32_t *v = sc->tris[st->adj[a]].v;
            int n_on = 0, c = 0, first = -1;
            for (int k = 0; k < 3; k++) {
                if (st->flags[v[k]] & STAND_ON) {
                    n_on++;
                    first = first < 0 ? k : first;
                } else {
                    c = k; /* the corner off s */
                }
            }
            if (n_on != 2 || v[first] != i)
                continue;
            struct dvec3 p = d3(sc->positions[v[(c + 1) % 3]]);
            struct dvec3 q = d3(sc->positions[v[(c + 2) % 3]]);
            struct dvec3 pq = d3_sub(q, p), mv = d3_cross(s->n, pq);
            struct dvec3 arm = groove_arm(d3_sub(d3(sc->positions[v[c]]), p), pq);
            double m_len = d3_length(mv), arm_len = d3_length(arm);
            if (!(m_len > 0.0 && arm_len > 0.0))
                continue;
            double phi = asin(fmin(1.0, fabs(d3_dot(arm, s->n)) / arm_len)); /* acute angle */
            if (st->n_out == st->cap) {
                uint32_t grown = st->cap ? 2 * st->cap : 16;
                struct contact *more = grown > st->cap ? realloc(st->out, grown * sizeof *st->out)
                                                       : NULL;
                if (!more) {
                    ok = false;
                    break;
                }
                st->out = more;
                st->cap = grown;
            }
            st->out[st->n_out++] = (struct contact){p, q, d3_scale(mv, 1.0 / m_len),
                                                    groove_factor(phi)};
            found++;
        }
    }
    for (uint32_t m = 0; m < st->n_marked; m++)
        st->flags[st->marked[m]] = 0;
    st->n_marked = 0;
    return ok;
}

/* A vertex of an open edge and one of its coordinates (stand_candidates). */
struct stand_cand {
    double x;
    uint32_t v;
};

static int stand_cand_cmp(const void *x, const void *y)
{
    const struct stand_cand *a = x, *b = y;
    if (a->x != b->x)
        return a->x < b->x ? -1 : 1;
    return (a->v > b->v) - (a->v < b->v);
}

/* The vertices of edges that one triangle alone has (from the edge lists: a run of one entry),
 * three times, sorted by x, by y and by z, in out[0..2] (*n_out each); NULL lists: none.  False
 * where out of memory. */
static bool stand_candidates(const struct scene *sc, const uint32_t *canon, const uint32_t *start,
                             const struct groove_ent *ent, struct stand_cand **out, uint32_t *n_out)
{
    out[0] = out[1] = out[2] = NULL;
    *n_out = 0;
    if (!canon || !start)
        return true;
    uint8_t *open = calloc(sc->n_positions, 1);
    if (!open)
        return false;
    for (uint32_t v = 0; v < sc->n_positions; v++)
        for (uint32_t j = start[v], k; j < start[v + 1]; j = k) {
            for (k = j + 1; k < start[v + 1] && ent[k].hi == ent[j].hi;)
                k++;
            if (k - j == 1)
                open[v] = open[ent[j].hi] = 1;
        }
    uint32_t n = 0;
    for (uint32_t p = 0; p < sc->n_positions; p++)
        n += open[canon[p]];
    for (int a = 0; n && a < 3; a++) {
        struct stand_cand *c = malloc((size_t)n * sizeof *c);
        if (!c) {
            free(open);
            for (int b = 0; b < a; b++)
                free(out[b]);
            return false;
        }
        uint32_t m = 0;
        for (uint32_t p = 0; p < sc->n_positions; p++)
            if (open[canon[p]])
                c[m++] = (struct stand_cand){v3_get(sc->positions[p], a), p};
        qsort(c, n, sizeof *c, stand_cand_cmp);
        out[a] = c;
    }
    free(open);
    *n_out = n;
    return true;
}

/* The triangles at each vertex, as a list per vertex (stand_state).  False where out of
 * memory. */
static bool stand_adjacency(struct stand_state *st)
{
    const struct scene *sc = st->sc;
    st->adj_start = calloc((size_t)sc->n_positions + 2, sizeof *st->adj_start);
    st->adj = malloc((3 * (size_t)sc->n_tris + 1) * sizeof *st->adj);
    if (!st->adj_start || !st->adj)
        return false;
    for (uint32_t t = 0; t < sc->n_tris; t++)
        for (int k = 0; k < 3; k++)
            st->adj_start[sc->tris[t].v[k] + 2]++;
    for (uint32_t v = 0; v < sc->n_positions; v++)
        st->adj_start[v + 2] += st->adj_start[v + 1];
    for (uint32_t t = 0; t < sc->n_tris; t++)
        for (int k = 0; k < 3; k++)
            st->adj[st->adj_start[sc->tris[t].v[k] + 1]++] = t;
    return true;
}

/* Surface k of the search (planes, then quads, then triangles) as *s, its triangle's corners
 * in tri[3]; false where it has no plane (a degenerate triangle or quad). */
static bool stand_surface_of(const struct scene *sc, uint32_t k, struct stand_surface *s,
                             struct dvec3 tri[3])
{
    *s = (struct stand_surface){{0.0, 0.0, 0.0}, {0.0, 0.0, 0.0}, NULL, NULL};
    if (k < sc->n_planes) {
        s->o = d3(sc->planes[k].point);
        s->n = d3(sc->planes[k].n);
    } else if (k < sc->n_planes + sc->n_quads) {
        s->q = &sc->quads[k - sc->n_planes];
        s->o = s->q->corner;
        s->n = d3_cross(s->q->e1, s->q->e2);
    } else {
        const uint32_t *v = sc->tris[k - sc->n_planes - sc->n_quads].v;
        for (int j = 0; j < 3; j++)
            tri[j] = d3(sc->positions[v[j]]);
        s->tri = tri;
        s->o = tri[0];
        s->n = d3_cross(d3_sub(tri[1], tri[0]), d3_sub(tri[2], tri[0]));
    }
    double len = d3_length(s->n);
    s->n = d3_scale(s->n, 1.0 / len);
    return len > 0.0;
}

/* Marks the vertices on surface k: for a plane or quad every vertex (a quad's in its box), for
 * triangle t the open edges' vertices (cand, sorted by each axis) within its range along the
 * axis it spans least (a floor's up axis: a thin slab) that are not at its own corners'
 * coordinates (canon). */
static void stand_mark_all(struct stand_state *st, uint32_t k, const struct stand_surface *s,
                           struct stand_cand *const *cands, uint32_t n_cand, const uint32_t *canon)
{
    const struct scene *sc = st->sc;
    if (!s->tri) {
        double lo[3] = {-INFINITY, -INFINITY, -INFINITY}, hi[3] = {INFINITY, INFINITY, INFINITY};
        if (s->q)
            quad_box(s->q, lo, hi);
        for (uint32_t i = 0; i < sc->n_positions; i++) {
            vec3 p = sc->positions[i];
            if (p.x >= lo[0] && p.x <= hi[0] && p.y >= lo[1] && p.y <= hi[1] && p.z >= lo[2] &&
                p.z <= hi[2])
                stand_mark(st, s, i);
        }
        return;
    }
    const uint32_t *v = sc->tris[k - sc->n_planes - sc->n_quads].v;
    int axis = 0;
    double x_lo = 0.0, x_hi = INFINITY;
    for (int a = 0; a < 3; a++) {
        double c[3]; /* the corners' coordinates along a (floats, exact in double) */
        for (int j = 0; j < 3; j++)
            c[j] = v3_get(sc->positions[v[j]], a);
        double l = fmin(c[0], fmin(c[1], c[2])), h = fmax(c[0], fmax(c[1], c[2]));
        if (h - l < x_hi - x_lo) {
            axis = a;
            x_lo = l;
            x_hi = h;
        }
    }
    const struct stand_cand *cand = cands[axis];
    double pad = 4.0 * CONTACT_ULPS * 0x1p-24 *
                 fmax(d3_max_abs(s->tri[0]), fmax(d3_max_abs(s->tri[1]), d3_max_abs(s->tri[2])));
    uint32_t lo = 0, hi = n_cand; /* the first candidate with x >= x_lo - pad */
    while (lo < hi) {
        uint32_t mid = lo + (hi - lo) / 2;
        if (cand[mid].x < x_lo - pad)
            lo = mid + 1;
        else
            hi = mid;
    }
    float box[2][3]; /* the triangle's box, padded: most of the slab lies outside it */
    for (int a = 0; a < 3; a++) {
        float c0 = v3_get(sc->positions[v[0]], a), c1 = v3_get(sc->positions[v[1]], a),
              c2 = v3_get(sc->positions[v[2]], a);
        box[0][a] = (float)(min_f(c0, min_f(c1, c2)) - pad);
        box[1][a] = (float)(max_f(c0, max_f(c1, c2)) + pad);
    }
    for (uint32_t c = lo; c < n_cand && cand[c].x <= x_hi + pad && st->work <= CONTACT_MAX_WORK;
         c++) {
        uint32_t i = cand[c].v;
        vec3 p = sc->positions[i];
        st->work++;
        if (p.x >= box[0][0] && p.x <= box[1][0] && p.y >= box[0][1] && p.y <= box[1][1] &&
            p.z >= box[0][2] && p.z <= box[1][2] && canon[i] != canon[v[0]] &&
            canon[i] != canon[v[1]] && canon[i] != canon[v[2]])
            stand_mark(st, s, i);
    }
}

/* Seats vertices on the planes, quads and triangles and fills sc->contacts and
 * sc->contact_start (see above); canon, start and ent are the weld and the edge lists (NULL:
 * no triangle is searched).  False where out of memory. */
static bool contacts(struct parser *ps, const uint32_t *canon, const uint32_t *start,
                     const struct groove_ent *ent)
{
    struct scene *sc = ps->scene;
    struct stand_state st = {sc, NULL, NULL, NULL, NULL, 0, NULL, 0, 0, 0};
    struct stand_cand *cand[3] = {NULL, NULL, NULL};
    uint32_t n_cand = 0;
    if (sc->n_tris == 0 || sc->n_tris > UINT32_MAX / 4 ||
        sc->n_planes + (uint64_t)sc->n_quads + sc->n_tris > UINT32_MAX / 2)
        return true;
    uint32_t n_tri_surf = 0;
    bool ok = stand_candidates(sc, canon, start, ent, cand, &n_cand);
    if (ok && n_cand > 0)
        n_tri_surf = sc->n_tris;
    uint32_t n_surf = sc->n_planes + sc->n_quads + n_tri_surf;
    if (!ok || n_surf == 0) {
        for (int a = 0; a < 3; a++)
            free(cand[a]);
        return ok || fail_oom(ps, 0);
    }
    uint32_t *cs_start = calloc((size_t)n_surf + 1, sizeof *cs_start);
    st.flags = calloc(sc->n_positions, 1);
    st.marked = malloc((size_t)sc->n_positions * sizeof *st.marked);
    ok = cs_start && st.flags && st.marked && stand_adjacency(&st);
    for (uint32_t k = 0; ok && k < n_surf; k++) {
        cs_start[k] = st.n_out;
        struct stand_surface s;
        struct dvec3 tri[3];
        if (st.work > CONTACT_MAX_WORK || !stand_surface_of(sc, k, &s, tri))
            continue;
        stand_mark_all(&st, k, &s, cand, n_cand, canon);
        ok = stand_finish(&st, &s);
        if (st.n_out - cs_start[k] > CONTACT_MAX)
            st.n_out = cs_start[k]; /* too many to test at every hit: none */
    }
    for (int a = 0; a < 3; a++)
        free(cand[a]);
    free(st.adj_start);
    free(st.adj);
    free(st.flags);
    free(st.marked);
    if (!ok) {
        free(cs_start);
        free(st.out);
        return fail_oom(ps, 0);
    }
    if (st.n_out == 0) {
        free(cs_start);
        free(st.out);
        return true;
    }
    cs_start[n_surf] = st.n_out;
    sc->contacts = st.out;
    sc->contact_start = cs_start;
    sc->n_contact_surfaces = n_surf;
    return true;
}

/* The load's passes over the triangles' shared corners: T-junctions closed (tj_pass), then the
 * grooves' factors (grooves), then where meshes stand on planes, quads and triangles
 * (contacts). */
static bool mesh_topology(struct parser *ps)
{
    struct scene *sc = ps->scene;
    if (!quads_to_triangles(ps))
        return false;
    uint32_t *canon = NULL;
    if (sc->n_tris > 0 && sc->n_tris < UINT32_MAX / 8 && sc->n_positions < UINT32_MAX / 4) {
        canon = weld_positions(sc); /* beyond that range no pass runs, every factor stays 1 */
        if (!canon)
            return fail_oom(ps, 0);
    }
    /* the edges as the file has them; listed again after each pass that split a triangle */
    uint32_t *start = NULL;
    struct groove_ent *ent = NULL;
    bool ok = !canon || edge_lists(sc, canon, &start, &ent);
    if (!ok) {
        free(canon);
        return fail_oom(ps, 0);
    }
    /* linear in the triangles, whatever the input: the passes together look at TJ_WORK list
     * entries an edge and add as many triangles as there were, 2^20 and 2^16 more */
    struct tj_budget budget = {TJ_WORK * 3 * (uint64_t)sc->n_tris + (1u << 20),
                               (uint64_t)sc->n_tris + (1u << 16)};
    bool split = canon != NULL;
    for (int pass = 0; ok && split && pass < TJ_PASSES; pass++) {
        ok = tj_pass(ps, canon, start, ent, &budget, &split);
        if (ok && split) {
            free(start);
            free(ent);
            start = NULL;
            ent = NULL;
            if (!edge_lists(sc, canon, &start, &ent))
                ok = fail_oom(ps, 0);
        }
    }
    ok = ok && grooves(ps, canon, start, ent) && contacts(ps, canon, start, ent);
    free(start);
    free(ent);
    free(canon);
    return ok;
}

/* ---- the light list ----------------------------------------------------------------------- */

/* Every emissive triangle of nonzero area, then emissive quads and spheres, then point lights
 * in file order. */
static bool build_lights(struct parser *ps)
{
    struct scene *sc = ps->scene;
    uint64_t n_max = (uint64_t)sc->n_tris + sc->n_quads + sc->n_spheres + ps->n_points;
    if (n_max == 0)
        return true;
    if (n_max > UINT32_MAX)
        return fail(ps, 0, "expected at most %u lights, got %llu", UINT32_MAX,
                    (unsigned long long)n_max);
    if ((size_t)n_max > SIZE_MAX / sizeof *sc->lights)
        return fail(ps, 0, "expected at most %zu lights, got %llu", SIZE_MAX / sizeof *sc->lights,
                    (unsigned long long)n_max);
    sc->lights = malloc((size_t)n_max * sizeof *sc->lights);
    if (!sc->lights)
        return fail(ps, 0, "expected memory for %llu lights, got an allocation failure",
                    (unsigned long long)n_max);
    for (uint32_t i = 0; i < sc->n_tris; i++) {
        const struct scene_tri *t = &sc->tris[i];
        vec3 p0 = sc->positions[t->v[0]];
        vec3 ng = v3_cross(v3_sub(sc->positions[t->v[1]], p0), v3_sub(sc->positions[t->v[2]], p0));
        if (is_emissive(&sc->materials[t->mat_idx]) && !v3_is_zero(ng))
            sc->lights[sc->n_lights++] = (struct light){.kind = LIGHT_TRIANGLE, .prim_idx = i};
    }
    for (uint32_t i = 0; i < sc->n_quads; i++)
        if (is_emissive(&sc->materials[sc->quads[i].mat_idx]))
            sc->lights[sc->n_lights++] = (struct light){.kind = LIGHT_QUAD, .prim_idx = i};
    for (uint32_t i = 0; i < sc->n_spheres; i++)
        if (is_emissive(&sc->materials[sc->spheres[i].mat_idx]))
            sc->lights[sc->n_lights++] = (struct light){.kind = LIGHT_SPHERE, .prim_idx = i};
    for (uint32_t i = 0; i < ps->n_points; i++)
        sc->lights[sc->n_lights++] = ps->points[i];
    return true;
}

/* ---- public API --------------------------------------------------------------------------- */

/* Parses the scene from the descriptor fd (-1: open path), named path in messages; the files
 * it names are relative to the first n_dir bytes of path (0: the working directory). */
static bool load(int fd, const char *path, size_t n_dir, struct scene *scene,
                 struct mcpt_error *err)
{
    struct mcpt_error err_local;
    struct parser ps = {.path = path,
                        .scene = scene,
                        .err = err ? err : &err_local,
                        .fd = fd,
                        .default_mat_idx = -1};
    char *line = NULL;
    bool ok = false;
    bool is_opened = fd < 0;
    memset(scene, 0, sizeof *scene);
    scene->file_hash = FILE_FNV_OFFSET;
    scene->width = 512;
    scene->height = 512;
    scene->render = (struct render_settings){.spp = 64,
                                             .max_depth = UINT32_MAX,
                                             .sampler = SAMPLER_DEFAULT,
                                             .adaptive_floor = -1.0f};

    /* a regular file, or a pipe (mcpt <(generate) reads /dev/fd/N); never a device, and open()
     * never waits for a FIFO's writer */
    const char *not_regular = NULL;
    if (is_opened)
        ps.fd = file_open_input(path, true, &not_regular);
    if (ps.fd < 0) {
        if (not_regular)
            mcpt_error_set(ps.err, path, 0, 0, "expected a regular file, got %s", not_regular);
        else
            mcpt_error_set(ps.err, path, 0, 0, "expected a readable file, got '%s'",
                           strerror(errno));
        goto done;
    }
    ps.dir = malloc(n_dir + 1);
    line = malloc(SCENE_MAX_LINE_BYTES + 1);
    ps.in = malloc(SCENE_READ_BYTES);
    if (!ps.dir || !line || !ps.in) {
        mcpt_error_runtime(ps.err, path, "out of memory");
        goto done;
    }
    memcpy(ps.dir, path, n_dir);
    ps.dir[n_dir] = '\0';

    ps.line = 1;
    if (!skip_byte_order_mark(&ps))
        goto done;
    ps.line = 0;
    for (;;) {
        if (ps.line == INT32_MAX) {
            fail(&ps, 0, "expected at most %d lines, got more", INT32_MAX);
            goto done;
        }
        ps.line++;
        int r = read_line(&ps, line);
        if (r < 0)
            goto done;
        if (r == 0)
            break;
        if (!parse_line(&ps, line))
            goto done;
    }
    ps.line = 0;
    if (!ps.seen_line[STMT_CAMERA]) {
        mcpt_error_set(ps.err, path, 0, 0, "expected a 'camera' statement, got none");
        goto done;
    }
    ok = mesh_topology(&ps) && build_lights(&ps);
done:
    if (ps.fd >= 0 && is_opened)
        close(ps.fd);
    free(line);
    free(ps.in);
    free(ps.dir);
    free(ps.mat_def_line);
    obj_names_free(&ps.mat_names);
    free(ps.points);
    if (!ok)
        scene_free(scene);
    return ok;
}

bool scene_load(const char *path, struct scene *scene, struct mcpt_error *err)
{
    const char *slash = strrchr(path, '/');
    return load(-1, path, slash ? (size_t)(slash - path) + 1 : 0, scene, err);
}

bool scene_load_stream(FILE *f, const char *name, struct scene *scene, struct mcpt_error *err)
{
    return load(fileno(f), name, 0, scene, err); /* read from the descriptor's offset */
}

void scene_free(struct scene *scene)
{
    free(scene->materials);
    free(scene->positions);
    free(scene->normals);
    free(scene->uvs);
    free(scene->tris);
    free(scene->tri_groove);
    free(scene->spheres);
    free(scene->quads);
    free(scene->planes);
    free(scene->contacts);
    free(scene->contact_start);
    free(scene->lights);
    for (uint32_t i = 0; i < scene->n_loaded; i++)
        free(scene->loaded_paths[i]);
    free(scene->loaded_paths);
    memset(scene, 0, sizeof *scene);
}
