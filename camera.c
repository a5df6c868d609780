/* camera.c - look-at perspective camera with vertical field of view and a thin lens.
 * The image plane sits at distance 1 along the view direction and spans
 * [-aspect tan(fov/2), aspect tan(fov/2)] x [-tan(fov/2), tan(fov/2)].  Thin lens: PBRT 4e,
 * ch. 5, "Projective Camera Models": a lens point at radius `aperture` (concentric disk) and the
 * pinhole ray's point on the plane of focus define the ray. */
#include "camera.h"

#include "sample.h"

bool camera_init(struct camera *cam, const struct camera_params *p, int width, int height,
                 struct mcpt_error *err)
{
    vec3 view = v3_sub(p->look_at, p->eye);
    float view_len = v3_length(view);
    if (!(view_len > 0.0f)) {
        mcpt_error_set(err, "", 0, 0, "expected eye and look-at to differ, got both at %g,%g,%g",
                       p->eye.x, p->eye.y, p->eye.z);
        return false;
    }
    vec3 forward = v3_scale(view, 1.0f / view_len);
    vec3 right = v3_cross(forward, p->up);
    float right_len = v3_length(right);
    if (!(right_len > 1e-6f * v3_length(p->up))) {
        mcpt_error_set(err, "", 0, 0, "expected an up vector not parallel to the view direction");
        return false;
    }
    cam->eye = p->eye;
    cam->forward = forward;
    cam->right = v3_scale(right, 1.0f / right_len);
    cam->up = v3_cross(cam->right, forward);
    cam->tan_half_fov_y = tanf(0.5f * p->fov_deg * (MCPT_PI / 180.0f));
    cam->aspect = (float)width / (float)height;
    cam->aperture = p->aperture;
    cam->focus_dist = p->focus_dist > 0.0f ? p->focus_dist : view_len;
    cam->width = width;
    cam->height = height;
    return true;
}

struct ray camera_ray(const struct camera *cam, float px, float py, vec2 u_lens)
{
    /* film position -> image plane at distance 1: x right, y up */
    float sx = (2.0f * px / (float)cam->width - 1.0f) * cam->aspect * cam->tan_half_fov_y;
    float sy = (1.0f - 2.0f * py / (float)cam->height) * cam->tan_half_fov_y;
    vec3 d = v3_add(cam->forward, v3_add(v3_scale(cam->right, sx), v3_scale(cam->up, sy)));
    struct ray ray = {.o = cam->eye, .t_min = 0.0f, .t_max = INFINITY};
    if (cam->aperture > 0.0f) {
        /* thin lens: the pinhole ray meets the plane of focus at p_focus = eye + focus_dist d
         * (d has unit length along forward); the lens ray starts at a disk point of radius
         * aperture and passes through p_focus */
        vec2 lens = sample_concentric_disk(u_lens);
        vec3 o = v3_add(cam->eye, v3_add(v3_scale(cam->right, cam->aperture * lens.x),
                                         v3_scale(cam->up, cam->aperture * lens.y)));
        vec3 p_focus = v3_add(cam->eye, v3_scale(d, cam->focus_dist));
        ray.o = o;
        d = v3_sub(p_focus, o);
    }
    ray.d = v3_normalize(d);
    return ray;
}
