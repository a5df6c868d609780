/* fuzz/fuzz_obj.c - libFuzzer harness for obj_load (obj.c: the OBJ and MTL readers).
 * An input is an OBJ file, optionally followed by a line "#MTL" and an MTL file: the two parts
 * are written to a.obj and a.mtl in a private temporary folder (a.mtl is absent when the input
 * has no such line), and obj_load reads a.obj, which reaches a.mtl through "mtllib a.mtl".
 * A crash, hang, leak or sanitizer report is a bug.  A rejected input must carry a one-line
 * message naming a file; an accepted one must satisfy the struct obj_mesh invariants below
 * (indices in range, finite numbers), which scene.c relies on.
 * Run: make fuzz FUZZ_SECONDS=N (fuzz/run.sh); seeds: tests/bad/obj, tests/bad/mtl,
 * tests/data/obj and scenes/models. */
#include "obj.h"

#include <stdlib.h>
#include <unistd.h>

#include "fuzz_util.h"

#define MTL_SEPARATOR "\n#MTL\n"

static char obj_path[96]; /* the scratch folder's a.obj */
static char mtl_path[96]; /* the scratch folder's a.mtl */

int LLVMFuzzerInitialize(int *argc, char ***argv);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
    (void)argc;
    (void)argv;
    fuzz_make_dir("obj");
    fuzz_path(obj_path, sizeof obj_path, "a.obj");
    fuzz_path(mtl_path, sizeof mtl_path, "a.mtl");
    return 0;
}

/* The first occurrence of needle in the first size bytes of data, or NULL. */
static const uint8_t *find(const uint8_t *data, size_t size, const char *needle)
{
    size_t n = strlen(needle);
    for (size_t i = 0; i + n <= size; i++)
        if (memcmp(data + i, needle, n) == 0)
            return data + i;
    return NULL;
}

static void check_mesh(const struct obj_mesh *m)
{
    for (uint32_t i = 0; i < m->n_positions; i++)
        if (!v3_is_finite(m->positions[i]))
            abort();
    for (uint32_t i = 0; i < m->n_normals; i++)
        if (!v3_is_finite(m->normals[i]))
            abort();
    for (uint32_t i = 0; i < m->n_tris; i++) {
        const struct obj_tri *t = &m->tris[i];
        if (t->mat_idx < -1 || t->mat_idx >= (int32_t)m->n_materials)
            abort();
        for (int k = 0; k < 3; k++)
            if (t->v[k] >= m->n_positions || t->vt[k] < -1 || t->vt[k] >= (int32_t)m->n_uvs ||
                t->vn[k] < -1 || t->vn[k] >= (int32_t)m->n_normals)
                abort();
    }
    for (uint32_t i = 0; i < m->n_materials; i++) {
        const struct obj_material *om = &m->materials[i];
        if (!memchr(om->name, '\0', sizeof om->name) || !v3_is_finite(om->Kd) ||
            !v3_is_finite(om->Ke) || !v3_is_finite(om->Ks) || !v3_is_finite(om->Tf) ||
            !isfinite(om->Ni) || !isfinite(om->d) || om->illum < 0 || om->illum > 10)
            abort();
    }
    /* warnings: one line each, "file:line:col: warning: ..." */
    for (uint32_t i = 0; i < m->n_warnings && i < OBJ_MAX_WARNINGS; i++)
        if (!memchr(m->warnings[i], '\0', OBJ_WARNING_BYTES) ||
            !strstr(m->warnings[i], ": warning: ") || strpbrk(m->warnings[i], "\r\n"))
            abort();
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    const uint8_t *sep = find(data, size, MTL_SEPARATOR);
    size_t n_obj = sep ? (size_t)(sep - data) + 1 : size; /* keep the OBJ's last newline */
    fuzz_write_file(obj_path, data, n_obj);
    if (sep) {
        size_t skip = (size_t)(sep - data) + strlen(MTL_SEPARATOR);
        fuzz_write_file(mtl_path, data + skip, size - skip);
    } else {
        unlink(mtl_path);
    }
    struct obj_mesh mesh;
    struct mcpt_error err = {0};
    if (obj_load(obj_path, &mesh, &err)) {
        check_mesh(&mesh);
        obj_free(&mesh);
    } else {
        fuzz_check_rejection(&err);
    }
    return 0;
}
