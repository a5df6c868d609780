/* obj.h - Wavefront OBJ and MTL reader.  Knows nothing of lights, the BVH or rendering: it
 * returns positions, normals, texture coordinates, fan-triangulated faces and the raw MTL
 * records; scene.c maps those records onto mcpt materials.  Also two small helpers the scene
 * parser shares: opening an input file without blocking, and a table of names. */
#ifndef MCPT_OBJ_H
#define MCPT_OBJ_H

#include "vec.h"

/* One MTL "newmtl" record with the keys mcpt reads.  Keys absent from the file keep the
 * defaults obj_load documents (Kd 0.8, Ks 0, Ke 0, Tf 1, Ns 0, Ni 1, d 1, illum 2). */
struct obj_material {
    char name[64]; /* newmtl name */
    vec3 Kd;       /* diffuse reflectance, linear RGB (an "xyz" colour is converted) */
    vec3 Ks;       /* specular reflectance */
    vec3 Ke;       /* emitted radiance */
    vec3 Tf;       /* transmission filter */
    float Ns;      /* specular exponent */
    float Ni;      /* index of refraction */
    float d;       /* dissolve (opacity) */
    int illum;     /* illumination model number */
    int line;      /* line of "newmtl" in its .mtl file, for messages */
};

/* One triangle.  vt/vn are -1 where the face gave no such index. */
struct obj_tri {
    uint32_t v[3];   /* indices into positions */
    int32_t vt[3];   /* indices into uvs, or -1 */
    int32_t vn[3];   /* indices into normals, or -1 */
    int32_t mat_idx; /* index into materials of the active usemtl, or -1 (none or unknown) */
    uint32_t line;   /* line of the face statement, for messages */
};                   /* 44 bytes */

#define OBJ_MAX_WARNINGS 4    /* warnings kept per load; n_warnings counts them all */
#define OBJ_WARNING_BYTES 400 /* one warning line, "file:line:col: warning: ...", with NUL */

struct obj_mesh {
    vec3 *positions; /* v */
    uint32_t n_positions;
    vec3 *normals; /* vn, as written (not normalised) */
    uint32_t n_normals;
    vec2 *uvs; /* vt (u, v); a third component is read and dropped */
    uint32_t n_uvs;
    struct obj_tri *tris; /* faces, fan-triangulated from each polygon's first vertex */
    uint32_t n_tris;
    struct obj_material *materials; /* from every mtllib, in file order */
    uint32_t n_materials;
    /* what was accepted but not used as written ('spectral' colours, a usemtl no mtllib
     * defines): one line each, for main to print */
    char warnings[OBJ_MAX_WARNINGS][OBJ_WARNING_BYTES];
    uint32_t n_warnings;
    char **mtl_paths; /* every MTL file read, as opened (the OBJ's folder prefixed), each
                         malloc'ed: inputs no output may overwrite */
    uint32_t n_mtl_paths;
};

/* Reads the OBJ at path and every MTL it names (paths relative to the OBJ's folder).
 * Statements: v vt vn f o g s usemtl mtllib (others are ignored: l p cstype ... are not).
 * Index forms v, v/vt, v//vn, v/vt/vn; negative indices count back from the current end.
 * CRLF, tabs, a UTF-8 byte order mark, a missing final newline and a '\' continuing a line are
 * accepted.  usemtl names are resolved after every mtllib of the file is read (so a usemtl may
 * come before the mtllib that defines it, as Blender reads it); a name no mtllib defines sets
 * mat_idx = -1, with a warning when the file names any mtllib (the dragon model has a stray
 * usemtl and no mtllib).  Files are read in chunks of whole lines, never whole, and reading
 * stops at the first NUL byte.
 * On success fills *mesh (caller frees with obj_free) and returns true.  On bad input returns
 * false, leaves *mesh empty and fills *err with "file:line:col" and what was expected; a file
 * that cannot be opened or is not a regular file has no line ("x.obj: error: cannot open: ..."). */
bool obj_load(const char *path, struct obj_mesh *mesh, struct mcpt_error *err);

/* obj_load for a file the caller has opened (with file.h's file_open_input): reads fd, which it closes,
 * naming path in messages and resolving MTL paths against path's folder. */
bool obj_load_fd(int fd, const char *path, struct obj_mesh *mesh, struct mcpt_error *err);

/* Frees what obj_load allocated and zeroes *mesh.  Safe on a zeroed mesh. */
void obj_free(struct obj_mesh *mesh);

/* A table of names (byte strings) to uint32 values: open addressing with linear probing on a
 * 64-bit FNV-1a hash, at most half full, so finding or adding a name costs O(1) expected.  The
 * table keeps its own copy of every name; entries are numbered 0, 1, ... in the order added.
 * A zeroed struct is an empty table. */
#define OBJ_NAMES_MAX ((uint32_t)1 << 30) /* most names: 2^31 slots, half full */

struct obj_name_entry {
    uint64_t hash;     /* FNV-1a 64 of the name */
    size_t key_offset; /* the name's first byte in keys (NUL-terminated there) */
    uint32_t key_bytes;
    uint32_t value;
}; /* 24 bytes */

struct obj_names {
    uint32_t *slots;  /* n_slots: entry index + 1, or 0 for an empty slot */
    uint32_t n_slots; /* 2^slot_bits, or 0 before the first name */
    unsigned slot_bits;
    struct obj_name_entry *entries;
    uint32_t n_entries;
    uint32_t cap_entries;
    char *keys; /* every name, each followed by a NUL */
    size_t n_key_bytes;
    size_t cap_key_bytes;
    uint64_t n_probes; /* slots inspected by every find and add so far (tests bound it) */
};

/* The value of the name [key, key + key_bytes), or -1 when the table has no such name. */
int64_t obj_names_find(struct obj_names *t, const char *key, size_t key_bytes);
/* Adds a name the table does not hold yet.  False when out of memory or past OBJ_NAMES_MAX
 * names (the table then holds what it held before). */
bool obj_names_add(struct obj_names *t, const char *key, size_t key_bytes, uint32_t value);
/* The NUL-terminated name of entry entry_idx (< n_entries). */
const char *obj_names_key(const struct obj_names *t, uint32_t entry_idx);
/* Frees the table and zeroes it. */
void obj_names_free(struct obj_names *t);

#endif
