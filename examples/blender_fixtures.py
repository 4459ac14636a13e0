"""Tiny Blender renders for brume's tests and docs (issue #50).

Run with Debian's Blender (3.4):

    blender -b --factory-startup --python examples/blender_fixtures.py -- --engine cycles --out cycles.exr
    blender -b --factory-startup --python examples/blender_fixtures.py -- --engine eevee --out eevee.exr

It builds one scene from nothing (no .blend file): a 2 km ground plane, three
boxes whose camera-facing sides lie at planar depths 4.7, 14.2 and 38.5 m, a
uniform blue-grey world as the sky, and a camera 1.6 m above the ground
looking north, pitched 4 degrees down, with a 35 mm lens on a 36 x 24 mm
sensor (sensor fit AUTO: the width spans the image's larger side) and a lens
shift of (-0.03, 0.08). It renders a 64 x 48 multilayer OpenEXR as an artist
would write one (Blender's defaults: half float, ZIP) with the Combined, AO,
Depth, Mist and Normal passes -- so AO sorts before Combined, the Mist pass
is a Z channel, and the sky is the renderer's background value -- and writes
beside it NAME.json: the camera as Blender holds it (mm, fit, shift) and the
projection Blender itself computes for the image (calc_matrix_camera), which
the tests use as the independent reference for brume's millimetre camera.

Options after "--": --engine cycles|eevee, --out FILE.exr, --width, --height,
--samples, --sensor-fit AUTO|HORIZONTAL|VERTICAL, --transparent (film
transparent: the sky's alpha 0), --border X0,X1,Y0,Y1 (a border render,
cropped: the file's data window is smaller than its display window).
Debian's Blender has no OpenImageDenoise, so Cycles' denoising is off.
"""

import argparse
import json
import math
import sys

import bpy


def parse():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser(prog="blender_fixtures.py")
    p.add_argument("--engine", choices=["cycles", "eevee"], required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--width", type=int, default=64)
    p.add_argument("--height", type=int, default=48)
    p.add_argument("--samples", type=int, default=16)
    p.add_argument("--sensor-fit", default="AUTO", choices=["AUTO", "HORIZONTAL", "VERTICAL"])
    p.add_argument("--transparent", action="store_true")
    p.add_argument("--border", default="")
    return p.parse_args(argv)


def material(name, rgb):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    bsdf = m.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*rgb, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.8
    return m


def box(name, front_y, centre_x, width, height, depth, rgb):
    """A box whose camera-facing side (normal -Y) lies at y = front_y."""
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(centre_x, front_y + depth / 2, height / 2))
    o = bpy.context.active_object
    o.name = name
    o.scale = (width, depth, height)
    o.data.materials.append(material(name, rgb))
    return o


def main():
    a = parse()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES" if a.engine == "cycles" else "BLENDER_EEVEE"
    scene.render.resolution_x, scene.render.resolution_y = a.width, a.height
    scene.render.resolution_percentage = 100
    scene.render.pixel_aspect_x = scene.render.pixel_aspect_y = 1.0
    scene.render.film_transparent = a.transparent
    if a.border:
        x0, x1, y0, y1 = (float(v) for v in a.border.split(","))
        scene.render.use_border = True
        scene.render.use_crop_to_border = False  # the data window lies inside the full frame
        scene.render.border_min_x, scene.render.border_max_x = x0, x1
        scene.render.border_min_y, scene.render.border_max_y = y0, y1
    if a.engine == "cycles":
        scene.cycles.samples = a.samples
        scene.cycles.use_denoising = False  # Debian's Blender is built without OpenImageDenoise
        scene.cycles.use_adaptive_sampling = False
        scene.cycles.seed = 1
        scene.cycles.device = "CPU"
    else:
        scene.eevee.taa_render_samples = a.samples
        scene.eevee.use_gtao = True

    world = bpy.data.worlds.new("Sky")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.45, 0.6, 0.85, 1.0)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 1.0
    world.mist_settings.start = 0.0
    world.mist_settings.depth = 50.0
    world.mist_settings.falloff = "LINEAR"
    scene.world = world

    bpy.ops.mesh.primitive_plane_add(size=2000.0, location=(0.0, 0.0, 0.0))
    bpy.context.active_object.name = "Ground"
    bpy.context.active_object.data.materials.append(material("Ground", (0.3, 0.28, 0.22)))
    box("Near", 4.7, -1.6, 1.0, 1.4, 1.0, (0.8, 0.2, 0.15))
    box("Middle", 14.2, 2.4, 2.5, 3.0, 2.0, (0.2, 0.6, 0.25))
    box("Far", 38.5, -0.5, 6.0, 9.0, 4.0, (0.85, 0.85, 0.8))

    bpy.ops.object.light_add(type="SUN", rotation=(math.radians(40), math.radians(-20), math.radians(30)))
    bpy.context.active_object.data.energy = 3.0

    cam_data = bpy.data.cameras.new("Camera")
    cam_data.lens_unit = "MILLIMETERS"
    cam_data.lens = 35.0
    cam_data.sensor_width, cam_data.sensor_height = 36.0, 24.0
    cam_data.sensor_fit = a.sensor_fit
    cam_data.shift_x, cam_data.shift_y = -0.03, 0.08
    cam_data.clip_start, cam_data.clip_end = 0.1, 5000.0
    cam = bpy.data.objects.new("Camera", cam_data)
    scene.collection.objects.link(cam)
    # Blender's camera looks down its local -Z; (90 - 4) degrees about X looks along +Y (north), 4 degrees down.
    cam.location = (0.0, 0.0, 1.6)
    cam.rotation_euler = (math.radians(86.0), 0.0, 0.0)
    scene.camera = cam

    vl = scene.view_layers[0]
    vl.use_pass_combined = True
    vl.use_pass_z = True
    vl.use_pass_mist = True
    vl.use_pass_normal = True
    vl.use_pass_ambient_occlusion = True

    s = scene.render.image_settings
    s.file_format = "OPEN_EXR_MULTILAYER"
    s.color_depth = "16"
    s.exr_codec = "ZIP"
    scene.render.filepath = a.out
    scene.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)

    depsgraph = bpy.context.evaluated_depsgraph_get()
    P = cam.calc_matrix_camera(depsgraph, x=a.width, y=a.height, scale_x=1.0, scale_y=1.0)
    side = {
        "blender": bpy.app.version_string,
        "engine": scene.render.engine,
        "width": a.width,
        "height": a.height,
        "view_layer": vl.name,
        "camera": {
            "lens_mm": cam_data.lens,
            "sensor_width_mm": cam_data.sensor_width,
            "sensor_height_mm": cam_data.sensor_height,
            "sensor_fit": cam_data.sensor_fit,
            "shift_x": cam_data.shift_x,
            "shift_y": cam_data.shift_y,
            "location_m": list(cam.location),
            "pitch_deg": -4.0,
        },
        # OpenGL projection for the image (rows): x_ndc = P00 x/(-z) + P02 z/(-z), ...
        "projection": [list(row) for row in P],
        "boxes_front_planar_m": {"Near": 4.7, "Middle": 14.2, "Far": 38.5},
        "world_rgb": [0.45, 0.6, 0.85],
        "mist": {"start_m": 0.0, "depth_m": 50.0, "falloff": "LINEAR"},
        "transparent": a.transparent,
        "border": a.border,
    }
    with open(a.out.rsplit(".", 1)[0] + ".json", "w") as f:
        json.dump(side, f, indent=1)
        f.write("\n")


main()
