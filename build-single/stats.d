build-single/stats.o: stats.c stats.h film.h vec.h image.h sample.h \
 file.h
stats.h:
film.h:
vec.h:
image.h:
sample.h:
file.h:
