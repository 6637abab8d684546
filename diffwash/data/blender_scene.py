"""Build a diffwash scene in Blender (written by diffwash __VERSION__'s `diffwash export --target blender`).

    python blender_scene.py [--render OUT.png] [--save OUT.blend]        # where Blender's bpy module is installed
    blender -b -P blender_scene.py -- [--render OUT.png] [--save OUT.blend]
    blender -P blender_scene.py                                         # opens Blender with the scene built

It reads blender_data.npz beside it (the mesh and the baked LUT) and builds, in a fresh scene:

- the mesh, with diffwash's vertex normals as the point attribute `diffwash_normal`;
- the camera (diffwash's pinhole camera: the same matrix, vertical field of view, clip distances);
- the world: the bare paper's colour;
- node groups named for diffwash: `diffwash thickness` (the wash and unlit thicknesses at a point,
  generated from diffwash.shading), `diffwash LUT` (the baked LUT over the paper, an image texture
  read at a (wash, unlit) thickness) and `diffwash watercolour` (both, per pixel), whose inputs hold
  the scene's light direction and constants (gain, bias, k_wash, ...);
- the materials `diffwash per-pixel` and `diffwash per-vertex` (the latter reads the thicknesses that
  the geometry-nodes modifier `diffwash per-vertex thickness` stores at the vertices), emission only;
- render settings that draw what diffwash draws: the view transform "Standard" (display sRGB, no
  tone curve), one sample at the pixel centre, no denoising, no dithering.

With a watercolour look, the material `diffwash look` draws the look's per-pixel effects (paper
granulation, density and shading, unevenness, strokes, the mix of two pigments by a per-vertex map)
with the node group `diffwash look` (the look's image terms, generated from diffwash.look; the screen
tile read at the pixel through the Window coordinates; the 3D mix LUT), and a backdrop behind the mesh
shows the paper's relief. Edge darkening, the own shadow and hatching are not carried (each needs more
than the pixel's own values); the script says which of them the scene turns on.

Only the scene's data is specific to it (CONFIG below); the rest is the same for every scene.
"""

import argparse
import json  # the export embeds the scene as CONFIG = json.loads(...)
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

CONFIG = "__CONFIG__"  # the export puts the scene's values here: json.loads of its JSON
HERE = Path(__file__).resolve().parent
SHADING_MODES = ("per-pixel", "per-vertex")
_SOCKET = {1: "NodeSocketFloat", 3: "NodeSocketVector"}


def image_size(text):
    w, _, h = text.lower().partition("x")
    if not (w.isdigit() and h.isdigit() and 0 < int(w) <= 16384 and 0 < int(h) <= 16384):
        raise argparse.ArgumentTypeError(f"must be WxH, 1 to 16384 pixels each, e.g. 512x512, got {text!r}")
    return int(w), int(h)


def arguments(argv):
    p = argparse.ArgumentParser(prog="blender_scene.py", description=__doc__.split("\n")[0])
    p.add_argument("--render", metavar="OUT.png", help="render the scene to this PNG (8-bit display sRGB)")
    p.add_argument("--save", metavar="OUT.blend", help="save the scene as a .blend (the LUT packed into it)")
    p.add_argument("--engine", choices=("auto", "eevee", "cycles"), default="auto",
                   help="auto: EEVEE where it draws (a GPU, or Mesa's llvmpipe), else Cycles on the CPU (default: %(default)s)")
    p.add_argument("--size", metavar="WxH", type=image_size, help="image size (default: the scene's)")
    p.add_argument("--shading", choices=SHADING_MODES, help="per-pixel or per-vertex thickness (default: the scene's)")
    p.add_argument("--probe-eevee", action="store_true", help=argparse.SUPPRESS)
    return p.parse_args(argv)


def script_arguments():
    """The script's own arguments: after `--` under `blender`, or all of them under `python`."""
    if "--" in sys.argv:
        return sys.argv[sys.argv.index("--") + 1:]
    if sys.argv and Path(sys.argv[0]).resolve() == Path(__file__).resolve():
        return sys.argv[1:]
    return []


# --- node programs ------------------------------------------------------------------------------


def new_group(name, tree_type, inputs, outputs):
    """A node group with the given (name, size, default) inputs and (name, size) outputs."""
    import bpy

    group = bpy.data.node_groups.new(name, tree_type)
    for socket_name, size, default in inputs:
        socket = group.interface.new_socket(socket_name, in_out="INPUT", socket_type=_SOCKET[size])
        if default is not None:
            socket.default_value = default
    for socket_name, size in outputs:
        group.interface.new_socket(socket_name, in_out="OUTPUT", socket_type=_SOCKET[size])
    group_in, group_out = group.nodes.new("NodeGroupInput"), group.nodes.new("NodeGroupOutput")
    return group, group_in, group_out


def build_program(tree, program, sources, x0=0):
    """Instantiate a diffwash node program (`diffwash._blender.node_program`) in `tree`.

    `sources`: input name -> output socket. Returns output name -> output socket.
    """
    kinds = {"math": "ShaderNodeMath", "vector": "ShaderNodeVectorMath",
             "combine": "ShaderNodeCombineXYZ", "separate": "ShaderNodeSeparateXYZ"}
    made, depth = [], []

    def socket(ref):
        if "input" in ref:
            return sources[ref["input"]]
        return made[ref["node"]].outputs[ref["output"]]

    for node in program["nodes"]:
        n = tree.nodes.new(kinds[node["op"]])
        if node["operation"]:
            n.operation = node["operation"]
        d = 0
        for i, ref in enumerate(node["inputs"]):
            if "value" in ref:
                n.inputs[i].default_value = ref["value"]
            else:
                tree.links.new(socket(ref), n.inputs[i])
                d = max(d, depth[ref["node"]] + 1 if "node" in ref else 1)
        depth.append(d)
        n.location = (x0 + 170 * d, -110 * sum(1 for e in depth[:-1] if e == d))
        n.hide = True
        made.append(n)
    return {name: socket(ref) for name, ref in program["outputs"].items()}, max(depth, default=0)


def thickness_group(tree_type, name):
    """`diffwash thickness`: the wash and unlit thicknesses at a point, diffwash.shading's program."""
    program = CONFIG["thickness"]
    labels = {"normal": "Normal", "view": "Incoming", "light_direction": "Light Direction"}
    defaults = {"light_direction": CONFIG["light_direction"], **CONFIG["constants"]}
    inputs = [(labels.get(k, k), size, defaults.get(k)) for k, size in program["inputs"]]
    group, gi, go = new_group(name, tree_type, inputs, [("Wash", 1), ("Unlit", 1)])
    sources = {k: gi.outputs[labels.get(k, k)] for k, _ in program["inputs"]}
    outs, width = build_program(group, program, sources, x0=200)
    group.links.new(outs["wash"], go.inputs["Wash"])
    group.links.new(outs["unlit"], go.inputs["Unlit"])
    go.location = (200 + 170 * (width + 1), 0)
    return group


def lut_image():
    """The baked LUT as a float image, linear values ("Non-Color"), the image's top row unlit = 0."""
    return float_image("diffwash LUT", np.load(HERE / "blender_data.npz")["lut"])


def _math(tree, operation, a, b, c=None, clamp=False):
    n = tree.nodes.new("ShaderNodeMath")
    n.operation, n.use_clamp = operation, clamp
    for i, v in enumerate((a, b, c)):
        if v is None:
            continue
        if isinstance(v, (int, float)):
            n.inputs[i].default_value = v
        else:
            tree.links.new(v, n.inputs[i])
    return n.outputs[0]


def _texel_indices(tree, t, n):
    """The indices of the two samples around `t` in [0, 1] on an axis of `n` texels, and the weight between them.

    docs/realtime.md's addressing: the thickness range maps onto the texel centres, so the position in texels is
    x = t (n - 1); the samples are floor(x) and the next one (the last texel at t = 1), weighted x - floor(x).
    """
    x = _math(tree, "MULTIPLY", t, float(n - 1))
    i0 = _math(tree, "FLOOR", x, 0.0)
    i1 = _math(tree, "MINIMUM", _math(tree, "ADD", i0, 1.0), float(n - 1))
    return (i0, i1), _math(tree, "SUBTRACT", x, i0)


def _texel_pair(tree, t, n):
    """Texel coordinates (centres, in [0, 1]) of the two samples around `t` (`_texel_indices`), and their weight."""
    (i0, i1), f = _texel_indices(tree, t, n)
    return [_math(tree, "DIVIDE", _math(tree, "ADD", i, 0.5), float(n)) for i in (i0, i1)], f


def _mix(tree, a, b, f):
    """a + (b - a) f, channel by channel."""
    mix = tree.nodes.new("ShaderNodeMix")
    mix.data_type, mix.clamp_factor = "VECTOR", False
    tree.links.new(f, mix.inputs["Factor"])
    tree.links.new(a, mix.inputs["A"])
    tree.links.new(b, mix.inputs["B"])
    return mix.outputs["Result"]


def lut_group(image):
    """`diffwash LUT`: the colour over the paper at a (wash, unlit) thickness, from the baked LUT.

    t = clamp(thickness / max, 0, 1) (0 where max = 0) on each axis, then bilinear interpolation between the
    texel centres (docs/realtime.md), written out: four "Closest" reads and three mixes, because EEVEE reads a
    "Linear" image texture through mipmaps, which a LUT must not be (its texels are not a picture).
    """
    lut = CONFIG["lut"]
    cols, rows = lut["size"]
    inputs = [("Wash", 1, 0.0), ("Unlit", 1, 0.0), ("LUT Wash Max", 1, lut["wash_max"]), ("LUT Unlit Max", 1, lut["unlit_max"])]
    group, gi, go = new_group("diffwash LUT", "ShaderNodeTree", inputs, [("Colour", 3)])
    axes = []
    for thickness, top, n in (("Wash", "LUT Wash Max", cols), ("Unlit", "LUT Unlit Max", rows)):
        t = _math(group, "DIVIDE", gi.outputs[thickness], gi.outputs[top], clamp=True)  # Blender's divide by 0 is 0
        axes.append(_texel_pair(group, t, n))
    (us, fu), (vs, fv) = axes
    texels = {}
    for a, u in enumerate(us):
        for b, v in enumerate(vs):
            uv = group.nodes.new("ShaderNodeCombineXYZ")
            group.links.new(u, uv.inputs[0])
            group.links.new(_math(group, "SUBTRACT", 1.0, v), uv.inputs[1])  # Blender's images start at the bottom row
            texture = group.nodes.new("ShaderNodeTexImage")
            texture.image, texture.interpolation, texture.extension = image, "Closest", "EXTEND"
            texture.location = (600, -300 * (2 * a + b))
            group.links.new(uv.outputs[0], texture.inputs["Vector"])
            texels[a, b] = texture.outputs["Color"]
    top, bottom = _mix(group, texels[0, 0], texels[1, 0], fu), _mix(group, texels[0, 1], texels[1, 1], fu)
    group.links.new(_mix(group, top, bottom, fv), go.inputs["Colour"])
    gi.location, go.location = (-400, 0), (1200, 0)
    return group


def float_image(name, values):
    """`values` (rows, cols, 3), row 0 at the top, as a float image of linear values ("Non-Color"), packed."""
    import bpy

    rows, cols = values.shape[:2]
    image = bpy.data.images.new(name, cols, rows, alpha=False, float_buffer=True)
    image.colorspace_settings.name = "Non-Color"
    image.use_half_precision = False
    rgba = np.ones((rows, cols, 4), np.float32)
    rgba[..., :3] = values
    image.pixels.foreach_set(np.ascontiguousarray(rgba[::-1]).ravel())  # Blender's rows run from the bottom
    image.update()
    image.file_format = "OPEN_EXR"
    image.pack()
    return image


def mix_lut_group():
    """`diffwash mix LUT`: the look's 3D LUT over (wash, unlit, mix), as the shaders' sampler3D reads it.

    The 16 mix slices lie side by side in one image (slice k in columns k N to (k + 1) N - 1); trilinear
    interpolation between texel centres, written out: eight "Closest" reads and seven mixes.
    """
    lut = CONFIG["look"]["mix_lut"]
    N, M, P = lut["size"]
    table = np.load(HERE / "blender_data.npz")["mix_lut"]  # (P, M, N, 3)
    image = float_image("diffwash mix LUT", np.concatenate(list(table), axis=1))
    inputs = [("Wash", 1, 0.0), ("Unlit", 1, 0.0), ("Mix", 1, 0.0), ("LUT Wash Max", 1, lut["wash_max"]),
              ("LUT Unlit Max", 1, lut["unlit_max"])]
    group, gi, go = new_group("diffwash mix LUT", "ShaderNodeTree", inputs, [("Colour", 3)])
    tw = _math(group, "DIVIDE", gi.outputs["Wash"], gi.outputs["LUT Wash Max"], clamp=True)
    tu = _math(group, "DIVIDE", gi.outputs["Unlit"], gi.outputs["LUT Unlit Max"], clamp=True)
    tm = _math(group, "MULTIPLY", gi.outputs["Mix"], 1.0, clamp=True)
    (ws, fw), (us, fu), (ms, fm) = _texel_indices(group, tw, N), _texel_indices(group, tu, M), _texel_indices(group, tm, P)
    slices = []
    for k in ms:
        texels = {}
        for a, i in enumerate(ws):
            column = _math(group, "ADD", _math(group, "MULTIPLY", k, float(N)), i)
            u = _math(group, "DIVIDE", _math(group, "ADD", column, 0.5), float(N * P))
            for b, j in enumerate(us):
                v = _math(group, "SUBTRACT", 1.0, _math(group, "DIVIDE", _math(group, "ADD", j, 0.5), float(M)))
                uv = group.nodes.new("ShaderNodeCombineXYZ")
                group.links.new(u, uv.inputs[0])
                group.links.new(v, uv.inputs[1])
                texture = group.nodes.new("ShaderNodeTexImage")
                texture.image, texture.interpolation, texture.extension = image, "Closest", "EXTEND"
                group.links.new(uv.outputs[0], texture.inputs["Vector"])
                texels[a, b] = texture.outputs["Color"]
        top, bottom = _mix(group, texels[0, 0], texels[1, 0], fw), _mix(group, texels[0, 1], texels[1, 1], fw)
        slices.append(_mix(group, top, bottom, fu))
    group.links.new(_mix(group, slices[0], slices[1], fm), go.inputs["Colour"])
    gi.location, go.location = (-400, 0), (1400, 0)
    return group


def look_group(mix_lut):
    """`diffwash look`: the look's image terms, the mix LUT and the paper's relief at a pixel.

    Inputs: the model's thicknesses there, the per-vertex mix and stroke value, and the Window coordinates,
    which place the screen tile at the scene's pixels (texel (x mod Tw, y mod Th), y from the image's top row:
    the shaders' `texelFetch`). The arithmetic is diffwash.look's (`pixel_terms` with the pixel's own value as
    its local mean, then `paper_shading`), lowered to nodes by diffwash._blender.look_programs.
    """
    look = CONFIG["look"]
    inputs = [("Wash", 1, 0.0), ("Unlit", 1, 0.0), ("Mix", 1, 0.0), ("Stroke", 1, 0.0), ("Window", 3, None)]
    group, gi, go = new_group("diffwash look", "ShaderNodeTree", inputs, [("Colour", 3)])
    th, tw = look["tile"]
    window = group.nodes.new("ShaderNodeSeparateXYZ")
    group.links.new(gi.outputs["Window"], window.inputs[0])
    uv = group.nodes.new("ShaderNodeCombineXYZ")
    group.links.new(_math(group, "MULTIPLY", window.outputs[0], CONFIG["width"] / tw), uv.inputs[0])
    group.links.new(_math(group, "MULTIPLY", _math(group, "SUBTRACT", window.outputs[1], 1.0), CONFIG["height"] / th), uv.inputs[1])
    screen = np.load(HERE / "blender_data.npz")["screen"]  # (Th, Tw, 6)
    channels = {}
    for part in range(2):
        texture = group.nodes.new("ShaderNodeTexImage")
        texture.image = float_image(f"diffwash screen tile {part}", screen[..., 3 * part:3 * part + 3])
        texture.interpolation, texture.extension = "Closest", "REPEAT"
        group.links.new(uv.outputs[0], texture.inputs["Vector"])
        split = group.nodes.new("ShaderNodeSeparateColor")
        group.links.new(texture.outputs["Color"], split.inputs[0])
        for c in range(3):
            channels[look["channels"][3 * part + c]] = split.outputs[c]
    sources = {"wash": gi.outputs["Wash"], "unlit": gi.outputs["Unlit"], "mix": gi.outputs["Mix"],
               "stroke": gi.outputs["Stroke"], **channels}
    terms, width = build_program(group, look["terms"], sources, x0=400)
    lut = group.nodes.new("ShaderNodeGroup")
    lut.node_tree = mix_lut
    group.links.new(terms["wash"], lut.inputs["Wash"])
    group.links.new(terms["unlit"], lut.inputs["Unlit"])
    group.links.new(gi.outputs["Mix"], lut.inputs["Mix"])
    lut.location = (400 + 170 * (width + 1), 0)
    relief, width2 = build_program(group, look["relief"], {"rgb": lut.outputs["Colour"], "shade": channels["shade"]},
                                   x0=400 + 170 * (width + 2))
    group.links.new(relief["rgb"], go.inputs["Colour"])
    go.location = (400 + 170 * (width + width2 + 3), 0)
    return group


def watercolour_group(thickness, lut):
    """`diffwash watercolour`: thickness per point, then the LUT: the seed's shading in one group."""
    inputs = [(s.name, 3 if s.socket_type == "NodeSocketVector" else 1, s.default_value if s.name not in ("Normal", "Incoming") else None)
              for s in thickness.interface.items_tree if s.in_out == "INPUT"]
    group, gi, go = new_group("diffwash watercolour", "ShaderNodeTree", inputs, [("Colour", 3), ("Wash", 1), ("Unlit", 1)])
    t = group.nodes.new("ShaderNodeGroup")
    t.node_tree = thickness
    for name, _, _ in inputs:
        group.links.new(gi.outputs[name], t.inputs[name])
    c = group.nodes.new("ShaderNodeGroup")
    c.node_tree = lut
    for name in ("Wash", "Unlit"):
        group.links.new(t.outputs[name], c.inputs[name])
        group.links.new(t.outputs[name], go.inputs[name])
    group.links.new(c.outputs["Colour"], go.inputs["Colour"])
    for i, n in enumerate((gi, t, c, go)):
        n.location = (-300 + 250 * i, 0)
    return group


# --- materials, geometry nodes, mesh, camera, world ---------------------------------------------------


def _emit(mat, colour, backfacing):
    """Emission of `colour` (what diffwash draws), and where back faces are culled, nothing on them."""
    tree = mat.node_tree
    emission = tree.nodes.new("ShaderNodeEmission")
    tree.links.new(colour, emission.inputs["Color"])
    emission.inputs["Strength"].default_value = 1.0
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    shader = emission.outputs[0]
    if CONFIG["cull_backfaces"]:
        mix = tree.nodes.new("ShaderNodeMixShader")
        tree.links.new(backfacing, mix.inputs[0])
        tree.links.new(shader, mix.inputs[1])
        tree.links.new(tree.nodes.new("ShaderNodeBsdfTransparent").outputs[0], mix.inputs[2])
        shader = mix.outputs[0]
        mat.use_backface_culling = True
    tree.links.new(shader, out.inputs["Surface"])
    mat.cycles.emission_sampling = "NONE"  # seen by the camera only: no light tree over 100k emitters
    out.location = (900, 0)


def _new_material(name):
    import bpy

    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    mat.node_tree.nodes.clear()
    mat.use_fake_user = True
    return mat


def _turned(tree, vector, backfacing):
    """`vector`, reversed on back faces where they are drawn (OpenGL's two-sided lighting)."""
    if CONFIG["cull_backfaces"]:
        return vector
    sign = _math(tree, "MULTIPLY_ADD", backfacing, -2.0, 1.0)
    scale = tree.nodes.new("ShaderNodeVectorMath")
    scale.operation = "SCALE"
    tree.links.new(vector, scale.inputs[0])
    tree.links.new(sign, scale.inputs["Scale"])
    return scale.outputs[0]


def per_pixel_material(watercolour, name="diffwash per-pixel"):
    mat = _new_material(name)
    tree = mat.node_tree
    geometry = tree.nodes.new("ShaderNodeNewGeometry")
    normal = tree.nodes.new("ShaderNodeAttribute")
    normal.attribute_type, normal.attribute_name = "GEOMETRY", "diffwash_normal"
    to_world = tree.nodes.new("ShaderNodeVectorTransform")
    to_world.vector_type, to_world.convert_from, to_world.convert_to = "NORMAL", "OBJECT", "WORLD"
    tree.links.new(normal.outputs["Vector"], to_world.inputs[0])
    group = tree.nodes.new("ShaderNodeGroup")
    group.node_tree = watercolour
    tree.links.new(_turned(tree, to_world.outputs[0], geometry.outputs["Backfacing"]), group.inputs["Normal"])
    tree.links.new(geometry.outputs["Incoming"], group.inputs["Incoming"])
    _emit(mat, group.outputs["Colour"], geometry.outputs["Backfacing"])
    group.location, geometry.location, normal.location, to_world.location = (400, 0), (0, 300), (-200, 0), (100, 0)
    return mat


def look_material(watercolour, look):
    """`diffwash look`: the thicknesses per pixel (`diffwash watercolour`), then the look's per-pixel effects."""
    mat = per_pixel_material(watercolour, "diffwash look")
    tree = mat.node_tree
    model = next(n for n in tree.nodes if n.type == "GROUP")
    node = tree.nodes.new("ShaderNodeGroup")
    node.node_tree = look
    for name in ("Wash", "Unlit"):
        tree.links.new(model.outputs[name], node.inputs[name])
    for name, attribute in (("Mix", "diffwash_mix"), ("Stroke", "diffwash_stroke")):
        a = tree.nodes.new("ShaderNodeAttribute")
        a.attribute_type, a.attribute_name = "GEOMETRY", attribute
        tree.links.new(a.outputs["Fac"], node.inputs[name])
    coordinates = tree.nodes.new("ShaderNodeTexCoord")
    tree.links.new(coordinates.outputs["Window"], node.inputs["Window"])
    emission = next(n for n in tree.nodes if n.type == "EMISSION")
    tree.links.new(node.outputs["Colour"], emission.inputs["Color"])
    node.location = (650, 0)
    return mat


def build_backdrop(camera, look):
    """The paper where no mesh is, with its relief: a quad filling the view just inside the far clip plane (behind
    the mesh, whose bounding sphere the clip planes enclose), drawn by `diffwash look` at zero thickness."""
    import bpy
    from mathutils import Matrix

    c = CONFIG["camera"]
    d = 0.995 * c["far"]
    h = 1.5 * d * np.tan(np.radians(c["fov_y"]) / 2)
    w = h * CONFIG["width"] / CONFIG["height"]
    mesh = bpy.data.meshes.new("diffwash paper")
    mesh.from_pydata([(-w, -h, -d), (w, -h, -d), (w, h, -d), (-w, h, -d)], [], [(0, 1, 2, 3)])
    obj = bpy.data.objects.new("diffwash paper", mesh)
    obj.matrix_world = Matrix(c["matrix_world"])
    mat = _new_material("diffwash paper")
    tree = mat.node_tree
    node = tree.nodes.new("ShaderNodeGroup")
    node.node_tree = look
    coordinates = tree.nodes.new("ShaderNodeTexCoord")
    tree.links.new(coordinates.outputs["Window"], node.inputs["Window"])
    emission = tree.nodes.new("ShaderNodeEmission")
    tree.links.new(node.outputs["Colour"], emission.inputs["Color"])
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    tree.links.new(emission.outputs[0], out.inputs["Surface"])
    mat.cycles.emission_sampling = "NONE"
    mesh.materials.append(mat)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def per_vertex_material(lut):
    mat = _new_material("diffwash per-vertex")
    tree = mat.node_tree
    geometry = tree.nodes.new("ShaderNodeNewGeometry")
    front, back = (tree.nodes.new("ShaderNodeAttribute") for _ in range(2))
    front.attribute_name, back.attribute_name = "diffwash_thickness", "diffwash_thickness_back"
    thickness = front.outputs["Vector"]
    if not CONFIG["cull_backfaces"]:
        mix = tree.nodes.new("ShaderNodeMix")
        mix.data_type = "VECTOR"
        tree.links.new(geometry.outputs["Backfacing"], mix.inputs["Factor"])
        tree.links.new(front.outputs["Vector"], mix.inputs["A"])
        tree.links.new(back.outputs["Vector"], mix.inputs["B"])
        thickness = mix.outputs["Result"]
    split = tree.nodes.new("ShaderNodeSeparateXYZ")
    tree.links.new(thickness, split.inputs[0])
    group = tree.nodes.new("ShaderNodeGroup")
    group.node_tree = lut
    tree.links.new(split.outputs[0], group.inputs["Wash"])
    tree.links.new(split.outputs[1], group.inputs["Unlit"])
    _emit(mat, group.outputs["Colour"], geometry.outputs["Backfacing"])
    group.location = (500, 0)
    return mat


def per_vertex_modifier(obj, camera):
    """`diffwash per-vertex thickness`: geometry nodes storing the thicknesses at the vertices (front and back)."""
    import bpy

    thickness = thickness_group("GeometryNodeTree", "diffwash thickness (geometry)")
    group = bpy.data.node_groups.new("diffwash per-vertex thickness", "GeometryNodeTree")
    group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    gi, go = group.nodes.new("NodeGroupInput"), group.nodes.new("NodeGroupOutput")
    normal = group.nodes.new("GeometryNodeInputNamedAttribute")
    normal.data_type = "FLOAT_VECTOR"
    normal.inputs["Name"].default_value = "diffwash_normal"
    eye = group.nodes.new("GeometryNodeObjectInfo")
    eye.transform_space = "RELATIVE"
    eye.inputs["Object"].default_value = camera
    view = group.nodes.new("ShaderNodeVectorMath")
    view.operation = "SUBTRACT"
    group.links.new(eye.outputs["Location"], view.inputs[0])
    group.links.new(group.nodes.new("GeometryNodeInputPosition").outputs[0], view.inputs[1])
    flipped = group.nodes.new("ShaderNodeVectorMath")
    flipped.operation = "SCALE"
    flipped.inputs["Scale"].default_value = -1.0
    group.links.new(normal.outputs["Attribute"], flipped.inputs[0])
    geometry = gi.outputs["Geometry"]
    for name, n in (("diffwash_thickness", normal.outputs["Attribute"]), ("diffwash_thickness_back", flipped.outputs[0])):
        t = group.nodes.new("GeometryNodeGroup")
        t.node_tree = thickness
        group.links.new(n, t.inputs["Normal"])
        group.links.new(view.outputs[0], t.inputs["Incoming"])
        pack = group.nodes.new("ShaderNodeCombineXYZ")
        group.links.new(t.outputs["Wash"], pack.inputs[0])
        group.links.new(t.outputs["Unlit"], pack.inputs[1])
        store = group.nodes.new("GeometryNodeStoreNamedAttribute")
        store.data_type, store.domain = "FLOAT_VECTOR", "POINT"
        store.inputs["Name"].default_value = name
        group.links.new(geometry, store.inputs["Geometry"])
        group.links.new(pack.outputs[0], store.inputs["Value"])
        geometry = store.outputs["Geometry"]
    group.links.new(geometry, go.inputs["Geometry"])
    modifier = obj.modifiers.new("diffwash per-vertex thickness", "NODES")
    modifier.node_group = group
    return modifier


def build_mesh():
    import bpy

    data = np.load(HERE / "blender_data.npz")
    vertices, faces, normals = data["vertices"], data["faces"], data["normals"]
    mesh = bpy.data.meshes.new("diffwash mesh")
    mesh.vertices.add(len(vertices))
    mesh.vertices.foreach_set("co", vertices.astype(np.float32).ravel())
    mesh.loops.add(faces.size)
    mesh.loops.foreach_set("vertex_index", faces.astype(np.int32).ravel())
    mesh.polygons.add(len(faces))
    mesh.polygons.foreach_set("loop_start", np.arange(0, faces.size, 3, dtype=np.int32))
    mesh.update(calc_edges=True)
    attribute = mesh.attributes.new("diffwash_normal", "FLOAT_VECTOR", "POINT")
    attribute.data.foreach_set("vector", normals.astype(np.float32).ravel())
    if CONFIG["look"]:  # the look's pigment mix and stroke value per vertex
        for name, key in (("diffwash_mix", "look_mix"), ("diffwash_stroke", "look_stroke")):
            mesh.attributes.new(name, "FLOAT", "POINT").data.foreach_set("value", data[key].astype(np.float32).ravel())
    mesh.shade_smooth()
    obj = bpy.data.objects.new("diffwash", mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def build_camera():
    """diffwash's pinhole camera: its object matrix, vertical field of view and clip distances."""
    import bpy
    from mathutils import Matrix

    c = CONFIG["camera"]
    cam = bpy.data.cameras.new("diffwash camera")
    cam.sensor_fit = "VERTICAL"
    cam.angle_y = np.radians(c["fov_y"])
    cam.clip_start, cam.clip_end = c["near"], c["far"]
    obj = bpy.data.objects.new("diffwash camera", cam)
    obj.matrix_world = Matrix(c["matrix_world"])
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.scene.camera = obj
    return obj


def build_world():
    """The bare paper where no mesh is: the world's background, emission of the paper's linear colour."""
    import bpy

    world = bpy.data.worlds.new("diffwash paper")
    world.use_nodes = True
    background = world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (*CONFIG["paper"], 1.0)
    background.inputs["Strength"].default_value = 1.0
    bpy.context.scene.world = world


def build_light():
    """`diffwash light`: a Sun lamp whose +z (it shines down its -z) is the scene's direction towards the light.

    It lights nothing (the materials are emission); drivers read its direction into the node groups'
    `Light Direction`, so rotating it moves the model's light.
    """
    import bpy
    from mathutils import Vector

    sun = bpy.data.objects.new("diffwash light", bpy.data.lights.new("diffwash light", "SUN"))
    sun.rotation_mode = "QUATERNION"
    sun.rotation_quaternion = Vector(CONFIG["light_direction"]).normalized().to_track_quat("Z", "Y")
    sun.location = Vector(CONFIG["camera"]["matrix_world"][i][3] for i in range(3)) * 0.5
    bpy.context.scene.collection.objects.link(sun)
    bpy.context.view_layer.update()  # its matrix_world, which the drivers read
    return sun


def drive_light(socket, sun):
    """Drive a `Light Direction` socket from the sun's world +z (simple expressions: no Python at render time)."""
    for i, curve in enumerate(socket.driver_add("default_value")):
        driver = curve.driver
        driver.type = "SCRIPTED"
        variable = driver.variables.new()
        variable.name, variable.type = "z", "SINGLE_PROP"
        variable.targets[0].id_type, variable.targets[0].id = "OBJECT", sun
        variable.targets[0].data_path = f"matrix_world[2][{i}]"  # RNA indexes the matrix column first: the z axis
        driver.expression = "z"


def build(shading):
    """The whole scene, in a fresh file."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    obj, camera, sun = build_mesh(), build_camera(), build_light()
    build_world()
    lut = lut_group(lut_image())
    watercolour = watercolour_group(thickness_group("ShaderNodeTree", "diffwash thickness"), lut)
    materials = {"per-pixel": per_pixel_material(watercolour), "per-vertex": per_vertex_material(lut)}
    if CONFIG["look"]:  # the look computes the thicknesses per pixel, as its geometry pass does
        look = look_group(mix_lut_group())
        materials["per-pixel"] = look_material(watercolour, look)
        shading = "per-pixel"
        build_backdrop(camera, look)
        if CONFIG["look"]["not_carried"]:
            print("blender_scene.py: the watercolour look's " + ", ".join(CONFIG["look"]["not_carried"]) + " are not "
                  "carried by shader nodes (docs/blender.md); its paper, unevenness, strokes and mix are")
    obj.data.materials.append(materials[shading])
    modifier = per_vertex_modifier(obj, camera)
    modifier.show_viewport = modifier.show_render = shading == "per-vertex"
    for tree in (materials["per-pixel"].node_tree, modifier.node_group):
        for node in tree.nodes:
            if node.type == "GROUP" and "Light Direction" in node.inputs:
                drive_light(node.inputs["Light Direction"], sun)
    return obj


# --- rendering ------------------------------------------------------------------------------------


def render_settings(size):
    """The scene's size; Standard view transform (sRGB, no tone curve), no dithering, 8-bit RGB PNG."""
    import bpy

    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = size
    scene.render.resolution_percentage, scene.render.pixel_aspect_x, scene.render.pixel_aspect_y = 100, 1, 1
    scene.display_settings.display_device = "sRGB"
    scene.view_settings.view_transform, scene.view_settings.look = "Standard", "None"
    scene.view_settings.exposure, scene.view_settings.gamma = 0.0, 1.0
    scene.render.dither_intensity = 0.0
    scene.render.film_transparent = False
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode, scene.render.image_settings.color_depth = "RGB", "8"
    # EEVEE: one sample, no reconstruction filter (the pixel centre, as diffwash samples it).
    scene.eevee.taa_render_samples = 1
    scene.render.filter_size = 0.0
    # Cycles: one camera sample per pixel, within 0.005 px of its centre; no bounces, no denoising.
    scene.cycles.device = "CPU"
    scene.cycles.samples, scene.cycles.use_adaptive_sampling, scene.cycles.use_denoising = 1, False, False
    scene.cycles.pixel_filter_type, scene.cycles.filter_width = "BOX", 0.01
    scene.cycles.max_bounces = 0
    scene.cycles.seed = 0


def probe_eevee():
    """Render 4x4 pixels of an empty scene with EEVEE (the child process of `eevee_runs`)."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    camera = bpy.data.objects.new("probe", bpy.data.cameras.new("probe"))
    scene.collection.objects.link(camera)
    scene.camera, scene.render.engine = camera, "BLENDER_EEVEE_NEXT"
    scene.render.resolution_x = scene.render.resolution_y = 4
    bpy.ops.render.render()


def eevee_runs():
    """Whether EEVEE draws here: Blender with a window does; headless, a child process tries (where no OpenGL
    context can be made, Blender aborts, which no exception would report)."""
    import bpy

    if not bpy.app.background:
        return True
    script = str(Path(__file__).resolve())
    if bpy.app.binary_path:  # blender -b -P: the same Blender
        command = [bpy.app.binary_path, "-b", "--factory-startup", "-P", script, "--", "--probe-eevee"]
    else:  # the bpy module: the same Python
        command = [sys.executable, script, "--probe-eevee"]
    try:
        done = subprocess.run(command, capture_output=True, timeout=300, check=False)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return done.returncode == 0


def render(out, engine, size):
    """Render to `out`: `engine="auto"` is EEVEE where it draws (a GPU, or Mesa's llvmpipe), else Cycles on the CPU."""
    import bpy

    scene = bpy.context.scene
    scene.render.filepath = os.path.abspath(out)
    if engine == "auto":
        engine = "eevee" if eevee_runs() else "cycles"
        print(f"blender_scene.py: {'EEVEE draws here' if engine == 'eevee' else 'EEVEE does not draw here: Cycles on the CPU'}")
    scene.render.engine = {"eevee": "BLENDER_EEVEE_NEXT", "cycles": "CYCLES"}[engine]
    start = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    print(f"blender_scene.py: rendered {out} ({size[0]}x{size[1]}) with {scene.render.engine} in {time.perf_counter() - start:.2f} s")
    return scene.render.engine


def main(argv=None):
    if not isinstance(CONFIG, dict):
        raise SystemExit("blender_scene.py: this is diffwash's template; diffwash export --target blender writes the script")
    args = arguments(script_arguments() if argv is None else argv)
    if args.probe_eevee:
        probe_eevee()
        return 0
    size = args.size or (CONFIG["width"], CONFIG["height"])
    build(args.shading or CONFIG["shading"])
    render_settings(size)
    if args.save:
        import bpy

        bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(args.save), compress=True)
        print(f"blender_scene.py: saved {args.save}")
    if args.render:
        render(args.render, args.engine, size)
    return 0


if __name__ == "__main__":
    sys.exit(main())
