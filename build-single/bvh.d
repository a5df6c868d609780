build-single/bvh.o: bvh.c bvh.h vec.h bvh_internal.h
bvh.h:
vec.h:
bvh_internal.h:
