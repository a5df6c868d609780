build-single/main.o: main.c checkpoint.h film.h vec.h cmd.h image.h \
 output.h file.h partial.h plot.h stats.h sample.h scene.h camera.h \
 material.h shape.h trace.h bvh.h
checkpoint.h:
film.h:
vec.h:
cmd.h:
image.h:
output.h:
file.h:
partial.h:
plot.h:
stats.h:
sample.h:
scene.h:
camera.h:
material.h:
shape.h:
trace.h:
bvh.h:
