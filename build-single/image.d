build-single/image.o: image.c image.h vec.h file.h \
 /usr/include/OpenEXR/openexr.h /usr/include/OpenEXR/openexr_conf.h \
 /usr/include/OpenEXR/OpenEXRConfig.h /usr/include/OpenEXR/openexr_base.h \
 /usr/include/OpenEXR/openexr_errors.h \
 /usr/include/OpenEXR/openexr_context.h \
 /usr/include/OpenEXR/openexr_attr.h /usr/include/OpenEXR/openexr_part.h \
 /usr/include/OpenEXR/openexr_std_attr.h \
 /usr/include/OpenEXR/openexr_chunkio.h \
 /usr/include/OpenEXR/openexr_decode.h \
 /usr/include/OpenEXR/openexr_coding.h \
 /usr/include/OpenEXR/openexr_encode.h \
 /usr/include/OpenEXR/openexr_debug.h /usr/include/libpng16/png.h \
 /usr/include/libpng16/pnglibconf.h /usr/include/libpng16/pngconf.h
image.h:
vec.h:
file.h:
/usr/include/OpenEXR/openexr.h:
/usr/include/OpenEXR/openexr_conf.h:
/usr/include/OpenEXR/OpenEXRConfig.h:
/usr/include/OpenEXR/openexr_base.h:
/usr/include/OpenEXR/openexr_errors.h:
/usr/include/OpenEXR/openexr_context.h:
/usr/include/OpenEXR/openexr_attr.h:
/usr/include/OpenEXR/openexr_part.h:
/usr/include/OpenEXR/openexr_std_attr.h:
/usr/include/OpenEXR/openexr_chunkio.h:
/usr/include/OpenEXR/openexr_decode.h:
/usr/include/OpenEXR/openexr_coding.h:
/usr/include/OpenEXR/openexr_encode.h:
/usr/include/OpenEXR/openexr_debug.h:
/usr/include/libpng16/png.h:
/usr/include/libpng16/pnglibconf.h:
/usr/include/libpng16/pngconf.h:
