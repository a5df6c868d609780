build-single/checkpoint.o: checkpoint.c checkpoint.h film.h vec.h file.h \
 sample.h
checkpoint.h:
film.h:
vec.h:
file.h:
sample.h:
