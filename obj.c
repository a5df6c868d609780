/* obj.c - Wavefront OBJ and MTL reader (grammar: Wavefront, "Object Files (.obj)" and
 * "Material Library File (.mtl)", Advanced Visualizer manual, appendix B).  A file is read in
 * chunks of whole lines (OBJ_CHUNK_BYTES), each chunk parsed in place as a NUL-terminated
 * buffer; n-gons are fan-triangulated from their first vertex.  Numbers: Clinger 1990, "How to
 * Read Floating Point Numbers Accurately", fast path (mantissa m <= 2^24 and 10^k with
 * |k| <= 10 are exact floats, so one IEEE multiply or divide rounds correctly); anything else
 * goes to strtof, so every literal reads as strtof reads it.  usemtl names resolve once the
 * whole file is read, through a hash table (FNV-1a; Fowler, Noll, Vo).
 * Columns in messages are 1-based byte offsets within the line (a tab counts as one). */
#include "obj.h"

#include <errno.h>
#include <float.h>
#include <fcntl.h>
#include <limits.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <unistd.h>

#include "file.h"

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
 *     f -4/1/1 -3/1/1 \
 *       -2/1/1 -1/1/1           # v/vt/vn; -k = k-th last so far; quad -> 2 triangles; a '\'
 *                               # before the line end continues the statement on the next line
 *
 * An index must name an element defined above the face.  Any other statement whose keyword
 * starts with a letter (l, p, vp, cstype, ...) is skipped; a line starting with anything else
 * is an error.  In an MTL file: newmtl; Ka Kd Ks Ke Tf as r [g b], "xyz x [y z]" (CIE XYZ,
 * converted to linear sRGB) or "spectral file.rfl [factor]" (ignored, with a warning); Ns Ni
 * d Tr (1 number; d = 1 - Tr; "d -halo f" reads f); illum (integer 0..10); other keys (map_Kd,
 * bump, Pr, ...) are skipped. */

#define OBJ_MAX_COUNT (UINT32_MAX - 1u) /* most positions or triangles one mesh may hold */
#define OBJ_MAX_ATTRIB_COUNT ((uint32_t)INT32_MAX) /* most vt, vn, materials: int32_t indices */
#define OBJ_PATH_BYTES 4096                        /* longest resolved MTL path, bytes incl. NUL */
#define OBJ_SHOW_BYTES 48                 /* longest token quoted in a message, bytes incl. NUL */
#define OBJ_CHUNK_BYTES ((size_t)1 << 18) /* bytes read at a time: 256 KiB, about L2 size */
#define OBJ_MIN_CHUNK_BYTES ((size_t)1 << 12) /* the chunk of a file smaller than a chunk */
#define OBJ_MAX_LINE_BYTES                                                                         \
    ((size_t)1 << 24) /* longest statement, '\' continuations included:
                                                16 MiB, a face of ~1M corners */

/* Where the parser stands in one NUL-terminated chunk of text. */
struct cursor {
    const char *p;          /* next byte to read */
    const char *line_start; /* first byte of the current line; columns count from 1 here */
    const char *tok_end;    /* one past the last token read: where a missing token would go */
    int line;               /* 1-based line number of the current statement's first line */
    const char *path;       /* file named in messages */
    struct mcpt_error *err;
    /* line ends a '\' joined into the statement (now blanks), in order, for line numbers */
    const char **joins;
    size_t n_joins;
    size_t cap_joins;
    size_t join_idx; /* joins before this one lie in statements already read */
};

/* Where a warning points: the first place, and how many more times it happened. */
struct warn_site {
    char path[OBJ_PATH_BYTES];
    int line;
    int col;
    uint32_t n_more;
    bool is_set;
};

/* Where a usemtl name is first used, for a warning when no mtllib defines it. */
struct usemtl_site {
    int line;
    int col;
};

/* State of one obj_load call; the arrays grow inside *mesh. */
struct reader {
    struct obj_mesh *mesh;
    size_t cap_positions; /* allocated elements of mesh->positions */
    size_t cap_normals;
    size_t cap_uvs;
    size_t cap_tris;
    size_t cap_materials;
    int32_t usemtl_idx;               /* the last usemtl's name in usemtl_names, or -1 */
    struct obj_names usemtl_names;    /* every usemtl name, numbered in order of first use */
    struct usemtl_site *usemtl_sites; /* per usemtl name: where it is first used */
    size_t cap_usemtl_sites;
    struct obj_names mtl_names; /* newmtl name -> index into mesh->materials */
    struct obj_names mtl_paths; /* MTL paths already read, so a repeated mtllib is read once */
    struct obj_names mtl_files; /* and their "device:inode", for the same file by another name */
    uint32_t mtl_first;         /* index of the first record of the MTL file being read */
    bool has_mtllib;            /* the OBJ names at least one MTL file */
    struct warn_site spectral;  /* the first 'spectral' colour, ignored */
    char spectral_key[4];       /* its key: Ka, Kd, Ks, Ke, Tf */
    const char *obj_path;
};

