/* tests/camera_test.c - camera.c: primary rays at the film's centre and corners match the
 * pinhole model (vertical fov, aspect), and the thin lens focuses on the plane of focus
 * (PBRT 4e, ch. 5, "Projective Camera Models"). */
#include <criterion/criterion.h>

#include "camera.h"

static struct camera make_cam(int w, int h, float aperture)
{
    struct camera_params p = {.eye = v3(0, 1, 3.9f), .look_at = v3(0, 1, 0), .up = v3(0, 1, 0),
                              .fov_deg = 40.0f, .aperture = aperture};
    struct camera cam;
    struct mcpt_error err;
    cr_assert(camera_init(&cam, &p, w, h, &err));
    return cam;
}

/* The film centre looks straight at look_at. */
Test(camera, centre)
{
    struct camera cam = make_cam(512, 256, 0.0f);
    struct ray r = camera_ray(&cam, 256.0f, 128.0f, (vec2){0.5f, 0.5f});
    cr_assert_float_eq(r.d.x, 0.0f, 1e-6f);
    cr_assert_float_eq(r.d.y, 0.0f, 1e-6f);
    cr_assert_float_eq(r.d.z, -1.0f, 1e-6f);
    cr_assert_float_eq(r.o.z, 3.9f, 1e-6f);
}

/* Corners: the top-left corner is at (-aspect tan(fov/2), +tan(fov/2), -1) before normalising;
 * y grows downwards on the film. */
Test(camera, corners)
{
    struct camera cam = make_cam(512, 256, 0.0f);
    float th = tanf(20.0f * MCPT_PI / 180.0f);
    vec3 tl = v3_normalize(v3(-2.0f * th, th, -1.0f));
    vec3 br = v3_normalize(v3(2.0f * th, -th, -1.0f));
    struct ray r = camera_ray(&cam, 0.0f, 0.0f, (vec2){0.5f, 0.5f});
    cr_assert_float_eq(r.d.x, tl.x, 1e-6f);
    cr_assert_float_eq(r.d.y, tl.y, 1e-6f);
    cr_assert_float_eq(r.d.z, tl.z, 1e-6f);
    r = camera_ray(&cam, 512.0f, 256.0f, (vec2){0.5f, 0.5f});
    cr_assert_float_eq(r.d.x, br.x, 1e-6f);
    cr_assert_float_eq(r.d.y, br.y, 1e-6f);
    cr_assert_float_eq(r.d.z, br.z, 1e-6f);
}

/* Thin lens: every lens sample's ray passes through the same point on the plane of focus. */
Test(camera, thin_lens_focus)
{
    struct camera cam = make_cam(100, 100, 0.2f);
    vec3 target = v3(0, 0, 0);
    for (int i = 0; i < 16; i++) {
        vec2 u = {0.0625f * (float)i + 0.01f, 0.37f * (float)(i % 3) + 0.05f};
        struct ray r = camera_ray(&cam, 30.0f, 70.0f, u);
        /* plane of focus: z = eye.z - focus_dist = 0 */
        float t = -r.o.z / r.d.z;
        vec3 p = v3_add(r.o, v3_scale(r.d, t));
        if (i == 0)
            target = p;
        cr_assert_float_eq(p.x, target.x, 1e-5f);
        cr_assert_float_eq(p.y, target.y, 1e-5f);
    }
}

/* Degenerate cameras are refused. */
Test(camera, degenerate)
{
    struct camera cam;
    struct mcpt_error err;
    struct camera_params p = {.eye = v3(1, 1, 1), .look_at = v3(1, 1, 1), .up = v3(0, 1, 0),
                              .fov_deg = 40.0f};
    cr_assert_not(camera_init(&cam, &p, 10, 10, &err));
    p.look_at = v3(1, 5, 1);
    cr_assert_not(camera_init(&cam, &p, 10, 10, &err), "up parallel to view");
}
