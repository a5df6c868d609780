build-single/material.o: material.c material.h vec.h sample.h \
 material_ggx_table.inc
material.h:
vec.h:
sample.h:
material_ggx_table.inc:
