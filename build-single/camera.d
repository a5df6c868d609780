build-single/camera.o: camera.c camera.h vec.h sample.h
camera.h:
vec.h:
sample.h:
