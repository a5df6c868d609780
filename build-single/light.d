build-single/light.o: light.c light.h scene.h camera.h vec.h material.h \
 sample.h shape.h
light.h:
scene.h:
camera.h:
vec.h:
material.h:
sample.h:
shape.h:
