/* tests/docs_test.c - docs/theory.md against the code.  Every function the Code column of its
 * tables names must be defined in the production sources (the top-level *.c and *.h) and
 * called from a production .c file, not just from its own body, so the page cannot point a
 * reader at a function the renderer never runs.  A name followed by "(tests)" or "(bench)" is
 * a tool of the tests or benchmarks and must be called from tests/ or bench/ instead.  A name
 * with '*' (shape_*_surface) stands for every function it matches, at least one; a lower-case
 * name that is no function (a field such as p_error) must occur in the code; upper-case names
 * (MAT_DIFFUSE, SAMPLE_DIM_*) are constants and are not checked.  The scan is lexical:
 * comments and literals are blanked, a function body is the {...} after "name(...)" at file
 * scope, and a call is any use of the name in a body (or a #define) other than its own, so a
 * function passed as a pointer counts as called.  Runs from the repository root. */
#include <criterion/criterion.h>

#include <ctype.h>
#include <fnmatch.h>
#include <glob.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define DOC_PATH "docs/theory.md"
#define MAX_NAMES 512
#define NAME_BYTES 64

enum caller { CALLER_RENDERER, CALLER_TESTS, CALLER_BENCH, CALLER_COUNT };
static const char *const CALLER_WHERE[CALLER_COUNT] = {"a production .c file", "tests/*.c",
                                                       "bench/*.c"};

struct doc_name {
    char name[NAME_BYTES]; /* as written between backquotes, '*' allowed */
    int doc_line;          /* line of theory.md that names it first */
    enum caller caller;    /* who must call it: the renderer, or "(tests)" / "(bench)" */
};

struct func_def {
    char name[NAME_BYTES];
    char file[64];
    int line;
};

struct code_index {
    struct func_def defs[4096]; /* every function defined at file scope in *.c and *.h */
    int n_defs;
    /* per name of interest: uses outside its own body in .c files, and any occurrence in code */
    const char **names; /* the names looked for (functions and fields, no wildcards) */
    int n_names;
    int calls[MAX_NAMES * 4][CALLER_COUNT];
    int occurrences[MAX_NAMES * 4];
};

/* Reads a whole file into a NUL-terminated buffer the caller frees. */
static char *read_all(const char *path)
{
    FILE *f = fopen(path, "rb");
    cr_assert(f, "cannot open %s", path);
    cr_assert_eq(fseek(f, 0, SEEK_END), 0);
    long n = ftell(f);
    cr_assert(n >= 0);
    rewind(f);
    char *buf = malloc((size_t)n + 1);
    cr_assert(buf);
    cr_assert_eq(fread(buf, 1, (size_t)n, f), (size_t)n);
    buf[n] = '\0';
    fclose(f);
    return buf;
}

/* Replaces the contents of comments and string and character literals by spaces, newlines
 * kept, so that only code is scanned and line numbers stay right. */
static void blank_comments_and_literals(char *s)
{
    enum { CODE, LINE_COMMENT, BLOCK_COMMENT, STRING, CHAR } state = CODE;
    for (char *p = s; *p; p++) {
        switch (state) {
        case CODE:
            if (p[0] == '/' && p[1] == '/')
                state = LINE_COMMENT, *p = ' ';
            else if (p[0] == '/' && p[1] == '*')
                state = BLOCK_COMMENT, *p = ' ', *++p = ' ';
            else if (*p == '"')
                state = STRING, *p = ' ';
            else if (*p == '\'')
                state = CHAR, *p = ' ';
            break;
        case LINE_COMMENT:
            if (*p == '\n')
                state = CODE;
            else
                *p = ' ';
            break;
        case BLOCK_COMMENT:
            if (p[0] == '*' && p[1] == '/')
                state = CODE, *p = ' ', *++p = ' ';
            else if (*p != '\n')
                *p = ' ';
            break;
        case STRING:
        case CHAR:
            if (*p == '\\' && p[1]) {
                *p = ' ';
                if (*++p != '\n')
                    *p = ' ';
            } else if (*p == (state == STRING ? '"' : '\'')) {
                state = CODE, *p = ' ';
            } else if (*p != '\n') {
                *p = ' ';
            }
            break;
        }
    }
}

static bool is_ident_start(char c) { return isalpha((unsigned char)c) || c == '_'; }
static bool is_ident_char(char c) { return isalnum((unsigned char)c) || c == '_'; }

static int name_idx(const struct code_index *ix, const char *tok, size_t len)
{
    for (int i = 0; i < ix->n_names; i++)
        if (strlen(ix->names[i]) == len && memcmp(ix->names[i], tok, len) == 0)
            return i;
    return -1;
}

/* Scans one source file: records its file-scope function definitions when is_production, and
 * counts the uses of the names of interest by caller (in a body other than their own, or in a
 * #define); caller < 0 (a header) counts occurrences only. */
static void scan_file(struct code_index *ix, const char *path, bool is_production, int caller)
{
    char *src = read_all(path);
    blank_comments_and_literals(src);
    int line = 1, depth = 0, paren = 0;
    bool at_line_start = true, in_define = false, in_directive = false;
    char cand[NAME_BYTES] = "", current_fn[NAME_BYTES] = "";
    char last_sig = ';'; /* last non-blank character outside identifiers, at file scope */
    for (const char *p = src; *p;) {
        char c = *p;
        if (c == '\n') {
            if (!(p > src && p[-1] == '\\'))
                in_directive = in_define = false;
            line++, at_line_start = true, p++;
            continue;
        }
        if (isspace((unsigned char)c)) {
            p++;
            continue;
        }
        if (at_line_start && c == '#') {
            const char *q = p + 1;
            while (*q == ' ' || *q == '\t')
                q++;
            in_directive = true;
            in_define = strncmp(q, "define", 6) == 0;
            at_line_start = false;
            p = q;
            while (is_ident_char(*p))
                p++;
            continue;
        }
        at_line_start = false;
        if (is_ident_start(c)) {
            const char *t = p;
            while (is_ident_char(*p))
                p++;
            size_t len = (size_t)(p - t);
            const char *q = p;
            while (*q == ' ' || *q == '\t' || *q == '\n')
                q++;
            bool is_member = (t > src && t[-1] == '.') ||
                             (t > src + 1 && t[-1] == '>' && t[-2] == '-');
            if (in_directive && !in_define)
                continue;
            int k = name_idx(ix, t, len);
            if (k >= 0 && is_production)
                ix->occurrences[k]++;
            if (in_define) {
                if (k >= 0 && caller >= 0 && !is_member)
                    ix->calls[k][caller]++;
                continue;
            }
            if (depth == 0) {
                if (*q == '(' && paren == 0 && len < NAME_BYTES) {
                    memcpy(cand, t, len);
                    cand[len] = '\0';
                }
                last_sig = 'a';
            } else if (k >= 0 && caller >= 0 && !is_member &&
                       strcmp(ix->names[k], current_fn) != 0) {
                ix->calls[k][caller]++;
            }
            continue;
        }
        if (in_directive) {
            p++;
            continue;
        }
        if (depth == 0) {
            if (c == '(')
                paren++;
            else if (c == ')')
                paren--;
            else if (c == ';')
                cand[0] = '\0';
        }
        if (c == '{') {
            if (depth == 0) {
                current_fn[0] = '\0';
                if (last_sig == ')' && cand[0]) {
                    strcpy(current_fn, cand);
                }
                if (last_sig == ')' && cand[0] && is_production) {
                    cr_assert(ix->n_defs < (int)(sizeof ix->defs / sizeof ix->defs[0]));
                    struct func_def *d = &ix->defs[ix->n_defs++];
                    snprintf(d->name, sizeof d->name, "%s", cand);
                    snprintf(d->file, sizeof d->file, "%s", path);
                    d->line = line;
                }
            }
            depth++;
        } else if (c == '}') {
            depth--;
            if (depth == 0)
                current_fn[0] = cand[0] = '\0';
        }
        if (depth == 0)
            last_sig = c;
        p++;
    }
    free(src);
}

/* The backquoted names in the last cell of each row of the tables whose header's last cell is
 * "Code", once each, with the line that names them first. */
static int read_doc_names(struct doc_name *out)
{
    char *doc = read_all(DOC_PATH);
    int n = 0, line_no = 0;
    bool in_table = false, in_code_table = false;
    for (char *line = doc; line && *line; line_no++) {
        char *next = strchr(line, '\n');
        if (next)
            *next++ = '\0';
        if (line[0] != '|') {
            in_table = false;
            line = next;
            continue;
        }
        /* the last cell: after the last '|' that is neither escaped nor the closing one */
        char *end = line + strlen(line);
        while (end > line && isspace((unsigned char)end[-1]))
            end--;
        if (end > line && end[-1] == '|')
            end--;
        char *start = end;
        while (start > line && !(start[-1] == '|' && (start - 1 == line || start[-2] != '\\')))
            start--;
        *end = '\0';
        if (!in_table) {
            in_table = true;
            char *cell = start;
            while (isspace((unsigned char)*cell))
                cell++;
            in_code_table = strncmp(cell, "Code", 4) == 0;
            line = next;
            continue;
        }
        for (char *q = start; in_code_table && (q = strchr(q, '`'));) {
            char *close = strchr(q + 1, '`');
            if (!close)
                break;
            size_t len = (size_t)(close - q - 1);
            bool ident = len > 0 && len < NAME_BYTES, has_lower = false;
            for (size_t i = 0; ident && i < len; i++) {
                char ch = q[1 + i];
                ident = is_ident_char(ch) || ch == '*';
                has_lower |= islower((unsigned char)ch) != 0;
            }
            if (ident && has_lower) {
                bool seen = false;
                for (int i = 0; i < n && !seen; i++)
                    seen = strlen(out[i].name) == len && memcmp(out[i].name, q + 1, len) == 0;
                if (!seen) {
                    cr_assert(n < MAX_NAMES);
                    memcpy(out[n].name, q + 1, len);
                    out[n].name[len] = '\0';
                    out[n].doc_line = line_no + 1;
                    const char *after = close + 1;
                    while (*after == ' ')
                        after++;
                    out[n].caller = strncmp(after, "(tests)", 7) == 0   ? CALLER_TESTS
                                    : strncmp(after, "(bench)", 7) == 0 ? CALLER_BENCH
                                                                        : CALLER_RENDERER;
                    n++;
                }
            }
            q = close + 1;
        }
        line = next;
    }
    free(doc);
    return n;
}

static void scan_tree(struct code_index *ix)
{
    static const struct {
        const char *pattern;
        bool is_production;
        int caller;
    } sets[4] = {{"*.c", true, CALLER_RENDERER},
                 {"*.h", true, -1},
                 {"tests/*.c", false, CALLER_TESTS},
                 {"bench/*.c", false, CALLER_BENCH}};
    for (int k = 0; k < 4; k++) {
        glob_t g;
        cr_assert_eq(glob(sets[k].pattern, 0, NULL, &g), 0, "no %s in the working folder",
                     sets[k].pattern);
        for (size_t i = 0; i < g.gl_pathc; i++)
            scan_file(ix, g.gl_pathv[i], sets[k].is_production, sets[k].caller);
        globfree(&g);
    }
}

static const struct func_def *find_def(const struct code_index *ix, const char *name)
{
    for (int i = 0; i < ix->n_defs; i++)
        if (strcmp(ix->defs[i].name, name) == 0)
            return &ix->defs[i];
    return NULL;
}

/* docs/theory.md names only functions the renderer calls (see the file comment). */
/* True when name is among names[0 .. n_names): each name is listed and counted once, whether
 * the page names it directly, through a wildcard, or both. */
static bool name_listed(const char *const *names, int n_names, const char *name)
{
    for (int j = 0; j < n_names; j++)
        if (strcmp(names[j], name) == 0)
            return true;
    return false;
}

Test(docs, theory_names_functions_the_renderer_calls)
{
    static struct doc_name doc[MAX_NAMES];
    int n_doc = read_doc_names(doc);
    cr_assert(n_doc > 50, "%s: found only %d names in the Code columns", DOC_PATH, n_doc);

    /* pass 1: the definitions; pass 2: the uses of every name, wildcards expanded */
    static struct code_index ix;
    memset(&ix, 0, sizeof ix);
    scan_tree(&ix);
    static const char *names[MAX_NAMES * 4];
    static char expanded[MAX_NAMES * 4][NAME_BYTES]; /* the functions a wildcard matches */
    int n_names = 0;
    for (int i = 0; i < n_doc; i++) {
        if (!strchr(doc[i].name, '*')) {
            if (!name_listed(names, n_names, doc[i].name))
                names[n_names++] = doc[i].name;
            continue;
        }
        for (int d = 0; d < ix.n_defs; d++) {
            if (!name_listed(names, n_names, ix.defs[d].name) &&
                fnmatch(doc[i].name, ix.defs[d].name, 0) == 0) {
                cr_assert(n_names < MAX_NAMES * 4);
                snprintf(expanded[n_names], NAME_BYTES, "%s", ix.defs[d].name);
                names[n_names] = expanded[n_names];
                n_names++;
            }
        }
    }
    ix.names = names;
    ix.n_names = n_names;
    ix.n_defs = 0;
    scan_tree(&ix);

    int n_bad = 0;
    for (int i = 0; i < n_doc; i++) {
        const char *name = doc[i].name, *where = CALLER_WHERE[doc[i].caller];
        bool is_pattern = strchr(name, '*') != NULL;
        int n_match = 0;
        for (int k = 0; k < n_names; k++) {
            if (is_pattern ? fnmatch(name, names[k], 0) != 0 : strcmp(name, names[k]) != 0)
                continue;
            n_match++;
            const struct func_def *d = find_def(&ix, names[k]);
            if (d && ix.calls[k][doc[i].caller] == 0) {
                n_bad++;
                cr_log_error("%s:%d: '%s' (defined at %s:%d) is never called from %s", DOC_PATH,
                             doc[i].doc_line, names[k], d->file, d->line, where);
            } else if (!d && ix.occurrences[k] == 0) {
                n_bad++;
                cr_log_error("%s:%d: '%s' is neither a function nor a name in the production "
                             "code",
                             DOC_PATH, doc[i].doc_line, name);
            }
            if (!is_pattern)
                break;
        }
        if (is_pattern && n_match == 0) {
            n_bad++;
            cr_log_error("%s:%d: no function matches '%s'", DOC_PATH, doc[i].doc_line, name);
        }
    }
    cr_assert_eq(n_bad, 0, "%s names %d function(s) nothing calls as it says (listed above)",
                 DOC_PATH, n_bad);
}
