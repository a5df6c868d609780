build-single/obj.o: obj.c obj.h vec.h
obj.h:
vec.h:
