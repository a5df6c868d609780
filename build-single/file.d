build-single/file.o: file.c file.h vec.h
file.h:
vec.h:
