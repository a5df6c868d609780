build-single/scene.o: scene.c scene.h camera.h vec.h material.h sample.h \
 shape.h obj.h
scene.h:
camera.h:
vec.h:
material.h:
sample.h:
shape.h:
obj.h:
