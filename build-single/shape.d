build-single/shape.o: shape.c shape.h vec.h sample.h
shape.h:
vec.h:
sample.h:
