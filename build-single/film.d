build-single/film.o: film.c film.h vec.h
film.h:
vec.h:
