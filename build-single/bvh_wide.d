build-single/bvh_wide.o: bvh_wide.c bvh_internal.h bvh.h vec.h
bvh_internal.h:
bvh.h:
vec.h:
