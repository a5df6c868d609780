/* obj.h - Wavefront OBJ and MTL reader.  Knows nothing of lights, the BVH or rendering: it
 * returns positions, normals, texture coordinates, fan-triangulated faces and the raw MTL
 * records; scene.c maps those records onto mcpt materials. */
#ifndef MCPT_OBJ_H
#define MCPT_OBJ_H

#include "vec.h"

/* One MTL "newmtl" record with the keys mcpt reads.  Keys absent from the file keep the
 * defaults obj_load documents (Kd 0.8, Ks 0, Ke 0, Tf 1, Ns 0, Ni 1, d 1, illum 2). */
struct obj_material {
    char name[64]; /* newmtl name */
    vec3 Kd;       /* diffuse reflectance */
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
}; /* 44 bytes */

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
};

/* Reads the OBJ at path and every MTL it names (paths relative to the OBJ's folder).
 * Statements: v vt vn f o g s usemtl mtllib (others are ignored: l p cstype ... are not).
 * Index forms v, v/vt, v//vn, v/vt/vn; negative indices count back from the current end.
 * CRLF, tabs and a missing final newline are accepted.  A usemtl naming a material that no
 * mtllib defined sets mat_idx = -1 (the dragon model has one).
 * On success fills *mesh (caller frees with obj_free) and returns true.  On bad input returns
 * false, leaves *mesh empty and fills *err with "file:line:col" and what was expected. */
bool obj_load(const char *path, struct obj_mesh *mesh, struct mcpt_error *err);

/* Frees what obj_load allocated and zeroes *mesh.  Safe on a zeroed mesh. */
void obj_free(struct obj_mesh *mesh);

#endif
