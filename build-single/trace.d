build-single/trace.o: trace.c trace.h bvh.h vec.h film.h sample.h scene.h \
 camera.h material.h shape.h light.h
trace.h:
bvh.h:
vec.h:
film.h:
sample.h:
scene.h:
camera.h:
material.h:
shape.h:
light.h:
