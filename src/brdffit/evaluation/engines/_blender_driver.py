"""Blender side of the Blender round trip: run by the Python interpreter that has ``bpy``
(``python _blender_driver.py JOB.json``), never imported by brdffit.

The job (JSON, written by :func:`brdffit.evaluation.engines.blender.render_file`) names the
glTF or USD file, the output directory and the scene in *glTF / Mitsuba coordinates* (+Y up):
camera origin, target, up and horizontal field of view; the directional light's direction of
travel and irradiance. Blender is +Z up; its glTF importer maps a glTF point (x, y, z) to
(x, −z, y), and its USD importer rotates a +Y-up stage by 90° about X, the same map; the
scene is mapped the same way, so the imported mesh and the rebuilt scene agree.

What is done, in order: an empty scene (factory settings, no startup file); the file is
imported with Blender's own glTF or USD importer (by its suffix) and **its default options**
(the job may ask for ``import_unused_materials``, the USD importer's
``import_all_materials``); with no seeds, the import report is all; else the camera (its
field of view on the sensor's width) and either a sun lamp (angle 0: a directional light;
strength = irradiance in W/m², Cycles' unit) with a black world, or a world of the job's
environment map (an equirectangular texture, linear, strength 1, looked up along the
direction turned about +Z to Mitsuba's lat-long convention) are added (transparent film: the
alpha is the coverage); Cycles on the CPU renders one image per seed with a 1-pixel box
filter, no denoising, no adaptive sampling, no clamping and no light threshold, so the
estimate is unbiased like Mitsuba's ``direct`` integrator. The Principled BSDF's
microfacet distribution is left as the importer set it unless the job names one
(``"GGX"`` or ``"MULTI_GGX"``). With ``sphere_segments`` the imported meshes take the scene's
sphere (:func:`use_scene_sphere`), their materials kept. Outputs: ``render_<seed>.npy`` (H, W, 4) float32, scene
linear Rec.709, rows top to bottom, and ``report.json`` (Blender version, the objects and
materials the import created and the Principled BSDF inputs of each material).
"""

import json
import math
import os
import sys

import bpy
import numpy as np
from mathutils import Matrix, Vector

PRINCIPLED_INPUTS = ("Base Color", "Metallic", "Roughness", "IOR", "Specular IOR Level",
                     "Specular Tint", "Coat Weight", "Coat Roughness", "Coat IOR",
                     "Anisotropic", "Anisotropic Rotation")


def to_blender(v):
    """A glTF (+Y up) vector in Blender's frame (+Z up), as the glTF importer maps it."""
    x, y, z = (float(c) for c in v)
    return Vector((x, -z, y))


def socket_value(sock):
    v = sock.default_value
    try:
        return [float(c) for c in v]
    except TypeError:
        return float(v)


def principled_nodes(mat):
    if not mat.use_nodes or mat.node_tree is None:
        return []
    return [n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED"]


def import_file(path, unused_materials):
    """Import ``path`` with Blender's importer for its suffix, default options."""
    if path.lower().endswith((".usd", ".usda", ".usdc")):
        return bpy.ops.wm.usd_import(filepath=path, import_all_materials=unused_materials)
    return bpy.ops.import_scene.gltf(filepath=path, import_unused_materials=unused_materials)


def add_sun(scene, sun):
    """A sun lamp of angle 0 (a directional light) travelling along ``sun["direction"]``,
    strength = the irradiance."""
    travel = to_blender(sun["direction"]).normalized()
    sun_data = bpy.data.lights.new("sun", type="SUN")
    sun_data.energy = float(sun["irradiance"])
    sun_data.angle = 0.0
    sun_data.color = (1.0, 1.0, 1.0)
    sun_obj = bpy.data.objects.new("sun", sun_data)
    # a sun lamp shines along its local −Z
    sun_obj.rotation_mode = "QUATERNION"
    sun_obj.rotation_quaternion = travel.to_track_quat("-Z", "Y")
    scene.collection.objects.link(sun_obj)


def make_world(env):
    """The world: black (strength 0), or the environment map ``env["exr"]`` (linear,
    strength 1) looked up along the direction turned by ``env["rotation_z_deg"]`` about +Z."""
    world = bpy.data.worlds.new("world")
    world.use_nodes = True
    nodes, links = world.node_tree.nodes, world.node_tree.links
    bg = next(n for n in nodes if n.type == "BACKGROUND")
    if env is None:
        bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        bg.inputs["Strength"].default_value = 0.0
        return world
    tex = nodes.new("ShaderNodeTexEnvironment")
    tex.image = bpy.data.images.load(env["exr"])
    tex.image.colorspace_settings.name = "Linear Rec.709"
    tex.interpolation = "Linear"
    coord = nodes.new("ShaderNodeTexCoord")
    mapping = nodes.new("ShaderNodeMapping")
    mapping.vector_type = "VECTOR"
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(env["rotation_z_deg"]))
    links.new(coord.outputs["Generated"], mapping.inputs["Vector"])
    links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
    links.new(tex.outputs["Color"], bg.inputs["Color"])
    bg.inputs["Strength"].default_value = 1.0
    return world


def use_scene_sphere(objects, segments):
    """Give every imported mesh object the scene's sphere: a UV sphere of radius 1 with
    ``segments`` = (around, along) faces, smooth shaded, its poles on +Z (the glTF file's +Y),
    UVs kept; the imported materials stay in their slots. Returns the vertex count of each
    replaced mesh."""
    import bmesh

    counts = []
    for obj in objects:
        if obj.type != "MESH":
            continue
        mats = [slot.material for slot in obj.material_slots]
        mesh = bpy.data.meshes.new(obj.data.name + "-scene-sphere")
        bm = bmesh.new()
        bmesh.ops.create_uvsphere(bm, u_segments=int(segments[0]), v_segments=int(segments[1]),
                                  radius=1.0, calc_uvs=True)
        bm.to_mesh(mesh)
        bm.free()
        mesh.shade_smooth()
        for mat in mats:
            mesh.materials.append(mat)
        obj.data = mesh
        counts.append(len(mesh.vertices))
    return counts


def build_scene(job):
    scene = bpy.context.scene
    cam = job["camera"]
    origin, target, up = (to_blender(cam[k]) for k in ("origin", "target", "up"))
    forward = (target - origin).normalized()
    right = forward.cross(up).normalized()
    true_up = right.cross(forward)
    # Blender's camera looks along its local −Z with +Y up
    rot = Matrix((right, true_up, -forward)).transposed()
    cam_data = bpy.data.cameras.new("camera")
    cam_data.sensor_fit = "HORIZONTAL"
    cam_data.angle = math.radians(float(cam["fov_degrees"]))
    cam_data.clip_start, cam_data.clip_end = 0.01, 1000.0
    cam_obj = bpy.data.objects.new("camera", cam_data)
    cam_obj.matrix_world = Matrix.Translation(origin) @ rot.to_4x4()
    scene.collection.objects.link(cam_obj)
    scene.camera = cam_obj

    if "sun" in job:
        add_sun(scene, job["sun"])
    scene.world = make_world(job.get("world"))

    res = int(job["resolution"])
    scene.render.engine = "CYCLES"
    scene.render.resolution_x = scene.render.resolution_y = res
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = True
    scene.render.threads_mode = "FIXED"
    scene.render.threads = int(job["threads"])
    cyc = scene.cycles
    cyc.device = "CPU"
    cyc.samples = int(job["spp"])
    cyc.use_adaptive_sampling = False
    cyc.use_denoising = False
    cyc.pixel_filter_type = "BOX"
    cyc.filter_width = 1.0
    cyc.sample_clamp_direct = 0.0
    cyc.sample_clamp_indirect = 0.0
    cyc.light_sampling_threshold = 0.0
    cyc.max_bounces = int(job["max_bounces"])
    scene.view_settings.view_transform = "Standard"
    settings = scene.render.image_settings
    settings.file_format = "OPEN_EXR"
    settings.color_mode = "RGBA"
    settings.color_depth = "32"
    settings.exr_codec = "ZIP"


def main(job_path):
    with open(job_path, encoding="utf-8") as fh:
        job = json.load(fh)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    before_objects = set(bpy.data.objects)
    before_materials = set(bpy.data.materials)
    result = import_file(job["file"], bool(job["import_unused_materials"]))
    objects = [o for o in bpy.data.objects if o not in before_objects]
    materials = [m for m in bpy.data.materials if m not in before_materials]
    report = {"blender": bpy.app.version_string, "import_result": sorted(result),
              "objects": [{"name": o.name, "type": o.type,
                           "materials": [s.material.name for s in o.material_slots
                                         if s.material is not None]} for o in objects],
              "materials": []}
    for mat in materials:
        entry = {"name": mat.name, "principled": []}
        for node in principled_nodes(mat):
            if job.get("distribution"):
                node.distribution = job["distribution"]
            entry["principled"].append(
                {"distribution": node.distribution,
                 "inputs": {k: socket_value(node.inputs[k]) for k in PRINCIPLED_INPUTS
                            if k in node.inputs and not node.inputs[k].is_linked},
                 "linked": [k for k in PRINCIPLED_INPUTS
                            if k in node.inputs and node.inputs[k].is_linked]})
        report["materials"].append(entry)
    if not job["seeds"]:
        with open(os.path.join(job["out_dir"], "report.json"), "w", encoding="utf-8") as fh:
            json.dump(report, fh, indent=1)
        return 0
    if job.get("sphere_segments"):
        report["scene_sphere"] = {"segments": job["sphere_segments"],
                                  "vertices": use_scene_sphere(objects, job["sphere_segments"])}
    build_scene(job)
    scene = bpy.context.scene
    out_dir = job["out_dir"]
    for seed in job["seeds"]:
        scene.cycles.seed = int(seed)
        exr = os.path.join(out_dir, f"render_{int(seed)}.exr")
        scene.render.filepath = exr
        bpy.ops.render.render(write_still=True)
        img = bpy.data.images.load(exr)
        px = np.empty(img.size[0] * img.size[1] * 4, np.float32)
        img.pixels.foreach_get(px)
        arr = px.reshape(img.size[1], img.size[0], 4)[::-1]   # Blender's rows are bottom-up
        np.save(os.path.join(out_dir, f"render_{int(seed)}.npy"), np.ascontiguousarray(arr))
        bpy.data.images.remove(img)
        os.remove(exr)
    with open(os.path.join(out_dir, "report.json"), "w", encoding="utf-8") as fh:
        json.dump(report, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[-1]))
