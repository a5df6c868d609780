/* obj_test.c - tests obj.c, the Wavefront OBJ/MTL reader.
 * Checks: every face index form (v, v/vt, v//vn, v/vt/vn) and negative indices counting back
 * from the end at the time the face is read (Wavefront "Object Files (.obj)", "Referencing
 * vertex data"); fan triangulation (n corners -> n-2 triangles in order); CRLF, tabs, comments,
 * BOM, no final newline; mtllib/usemtl mapping and MTL keys with their defaults; floats equal to
 * strtof bit for bit (Clinger 1990 fast path); the real Cornell box; and golden error strings
 * "file:line:col: error: msg" for every malformed input (STYLE.md §5).  Also what issue 15
 * found: '\' line continuation, usemtl before its mtllib (resolved as Blender does), MTL
 * "xyz" colours (IEC 61966-2-1 matrix) and "spectral" ones (a warning), reading in chunks
 * (a 3 GiB sparse file of NULs stops at 1:1 in little memory), FIFOs refused without
 * blocking, and name lookups that stay O(1) (counted probes, not time).
 * Fixtures: tests/data/obj/, scenes/models/; paths are relative to the repo root. */
#ifndef _DEFAULT_SOURCE
#define _DEFAULT_SOURCE /* mkstemp, mkdtemp, mkfifo, close, unlink, ftruncate */
#endif

#include <criterion/criterion.h>

#include <stdlib.h>
#include <sys/resource.h>
#include <unistd.h>

#include "obj.h"
#include "test_util.h"

#define DATA "tests/data/obj/"

static void load_ok(const char *path, struct obj_mesh *mesh)
{
    struct mcpt_error err = {0};
    char msg[MCPT_ERROR_LINE_BYTES];
    bool ok = obj_load(path, mesh, &err);
    mcpt_error_format(&err, msg, sizeof msg);
    cr_assert(ok, "%s failed: %s", path, msg);
}

/* PCG-style LCG step (Knuth's MMIX constants); the high bits are the random ones. */
static uint64_t next_u64(uint64_t *state)
{
    *state = *state * 6364136223846793005u + 1442695040888963407u;
    return *state >> 24;
}

static bool vec3_eq(vec3 a, vec3 b) { return a.x == b.x && a.y == b.y && a.z == b.z; }

static void assert_tri(const struct obj_mesh *m, uint32_t i, uint32_t v0, uint32_t v1, uint32_t v2,
                       int32_t t0, int32_t t1, int32_t t2, int32_t n0, int32_t n1, int32_t n2)
{
    cr_assert_lt(i, m->n_tris);
    const struct obj_tri *t = &m->tris[i];
    cr_assert(t->v[0] == v0 && t->v[1] == v1 && t->v[2] == v2,
              "tri %u: v = (%u %u %u), expected (%u %u %u)", i, t->v[0], t->v[1], t->v[2], v0, v1,
              v2);
    cr_assert(t->vt[0] == t0 && t->vt[1] == t1 && t->vt[2] == t2,
              "tri %u: vt = (%d %d %d), expected (%d %d %d)", i, t->vt[0], t->vt[1], t->vt[2], t0,
              t1, t2);
    cr_assert(t->vn[0] == n0 && t->vn[1] == n1 && t->vn[2] == n2,
              "tri %u: vn = (%d %d %d), expected (%d %d %d)", i, t->vn[0], t->vn[1], t->vn[2], n0,
              n1, n2);
}

/* The quad written five ways (crlf, tabs, comments, BOM, no final newline, ignored statements):
 * 4 positions, one face on line face_line -> triangles (0 1 2) and (0 2 3). */
static void assert_quad(const char *path, uint32_t face_line)
{
    struct obj_mesh m;
    load_ok(path, &m);
    cr_assert_eq(m.n_positions, 4);
    cr_assert(vec3_eq(m.positions[0], v3(0.5f, -1.25f, 2.0f)), "%s: v1 misread", path);
    cr_assert(vec3_eq(m.positions[3], v3(0.0f, 1.0f, 0.0f)), "%s: v4 misread", path);
    cr_assert_eq(m.n_tris, 2);
    assert_tri(&m, 0, 0, 1, 2, -1, -1, -1, -1, -1, -1);
    assert_tri(&m, 1, 0, 2, 3, -1, -1, -1, -1, -1, -1);
    cr_assert_eq(m.tris[0].line, face_line);
    cr_assert_eq(m.tris[1].line, face_line);
    cr_assert_eq(m.tris[0].mat_idx, -1);
    cr_assert_eq(m.n_normals + m.n_uvs + m.n_materials, 0);
    obj_free(&m);
}

/* Each form sets exactly the indices it names; the others stay -1; 1-based -> 0-based. */
Test(obj, index_forms)
{
    struct obj_mesh m;
    load_ok(DATA "index_forms.obj", &m);
    cr_assert_eq(m.n_positions, 4);
    cr_assert_eq(m.n_uvs, 3);
    cr_assert_eq(m.n_normals, 2);
    cr_assert_eq(m.n_tris, 5);
    assert_tri(&m, 0, 0, 1, 2, -1, -1, -1, -1, -1, -1); /* f 1 2 3 */
    assert_tri(&m, 1, 0, 1, 2, 0, 1, 2, -1, -1, -1);    /* f 1/1 2/2 3/3 */
    assert_tri(&m, 2, 1, 2, 3, -1, -1, -1, 1, 0, 1);    /* f 2//2 3//1 4//2 */
    assert_tri(&m, 3, 3, 2, 0, 2, 1, 0, 0, 1, 0);       /* f 4/3/1 3/2/2 1/1/1 */
    assert_tri(&m, 4, 0, 1, 2, -1, 2, -1, -1, -1, 1);   /* f 1 2/3 3//2: mixed per corner */
    for (uint32_t i = 0; i < m.n_tris; i++)
        cr_assert_eq(m.tris[i].line, 11 + i);
    cr_assert(m.uvs[2].x == 0.0f && m.uvs[2].y == 1.0f);
    cr_assert(vec3_eq(m.normals[1], v3(1.0f, 0.0f, 0.0f)));
    obj_free(&m);
}

/* -k names the k-th last element defined before the face, so the same -1 changes meaning once
 * more vertices are read. */
Test(obj, negative_indices_count_back_from_current_end)
{
    struct obj_mesh m;
    load_ok(DATA "negative.obj", &m);
    cr_assert_eq(m.n_tris, 2);
    assert_tri(&m, 0, 0, 1, 2, -1, -1, -1, -1, -1, -1); /* f -3 -2 -1 with 3 v */
    assert_tri(&m, 1, 3, 0, 2, 0, 1, -1, 0, 0, 0);      /* f -1/-2/-1 -4/-1/-1 -2//-1 with 4 v */
    obj_free(&m);
}

/* Fan from the first corner: quad -> 2, pentagon -> 3 triangles, in face order. */
Test(obj, polygons_fan_from_first_vertex)
{
    struct obj_mesh m;
    load_ok(DATA "polygons.obj", &m);
    cr_assert_eq(m.n_tris, 6);
    assert_tri(&m, 0, 0, 1, 2, -1, -1, -1, -1, -1, -1); /* quad 1 2 3 4 */
    assert_tri(&m, 1, 0, 2, 3, -1, -1, -1, -1, -1, -1);
    assert_tri(&m, 2, 0, 1, 2, -1, -1, -1, -1, -1, -1); /* pentagon 1 2 3 4 5 */
    assert_tri(&m, 3, 0, 2, 3, -1, -1, -1, -1, -1, -1);
    assert_tri(&m, 4, 0, 3, 4, -1, -1, -1, -1, -1, -1);
    assert_tri(&m, 5, 4, 3, 2, -1, -1, -1, -1, -1, -1); /* triangle 5 4 3 */
    const uint32_t lines[6] = {6, 6, 7, 7, 7, 8};
    for (uint32_t i = 0; i < 6; i++)
        cr_assert_eq(m.tris[i].line, lines[i]);
    obj_free(&m);
}

/* CRLF line ends (the Cornell box and dragon files use them). */
Test(obj, crlf) { assert_quad(DATA "crlf.obj", 6); }

/* Tabs as separators, leading and trailing; a line of blanks only. */
Test(obj, tabs) { assert_quad(DATA "tabs.obj", 6); }

/* The last statement ends at end of file, not at a newline. */
Test(obj, no_final_newline) { assert_quad(DATA "no_final_newline.obj", 5); }

/* Full-line, indented and inline comments, with and without a blank before '#'. */
Test(obj, comments) { assert_quad(DATA "comments.obj", 9); }

/* A UTF-8 byte order mark before the first statement. */
Test(obj, byte_order_mark) { assert_quad(DATA "bom.obj", 5); }

/* o, g (with and without names), s, and statements mcpt does not use (vp l p cstype deg curv
 * end) are skipped. */
Test(obj, ignored_statements) { assert_quad(DATA "ignored.obj", 15); }

/* An empty file is a valid empty mesh; the scene decides whether that is an error. */
Test(obj, empty_file_is_empty_mesh)
{
    struct obj_mesh m;
    load_ok(DATA "empty.obj", &m);
    cr_assert_eq(m.n_positions + m.n_normals + m.n_uvs + m.n_tris + m.n_materials, 0);
    obj_free(&m);
}

/* usemtl maps faces to materials of every mtllib read so far; an unknown name gives -1; MTL
 * lines may be indented and carry inline comments; absent keys keep the obj.h defaults;
 * Kd with one number is grey; Tr = 1 - d; a repeated mtllib is read once (no duplicate). */
Test(obj, mtllib_usemtl_mapping)
{
    struct obj_mesh m;
    load_ok(DATA "materials.obj", &m);
    cr_assert_eq(m.n_materials, 4);
    cr_assert_eq(m.n_tris, 5);
    const int32_t expected_mat[5] = {-1, 0, 1, -1, 2};
    for (uint32_t i = 0; i < 5; i++)
        cr_assert_eq(m.tris[i].mat_idx, expected_mat[i], "tri %u: mat_idx %d, expected %d", i,
                     m.tris[i].mat_idx, expected_mat[i]);

    const struct obj_material *red = &m.materials[0];
    cr_assert_str_eq(red->name, "red");
    cr_assert(vec3_eq(red->Kd, v3(0.63f, 0.065f, 0.05f)));
    cr_assert(vec3_eq(red->Ks, v3(0.0f, 0.0f, 0.0f)));
    cr_assert_eq(red->Ns, 10.0f);
    cr_assert_eq(red->illum, 2);
    cr_assert_eq(red->line, 2);

    const struct obj_material *light = &m.materials[1];
    cr_assert_str_eq(light->name, "light");
    cr_assert(vec3_eq(light->Kd, v3(0.78f, 0.78f, 0.78f)));
    cr_assert(vec3_eq(light->Ke, v3(17.0f, 12.0f, 4.0f)));
    cr_assert_eq(light->line, 10);

    const struct obj_material *glass = &m.materials[2];
    cr_assert_str_eq(glass->name, "glass");
    cr_assert_eq(glass->Ni, 1.5f);
    cr_assert_eq(glass->d, 0.75f);
    cr_assert_eq(glass->illum, 7);
    cr_assert(vec3_eq(glass->Ks, v3(0.9f, 0.9f, 0.9f)));
    cr_assert(vec3_eq(glass->Tf, v3(1.0f, 1.0f, 1.0f)));

    const struct obj_material *def = &m.materials[3];
    cr_assert_str_eq(def->name, "defaults");
    cr_assert(vec3_eq(def->Kd, v3(0.8f, 0.8f, 0.8f)));
    cr_assert(vec3_eq(def->Ks, v3(0.0f, 0.0f, 0.0f)));
    cr_assert(vec3_eq(def->Ke, v3(0.0f, 0.0f, 0.0f)));
    cr_assert(vec3_eq(def->Tf, v3(1.0f, 1.0f, 1.0f)));
    cr_assert(def->Ns == 0.0f && def->Ni == 1.0f && def->d == 1.0f && def->illum == 2);
    obj_free(&m);
}

/* Every coordinate equals strtof of its text bit for bit (-0 included): the Clinger fast path
 * (m <= 2^24, |k| <= 10) and the strtof fallback must both round correctly.  20000 random
 * literals: mostly fast-path forms, plus long mantissas, exponents, subnormals, signs. */
Test(obj, floats_match_strtof)
{
    enum { N_VERTS = 20000 / 3 + 1 };
    static char text[N_VERTS][3][48];
    char path[] = "/tmp/mcpt_obj_test_XXXXXX";
    int fd = mkstemp(path);
    cr_assert_neq(fd, -1);
    FILE *f = fdopen(fd, "w");
    cr_assert_not_null(f);
    uint64_t state = 0x9e3779b97f4a7c15u; /* fixed seed: the same literals every run */
    for (int i = 0; i < N_VERTS; i++) {
        for (int j = 0; j < 3; j++) {
            char *s = text[i][j];
            int n = 0;
            uint64_t sign = next_u64(&state) % 3;
            if (sign != 2)
                s[n++] = sign ? '-' : '+';
            int n_int = (int)(next_u64(&state) % 4);                          /* 0..3 digits */
            int n_frac = next_u64(&state) % 4 ? (int)(next_u64(&state) % 8)   /* 0..7 */
                                              : (int)(next_u64(&state) % 13); /* 0..12 */
            for (int d = 0; d < n_int; d++)
                s[n++] = (char)('0' + next_u64(&state) % 10);
            if (n_int == 0 && n_frac == 0)
                s[n++] = '0';
            if (n_frac > 0)
                s[n++] = '.';
            for (int d = 0; d < n_frac; d++)
                s[n++] = (char)('0' + next_u64(&state) % 10);
            s[n] = '\0';
            if (next_u64(&state) % 4 == 0) /* an exponent e-60..e30 in one literal of four */
                sprintf(s + n, "e%d", (int)(next_u64(&state) % 91) - 60);
        }
        fprintf(f, "v %s %s %s\n", text[i][0], text[i][1], text[i][2]);
    }
    fclose(f);

    struct obj_mesh m;
    struct mcpt_error err = {0};
    bool ok = obj_load(path, &m, &err);
    unlink(path);
    cr_assert(ok, "%s", err.msg);
    cr_assert_eq(m.n_positions, N_VERTS);
    for (int i = 0; i < N_VERTS; i++) {
        const float got[3] = {m.positions[i].x, m.positions[i].y, m.positions[i].z};
        for (int j = 0; j < 3; j++) {
            float want = strtof(text[i][j], NULL);
            cr_assert(memcmp(&got[j], &want, sizeof want) == 0, "'%s': got %a, strtof %a",
                      text[i][j], (double)got[j], (double)want);
        }
    }
    obj_free(&m);
}

/* The real McGuire Cornell box (CRLF, negative indices, quads, indented MTL with inline
 * comments): 18 quads -> 36 triangles, 8 materials, every face has a material, the light's
 * Ke = (17, 12, 4) and its quad gives 2 triangles. */
Test(obj, cornell_box_original)
{
    struct obj_mesh m;
    load_ok("scenes/models/CornellBox-Original.obj", &m);
    cr_assert_eq(m.n_positions, 72);
    cr_assert_eq(m.n_tris, 36);
    cr_assert_eq(m.n_materials, 8);
    cr_assert(vec3_eq(m.positions[0], v3(-1.01f, 0.0f, 0.99f)));
    int32_t light_idx = -1;
    for (uint32_t i = 0; i < m.n_materials; i++) {
        if (strcmp(m.materials[i].name, "light") == 0)
            light_idx = (int32_t)i;
    }
    cr_assert_geq(light_idx, 0);
    cr_assert(vec3_eq(m.materials[light_idx].Ke, v3(17.0f, 12.0f, 4.0f)));
    cr_assert(vec3_eq(m.materials[light_idx].Kd, v3(0.78f, 0.78f, 0.78f)));
    cr_assert(vec3_eq(m.materials[0].Kd, v3(0.63f, 0.065f, 0.05f))); /* leftWall, red */
    uint32_t n_light_tris = 0;
    for (uint32_t i = 0; i < m.n_tris; i++) {
        cr_assert(m.tris[i].mat_idx >= 0 && m.tris[i].mat_idx < (int32_t)m.n_materials,
                  "tri %u has mat_idx %d", i, m.tris[i].mat_idx);
        n_light_tris += m.tris[i].mat_idx == light_idx;
    }
    cr_assert_eq(n_light_tris, 2);
    obj_free(&m);
}

/* The 100k Stanford dragon (shared models, when present): counts from models/README.md; its
 * stray "usemtl" with no mtllib leaves every mat_idx at -1. */
Test(obj, stanford_dragon_if_present)
{
    const char *path = "../shared/models/stanford-dragon-100k.obj";
    FILE *f = fopen(path, "rb");
    if (!f)
        cr_skip_test("%s not present", path);
    fclose(f);
    struct obj_mesh m;
    load_ok(path, &m);
    cr_assert_eq(m.n_positions, 50000);
    cr_assert_eq(m.n_tris, 100000);
    cr_assert(vec3_eq(m.positions[0], v3(1.6831f, 3.0852f, -0.9792f)));
    for (uint32_t i = 0; i < m.n_tris; i++)
        cr_assert_eq(m.tris[i].mat_idx, -1);
    obj_free(&m);
}

/* Dabrovic Sponza (shared models, when present): v/vt/vn triangles, 3-component vt. */
Test(obj, sponza_if_present)
{
    const char *path = "../shared/models/sponza-dabrovic.obj";
    FILE *f = fopen(path, "rb");
    if (!f)
        cr_skip_test("%s not present", path);
    fclose(f);
    struct obj_mesh m;
    load_ok(path, &m);
    cr_assert_eq(m.n_positions, 39999);
    cr_assert_eq(m.n_uvs, 71396);
    cr_assert_eq(m.n_normals, 39999);
    cr_assert_eq(m.n_tris, 66454);
    for (uint32_t i = 0; i < m.n_tris; i++) {
        for (int k = 0; k < 3; k++)
            cr_assert(m.tris[i].vt[k] >= 0 && m.tris[i].vn[k] >= 0, "tri %u", i);
    }
    obj_free(&m);
}

/* ---- golden error messages: "file:line:col: error: msg", column of the offending token ---- */

struct golden {
    const char *path;
    const char *message;
};

/* Loads each path, which must fail with exactly its message and leave the mesh zeroed. */
static void check_golden(const struct golden *cases, size_t n_cases)
{
    for (size_t i = 0; i < n_cases; i++) {
        struct obj_mesh m;
        memset(&m, 0xab, sizeof m); /* obj_load must zero it whatever it held */
        struct mcpt_error err = {0};
        bool ok = obj_load(cases[i].path, &m, &err);
        cr_expect_not(ok, "%s loaded but should fail", cases[i].path);
        char got[MCPT_ERROR_LINE_BYTES];
        mcpt_error_format(&err, got, sizeof got);
        cr_expect_str_eq(got, cases[i].message);
        struct obj_mesh zero;
        memset(&zero, 0, sizeof zero);
        cr_expect(memcmp(&m, &zero, sizeof m) == 0, "%s: mesh not left empty", cases[i].path);
    }
}

/* Face indices: zero, past the end, too far back, huge, before any v/vt/vn (the column is the
 * offending number's). */
Test(obj, errors_face_indices)
{
    static const struct golden cases[] = {
        {DATA "err_index_zero.obj", DATA "err_index_zero.obj:4:5: error: expected a vertex index "
                                         "in 1..3 or -3..-1, got 0"},
        {DATA "err_index_high.obj", DATA "err_index_high.obj:4:7: error: expected a vertex index "
                                         "in 1..3 or -3..-1, got 4"},
        {DATA "err_index_negative.obj", DATA "err_index_negative.obj:4:9: error: expected a "
                                             "vertex index in 1..3 or -3..-1, got -4"},
        {DATA "err_index_huge.obj", DATA "err_index_huge.obj:4:7: error: expected a vertex index "
                                         "in 1..3 or -3..-1, got 99999999999999999999"},
        {DATA "err_index_no_v.obj", DATA "err_index_no_v.obj:1:3: error: expected a vertex "
                                         "index, got 1 before any 'v' statement"},
        {DATA "err_vt_range.obj", DATA "err_vt_range.obj:6:13: error: expected a texture index "
                                       "in 1..2 or -2..-1, got 3"},
        {DATA "err_vn_range.obj", DATA "err_vn_range.obj:5:11: error: expected a normal index in "
                                       "1..1 or -1..-1, got -2"},
        {DATA "err_vn_none.obj", DATA "err_vn_none.obj:4:6: error: expected a normal index, got 1 "
                                      "before any 'vn' statement"},
    };
    check_golden(cases, sizeof cases / sizeof cases[0]);
}

/* Malformed statements: corner forms, too few corners, wrong number counts, bad numbers,
 * NaN/Inf/overflow, a CRLF line, missing names. */
Test(obj, errors_statements)
{
    static const struct golden cases[] = {
        {DATA "err_corner_form.obj", DATA "err_corner_form.obj:4:7: error: expected a vertex of "
                                          "the form v, v/vt, v//vn or v/vt/vn, got '3/4/5/6'"},
        {DATA "err_corner_float.obj", DATA "err_corner_float.obj:4:3: error: expected a vertex "
                                           "of the form v, v/vt, v//vn or v/vt/vn, got '1.5'"},
        {DATA "err_corner_empty_vt.obj", DATA "err_corner_empty_vt.obj:4:3: error: expected a "
                                              "vertex of the form v, v/vt, v//vn or v/vt/vn, "
                                              "got '1/'"},
        {DATA "err_face_two.obj", DATA "err_face_two.obj:4:6: error: expected at least 3 "
                                       "vertices after 'f', got 2"},
        {DATA "err_v_count.obj", DATA "err_v_count.obj:1:6: error: expected 3 numbers after 'v', "
                                      "got 2"},
        {DATA "err_v_count5.obj", DATA "err_v_count5.obj:1:12: error: expected 3, 4 or 6 "
                                       "numbers after 'v', got 5"},
        {DATA "err_vn_count.obj", DATA "err_vn_count.obj:1:10: error: expected 3 numbers after "
                                       "'vn', got 4"},
        {DATA "err_vt_count.obj", DATA "err_vt_count.obj:1:3: error: expected 1 to 3 numbers "
                                       "after 'vt', got 0"},
        {DATA "err_number.obj", DATA "err_number.obj:1:5: error: expected a number, got 'abc'"},
        {DATA "err_nan.obj", DATA "err_nan.obj:1:3: error: expected a finite number, got 'nan'"},
        {DATA "err_inf.obj", DATA "err_inf.obj:1:5: error: expected a finite number, got '-inf'"},
        {DATA "err_overflow.obj", DATA "err_overflow.obj:1:7: error: expected a finite number, "
                                       "got '1e39'"},
        {DATA "err_crlf.obj", DATA "err_crlf.obj:2:6: error: expected 3 numbers after 'v', got "
                                   "2"},
        {DATA "err_mtllib_empty.obj", DATA "err_mtllib_empty.obj:1:7: error: expected an MTL "
                                           "file name after 'mtllib', got end of line"},
        {DATA "err_usemtl_empty.obj", DATA "err_usemtl_empty.obj:1:7: error: expected a "
                                           "material name after 'usemtl', got end of line"},
    };
    check_golden(cases, sizeof cases / sizeof cases[0]);
}

/* MTL errors name the .mtl file: duplicate newmtl (same file, earlier mtllib), wrong counts,
 * illum not an integer 0..10, a key before newmtl, an over-long name, Inf, a NUL byte. */
Test(obj, errors_mtl)
{
    static const struct golden cases[] = {
        {DATA "err_mtl_dup.obj", DATA "err_mtl_dup.mtl:4:8: error: expected a new material name, "
                                      "got 'red' (already defined at line 1)"},
        {DATA "err_mtl_dup2.obj", DATA "err_mtl_dup2.mtl:1:8: error: expected a new material "
                                       "name, got 'red' (already defined by an earlier mtllib)"},
        {DATA "err_mtl_kd_count.obj", DATA "err_mtl_kd_count.mtl:2:13: error: expected 1 or 3 "
                                           "numbers after 'Kd', got 2"},
        {DATA "err_mtl_ns_count.obj", DATA "err_mtl_ns_count.mtl:2:3: error: expected 1 number "
                                           "after 'Ns', got 0"},
        {DATA "err_mtl_illum.obj", DATA "err_mtl_illum.mtl:2:7: error: expected an integer 0..10 "
                                        "after 'illum', got '2.5'"},
        {DATA "err_mtl_no_newmtl.obj", DATA "err_mtl_no_newmtl.mtl:1:1: error: expected "
                                            "'newmtl', got 'Kd' before any material"},
        {DATA "err_mtl_long_name.obj", DATA "err_mtl_long_name.mtl:1:8: error: expected a "
                                            "material name of at most 63 bytes, got 64 bytes"},
        {DATA "err_mtl_inf.obj", DATA "err_mtl_inf.mtl:2:4: error: expected a finite number, got "
                                      "'inf'"},
        {DATA "err_mtl_nul.obj", DATA "err_mtl_nul.mtl:2:1: error: expected text, got a NUL "
                                      "byte"},
    };
    check_golden(cases, sizeof cases / sizeof cases[0]);
}

/* Files: a missing OBJ or a directory has no line (strerror text, or what the path is); a
 * missing mtllib points at the name in the OBJ line; NUL bytes and a binary first byte are not
 * misread as text. */
Test(obj, errors_files)
{
    static const struct golden cases[] = {
        {DATA "no_such_file.obj", DATA "no_such_file.obj: error: cannot open: No such file or "
                                       "directory"},
        {"tests/data/obj", "tests/data/obj: error: expected a regular file, got a directory"},
        {DATA "err_mtllib_missing.obj", DATA "err_mtllib_missing.obj:1:8: error: cannot open "
                                             "mtllib 'no_such.mtl' (" DATA "no_such.mtl): No "
                                             "such file or directory"},
        {DATA "err_nul.obj", DATA "err_nul.obj:2:4: error: expected text, got a NUL byte"},
        {DATA "err_keyword.obj", DATA "err_keyword.obj:2:1: error: expected a statement keyword, "
                                      "got '\\x89PNG'"},
    };
    check_golden(cases, sizeof cases / sizeof cases[0]);
}

/* obj_free zeroes the mesh and is safe on a zeroed one (and twice). */
Test(obj, free_is_idempotent)
{
    struct obj_mesh m;
    load_ok(DATA "polygons.obj", &m);
    obj_free(&m);
    cr_assert_null(m.positions);
    cr_assert_null(m.tris);
    cr_assert_eq(m.n_tris, 0);
    obj_free(&m);
}

/* ---- issue 15: continuation, late mtllib, MTL colour forms, chunks, FIFOs, name tables ---- */

static char tmp_dir[256];

static void tmp_setup(void) { test_make_dir(tmp_dir, sizeof tmp_dir, "obj_test"); }
static void tmp_teardown(void) { test_remove_dir(tmp_dir); }

/* Writes len bytes of text to tmp_dir/name; returns the path in a static buffer (one at a time). */
static const char *write_tmp_n(const char *name, const char *text, size_t len)
{
    static char path[512];
    snprintf(path, sizeof path, "%s/%s", tmp_dir, name);
    FILE *f = fopen(path, "wb");
    cr_assert_not_null(f, "%s", path);
    cr_assert_eq(fwrite(text, 1, len, f), len);
    cr_assert_eq(fclose(f), 0);
    return path;
}

static const char *write_tmp(const char *name, const char *text)
{
    return write_tmp_n(name, text, strlen(text));
}

/* The error obj_load gives for path, with tmp_dir cut off the front: "a.obj:2:3: error: ...". */
static void expect_error(const char *path, const char *golden)
{
    struct obj_mesh m;
    struct mcpt_error err = {0};
    cr_assert_not(obj_load(path, &m, &err), "%s loaded but should fail", path);
    char got[MCPT_ERROR_LINE_BYTES];
    mcpt_error_format(&err, got, sizeof got);
    size_t n_dir = strlen(tmp_dir);
    const char *shown = strncmp(got, tmp_dir, n_dir) == 0 ? got + n_dir + 1 : got;
    cr_assert_str_eq(shown, golden);
}

/* The same, for the message with tmp_dir cut out wherever it appears (MTL paths in messages). */
static void expect_error_anywhere(const char *path, const char *golden)
{
    struct obj_mesh m;
    struct mcpt_error err = {0};
    cr_assert_not(obj_load(path, &m, &err), "%s loaded but should fail", path);
    char got[MCPT_ERROR_LINE_BYTES], cut[MCPT_ERROR_LINE_BYTES];
    mcpt_error_format(&err, got, sizeof got);
    size_t n_dir = strlen(tmp_dir), n = 0;
    for (const char *s = got; *s;) {
        if (strncmp(s, tmp_dir, n_dir) == 0 && s[n_dir] == '/')
            s += n_dir + 1;
        else
            cut[n++] = *s++;
    }
    cut[n] = '\0';
    cr_assert_str_eq(cut, golden);
}

/* Warning i of the mesh with tmp_dir cut off the front. */
static const char *warning_text(const struct obj_mesh *m, uint32_t i)
{
    cr_assert_lt(i, m->n_warnings);
    size_t n_dir = strlen(tmp_dir);
    const char *w = m->warnings[i];
    return strncmp(w, tmp_dir, n_dir) == 0 ? w + n_dir + 1 : w;
}

/* Wavefront, "Object Files (.obj)": a '\' at the end of a line continues the statement on the
 * next (Blender reads it so: the '\' and the line end become blanks).  Blanks and a CR may
 * follow the '\'; a '\' inside a token (a Windows path) is an ordinary byte; the last line's
 * '\' at the end of the file is a blank.  Faces keep the line they start on, and an error
 * after a continuation names the physical line and column. */
Test(obj, backslash_continues_a_statement, .init = tmp_setup, .fini = tmp_teardown)
{
    const char *path = write_tmp("cont.obj", "v 0 0 \\\n0\nv 1 \\  \r\n 0 0\r\nv 0 1 0\n"
                                             "v 1 1 0\nf 1 2 \\\n\\\n 3 4\nf -1 -2 -3 \\");
    struct obj_mesh m;
    load_ok(path, &m);
    cr_assert_eq(m.n_positions, 4);
    cr_assert(vec3_eq(m.positions[0], v3(0, 0, 0)) && vec3_eq(m.positions[1], v3(1, 0, 0)));
    cr_assert_eq(m.n_tris, 3);
    assert_tri(&m, 0, 0, 1, 2, -1, -1, -1, -1, -1, -1);
    assert_tri(&m, 1, 0, 2, 3, -1, -1, -1, -1, -1, -1);
    assert_tri(&m, 2, 3, 2, 1, -1, -1, -1, -1, -1, -1);
    cr_assert_eq(m.tris[0].line, 7, "the face starts on line 7");
    cr_assert_eq(m.tris[2].line, 10, "the last face follows the joined lines");
    obj_free(&m);

    path = write_tmp("cont_err.obj", "v 0 0 0\nv 1 2 \\\n  3 oops\n");
    expect_error(path, "cont_err.obj:3:5: error: expected a number, got 'oops'");
    path = write_tmp("cont_err2.obj", "v 0 0 0\nf 1 \\\r\n \\\r\n 1 1 9\n");
    expect_error(path, "cont_err2.obj:4:6: error: expected a vertex index in 1..1 or -1..-1, got "
                       "9");
    /* a backslash inside a token is not a continuation */
    path = write_tmp("cont_token.obj", "v 0 0 0\\x\n");
    expect_error(path, "cont_token.obj:1:7: error: expected a number, got '0\\x'");
}

/* Continuation works in MTL files too. */
Test(obj, backslash_continues_an_mtl_statement, .init = tmp_setup, .fini = tmp_teardown)
{
    write_tmp("c.mtl", "newmtl a\nKd 0.25 \\\n 0.5 \\\n 0.75\nKe 1 2 3\n");
    const char *path = write_tmp("c.obj", "mtllib c.mtl\n");
    struct obj_mesh m;
    load_ok(path, &m);
    cr_assert_eq(m.n_materials, 1);
    cr_assert(vec3_eq(m.materials[0].Kd, v3(0.25f, 0.5f, 0.75f)));
    cr_assert(vec3_eq(m.materials[0].Ke, v3(1, 2, 3)));
    obj_free(&m);
}

/* A repeated mtllib is read once when it names the same file another way too: "./a.mtl", a
 * symbolic link (docs/scene-format.md: "each file is read once"); reading it twice would make
 * its newmtl names duplicates, an error.  A different file that defines the same name still
 * is one. */
Test(obj, mtllib_same_file_by_another_name_is_read_once, .init = tmp_setup, .fini = tmp_teardown)
{
    write_tmp("a.mtl", "newmtl red\nKd 1 0 0\n");
    char target[512], link[512];
    snprintf(target, sizeof target, "%s/a.mtl", tmp_dir);
    snprintf(link, sizeof link, "%s/b.mtl", tmp_dir);
    cr_assert_eq(symlink(target, link), 0);
    const char *path = write_tmp("same.obj", "mtllib a.mtl\nmtllib ./a.mtl\nmtllib b.mtl a.mtl\n"
                                             "v 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl red\nf 1 2 3\n");
    struct obj_mesh m;
    load_ok(path, &m);
    cr_assert_eq(m.n_materials, 1);
    cr_assert_eq(m.tris[0].mat_idx, 0);
    obj_free(&m);

    write_tmp("c.mtl", "newmtl red\nKd 0 1 0\n");
    path = write_tmp("other.obj", "mtllib a.mtl c.mtl\n");
    expect_error(path, "c.mtl:1:8: error: expected a new material name, got 'red' (already "
                       "defined by an earlier mtllib)");
}

/* A usemtl may come before the mtllib that defines its name: names resolve once every mtllib
 * is read (Blender reads the MTL files after the whole OBJ).  A name no mtllib defines gets
 * mat_idx -1 and one warning at its first use, counting the other undefined names; without
 * any mtllib (the dragon's stray usemtl) there is nothing to warn about. */
Test(obj, usemtl_before_mtllib_resolves, .init = tmp_setup, .fini = tmp_teardown)
{
    write_tmp("late.mtl", "newmtl lamp\nKe 17 12 4\nnewmtl white\nKd 0.7\n");
    const char *path = write_tmp("late.obj", "usemtl lamp\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                             "f 1 2 3\nusemtl white\nf 1 2 3\nusemtl nope\n"
                                             "f 1 2 3\nusemtl nope2\nf 3 2 1\nusemtl lamp\n"
                                             "f 3 2 1\nmtllib late.mtl\n");
    struct obj_mesh m;
    load_ok(path, &m);
    cr_assert_eq(m.n_tris, 5);
    const int32_t want[5] = {0, 1, -1, -1, 0};
    for (uint32_t i = 0; i < 5; i++)
        cr_assert_eq(m.tris[i].mat_idx, want[i], "tri %u: %d", i, m.tris[i].mat_idx);
    cr_assert_eq(m.n_warnings, 1);
    cr_assert_str_eq(warning_text(&m, 0), "late.obj:8:8: warning: usemtl 'nope': no mtllib "
                                          "defines it, so its faces get the default material "
                                          "(1 more usemtl name is undefined too)");
    obj_free(&m);

    path = write_tmp("nolib.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl x\nf 1 2 3\n");
    load_ok(path, &m);
    cr_assert_eq(m.tris[0].mat_idx, -1);
    cr_assert_eq(m.n_warnings, 0, "no mtllib: usemtl names only label faces");
    obj_free(&m);
}

/* MTL colour forms (Wavefront, "Material Library File (.mtl)", Ka): "xyz x [y z]" is CIE XYZ,
 * converted with the IEC 61966-2-1 (sRGB) matrix: D65 white XYZ (0.9505, 1, 1.089) -> RGB
 * (1, 1, 1) to the matrix's 4 decimals, and one number means x = y = z; "spectral file.rfl
 * [factor]" is ignored (the key keeps its value) with one warning for the whole load;
 * "d -halo f" reads f. */
Test(obj, mtl_xyz_spectral_and_halo, .init = tmp_setup, .fini = tmp_teardown)
{
    write_tmp("forms.mtl", "newmtl a\nKd xyz 0.9505 1 1.089\nKa spectral wood.rfl 0.5\n"
                           "Ke xyz 1\nd -halo 0.25\nnewmtl b\nKd 0.5\nKd spectral w.rfl\n"
                           "Tf spectral w.rfl 2\n");
    const char *path = write_tmp("forms.obj", "mtllib forms.mtl\n");
    struct obj_mesh m;
    load_ok(path, &m);
    cr_assert_eq(m.n_materials, 2);
    const struct obj_material *a = &m.materials[0];
    cr_assert(fabsf(a->Kd.x - 1.0f) < 1e-4f && fabsf(a->Kd.y - 1.0f) < 1e-4f &&
                  fabsf(a->Kd.z - 1.0f) < 1e-4f,
              "D65 white -> (%g, %g, %g)", a->Kd.x, a->Kd.y, a->Kd.z);
    /* XYZ (1, 1, 1): each row of the matrix summed */
    cr_assert(fabsf(a->Ke.x - (3.2406f - 1.5372f - 0.4986f)) < 1e-6f &&
              fabsf(a->Ke.y - (-0.9689f + 1.8758f + 0.0415f)) < 1e-6f &&
              fabsf(a->Ke.z - (0.0557f - 0.2040f + 1.0570f)) < 1e-6f);
    cr_assert_eq(a->d, 0.25f);
    cr_assert(vec3_eq(m.materials[1].Kd, v3(0.5f, 0.5f, 0.5f)), "spectral keeps the value");
    cr_assert(vec3_eq(m.materials[1].Tf, v3(1, 1, 1)), "spectral keeps the default");
    cr_assert_eq(m.n_warnings, 1, "one warning for every spectral colour");
    cr_assert_str_eq(warning_text(&m, 0), "forms.mtl:3:4: warning: 'Ka spectral' ignored: mcpt "
                                          "reads no .rfl spectral curves, so Ka keeps its value "
                                          "(2 more 'spectral' colours ignored too)");
    obj_free(&m);

    write_tmp("bad1.mtl", "newmtl a\nKd xyz 1 2\n");
    expect_error(write_tmp("bad1.obj", "mtllib bad1.mtl\n"),
                 "bad1.mtl:2:11: error: expected 1 or 3 numbers after 'Kd xyz', got 2");
    write_tmp("bad2.mtl", "newmtl a\nKd spectral\n");
    expect_error(write_tmp("bad2.obj", "mtllib bad2.mtl\n"),
                 "bad2.mtl:2:12: error: expected an .rfl file name after 'Kd spectral', got end "
                 "of line");
    write_tmp("bad3.mtl", "newmtl a\nKe xyz 3e38 0 0\n");
    expect_error(write_tmp("bad3.obj", "mtllib bad3.mtl\n"),
                 "bad3.mtl:2:4: error: expected 'Ke xyz' values whose RGB is within float range "
                 "(|component| <= 3.40282e+38), got 9.7218e+38 for R");
    write_tmp("bad4.mtl", "newmtl a\nd -halo\n");
    expect_error(write_tmp("bad4.obj", "mtllib bad4.mtl\n"),
                 "bad4.mtl:2:8: error: expected 1 number after 'd', got 0");
}

/* mtllib: a name with spaces that names a file as a whole is one name (Blender's reading; the
 * Blender exporter writes the OBJ's own name, spaces and all), double quotes are dropped, and
 * otherwise the names are split at blanks as the format says; a repeated name is read once. */
Test(obj, mtllib_names_with_spaces_and_quotes, .init = tmp_setup, .fini = tmp_teardown)
{
    write_tmp("my scene.mtl", "newmtl a\n");
    write_tmp("b.mtl", "newmtl b\n");
    struct obj_mesh m;
    load_ok(write_tmp("s1.obj", "mtllib my scene.mtl\n"), &m);
    cr_assert_eq(m.n_materials, 1);
    obj_free(&m);
    load_ok(write_tmp("s2.obj", "mtllib \"my scene.mtl\"\nmtllib b.mtl \"b.mtl\" b.mtl\n"), &m);
    cr_assert_eq(m.n_materials, 2);
    cr_assert_str_eq(m.materials[1].name, "b");
    obj_free(&m);
    expect_error_anywhere(write_tmp("s3.obj", "mtllib b.mtl nope.mtl\n"),
                          "s3.obj:1:14: error: cannot open mtllib 'nope.mtl' (nope.mtl): No "
                          "such file or directory");
}

/* A FIFO (no writer) as OBJ or as MTL is refused at once, not waited on in open(); so are a
 * directory and a character device as MTL.  UTF-16 is named as such. */
Test(obj, fifo_and_other_files_refused, .init = tmp_setup, .fini = tmp_teardown,
     .timeout = TEST_TIMEOUT_S(10))
{
    char fifo[400];
    snprintf(fifo, sizeof fifo, "%s/pipe.obj", tmp_dir);
    cr_assert_eq(mkfifo(fifo, 0600), 0);
    expect_error(fifo, "pipe.obj: error: expected a regular file, got a FIFO");
    expect_error_anywhere(write_tmp("f.obj", "mtllib pipe.obj\n"),
                          "f.obj:1:8: error: expected a regular file for mtllib 'pipe.obj' "
                          "(pipe.obj), got a FIFO");
    expect_error_anywhere(write_tmp("d.obj", "mtllib .\n"),
                          "d.obj:1:8: error: expected a regular file for mtllib '.' (.), got a "
                          "directory");
    expect_error_anywhere(write_tmp("z.obj", "mtllib /dev/zero\n"),
                          "z.obj:1:8: error: expected a regular file for mtllib '/dev/zero' "
                          "(/dev/zero), got a character device");
    expect_error(write_tmp_n("u16.obj", "\xff\xfev\0 \0", 6),
                 "u16.obj:1:1: error: expected UTF-8 text, got UTF-16 (byte order mark 0xff "
                 "0xfe)");
}

/* Reading in chunks: a file of many chunks reads as one (statements cross chunk boundaries,
 * one of them continued across one), and a NUL byte far into the file is reported at its
 * line and column after the statements before it. */
Test(obj, chunks_join_and_stop_at_the_first_nul, .init = tmp_setup, .fini = tmp_teardown)
{
    enum { N_VERTS = 100000 }; /* ~2 MB: several 256 KiB chunks */
    size_t cap = (size_t)N_VERTS * 40 + 64, n = 0;
    char *text = malloc(cap);
    cr_assert_not_null(text);
    for (int i = 0; i < N_VERTS; i++)
        n += (size_t)snprintf(text + n, cap - n,
                              i % 1000 == 7 ? "v %d.5 -%d \\\n %d\n" : "v %d.5 -%d %d\n", i, i,
                              i % 7);
    n += (size_t)snprintf(text + n, cap - n, "f 1 2 3\n");
    struct obj_mesh m;
    load_ok(write_tmp_n("big.obj", text, n), &m);
    cr_assert_eq(m.n_positions, N_VERTS);
    for (int i = 0; i < N_VERTS; i++)
        cr_assert(vec3_eq(m.positions[i], v3((float)i + 0.5f, -(float)i, (float)(i % 7))),
                  "vertex %d", i);
    obj_free(&m);
    size_t at = n - 8 + 3; /* the face line: "f 1\0..." */
    text[at] = '\0';
    int n_lines = N_VERTS + N_VERTS / 1000 + 1; /* + the joined lines: the face's line */
    char golden[200];
    snprintf(golden, sizeof golden, "big.obj:%d:4: error: expected text, got a NUL byte", n_lines);
    expect_error(write_tmp_n("big.obj", text, n), golden);
    free(text);
}

/* A 3 GiB sparse file of NUL bytes (no disk used): the error comes at 1:1 after reading one
 * chunk, and the process holds far less than the file (it held 3.1 GB when the reader read
 * whole files). */
Test(obj, sparse_3gib_of_nuls_stops_at_once, .init = tmp_setup, .fini = tmp_teardown,
     .timeout = TEST_TIMEOUT_S(20))
{
    char path[400];
    snprintf(path, sizeof path, "%s/zeros.obj", tmp_dir);
    int fd = open(path, O_WRONLY | O_CREAT | O_TRUNC, 0600);
    cr_assert_geq(fd, 0);
    cr_assert_eq(ftruncate(fd, (off_t)3 << 30), 0);
    close(fd);
    expect_error(path, "zeros.obj:1:1: error: expected text, got a NUL byte");
    struct rusage ru;
    cr_assert_eq(getrusage(RUSAGE_SELF, &ru), 0);
    cr_assert_lt(ru.ru_maxrss, 256 * 1024, "peak %ld KiB", ru.ru_maxrss); /* ru_maxrss: KiB */
}

/* A statement longer than 16 MiB (here one line of 20 MB without a newline) is refused
 * instead of growing the buffer without bound. */
Test(obj, overlong_statement_refused, .init = tmp_setup, .fini = tmp_teardown,
     .timeout = TEST_TIMEOUT_S(30))
{
    size_t n = 20u << 20;
    char *text = malloc(n);
    cr_assert_not_null(text);
    memcpy(text, "v 0 0 0\nv", 9);
    memset(text + 9, ' ', n - 9);
    expect_error(write_tmp_n("long.obj", text, n),
                 "long.obj:2:1: error: expected a statement of at most 16777216 bytes ('\\' "
                 "continuation lines included), got a longer one");
    free(text);
}

/* The name table: every name found with its value, absent names not found, keys kept; and
 * the cost stays O(1) per operation, counted in probes rather than timed: with the table at
 * most half full, linear probing inspects about 1.5 slots per successful search and 2.5 per
 * unsuccessful one (Knuth, TAOCP vol. 3, 6.4), so 3 per operation on average is a generous
 * bound.  A quadratic lookup (the old linear scan) would inspect ~n/2 per operation. */
Test(obj, name_table_is_linear)
{
    enum { N = 300000 };
    struct obj_names t = {0};
    char name[32];
    uint32_t n_wrong = 0; /* one assertion at the end: a million cr_asserts cost seconds */
    for (uint32_t i = 0; i < N; i++) {
        int len = snprintf(name, sizeof name, "mat_%u", i * 7919u);
        n_wrong += obj_names_find(&t, name, (size_t)len) != -1;
        n_wrong += !obj_names_add(&t, name, (size_t)len, i);
    }
    for (uint32_t i = 0; i < N; i++) {
        int len = snprintf(name, sizeof name, "mat_%u", i * 7919u);
        n_wrong += obj_names_find(&t, name, (size_t)len) != (int64_t)i;
    }
    cr_assert_eq(n_wrong, 0);
    cr_assert_eq(obj_names_find(&t, "mat_1", 5), -1);
    cr_assert_eq(obj_names_find(&t, "mat_", 4), -1);
    cr_assert_str_eq(obj_names_key(&t, 3), "mat_23757");
    uint64_t n_ops = 3u * (uint64_t)N; /* a find and an add per name, then a find */
    cr_assert_lt(t.n_probes, 3 * n_ops, "%llu probes for %llu operations",
                 (unsigned long long)t.n_probes, (unsigned long long)n_ops);
    obj_names_free(&t);
    cr_assert_null(t.slots);
}

/* 200k materials and 200k usemtl in one OBJ: the duplicate check of newmtl and the usemtl
 * lookups were linear scans (2 * 2e10 string compares: minutes); with the hash tables this
 * loads in well under a second.  The timeout is the hang cap, set far above the linear time
 * (sanitizer builds are ~10x slower) and far below the quadratic one. */
Test(obj, many_materials_load_in_linear_time, .init = tmp_setup, .fini = tmp_teardown,
     .timeout = TEST_TIMEOUT_S(60))
{
    enum { N = 200000 };
    size_t cap = (size_t)N * 32, n_mtl = 0, n_obj = 0;
    char *mtl = malloc(cap), *obj = malloc(cap + 64);
    cr_assert(mtl && obj);
    n_obj += (size_t)sprintf(obj, "mtllib many.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n");
    for (int i = 0; i < N; i++) {
        n_mtl += (size_t)sprintf(mtl + n_mtl, "newmtl m%d\nKd 0.5\n", i);
        n_obj += (size_t)sprintf(obj + n_obj, "usemtl m%d\nf 1 2 3\n", N - 1 - i);
    }
    write_tmp_n("many.mtl", mtl, n_mtl);
    struct obj_mesh m;
    load_ok(write_tmp_n("many.obj", obj, n_obj), &m);
    cr_assert_eq(m.n_materials, N);
    for (uint32_t i = 0; i < N; i++)
        cr_assert_eq(m.tris[i].mat_idx, (int32_t)(N - 1 - i));
    obj_free(&m);
    free(mtl);
    free(obj);
}

/* Number literals at the edges: a literal that underflows is the 0 or denormal it rounds to
 * (strtof's ERANGE is not an error); hexadecimal floats, which strtof would read, are not OBJ
 * numbers (the scene format refuses them too); NaN in any spelling is refused. */
Test(obj, number_literal_edges, .init = tmp_setup, .fini = tmp_teardown)
{
    struct obj_mesh m;
    load_ok(write_tmp("tiny.obj", "v 1e-50 -1e-50 1e-40\n"), &m);
    cr_assert(m.positions[0].x == 0.0f && m.positions[0].y == 0.0f && signbit(m.positions[0].y));
    cr_assert_eq(m.positions[0].z, 1e-40f);
    obj_free(&m);
    expect_error(write_tmp("hex.obj", "v 0x1p3 0 0\n"), "hex.obj:1:3: error: expected a number, "
                                                        "got '0x1p3'");
    expect_error(write_tmp("nanp.obj", "v 0 nan(0x1) 0\n"), "nanp.obj:1:5: error: expected a "
                                                            "finite number, got 'nan(0x1)'");
}
