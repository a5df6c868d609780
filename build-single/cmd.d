build-single/cmd.o: cmd.c cmd.h vec.h image.h output.h file.h film.h \
 partial.h plot.h stats.h sample.h
cmd.h:
vec.h:
image.h:
output.h:
file.h:
film.h:
partial.h:
plot.h:
stats.h:
sample.h:
