build-single/partial.o: partial.c partial.h film.h vec.h image.h
partial.h:
film.h:
vec.h:
image.h:
