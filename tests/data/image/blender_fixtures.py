import bpy
s = bpy.context.scene
s.render.engine = 'CYCLES'
s.cycles.samples = 4
s.cycles.use_denoising = False
s.cycles.seed = 1
s.render.resolution_x = 8
s.render.resolution_y = 6
s.render.resolution_percentage = 100
s.render.image_settings.file_format = 'OPEN_EXR_MULTILAYER'
s.render.image_settings.exr_codec = 'ZIP'
vl = s.view_layers[0]
for a in dir(vl):
    if a.startswith('use_pass_') and a not in ('use_pass_cryptomatte_accurate',):
        try: setattr(vl, a, True)
        except Exception: pass
s.render.filepath = '/tmp/bl/blender-passes.exr'
bpy.ops.render.render(write_still=True)
vl.use_pass_combined = False
s.render.filepath = '/tmp/bl/blender-passes-no-combined.exr'
bpy.ops.render.render(write_still=True)
vl.use_pass_combined = True
s.render.image_settings.file_format = 'OPEN_EXR'
s.render.image_settings.color_depth = '32'
s.render.filepath = '/tmp/bl/blender-single.exr'
bpy.ops.render.render(write_still=True)
