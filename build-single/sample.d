build-single/sample.o: sample.c sample.h vec.h sobol_matrices.h
sample.h:
vec.h:
sobol_matrices.h:
