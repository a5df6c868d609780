/* bench_scene.h - what the benchmarks that render a scene (raydump.c, packetbench.c) share:
 * their numeric options and the scene with its render settings.  They link the renderer; the
 * ray-kernel benchmarks (bench.h) do not. */
#ifndef MCPT_BENCH_SCENE_H
#define MCPT_BENCH_SCENE_H

#include <stdbool.h>
#include <stdint.h>

#include "scene.h"
#include "trace.h"

/* Parses a decimal integer in [min, UINT32_MAX] into *v; prints "prog: expected NAME >= MIN,
 * got 'S'" and returns false otherwise. */
bool bench_parse_u32(const char *prog, const char *s, const char *name, uint32_t min, uint32_t *v);

/* Loads the scene at path (width, height: the film's size where nonzero) and fills *opt with
 * its render settings, spp and seed, on one thread.  Prints the error and returns false on bad
 * input. */
bool bench_scene_load(const char *path, uint32_t width, uint32_t height, uint32_t spp,
                      uint32_t seed, struct scene *scene, struct trace_options *opt);

#endif
