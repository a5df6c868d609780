build-single/plot.o: plot.c plot.h film.h vec.h stats.h image.h sample.h \
 file.h
plot.h:
film.h:
vec.h:
stats.h:
image.h:
sample.h:
file.h:
