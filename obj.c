/* obj.c - Wavefront OBJ and MTL reader (grammar: Wavefront, "Object Files (.obj)" and
 * "Material Library File (.mtl)", Advanced Visualizer manual, appendix B).  Each file is read
 * with one fread into a NUL-terminated buffer and parsed line by line in place; n-gons are
 * fan-triangulated from their first vertex.  Numbers: Clinger 1990, "How to Read Floating Point
 * Numbers Accurately", fast path (mantissa m <= 2^24 and 10^k with |k| <= 10 are exact floats,
 * so one IEEE multiply or divide rounds correctly); anything else goes to strtof.  Both give the
 * correctly rounded float, so the result is the same as strtof for every literal.
 * Columns in messages are 1-based byte offsets within the line (a tab counts as one). */
#include "obj.h"

#include <errno.h>
#include <limits.h>
#include <stdlib.h>

/* The subset read, as an example file:
 *
 *     mtllib box.mtl            # one or more MTL files, relative to this file's folder
 *     o box                     # o, g, s: accepted, arguments ignored
 *     v 0 0 0                   # position x y z [w] (or x y z r g b); w, rgb dropped
 *     vt 0.5 1                  # texture coordinate u [v [w]]; w dropped
 *     vn 0 0 1                  # normal, kept as written
 *     usemtl white              # material of the faces that follow (-1 if no mtllib has it)
 *     f 1 2 3                   # v
 *     f 1/1 2/1 3/1             # v/vt
 *     f 1//1 2//1 3//1          # v//vn
 *     f -4/1/1 -3/1/1 -2/1/1 -1/1/1   # v/vt/vn; -k = k-th last so far; quad -> 2 triangles
 *
 * An index must name an element defined above the face.  Any other statement whose keyword
 * starts with a letter (l, p, vp, cstype, ...) is skipped; a line starting with anything else
 * is an error.  In an MTL file: newmtl Ka Kd Ks Ke Tf (1 or 3 numbers), Ns Ni d Tr (1 number;
 * d = 1 - Tr), illum (integer 0..10); other keys (map_Kd, bump, Pr, ...) are skipped. */

#define OBJ_MAX_COUNT (UINT32_MAX - 1u) /* most positions or triangles one mesh may hold */
#define OBJ_MAX_ATTRIB_COUNT ((uint32_t)INT32_MAX) /* most vt, vn, materials: int32_t indices */
#define OBJ_PATH_BYTES 4096 /* longest resolved MTL path, bytes incl. NUL */
#define OBJ_SHOW_BYTES 48   /* longest token quoted in a message, bytes incl. NUL */

/* Where the parser stands in one NUL-terminated text buffer. */
struct cursor {
    const char *p;          /* next byte to read */
    const char *line_start; /* first byte of the current line; columns count from 1 here */
    const char *tok_end;    /* one past the last token read: where a missing token would go */
    int line;               /* 1-based line number */
    const char *path;       /* file named in messages */
    struct mcpt_error *err;
};

/* State of one obj_load call; the arrays grow inside *mesh. */
struct reader {
    struct obj_mesh *mesh;
    size_t cap_positions; /* allocated elements of mesh->positions */
    size_t cap_normals;
    size_t cap_uvs;
    size_t cap_tris;
    size_t cap_materials;
    int32_t mat_idx;    /* material of the last usemtl, or -1 */
    char **mtl_paths;   /* MTL files already read, so a repeated mtllib is read once */
    size_t n_mtl_paths;
    size_t cap_mtl_paths;
    const char *obj_path;
};

/* ---- lexing ---- */

/* Byte classes: a blank separates tokens; an end byte ends the statement (newline, the final
 * NUL, or a '#' comment).  A table, because the parser asks once per byte. */
enum { CH_BLANK = 1, CH_END = 2 };
static const unsigned char CHAR_CLASS[256] = {
    [' '] = CH_BLANK, ['\t'] = CH_BLANK, ['\r'] = CH_BLANK, ['\v'] = CH_BLANK, ['\f'] = CH_BLANK,
    ['\n'] = CH_END, ['\0'] = CH_END, ['#'] = CH_END,
};

static bool is_blank(char ch) { return CHAR_CLASS[(unsigned char)ch] & CH_BLANK; }

static bool is_end(char ch) { return CHAR_CLASS[(unsigned char)ch] & CH_END; }

static bool is_delim(char ch) { return CHAR_CLASS[(unsigned char)ch] != 0; }

static bool is_digit(char ch) { return ch >= '0' && ch <= '9'; }

static bool is_letter(char ch) { return (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z'); }

static void skip_blanks(struct cursor *c)
{
    while (is_blank(*c->p))
        c->p++;
}

static const char *token_end(const char *s)
{
    while (!is_delim(*s))
        s++;
    return s;
}

/* Moves to the first byte after the next newline (or to the final NUL). */
static void next_line(struct cursor *c)
{
    const char *nl = strchr(c->p, '\n');
    c->p = nl ? nl + 1 : c->p + strlen(c->p);
    c->line_start = c->p;
    if (c->line < INT_MAX)
        c->line++;
}

/* Writes [s, e) into out for a message: bytes outside printable ASCII as \xNN, cut with "..." */
static const char *show_span(const char *s, const char *e, char *out)
{
    size_t n = 0;
    for (; s < e; s++) {
        unsigned char ch = (unsigned char)*s;
        size_t need = (ch >= 0x20 && ch < 0x7f) ? 1 : 4;
        if (n + need + 4 > OBJ_SHOW_BYTES) {
            memcpy(out + n, "...", 3);
            n += 3;
            break;
        }
        if (need == 1)
            out[n] = (char)ch;
        else
            snprintf(out + n, 5, "\\x%02x", ch);
        n += need;
    }
    out[n] = '\0';
    return out;
}

static const char *show_token(const char *s, char *out) { return show_span(s, token_end(s), out); }

/* Fills c->err with the position of `at` on the current line; always returns false. */
static bool fail_at(const struct cursor *c, const char *at, const char *fmt, ...)
{
    char msg[sizeof c->err->msg];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    mcpt_error_set(c->err, c->path, c->line, (int)(at - c->line_start) + 1, "%s", msg);
    return false;
}

/* ---- helpers defined below the line parsers ---- */

static char *read_whole_file(const char *path, size_t *n_bytes, const char **step,
                             int *error_number);
static bool check_text(struct cursor *c, size_t n_bytes);
static bool check_keyword(const struct cursor *c, const char *kw);
static bool keyword_is(const char *kw, size_t len, const char *name);
static bool read_obj_text(struct reader *r, struct cursor *c);
static bool read_mtl_text(struct reader *r, struct cursor *c);
static bool read_v(struct reader *r, struct cursor *c, const char *kw);
static bool read_vt(struct reader *r, struct cursor *c, const char *kw);
static bool read_vn(struct reader *r, struct cursor *c, const char *kw);
static bool read_f(struct reader *r, struct cursor *c);
static bool read_usemtl(struct reader *r, struct cursor *c);
static bool read_mtllib(struct reader *r, struct cursor *c);
static bool read_newmtl(struct reader *r, struct cursor *c, uint32_t first_of_file);
static bool is_mtl_key(const char *kw, size_t len);
static bool read_mtl_color(struct cursor *c, const char *key, vec3 *out);
static bool read_mtl_scalar(struct cursor *c, const char *key, float *out);
static bool read_illum(struct cursor *c, int *out);
static int read_floats(struct cursor *c, float *vals, int n_max, const char **extra_at);
static bool parse_index(const char **s, int64_t *out);
static const char *count_error_at(const struct cursor *c, const char *extra_at);
static bool resolve_index(const struct cursor *c, const char *at, const char *at_end, int64_t idx,
                          uint32_t n, const char *what, const char *kw, uint32_t *out);
static void *grow(void *items, size_t *cap, size_t elem_bytes);
static bool fail_oom(const struct cursor *c, const char *at);
static bool push_vec3(struct cursor *c, const char *at, const char *kw, vec3 **items, uint32_t *n,
                      size_t *cap, uint32_t n_max, vec3 v);

/* ---- public ---- */

bool obj_load(const char *path, struct obj_mesh *mesh, struct mcpt_error *err)
{
    memset(mesh, 0, sizeof *mesh);
    struct reader r = {.mesh = mesh, .mat_idx = -1, .obj_path = path};
    bool ok = false;
    const char *step;
    int error_number = 0;
    size_t n_bytes = 0;
    char *text = read_whole_file(path, &n_bytes, &step, &error_number);
    if (!text) {
        mcpt_error_set(err, path, 0, 0, "cannot %s: %s", step, strerror(error_number));
        goto done;
    }
    struct cursor c = {.p = text, .line_start = text, .tok_end = text, .line = 1, .path = path,
                       .err = err};
    ok = check_text(&c, n_bytes) && read_obj_text(&r, &c);
done:
    free(text);
    for (size_t i = 0; i < r.n_mtl_paths; i++)
        free(r.mtl_paths[i]);
    free(r.mtl_paths);
    if (!ok)
        obj_free(mesh);
    return ok;
}

void obj_free(struct obj_mesh *mesh)
{
    free(mesh->positions);
    free(mesh->normals);
    free(mesh->uvs);
    free(mesh->tris);
    free(mesh->materials);
    memset(mesh, 0, sizeof *mesh);
}

/* ---- line parsers ---- */

/* The OBJ line loop: one statement per line. */
static bool read_obj_text(struct reader *r, struct cursor *c)
{
    for (; *c->p; next_line(c)) {
        skip_blanks(c);
        if (is_end(*c->p))
            continue;
        const char *kw = c->p;
        c->p = c->tok_end = token_end(kw);
        size_t len = (size_t)(c->p - kw);
        bool ok = true;
        if (keyword_is(kw, len, "v"))
            ok = read_v(r, c, kw);
        else if (keyword_is(kw, len, "f"))
            ok = read_f(r, c);
        else if (keyword_is(kw, len, "vn"))
            ok = read_vn(r, c, kw);
        else if (keyword_is(kw, len, "vt"))
            ok = read_vt(r, c, kw);
        else if (keyword_is(kw, len, "usemtl"))
            ok = read_usemtl(r, c);
        else if (keyword_is(kw, len, "mtllib"))
            ok = read_mtllib(r, c);
        else
            ok = check_keyword(c, kw); /* o g s and statements mcpt does not use: skipped */
        if (!ok)
            return false;
    }
    return true;
}

/* The MTL line loop: keys fill the record of the last newmtl of this file. */
static bool read_mtl_text(struct reader *r, struct cursor *c)
{
    struct obj_mesh *m = r->mesh;
    const uint32_t first_of_file = m->n_materials;
    for (; *c->p; next_line(c)) {
        skip_blanks(c);
        if (is_end(*c->p))
            continue;
        const char *kw = c->p;
        c->p = c->tok_end = token_end(kw);
        size_t len = (size_t)(c->p - kw);
        struct obj_material *mat =
            m->n_materials > first_of_file ? &m->materials[m->n_materials - 1] : NULL;
        char tok[OBJ_SHOW_BYTES];
        vec3 ka;
        float tr;
        bool ok;
        if (keyword_is(kw, len, "newmtl"))
            ok = read_newmtl(r, c, first_of_file);
        else if (!check_keyword(c, kw))
            ok = false;
        else if (!is_mtl_key(kw, len))
            ok = true; /* map_Kd, bump, Pr, ...: not used by mcpt */
        else if (!mat)
            ok = fail_at(c, kw, "expected 'newmtl', got '%s' before any material",
                         show_token(kw, tok));
        else if (keyword_is(kw, len, "Ka"))
            ok = read_mtl_color(c, "Ka", &ka); /* ambient: checked, unused */
        else if (keyword_is(kw, len, "Kd"))
            ok = read_mtl_color(c, "Kd", &mat->Kd);
        else if (keyword_is(kw, len, "Ks"))
            ok = read_mtl_color(c, "Ks", &mat->Ks);
        else if (keyword_is(kw, len, "Ke"))
            ok = read_mtl_color(c, "Ke", &mat->Ke);
        else if (keyword_is(kw, len, "Tf"))
            ok = read_mtl_color(c, "Tf", &mat->Tf);
        else if (keyword_is(kw, len, "Ns"))
            ok = read_mtl_scalar(c, "Ns", &mat->Ns);
        else if (keyword_is(kw, len, "Ni"))
            ok = read_mtl_scalar(c, "Ni", &mat->Ni);
        else if (keyword_is(kw, len, "d"))
            ok = read_mtl_scalar(c, "d", &mat->d);
        else if (keyword_is(kw, len, "Tr")) {
            ok = read_mtl_scalar(c, "Tr", &tr); /* transparency: d = 1 - Tr */
            mat->d = 1.0f - tr;
        } else
            ok = read_illum(c, &mat->illum);
        if (!ok)
            return false;
    }
    return true;
}

/* ---- OBJ statements ---- */

/* v x y z [w]  or  v x y z r g b */
static bool read_v(struct reader *r, struct cursor *c, const char *kw)
{
    float x[6];
    const char *extra_at;
    int n = read_floats(c, x, 6, &extra_at);
    if (n < 0)
        return false;
    if (n < 3)
        return fail_at(c, count_error_at(c, extra_at), "expected 3 numbers after 'v', got %d", n);
    if (n == 5 || n > 6)
        return fail_at(c, count_error_at(c, extra_at),
                       "expected 3, 4 or 6 numbers after 'v', got %d", n);
    struct obj_mesh *m = r->mesh;
    return push_vec3(c, kw, "v", &m->positions, &m->n_positions, &r->cap_positions,
                     OBJ_MAX_COUNT, v3(x[0], x[1], x[2]));
}

/* vn x y z */
static bool read_vn(struct reader *r, struct cursor *c, const char *kw)
{
    float x[3];
    const char *extra_at;
    int n = read_floats(c, x, 3, &extra_at);
    if (n < 0)
        return false;
    if (n != 3)
        return fail_at(c, count_error_at(c, extra_at), "expected 3 numbers after 'vn', got %d", n);
    struct obj_mesh *m = r->mesh;
    return push_vec3(c, kw, "vn", &m->normals, &m->n_normals, &r->cap_normals,
                     OBJ_MAX_ATTRIB_COUNT, v3(x[0], x[1], x[2]));
}

/* vt u [v [w]] */
static bool read_vt(struct reader *r, struct cursor *c, const char *kw)
{
    float x[3] = {0.0f, 0.0f, 0.0f};
    const char *extra_at;
    int n = read_floats(c, x, 3, &extra_at);
    if (n < 0)
        return false;
    if (n < 1 || n > 3)
        return fail_at(c, count_error_at(c, extra_at), "expected 1 to 3 numbers after 'vt', got %d",
                       n);
    struct obj_mesh *m = r->mesh;
    if (m->n_uvs >= OBJ_MAX_ATTRIB_COUNT)
        return fail_at(c, kw, "expected at most %u 'vt' statements, got more",
                       (unsigned)OBJ_MAX_ATTRIB_COUNT);
    if (m->n_uvs == r->cap_uvs) {
        vec2 *grown = grow(m->uvs, &r->cap_uvs, sizeof *grown);
        if (!grown)
            return fail_oom(c, kw);
        m->uvs = grown;
    }
    m->uvs[m->n_uvs++] = (vec2){x[0], x[1]};
    return true;
}

/* One face corner after index resolution. */
struct corner {
    uint32_t v;
    int32_t vt; /* -1: none */
    int32_t vn; /* -1: none */
};

/* Reads one corner "v", "v/vt", "v//vn" or "v/vt/vn" at c->p and resolves its indices
 * against the counts so far. */
static bool read_corner(struct reader *r, struct cursor *c, struct corner *out)
{
    const struct obj_mesh *m = r->mesh;
    const char *ref = c->p;
    const char *s = ref;
    const char *at_v = s, *at_vt = NULL, *at_vn = NULL;
    const char *end_v = NULL, *end_vt = NULL, *end_vn = NULL;
    int64_t iv = 0, ivt = 0, ivn = 0;
    bool ok = parse_index(&s, &iv);
    end_v = s;
    if (ok && *s == '/') {
        s++;
        if (*s != '/') {
            at_vt = s;
            ok = parse_index(&s, &ivt);
            end_vt = s;
        }
        if (ok && *s == '/') {
            s++;
            at_vn = s;
            ok = parse_index(&s, &ivn);
            end_vn = s;
        }
    }
    if (!ok || !is_delim(*s)) {
        char tok[OBJ_SHOW_BYTES];
        return fail_at(c, ref, "expected a vertex of the form v, v/vt, v//vn or v/vt/vn, got '%s'",
                       show_token(ref, tok));
    }
    uint32_t idx = 0;
    if (!resolve_index(c, at_v, end_v, iv, m->n_positions, "vertex", "v", &out->v))
        return false;
    out->vt = -1;
    if (at_vt) {
        if (!resolve_index(c, at_vt, end_vt, ivt, m->n_uvs, "texture", "vt", &idx))
            return false;
        out->vt = (int32_t)idx;
    }
    out->vn = -1;
    if (at_vn) {
        if (!resolve_index(c, at_vn, end_vn, ivn, m->n_normals, "normal", "vn", &idx))
            return false;
        out->vn = (int32_t)idx;
    }
    c->p = s;
    c->tok_end = s;
    return true;
}

/* Appends triangle (k0, k1, k2) with the active material; `at`: the corner that closed it. */
static bool push_tri(struct reader *r, struct cursor *c, const char *at, const struct corner *k0,
                     const struct corner *k1, const struct corner *k2)
{
    struct obj_mesh *m = r->mesh;
    if (m->n_tris >= OBJ_MAX_COUNT)
        return fail_at(c, at, "expected at most %u triangles, got more", (unsigned)OBJ_MAX_COUNT);
    if (m->n_tris == r->cap_tris) {
        struct obj_tri *grown = grow(m->tris, &r->cap_tris, sizeof *grown);
        if (!grown)
            return fail_oom(c, at);
        m->tris = grown;
    }
    m->tris[m->n_tris++] = (struct obj_tri){
        .v = {k0->v, k1->v, k2->v},
        .vt = {k0->vt, k1->vt, k2->vt},
        .vn = {k0->vn, k1->vn, k2->vn},
        .mat_idx = r->mat_idx,
        .line = (uint32_t)c->line,
    };
    return true;
}

/* f c0 c1 c2 ... cn-1  ->  triangles (c0, c_i, c_i+1) for i = 1..n-2, in that order */
static bool read_f(struct reader *r, struct cursor *c)
{
    struct corner first = {0, -1, -1}, prev = first, cur = first;
    size_t n_corners = 0;
    for (;;) {
        skip_blanks(c);
        if (is_end(*c->p))
            break;
        const char *at = c->p;
        if (!read_corner(r, c, &cur))
            return false;
        if (n_corners >= 2 && !push_tri(r, c, at, &first, &prev, &cur))
            return false;
        if (n_corners == 0)
            first = cur;
        prev = cur;
        n_corners++;
    }
    if (n_corners < 3)
        return fail_at(c, c->tok_end, "expected at least 3 vertices after 'f', got %zu",
                       n_corners);
    return true;
}

/* The rest of the line after a keyword, blanks and any '#' comment trimmed off. */
static size_t read_rest(struct cursor *c, const char **text)
{
    skip_blanks(c);
    const char *s = c->p;
    const char *e = s;
    while (!is_end(*e))
        e++;
    c->p = e;
    while (e > s && is_blank(e[-1]))
        e--;
    *text = s;
    return (size_t)(e - s);
}

/* Index of the material called [name, name + len), or -1. */
static int32_t find_material(const struct obj_mesh *m, const char *name, size_t len)
{
    for (uint32_t i = 0; i < m->n_materials; i++) {
        if (strlen(m->materials[i].name) == len && memcmp(m->materials[i].name, name, len) == 0)
            return (int32_t)i;
    }
    return -1;
}

/* usemtl name: later faces get this material, or -1 when no mtllib so far defined it */
static bool read_usemtl(struct reader *r, struct cursor *c)
{
    const char *name;
    size_t len = read_rest(c, &name);
    if (len == 0)
        return fail_at(c, c->tok_end, "expected a material name after 'usemtl', got end of line");
    r->mat_idx = find_material(r->mesh, name, len);
    return true;
}

/* mtllib a.mtl [b.mtl ...]: each name is relative to the OBJ's folder unless it starts '/' */
static bool read_mtllib(struct reader *r, struct cursor *c)
{
    const char *slash = strrchr(r->obj_path, '/');
    size_t dir_len = slash ? (size_t)(slash - r->obj_path) + 1 : 0;
    size_t n_names = 0;
    for (;;) {
        skip_blanks(c);
        if (is_end(*c->p))
            break;
        const char *name = c->p;
        const char *name_end = token_end(name);
        c->p = c->tok_end = name_end;
        n_names++;

        char mtl_path[OBJ_PATH_BYTES];
        size_t name_len = (size_t)(name_end - name);
        size_t prefix_len = name[0] == '/' ? 0 : dir_len;
        if (prefix_len + name_len >= sizeof mtl_path)
            return fail_at(c, name, "expected an MTL path shorter than %d bytes, got %zu bytes",
                           OBJ_PATH_BYTES, prefix_len + name_len);
        memcpy(mtl_path, r->obj_path, prefix_len);
        memcpy(mtl_path + prefix_len, name, name_len);
        mtl_path[prefix_len + name_len] = '\0';

        bool is_read_already = false;
        for (size_t i = 0; i < r->n_mtl_paths; i++)
            is_read_already = is_read_already || strcmp(r->mtl_paths[i], mtl_path) == 0;
        if (is_read_already)
            continue;
        if (r->n_mtl_paths == r->cap_mtl_paths) {
            char **grown = grow(r->mtl_paths, &r->cap_mtl_paths, sizeof *grown);
            if (!grown)
                return fail_oom(c, name);
            r->mtl_paths = grown;
        }
        char *copy = malloc(prefix_len + name_len + 1);
        if (!copy)
            return fail_oom(c, name);
        memcpy(copy, mtl_path, prefix_len + name_len + 1);
        r->mtl_paths[r->n_mtl_paths++] = copy;

        const char *step;
        int error_number = 0;
        size_t n_bytes = 0;
        char *text = read_whole_file(mtl_path, &n_bytes, &step, &error_number);
        if (!text)
            return fail_at(c, name, "cannot %s '%s': %s", step, mtl_path, strerror(error_number));
        struct cursor mc = {.p = text, .line_start = text, .tok_end = text, .line = 1,
                            .path = mtl_path, .err = c->err};
        bool ok = check_text(&mc, n_bytes) && read_mtl_text(r, &mc);
        free(text);
        if (!ok)
            return false;
    }
    if (n_names == 0)
        return fail_at(c, c->tok_end, "expected an MTL file name after 'mtllib', got end of line");
    return true;
}

/* ---- MTL ---- */

/* newmtl name: a new record with the defaults documented in obj.h */
static bool read_newmtl(struct reader *r, struct cursor *c, uint32_t first_of_file)
{
    struct obj_mesh *m = r->mesh;
    const char *name;
    size_t len = read_rest(c, &name);
    char tok[OBJ_SHOW_BYTES];
    if (len == 0)
        return fail_at(c, c->tok_end, "expected a material name after 'newmtl', got end of line");
    if (len >= sizeof m->materials[0].name)
        return fail_at(c, name, "expected a material name of at most %zu bytes, got %zu bytes",
                       sizeof m->materials[0].name - 1, len);
    int32_t old_idx = find_material(m, name, len);
    if (old_idx >= 0 && (uint32_t)old_idx >= first_of_file)
        return fail_at(c, name, "expected a new material name, got '%s' (already defined at "
                       "line %d)", show_span(name, name + len, tok), m->materials[old_idx].line);
    if (old_idx >= 0)
        return fail_at(c, name, "expected a new material name, got '%s' (already defined by an "
                       "earlier mtllib)", show_span(name, name + len, tok));
    if (m->n_materials >= OBJ_MAX_ATTRIB_COUNT)
        return fail_at(c, name, "expected at most %u materials, got more",
                       (unsigned)OBJ_MAX_ATTRIB_COUNT);
    if (m->n_materials == r->cap_materials) {
        struct obj_material *grown = grow(m->materials, &r->cap_materials, sizeof *grown);
        if (!grown)
            return fail_oom(c, name);
        m->materials = grown;
    }
    struct obj_material *mat = &m->materials[m->n_materials++];
    *mat = (struct obj_material){
        .Kd = v3_splat(0.8f),
        .Ks = v3_splat(0.0f),
        .Ke = v3_splat(0.0f),
        .Tf = v3_splat(1.0f),
        .Ns = 0.0f,
        .Ni = 1.0f,
        .d = 1.0f,
        .illum = 2,
        .line = c->line,
    };
    memcpy(mat->name, name, len);
    mat->name[len] = '\0';
    return true;
}

/* Ka/Kd/Ks/Ke/Tf r [g b]: one number means grey (g = b = r) */
static bool read_mtl_color(struct cursor *c, const char *key, vec3 *out)
{
    float x[3];
    const char *extra_at;
    int n = read_floats(c, x, 3, &extra_at);
    if (n < 0)
        return false;
    if (n != 1 && n != 3)
        return fail_at(c, count_error_at(c, extra_at), "expected 1 or 3 numbers after '%s', got %d",
                       key, n);
    *out = n == 1 ? v3_splat(x[0]) : v3(x[0], x[1], x[2]);
    return true;
}

/* Ns/Ni/d/Tr/illum value */
static bool read_mtl_scalar(struct cursor *c, const char *key, float *out)
{
    const char *extra_at;
    int n = read_floats(c, out, 1, &extra_at);
    if (n < 0)
        return false;
    if (n != 1)
        return fail_at(c, count_error_at(c, extra_at), "expected 1 number after '%s', got %d", key,
                       n);
    return true;
}

/* illum n: an illumination model number 0..10 */
static bool read_illum(struct cursor *c, int *out)
{
    skip_blanks(c);
    const char *at = c->p;
    float x;
    if (!read_mtl_scalar(c, "illum", &x))
        return false;
    char tok[OBJ_SHOW_BYTES];
    if (!(x >= 0.0f && x <= 10.0f && x == floorf(x)))
        return fail_at(c, at, "expected an integer 0..10 after 'illum', got '%s'",
                       show_token(at, tok));
    *out = (int)x;
    return true;
}

static bool is_mtl_key(const char *kw, size_t len)
{
    static const char *const keys[] = {"Ka", "Kd", "Ks", "Ke", "Tf",
                                       "Ns", "Ni", "d",  "Tr", "illum"};
    for (size_t i = 0; i < sizeof keys / sizeof keys[0]; i++) {
        if (keyword_is(kw, len, keys[i]))
            return true;
    }
    return false;
}

/* Reads the whole file into a malloc'd NUL-terminated buffer of *n_bytes + 1 bytes.  On
 * failure returns NULL with *step = "open" or "read" and *error_number an errno value. */
static char *read_whole_file(const char *path, size_t *n_bytes, const char **step,
                             int *error_number)
{
    char *text = NULL;
    *step = "open";
    errno = 0;
    FILE *f = fopen(path, "rb");
    if (!f)
        goto fail;
    *step = "read";
    /* probe one byte first: a directory opens, then fails here with EISDIR, while its
     * ftell(SEEK_END) size would be meaningless */
    if (fgetc(f) == EOF && ferror(f))
        goto fail;
    long size = -1;
    if (fseek(f, 0, SEEK_END) != 0 || (size = ftell(f)) < 0 || fseek(f, 0, SEEK_SET) != 0)
        goto fail;
    if ((unsigned long)size >= SIZE_MAX) {
        errno = EFBIG;
        goto fail;
    }
    text = malloc((size_t)size + 1);
    if (!text) {
        errno = ENOMEM;
        goto fail;
    }
    if (fread(text, 1, (size_t)size, f) != (size_t)size) {
        if (!ferror(f))
            errno = EIO; /* the file shrank while we read it */
        goto fail;
    }
    text[size] = '\0';
    *n_bytes = (size_t)size;
    fclose(f);
    return text;
fail:
    *error_number = errno ? errno : EIO;
    free(text);
    if (f)
        fclose(f);
    return NULL;
}

/* Rejects NUL bytes (binary input) and skips a UTF-8 byte order mark. */
static bool check_text(struct cursor *c, size_t n_bytes)
{
    const char *text = c->p;
    const char *nul = memchr(text, '\0', n_bytes);
    if (nul) {
        for (const char *s = text; s < nul; s++) {
            if (*s == '\n') {
                c->line++;
                c->line_start = s + 1;
            }
        }
        return fail_at(c, nul, "expected text, got a NUL byte");
    }
    if (n_bytes >= 3 && memcmp(text, "\xef\xbb\xbf", 3) == 0)
        c->p = c->line_start = text + 3;
    return true;
}

/* A statement keyword must start with a letter; anything else is not OBJ/MTL text. */
static bool check_keyword(const struct cursor *c, const char *kw)
{
    char tok[OBJ_SHOW_BYTES];
    if (!is_letter(kw[0]))
        return fail_at(c, kw, "expected a statement keyword, got '%s'", show_token(kw, tok));
    return true;
}

static bool keyword_is(const char *kw, size_t len, const char *name)
{
    return strlen(name) == len && memcmp(kw, name, len) == 0;
}

/* ---- numbers ---- */

/* 10^k for k = 0..10: every one is an exact float (10^10 = 2^10 * 5^10, 5^10 < 2^24). */
static const float POW10_EXACT[] = {1e0f, 1e1f, 1e2f, 1e3f, 1e4f, 1e5f,
                                    1e6f, 1e7f, 1e8f, 1e9f, 1e10f};

/* Clinger 1990 fast path for [sign] digits [. digits] [e [sign] digits] at s, ending at a
 * blank or end byte (*end is set there): when the decimal mantissa m <= 2^24 and the power of
 * ten |k| <= 10, m and 10^|k| are exact floats and m * 10^k (or m / 10^-k) is one correctly
 * rounded IEEE operation.  Returns false for any other form, which strtof then reads. */
static bool parse_float_fast(const char *s, const char **end, float *out)
{
    const uint64_t m_max = 1u << 24; /* every integer up to 2^24 is an exact float */
    bool is_negative = false;
    if (*s == '+' || *s == '-')
        is_negative = *s++ == '-';
    uint64_t m = 0;
    int k = 0;
    int n_digits = 0;
    for (; is_digit(*s); s++, n_digits++) {
        m = m * 10u + (uint64_t)(*s - '0');
        if (m > m_max)
            return false;
    }
    if (*s == '.') {
        for (s++; is_digit(*s); s++, n_digits++, k--) {
            m = m * 10u + (uint64_t)(*s - '0');
            if (m > m_max)
                return false;
        }
    }
    if (n_digits == 0)
        return false;
    if (*s == 'e' || *s == 'E') {
        s++;
        bool is_exp_negative = false;
        if (*s == '+' || *s == '-')
            is_exp_negative = *s++ == '-';
        if (!is_digit(*s))
            return false;
        int exp10 = 0;
        for (; is_digit(*s); s++) {
            exp10 = exp10 * 10 + (*s - '0');
            if (exp10 > 100)
                return false;
        }
        k += is_exp_negative ? -exp10 : exp10;
    }
    if (!is_delim(*s) || k < -10 || k > 10)
        return false;
    float f = (float)m;
    f = k < 0 ? f / POW10_EXACT[-k] : f * POW10_EXACT[k];
    *out = is_negative ? -f : f;
    *end = s;
    return true;
}

/* Reads the token at c->p as a finite float; NaN, Inf and overflowing literals are errors. */
static bool read_float(struct cursor *c, float *out)
{
    const char *s = c->p;
    const char *e;
    if (!parse_float_fast(s, &e, out)) {
        char tok[OBJ_SHOW_BYTES];
        char *strtof_end = NULL;
        *out = strtof(s, &strtof_end); /* stops at e or before: blanks, '#', '\n' end numbers */
        e = token_end(s);
        if (strtof_end != e)
            return fail_at(c, s, "expected a number, got '%s'", show_token(s, tok));
        if (!isfinite(*out))
            return fail_at(c, s, "expected a finite number, got '%s'", show_token(s, tok));
    }
    c->p = e;
    c->tok_end = e;
    return true;
}

/* Reads every token up to the end of the line as a float into vals[0..n_max-1].  Returns the
 * number of tokens, extras counted but not read (*extra_at: the first extra one, else NULL),
 * or -1 after a bad number.  c->tok_end is left after the last number read. */
static int read_floats(struct cursor *c, float *vals, int n_max, const char **extra_at)
{
    int n = 0;
    *extra_at = NULL;
    for (;;) {
        skip_blanks(c);
        if (is_end(*c->p))
            return n;
        if (n >= n_max) {
            if (!*extra_at)
                *extra_at = c->p;
            c->p = token_end(c->p);
        } else if (!read_float(c, &vals[n])) {
            return -1;
        }
        if (n < INT_MAX)
            n++;
    }
}

/* Where a count error points: the first token too many, else where the missing one belongs. */
static const char *count_error_at(const struct cursor *c, const char *extra_at)
{
    return extra_at ? extra_at : c->tok_end;
}

/* Reads [sign] digits at *s as an OBJ index; *s moves past them.  Magnitudes beyond 2^40
 * saturate (they are out of range anyway).  Returns false if there is no digit. */
static bool parse_index(const char **s, int64_t *out)
{
    const char *p = *s;
    bool is_negative = false;
    if (*p == '+' || *p == '-')
        is_negative = *p++ == '-';
    if (!is_digit(*p))
        return false;
    int64_t v = 0;
    for (; is_digit(*p); p++) {
        if (v < ((int64_t)1 << 40))
            v = v * 10 + (*p - '0');
    }
    *out = is_negative ? -v : v;
    *s = p;
    return true;
}

/* OBJ index -> 0-based: 1..n count from the first element, -1..-n back from the last one
 * defined so far.  what/kw name the element in the message ("vertex", "v"). */
static bool resolve_index(const struct cursor *c, const char *at, const char *at_end, int64_t idx,
                          uint32_t n, const char *what, const char *kw, uint32_t *out)
{
    if (idx > 0 && idx <= (int64_t)n) {
        *out = (uint32_t)(idx - 1);
        return true;
    }
    if (idx < 0 && -idx <= (int64_t)n) {
        *out = (uint32_t)((int64_t)n + idx);
        return true;
    }
    char tok[OBJ_SHOW_BYTES];
    show_span(at, at_end, tok);
    if (n == 0)
        return fail_at(c, at, "expected a %s index, got %s before any '%s' statement", what, tok,
                       kw);
    return fail_at(c, at, "expected a %s index in 1..%u or -%u..-1, got %s", what, (unsigned)n,
                   (unsigned)n, tok);
}

/* ---- growth: capacity doubles, so n appends cost O(n) ---- */

/* Returns items reallocated to twice *cap elements (64 at first), or NULL when out of memory or
 * when the size would overflow; *cap is updated on success. */
static void *grow(void *items, size_t *cap, size_t elem_bytes)
{
    size_t new_cap = *cap ? *cap * 2 : 64;
    if (new_cap < *cap || new_cap > SIZE_MAX / elem_bytes)
        return NULL;
    void *grown = realloc(items, new_cap * elem_bytes);
    if (grown)
        *cap = new_cap;
    return grown;
}

static bool fail_oom(const struct cursor *c, const char *at)
{
    return fail_at(c, at, "out of memory");
}

/* Appends v to a vec3 array of *n elements (at most n_max) for statement kw at `at`. */
static bool push_vec3(struct cursor *c, const char *at, const char *kw, vec3 **items, uint32_t *n,
                      size_t *cap, uint32_t n_max, vec3 v)
{
    if (*n >= n_max)
        return fail_at(c, at, "expected at most %u '%s' statements, got more", (unsigned)n_max, kw);
    if (*n == *cap) {
        vec3 *grown = grow(*items, cap, sizeof *grown);
        if (!grown)
            return fail_oom(c, at);
        *items = grown;
    }
    (*items)[(*n)++] = v;
    return true;
}