/* ---- lexing ---- */

/* Byte classes: a blank separates tokens; an end byte ends the statement (newline, the final
 * NUL, or a '#' comment).  A table, because the parser asks once per byte. */
enum { CH_BLANK = 1, CH_END = 2 };
static const unsigned char CHAR_CLASS[256] = {
    [' '] = CH_BLANK,  ['\t'] = CH_BLANK, ['\r'] = CH_BLANK, ['\v'] = CH_BLANK,
    ['\f'] = CH_BLANK, ['\n'] = CH_END,   ['\0'] = CH_END,   ['#'] = CH_END,
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

/* Moves to the first byte after the next newline (or to the final NUL), counting the lines a
 * '\' joined into the statement just read. */
static void next_line(struct cursor *c)
{
    const char *nl = strchr(c->p, '\n');
    c->p = nl ? nl + 1 : c->p + strlen(c->p);
    c->line_start = c->p;
    if (c->line < INT_MAX)
        c->line++;
    for (; c->join_idx < c->n_joins && c->joins[c->join_idx] < c->p; c->join_idx++)
        if (c->line < INT_MAX)
            c->line++;
}

/* Writes [s, e) into out (out_bytes) for a message: bytes outside printable ASCII as \xNN, cut
 * with "..." */
static const char *show_span_n(const char *s, const char *e, char *out, size_t out_bytes)
{
    size_t n = 0;
    for (; s < e; s++) {
        unsigned char ch = (unsigned char)*s;
        size_t need = (ch >= 0x20 && ch < 0x7f) ? 1 : 4;
        if (n + need + 4 > out_bytes) {
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

static const char *show_span(const char *s, const char *e, char *out)
{
    return show_span_n(s, e, out, OBJ_SHOW_BYTES);
}

static const char *show_token(const char *s, char *out) { return show_span(s, token_end(s), out); }

/* The physical line and column of `at` in the current statement: past a joined line end the
 * line number grows and columns count from the byte after it. */
static void locate(const struct cursor *c, const char *at, int *line, int *col)
{
    const char *start = c->line_start;
    int n = c->line;
    for (size_t j = c->join_idx; j < c->n_joins && c->joins[j] < at; j++) {
        start = c->joins[j] + 1;
        if (n < INT_MAX)
            n++;
    }
    *line = n;
    *col = (int)(at - start) + 1;
}

/* Fills c->err with the position of `at` on the current line; always returns false. */
static bool fail_at(const struct cursor *c, const char *at, const char *fmt, ...)
{
    char msg[sizeof c->err->msg];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    int line, col;
    locate(c, at, &line, &col);
    mcpt_error_set(c->err, c->path, line, col, "%s", msg);
    return false;
}

/* ---- helpers defined below the line parsers ---- */

static bool read_file(struct reader *r, struct cursor *c, int fd, bool is_mtl);
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
static bool read_mtl_color(struct reader *r, struct cursor *c, const char *key, vec3 *out);
static bool read_mtl_scalar(struct cursor *c, const char *key, float *out);
static bool read_dissolve(struct cursor *c, float *out);
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
static bool resolve_usemtl(struct reader *r, struct mcpt_error *err);
static void add_warning(struct obj_mesh *m, const char *path, int line, int col, const char *fmt,
                        ...);
static void note_site(struct warn_site *w, const struct cursor *c, const char *at);
static bool keep_mtl_paths(struct obj_mesh *mesh, const struct obj_names *paths,
                           const char *obj_path, struct mcpt_error *err);

/* ---- public ---- */

bool obj_load(const char *path, struct obj_mesh *mesh, struct mcpt_error *err)
{
    const char *not_regular = NULL;
    int fd = file_open_input(path, false, &not_regular);
    if (fd < 0) {
        memset(mesh, 0, sizeof *mesh);
        if (not_regular)
            mcpt_error_set(err, path, 0, 0, "expected a regular file, got %s", not_regular);
        else
            mcpt_error_set(err, path, 0, 0, "cannot open: %s", strerror(errno));
        return false;
    }
    return obj_load_fd(fd, path, mesh, err);
}

bool obj_load_fd(int fd, const char *path, struct obj_mesh *mesh, struct mcpt_error *err)
{
    memset(mesh, 0, sizeof *mesh);
    struct reader r = {.mesh = mesh, .usemtl_idx = -1, .obj_path = path};
    struct cursor c = {.line = 1, .path = path, .err = err};
    bool ok = read_file(&r, &c, fd, false) && resolve_usemtl(&r, err);
    if (ok && r.spectral.is_set) {
        char more[64] = "";
        uint32_t n_more = r.spectral.n_more;
        if (n_more)
            snprintf(more, sizeof more, " (%u more 'spectral' colour%s ignored too)", n_more,
                     n_more == 1 ? "" : "s");
        add_warning(mesh, r.spectral.path, r.spectral.line, r.spectral.col,
                    "'%s spectral' ignored: mcpt reads no .rfl spectral curves, so %s keeps its "
                    "value%s",
                    r.spectral_key, r.spectral_key, more);
    }
    if (ok && r.mtl_paths.n_entries > 0)
        ok = keep_mtl_paths(mesh, &r.mtl_paths, path, err);
    free(c.joins);
    obj_names_free(&r.usemtl_names);
    obj_names_free(&r.mtl_names);
    obj_names_free(&r.mtl_paths);
    obj_names_free(&r.mtl_files);
    free(r.usemtl_sites);
    if (!ok)
        obj_free(mesh);
    return ok;
}

/* Copies the paths of the MTL files read into mesh->mtl_paths; false with *err (runtime, file
 * = obj_path) when out of memory. */
static bool keep_mtl_paths(struct obj_mesh *mesh, const struct obj_names *paths,
                           const char *obj_path, struct mcpt_error *err)
{
    mesh->mtl_paths = calloc(paths->n_entries, sizeof *mesh->mtl_paths);
    for (uint32_t i = 0; mesh->mtl_paths && i < paths->n_entries; i++) {
        const char *key = obj_names_key(paths, i);
        size_t n = strlen(key) + 1;
        if (!(mesh->mtl_paths[i] = malloc(n))) {
            mcpt_error_runtime(err, obj_path, "out of memory");
            return false; /* obj_free frees what was copied */
        }
        memcpy(mesh->mtl_paths[i], key, n);
        mesh->n_mtl_paths = i + 1;
    }
    if (!mesh->mtl_paths)
        mcpt_error_runtime(err, obj_path, "out of memory");
    return mesh->mtl_paths != NULL;
}

void obj_free(struct obj_mesh *mesh)
{
    free(mesh->positions);
    free(mesh->normals);
    free(mesh->uvs);
    free(mesh->tris);
    free(mesh->materials);
    for (uint32_t i = 0; i < mesh->n_mtl_paths; i++)
        free(mesh->mtl_paths[i]);
    free(mesh->mtl_paths);
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
    const uint32_t first_of_file = r->mtl_first; /* this MTL file's first record */
    for (; *c->p; next_line(c)) {
        skip_blanks(c);
        if (is_end(*c->p))
            continue;
        const char *kw = c->p;
        c->p = c->tok_end = token_end(kw);
        size_t len = (size_t)(c->p - kw);
        struct obj_material *mat = m->n_materials > first_of_file
                                       ? &m->materials[m->n_materials - 1]
                                       : NULL;
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
            ok = read_mtl_color(r, c, "Ka", &ka); /* ambient: checked, unused */
        else if (keyword_is(kw, len, "Kd"))
            ok = read_mtl_color(r, c, "Kd", &mat->Kd);
        else if (keyword_is(kw, len, "Ks"))
            ok = read_mtl_color(r, c, "Ks", &mat->Ks);
        else if (keyword_is(kw, len, "Ke"))
            ok = read_mtl_color(r, c, "Ke", &mat->Ke);
        else if (keyword_is(kw, len, "Tf"))
            ok = read_mtl_color(r, c, "Tf", &mat->Tf);
        else if (keyword_is(kw, len, "Ns"))
            ok = read_mtl_scalar(c, "Ns", &mat->Ns);
        else if (keyword_is(kw, len, "Ni"))
            ok = read_mtl_scalar(c, "Ni", &mat->Ni);
        else if (keyword_is(kw, len, "d"))
            ok = read_dissolve(c, &mat->d);
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
    return push_vec3(c, kw, "v", &m->positions, &m->n_positions, &r->cap_positions, OBJ_MAX_COUNT,
                     v3(x[0], x[1], x[2]));
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
    return push_vec3(c, kw, "vn", &m->normals, &m->n_normals, &r->cap_normals, OBJ_MAX_ATTRIB_COUNT,
                     v3(x[0], x[1], x[2]));
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
        .mat_idx = r->usemtl_idx, /* a usemtl name index until resolve_usemtl */
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
        return fail_at(c, c->tok_end, "expected at least 3 vertices after 'f', got %zu", n_corners);
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

/* usemtl name: later faces get this material.  Names resolve in resolve_usemtl, once every
 * mtllib is read; until then a face holds the index of its usemtl name. */
static bool read_usemtl(struct reader *r, struct cursor *c)
{
    const char *name;
    size_t len = read_rest(c, &name);
    if (len == 0)
        return fail_at(c, c->tok_end, "expected a material name after 'usemtl', got end of line");
    int64_t idx = obj_names_find(&r->usemtl_names, name, len);
    if (idx < 0) {
        uint32_t n = r->usemtl_names.n_entries;
        if (n >= OBJ_MAX_ATTRIB_COUNT || n >= OBJ_NAMES_MAX)
            return fail_at(c, name, "expected at most %u material names, got more",
                           (unsigned)OBJ_NAMES_MAX);
        if (n == r->cap_usemtl_sites) {
            struct usemtl_site *grown = grow(r->usemtl_sites, &r->cap_usemtl_sites, sizeof *grown);
            if (!grown)
                return fail_oom(c, name);
            r->usemtl_sites = grown;
        }
        if (!obj_names_add(&r->usemtl_names, name, len, n))
            return fail_oom(c, name);
        locate(c, name, &r->usemtl_sites[n].line, &r->usemtl_sites[n].col);
        idx = n;
    }
    r->usemtl_idx = (int32_t)idx;
    return true;
}

/* Reads the MTL file [name, name_end) names (relative to the OBJ's folder unless it starts
 * '/'), unless this OBJ read it already. */
static bool read_mtl_file(struct reader *r, struct cursor *c, const char *name,
                          const char *name_end)
{
    const char *slash = strrchr(r->obj_path, '/');
    size_t dir_len = slash ? (size_t)(slash - r->obj_path) + 1 : 0;
    char mtl_path[OBJ_PATH_BYTES];
    size_t name_len = (size_t)(name_end - name);
    size_t prefix_len = name[0] == '/' ? 0 : dir_len;
    if (prefix_len + name_len >= sizeof mtl_path)
        return fail_at(c, name, "expected an MTL path shorter than %d bytes, got %zu bytes",
                       OBJ_PATH_BYTES, prefix_len + name_len);
    memcpy(mtl_path, r->obj_path, prefix_len);
    memcpy(mtl_path + prefix_len, name, name_len);
    size_t path_len = prefix_len + name_len;
    mtl_path[path_len] = '\0';
    if (obj_names_find(&r->mtl_paths, mtl_path, path_len) >= 0)
        return true;
    if (!obj_names_add(&r->mtl_paths, mtl_path, path_len, 0))
        return fail_oom(c, name);

    char tok[OBJ_SHOW_BYTES], shown_path[OBJ_SHOW_BYTES * 3];
    show_span(name, name_end, tok);
    show_span_n(mtl_path, mtl_path + path_len, shown_path, sizeof shown_path);
    const char *not_regular = NULL;
    int fd = file_open_input(mtl_path, false, &not_regular);
    if (fd < 0 && not_regular)
        return fail_at(c, name, "expected a regular file for mtllib '%s' (%s), got %s", tok,
                       shown_path, not_regular);
    if (fd < 0)
        return fail_at(c, name, "cannot open mtllib '%s' (%s): %s", tok, shown_path,
                       strerror(errno));
    /* the same file under another name ("./a.mtl", a link) is read once too */
    struct stat st;
    if (fstat(fd, &st) == 0) {
        char key[48];
        int key_len = snprintf(key, sizeof key, "%llu:%llu", (unsigned long long)st.st_dev,
                               (unsigned long long)st.st_ino);
        if (obj_names_find(&r->mtl_files, key, (size_t)key_len) >= 0) {
            close(fd);
            return true;
        }
        if (!obj_names_add(&r->mtl_files, key, (size_t)key_len, 0)) {
            close(fd);
            return fail_oom(c, name);
        }
    }
    struct cursor mc = {.line = 1, .path = mtl_path, .err = c->err};
    r->mtl_first = r->mesh->n_materials;
    bool ok = read_file(r, &mc, fd, true);
    free(mc.joins);
    return ok;
}

/* mtllib a.mtl [b.mtl ...]: each file is read once.  When the whole rest of the line names a
 * regular file it is one name (Blender reads mtllib so, and exporters write names with
 * spaces), and double quotes around a name are dropped (Blender does too). */
static bool read_mtllib(struct reader *r, struct cursor *c)
{
    r->has_mtllib = true;
    const char *rest;
    size_t rest_len = read_rest(c, &rest);
    if (rest_len == 0)
        return fail_at(c, c->tok_end, "expected an MTL file name after 'mtllib', got end of line");
    const char *s = rest, *e = rest + rest_len;
    if (e - s > 2 && *s == '"' && e[-1] == '"') {
        s++;
        e--;
    }
    bool has_blank = false;
    for (const char *q = s; q < e; q++)
        has_blank |= is_blank(*q);
    if (has_blank) {
        const char *slash = strrchr(r->obj_path, '/');
        size_t dir_len = slash && *s != '/' ? (size_t)(slash - r->obj_path) + 1 : 0;
        char path[OBJ_PATH_BYTES];
        struct stat st;
        if (dir_len + (size_t)(e - s) < sizeof path) {
            memcpy(path, r->obj_path, dir_len);
            memcpy(path + dir_len, s, (size_t)(e - s));
            path[dir_len + (size_t)(e - s)] = '\0';
            if (stat(path, &st) == 0 && S_ISREG(st.st_mode))
                return read_mtl_file(r, c, s, e);
        }
    }
    for (const char *name = s; name < e;) {
        const char *name_end = name;
        while (name_end < e && !is_blank(*name_end))
            name_end++;
        const char *u = name, *v = name_end; /* the name without quotes */
        if (v - u > 2 && *u == '"' && v[-1] == '"') {
            u++;
            v--;
        }
        if (!read_mtl_file(r, c, u, v))
            return false;
        for (name = name_end; name < e && is_blank(*name); name++) {
        }
    }
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
    int64_t old_idx = obj_names_find(&r->mtl_names, name, len);
    if (old_idx >= 0 && (uint32_t)old_idx >= first_of_file)
        return fail_at(c, name,
                       "expected a new material name, got '%s' (already defined at "
                       "line %d)",
                       show_span(name, name + len, tok), m->materials[old_idx].line);
    if (old_idx >= 0)
        return fail_at(c, name,
                       "expected a new material name, got '%s' (already defined by an "
                       "earlier mtllib)",
                       show_span(name, name + len, tok));
    if (m->n_materials >= OBJ_MAX_ATTRIB_COUNT || m->n_materials >= OBJ_NAMES_MAX)
        return fail_at(c, name, "expected at most %u materials, got more", (unsigned)OBJ_NAMES_MAX);
    if (m->n_materials == r->cap_materials) {
        struct obj_material *grown = grow(m->materials, &r->cap_materials, sizeof *grown);
        if (!grown)
            return fail_oom(c, name);
        m->materials = grown;
    }
    if (!obj_names_add(&r->mtl_names, name, len, m->n_materials))
        return fail_oom(c, name);
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

/* CIE XYZ (D65 white) -> linear RGB on the sRGB / Rec. 709 primaries: the matrix of
 * IEC 61966-2-1:1999 (sRGB), to the 4 decimals the standard gives. */
static const double XYZ_TO_SRGB[3][3] = {
    {3.2406, -1.5372, -0.4986},
    {-0.9689, 1.8758, 0.0415},
    {0.0557, -0.2040, 1.0570},
};

/* Ka/Kd/Ks/Ke/Tf in one of the three forms of the MTL format:
 *   r [g b]                 linear RGB; one number is grey (g = b = r)
 *   xyz x [y z]             CIE XYZ, y = z = x when one is given; converted to linear sRGB
 *   spectral file [factor]  an .rfl curve: not read; the key keeps its value, with a warning */
static bool read_mtl_color(struct reader *r, struct cursor *c, const char *key, vec3 *out)
{
    skip_blanks(c);
    const char *form = c->p;
    const char *form_end = token_end(form);
    size_t form_len = (size_t)(form_end - form);
    float x[3];
    const char *extra_at;
    int n;
    if (keyword_is(form, form_len, "spectral")) {
        c->p = c->tok_end = form_end;
        skip_blanks(c);
        if (is_end(*c->p))
            return fail_at(c, c->tok_end,
                           "expected an .rfl file name after '%s spectral', got "
                           "end of line",
                           key);
        c->p = c->tok_end = token_end(c->p);
        if ((n = read_floats(c, x, 1, &extra_at)) < 0)
            return false;
        if (n > 1)
            return fail_at(c, extra_at,
                           "expected at most a factor after '%s spectral FILE', got "
                           "%d numbers",
                           key, n);
        if (!r->spectral.is_set)
            snprintf(r->spectral_key, sizeof r->spectral_key, "%s", key);
        note_site(&r->spectral, c, form);
        return true;
    }
    bool is_xyz = keyword_is(form, form_len, "xyz");
    if (is_xyz)
        c->p = c->tok_end = form_end;
    if ((n = read_floats(c, x, 3, &extra_at)) < 0)
        return false;
    if (n != 1 && n != 3)
        return fail_at(c, count_error_at(c, extra_at),
                       "expected 1 or 3 numbers after '%s%s', got "
                       "%d",
                       key, is_xyz ? " xyz" : "", n);
    if (n == 1)
        x[1] = x[2] = x[0];
    if (!is_xyz) {
        *out = v3(x[0], x[1], x[2]);
        return true;
    }
    /* rgb = M xyz, in double; each component must be a finite float */
    double rgb[3];
    for (int i = 0; i < 3; i++) {
        rgb[i] = XYZ_TO_SRGB[i][0] * x[0] + XYZ_TO_SRGB[i][1] * x[1] + XYZ_TO_SRGB[i][2] * x[2];
        if (!(fabs(rgb[i]) <= FLT_MAX))
            return fail_at(c, form,
                           "expected '%s xyz' values whose RGB is within float range "
                           "(|component| <= %g), got %g for %c",
                           key, (double)FLT_MAX, rgb[i], "RGB"[i]);
    }
    *out = v3((float)rgb[0], (float)rgb[1], (float)rgb[2]);
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

/* d factor, or "d -halo factor": a halo dissolve depends on the view, which mcpt does not
 * model, so d = factor */
static bool read_dissolve(struct cursor *c, float *out)
{
    skip_blanks(c);
    const char *e = token_end(c->p);
    if (keyword_is(c->p, (size_t)(e - c->p), "-halo"))
        c->p = c->tok_end = e;
    return read_mtl_scalar(c, "d", out);
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

/* ---- after the whole file: material names, warnings ---- */

/* Maps each usemtl name to the material of that name now that every mtllib is read (-1: no
 * mtllib defines it), rewrites the faces' name indices to material indices, and warns about
 * the first undefined name when the file names any mtllib. */
static bool resolve_usemtl(struct reader *r, struct mcpt_error *err)
{
    struct obj_mesh *m = r->mesh;
    uint32_t n = r->usemtl_names.n_entries;
    if (n == 0)
        return true;
    int32_t *mat_of = malloc((size_t)n * sizeof *mat_of);
    if (!mat_of) {
        mcpt_error_runtime(err, r->obj_path, "out of memory");
        return false;
    }
    uint32_t n_undefined = 0, first_undefined = 0;
    for (uint32_t i = 0; i < n; i++) {
        const struct obj_name_entry *e = &r->usemtl_names.entries[i];
        int64_t idx = obj_names_find(&r->mtl_names, obj_names_key(&r->usemtl_names, i),
                                     e->key_bytes);
        mat_of[e->value] = (int32_t)idx;
        if (idx < 0 && n_undefined++ == 0)
            first_undefined = e->value;
    }
    for (uint32_t i = 0; i < m->n_tris; i++)
        if (m->tris[i].mat_idx >= 0)
            m->tris[i].mat_idx = mat_of[m->tris[i].mat_idx];
    free(mat_of);
    if (n_undefined > 0 && r->has_mtllib) {
        char name[OBJ_SHOW_BYTES], more[64] = "";
        const char *key = obj_names_key(&r->usemtl_names, first_undefined);
        show_span(key, key + strlen(key), name);
        if (n_undefined > 1)
            snprintf(more, sizeof more, " (%u more usemtl name%s undefined too)", n_undefined - 1,
                     n_undefined == 2 ? " is" : "s are");
        add_warning(m, r->obj_path, r->usemtl_sites[first_undefined].line,
                    r->usemtl_sites[first_undefined].col,
                    "usemtl '%s': no mtllib defines it, so its faces get the default material%s",
                    name, more);
    }
    return true;
}

/* Appends "path:line:col: warning: msg" to the mesh's warnings (counted once they are full). */
static void add_warning(struct obj_mesh *m, const char *path, int line, int col, const char *fmt,
                        ...)
{
    if (m->n_warnings < OBJ_MAX_WARNINGS) {
        char msg[256]; /* as struct mcpt_error.msg */
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(msg, sizeof msg, fmt, ap);
        va_end(ap);
        snprintf(m->warnings[m->n_warnings], OBJ_WARNING_BYTES, "%s:%d:%d: warning: %s", path, line,
                 col, msg);
    }
    if (m->n_warnings < UINT32_MAX)
        m->n_warnings++;
}

/* Records `at` as where a warning points, or counts one more time when it has a place. */
static void note_site(struct warn_site *w, const struct cursor *c, const char *at)
{
    if (w->is_set) {
        if (w->n_more < UINT32_MAX)
            w->n_more++;
        return;
    }
    snprintf(w->path, sizeof w->path, "%s", c->path);
    locate(c, at, &w->line, &w->col);
    w->is_set = true;
}

/* ---- reading a file in chunks ---- */

/* Does the line that ends at the newline buf[nl] end in '\' (blanks may follow it)? */
static bool is_continued(const char *buf, size_t lo, size_t nl)
{
    size_t s = nl;
    while (s > lo && is_blank(buf[s - 1]))
        s--;
    return s > lo && buf[s - 1] == '\\';
}

/* The first byte of the statement that holds buf[pos] (or starts there): past the last line
 * end before pos that no '\' continues; lo when there is none after lo. */
static size_t statement_start(const char *buf, size_t lo, size_t pos)
{
    while (pos > lo) {
        size_t nl = pos - 1;
        while (nl > lo && buf[nl] != '\n')
            nl--;
        if (buf[nl] != '\n')
            return lo;
        if (!is_continued(buf, lo, nl))
            return nl + 1;
        pos = nl;
    }
    return lo;
}

/* Turns each '\' that ends a line (blanks may follow) and that line's end into blanks, so the
 * statement reads on, and records the joined line ends for line numbers.  At the end of the
 * file (is_final) a last '\' followed only by blanks is a blank too. */
static bool join_continuations(struct cursor *c, char *begin, char *end, bool is_final)
{
    c->n_joins = 0;
    c->join_idx = 0;
    for (char *s = begin; s < end && (s = memchr(s, '\\', (size_t)(end - s)));) {
        char *t = s + 1;
        while (t < end && is_blank(*t))
            t++;
        if (t < end && *t == '\n') {
            if (c->n_joins == c->cap_joins) {
                const char **grown = grow(c->joins, &c->cap_joins, sizeof *grown);
                if (!grown)
                    return fail_oom(c, s);
                c->joins = grown;
            }
            c->joins[c->n_joins++] = t;
            *s = ' ';
            *t = ' ';
            s = t + 1;
        } else {
            if (t == end && is_final)
                *s = ' ';
            s++;
        }
    }
    return true;
}

/* Reads the file fd (closed here) in chunks of whole statements, '\' continuations joined,
 * each handed to the OBJ or MTL line loop.  A UTF-8 byte order mark is skipped; UTF-16 is
 * refused; reading stops at the first NUL byte, an error once the statements before its line
 * are read.  Memory: one chunk, grown only for a statement longer than a chunk. */
static bool read_file(struct reader *r, struct cursor *c, int fd, bool is_mtl)
{
    /* a chunk, or less for a small file: loading many small meshes then costs no large
     * allocations (a file that grows while read is still read whole, in smaller chunks) */
    size_t cap = OBJ_CHUNK_BYTES, n = 0, start = 0;
    struct stat st;
    if (fstat(fd, &st) == 0 && st.st_size >= 0 && (uint64_t)st.st_size < cap)
        cap = (size_t)st.st_size < OBJ_MIN_CHUNK_BYTES ? OBJ_MIN_CHUNK_BYTES : (size_t)st.st_size;
    char *buf = malloc(cap + 1); /* + 1: the NUL after a chunk */
    bool at_eof = false, is_first = true, ok = false;
    if (!buf) {
        mcpt_error_runtime(c->err, c->path, "out of memory");
        goto done;
    }
    for (;;) {
        while (!at_eof && n < cap) {
            ssize_t got = read(fd, buf + n, cap - n);
            if (got < 0 && errno == EINTR)
                continue;
            if (got < 0) {
                mcpt_error_runtime(c->err, c->path, "cannot read: %s", strerror(errno));
                goto done;
            }
            at_eof = got == 0;
            n += (size_t)got;
        }
        if (is_first) {
            is_first = false;
            unsigned char b0 = n > 0 ? (unsigned char)buf[0] : 0;
            unsigned char b1 = n > 1 ? (unsigned char)buf[1] : 0;
            if ((b0 == 0xff && b1 == 0xfe) || (b0 == 0xfe && b1 == 0xff)) {
                mcpt_error_set(c->err, c->path, 1, 1,
                               "expected UTF-8 text, got UTF-16 (byte "
                               "order mark 0x%02x 0x%02x)",
                               b0, b1);
                goto done;
            }
            if (n >= 3 && memcmp(buf, "\xef\xbb\xbf", 3) == 0)
                start = 3;
        }
        const char *nul = memchr(buf + start, '\0', n - start);
        size_t end = nul      ? statement_start(buf, start, (size_t)(nul - buf))
                     : at_eof ? n
                              : statement_start(buf, start, n);
        if (!nul && !at_eof && end == start) { /* the chunk holds part of one statement */
            c->p = c->line_start = buf + start;
            c->n_joins = c->join_idx = 0;
            if (cap >= OBJ_MAX_LINE_BYTES) {
                fail_at(c, c->p,
                        "expected a statement of at most %zu bytes ('\\' continuation "
                        "lines included), got a longer one",
                        OBJ_MAX_LINE_BYTES);
                goto done;
            }
            char *grown = realloc(buf, 2 * cap + 1);
            if (!grown) {
                fail_oom(c, c->p);
                goto done;
            }
            buf = grown;
            cap *= 2;
            continue;
        }
        if (!join_continuations(c, buf + start, buf + end, at_eof && !nul))
            goto done;
        char saved = buf[end];
        buf[end] = '\0';
        c->p = c->line_start = c->tok_end = buf + start;
        bool is_read = is_mtl ? read_mtl_text(r, c) : read_obj_text(r, c);
        buf[end] = saved;
        if (!is_read)
            goto done;
        if (nul) { /* its line and column, from the statement's start */
            int line = c->line;
            const char *line_start = buf + end;
            for (const char *s = buf + end; s < nul; s++) {
                if (*s == '\n') {
                    line += line < INT_MAX;
                    line_start = s + 1;
                }
            }
            mcpt_error_set(c->err, c->path, line, (int)(nul - line_start) + 1,
                           "expected text, got a NUL byte");
            goto done;
        }
        if (at_eof) {
            ok = true;
            goto done;
        }
        memmove(buf, buf + end, n - end);
        n -= end;
        start = 0;
    }
done:
    free(buf);
    close(fd);
    return ok;
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

/* Reads the token at c->p as a finite float; NaN, Inf, hexadecimal and overflowing literals
 * are errors; one that underflows reads as the 0 or denormal it rounds to. */
static bool read_float(struct cursor *c, float *out)
{
    const char *s = c->p;
    const char *e;
    if (!parse_float_fast(s, &e, out)) {
        char tok[OBJ_SHOW_BYTES];
        char *strtof_end = NULL;
        *out = strtof(s, &strtof_end); /* stops at e or before: blanks, '#', '\n' end numbers */
        e = token_end(s);
        const char *digits = s + (*s == '+' || *s == '-'); /* strtof reads C99 hex floats, */
        bool is_hex = digits[0] == '0' && (digits[1] == 'x' || digits[1] == 'X'); /* OBJ not */
        if (strtof_end != e || is_hex)
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

/* Out of memory at `at`: a runtime error (exit status 1), not the input's fault. */
static bool fail_oom(const struct cursor *c, const char *at)
{
    fail_at(c, at, "out of memory");
    c->err->kind = MCPT_ERROR_RUNTIME;
    return false;
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

/* ---- the name table (obj.h) ---- */

/* FNV-1a, 64 bits (Fowler, Noll, Vo, "The FNV Non-Cryptographic Hash Algorithm",
 * draft-eastlake-fnv): file.c's. */
static uint64_t fnv1a_64(const char *s, size_t n) { return file_fnv1a64(FILE_FNV_OFFSET, s, n); }

/* The home slot of hash in a table of 2^bits slots: the top bits of hash * 2^64/phi
 * (Fibonacci hashing, Knuth, TAOCP vol. 3, 6.4), which spreads FNV's weaker low bits. */
static uint32_t home_slot(uint64_t hash, unsigned bits)
{
    return (uint32_t)((hash * 0x9e3779b97f4a7c15u) >> (64 - bits));
}

int64_t obj_names_find(struct obj_names *t, const char *key, size_t key_bytes)
{
    if (t->n_slots == 0)
        return -1;
    uint64_t h = fnv1a_64(key, key_bytes);
    for (uint32_t s = home_slot(h, t->slot_bits);; s = (s + 1) & (t->n_slots - 1)) {
        t->n_probes++;
        uint32_t e = t->slots[s];
        if (e == 0)
            return -1;
        const struct obj_name_entry *en = &t->entries[e - 1];
        if (en->hash == h && en->key_bytes == key_bytes &&
            memcmp(t->keys + en->key_offset, key, key_bytes) == 0)
            return en->value;
    }
}

bool obj_names_add(struct obj_names *t, const char *key, size_t key_bytes, uint32_t value)
{
    if (t->n_entries >= OBJ_NAMES_MAX || key_bytes >= UINT32_MAX)
        return false;
    /* at most half full: with linear probing a search then inspects about 2.5 slots on
     * average (Knuth, TAOCP vol. 3, 6.4, Algorithm L analysis) */
    if (2 * ((uint64_t)t->n_entries + 1) > t->n_slots) {
        unsigned bits = t->slot_bits ? t->slot_bits + 1 : 4;
        uint32_t n_slots = (uint32_t)1 << bits;
        uint32_t *slots = calloc(n_slots, sizeof *slots);
        if (!slots)
            return false;
        for (uint32_t i = 0; i < t->n_entries; i++) {
            uint32_t s = home_slot(t->entries[i].hash, bits);
            while (slots[s])
                s = (s + 1) & (n_slots - 1);
            slots[s] = i + 1;
        }
        free(t->slots);
        t->slots = slots;
        t->n_slots = n_slots;
        t->slot_bits = bits;
    }
    if (t->n_entries == t->cap_entries) {
        size_t cap = t->cap_entries;
        struct obj_name_entry *grown = grow(t->entries, &cap, sizeof *grown);
        if (!grown)
            return false;
        t->entries = grown;
        t->cap_entries = (uint32_t)cap; /* at most 2^30: n_entries < OBJ_NAMES_MAX */
    }
    if (key_bytes + 1 > SIZE_MAX - t->n_key_bytes)
        return false;
    while (t->n_key_bytes + key_bytes + 1 > t->cap_key_bytes) {
        char *grown = grow(t->keys, &t->cap_key_bytes, 1);
        if (!grown)
            return false;
        t->keys = grown;
    }
    uint64_t h = fnv1a_64(key, key_bytes);
    struct obj_name_entry *en = &t->entries[t->n_entries];
    *en = (struct obj_name_entry){.hash = h,
                                  .key_offset = t->n_key_bytes,
                                  .key_bytes = (uint32_t)key_bytes,
                                  .value = value};
    memcpy(t->keys + t->n_key_bytes, key, key_bytes);
    t->keys[t->n_key_bytes + key_bytes] = '\0';
    t->n_key_bytes += key_bytes + 1;
    uint32_t s = home_slot(h, t->slot_bits);
    for (t->n_probes++; t->slots[s]; t->n_probes++)
        s = (s + 1) & (t->n_slots - 1);
    t->slots[s] = ++t->n_entries;
    return true;
}

const char *obj_names_key(const struct obj_names *t, uint32_t entry_idx)
{
    return t->keys + t->entries[entry_idx].key_offset;
}

void obj_names_free(struct obj_names *t)
{
    free(t->slots);
    free(t->entries);
    free(t->keys);
    memset(t, 0, sizeof *t);
}
