build-single/output.o: output.c output.h file.h vec.h film.h partial.h \
 plot.h stats.h image.h sample.h
output.h:
file.h:
vec.h:
film.h:
partial.h:
plot.h:
stats.h:
image.h:
sample.h:
