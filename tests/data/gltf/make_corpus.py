#!/usr/bin/env python3
"""Writes the glTF test corpus under good/ and bad/ (run from anywhere; output is committed).

good/: small scenes with known contents, checked by tests/unit/test_gltf_import.cpp.
bad/:  one hostile case per file, derived from a valid single-triangle scene by one mutation,
       checked by tests/unit/test_gltf_bad_input.cpp (which lists the field each must name).
Only the standard library: buffers are packed with struct, PNGs with zlib."""

import base64
import copy
import json
import math
import struct
import zlib
from pathlib import Path

HERE = Path(__file__).resolve().parent
FLOAT, UBYTE, USHORT, UINT, DOUBLE = 5126, 5121, 5123, 5125, 5130


class Buffer:
    """One glTF buffer: bytes plus the buffer views and accessors laid over them."""

    def __init__(self):
        self.data = bytearray()
        self.views = []
        self.accessors = []

    def view(self, payload, stride=None):
        while len(self.data) % 4:
            self.data.append(0)
        view = {"buffer": 0, "byteOffset": len(self.data), "byteLength": len(payload)}
        if stride:
            view["byteStride"] = stride
        self.data += payload
        self.views.append(view)
        return len(self.views) - 1

    def accessor(self, view, component_type, count, type_, offset=0, normalized=False, **extra):
        a = {"bufferView": view, "componentType": component_type, "count": count, "type": type_}
        if offset:
            a["byteOffset"] = offset
        if normalized:
            a["normalized"] = True
        a.update(extra)
        self.accessors.append(a)
        return len(self.accessors) - 1

    def floats(self, values, type_, bounds=True, **extra):
        """Tightly packed floats; positions need min and max, so VEC3 gets them by default."""
        count = len(values) // {"VEC2": 2, "VEC3": 3}[type_]
        view = self.view(struct.pack(f"<{len(values)}f", *values))
        if type_ == "VEC3" and bounds:
            xs, ys, zs = values[0::3], values[1::3], values[2::3]
            extra.setdefault("min", [min(xs), min(ys), min(zs)])
            extra.setdefault("max", [max(xs), max(ys), max(zs)])
        return self.accessor(view, FLOAT, count, type_, **extra)

    def uri(self):
        return "data:application/octet-stream;base64," + base64.b64encode(self.data).decode()


def png(width, height, rgba):
    """An 8-bit RGBA PNG of `rgba` (rows top to bottom)."""
    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
    rows = b"".join(b"\0" + bytes(rgba[y * width * 4:(y + 1) * width * 4]) for y in range(height))
    header = struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(rows))
            + chunk(b"IEND", b""))


# 2x2 texture: red, green / blue, white with alpha 128 (test_gltf_import.cpp knows these).
TEXTURE = [255, 0, 0, 255, 0, 255, 0, 255, 0, 0, 255, 255, 255, 255, 255, 128]
QUAD = [0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0]


def glb(document, binary=b""):
    """A GLB container: header, JSON chunk, and a BIN chunk when there is binary data."""
    text = json.dumps(document).encode()
    text += b" " * (-len(text) % 4)
    chunks = struct.pack("<I4s", len(text), b"JSON") + text
    if binary:
        binary = bytes(binary) + b"\0" * (-len(binary) % 4)
        chunks += struct.pack("<I4s", len(binary), b"BIN\0") + binary
    return struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks


def write(path, document):
    path.write_text(json.dumps(document, indent=2) + "\n")


def triangle_scene():
    """The valid base of every bad case: one triangle, indexed, data URI buffer."""
    b = Buffer()
    position = b.floats([0, 0, 0, 1, 0, 0, 0, 1, 0], "VEC3")
    indices = b.accessor(b.view(struct.pack("<3H", 0, 1, 2) + b"\0\0"), USHORT, 3, "SCALAR")
    return {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "Triangle", "mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": position}, "indices": indices}]}],
        "accessors": b.accessors,
        "bufferViews": b.views,
        "buffers": [{"byteLength": len(b.data), "uri": b.uri()}],
    }


def good():
    out = HERE / "good"
    # triangle.gltf: non-indexed, external .bin, translated node.
    b = Buffer()
    position = b.floats([0, 0, 0, 1, 0, 0, 0, 1, 0], "VEC3")
    normal = b.floats([0, 0, 1] * 3, "VEC3", bounds=False)
    (out / "triangle.bin").write_bytes(b.data)
    write(out / "triangle.gltf", {
        "asset": {"version": "2.0", "generator": "make_corpus.py"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "Triangle", "mesh": 0, "translation": [1, 2, 3]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": position, "NORMAL": normal}}]}],
        "accessors": b.accessors,
        "bufferViews": b.views,
        "buffers": [{"byteLength": len(b.data), "uri": "triangle.bin"}],
    })

    # hierarchy.gltf: a matrix parent, a TRS child whose mesh has three primitives (one per
    # index component type and texcoord encoding, one interleaved), a leaf, a mirrored root.
    b = Buffer()
    p0 = b.floats(QUAD, "VEC3")
    uv_float = b.floats([0, 0, 1, 0, 1, 1, 0, 1], "VEC2")
    i_ubyte = b.accessor(b.view(bytes([0, 1, 2, 0, 2, 3])), UBYTE, 6, "SCALAR")
    interleaved = []
    for k in range(4):
        interleaved += QUAD[3 * k:3 * k + 2] + [1.0] + [0.0, 0.0, 1.0]
    v = b.view(struct.pack("<24f", *interleaved), stride=24)
    p1 = b.accessor(v, FLOAT, 4, "VEC3", min=[0, 0, 1], max=[1, 1, 1])
    n1 = b.accessor(v, FLOAT, 4, "VEC3", offset=12)
    uv_ubyte = b.accessor(b.view(bytes([0, 0, 255, 0, 255, 255, 0, 255])), UBYTE, 4, "VEC2",
                          normalized=True)
    i_ushort = b.accessor(b.view(struct.pack("<6H", 0, 1, 2, 0, 2, 3)), USHORT, 6, "SCALAR")
    p2 = b.floats([c if k % 3 != 2 else 2.0 for k, c in enumerate(QUAD)], "VEC3")
    uv_ushort = b.accessor(b.view(struct.pack("<8H", 0, 0, 65535, 0, 65535, 65535, 0, 65535)),
                           USHORT, 4, "VEC2", normalized=True)
    # Four bytes of padding first: the accessor's byteOffset must be honoured.
    i_uint = b.accessor(b.view(struct.pack("<7I", 0xDEADBEEF, 0, 1, 2, 0, 2, 3)), UINT, 6,
                        "SCALAR", offset=4)
    p3 = b.floats([0, 0, 0, 1, 0, 0, 0, 1, 0], "VEC3")
    write(out / "hierarchy.gltf", {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0, 3]}],
        "nodes": [
            # translate(0, 1, 0) * rotateY(90 degrees) * scale(2), column-major.
            {"name": "Parent", "children": [1],
             "matrix": [0, 0, -2, 0, 0, 2, 0, 0, 2, 0, 0, 0, 0, 1, 0, 1]},
            {"name": "Child", "children": [2], "mesh": 0, "translation": [1, 0, 0],
             "rotation": [0, 0, math.sqrt(0.5), math.sqrt(0.5)], "scale": [1, 0.5, 1]},
            {"name": "Leaf", "translation": [0, 0, 5]},
            # A mirror: x scale -1, translated by (5, 0, 0).
            {"name": "Mirror", "mesh": 1, "matrix": [-1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 5, 0, 0, 1]},
        ],
        "meshes": [
            {"name": "Quads", "primitives": [
                {"attributes": {"POSITION": p0, "TEXCOORD_0": uv_float}, "indices": i_ubyte,
                 "material": 0},
                {"attributes": {"POSITION": p1, "NORMAL": n1, "TEXCOORD_0": uv_ubyte},
                 "indices": i_ushort, "material": 1},
                {"attributes": {"POSITION": p2, "TEXCOORD_0": uv_ushort}, "indices": i_uint},
            ]},
            {"name": "Triangle", "primitives": [{"attributes": {"POSITION": p3}, "mode": 4}]},
        ],
        "materials": [
            {"name": "Clay", "pbrMetallicRoughness": {
                "baseColorFactor": [0.5, 0.25, 0.125, 1], "metallicFactor": 0, "roughnessFactor": 0.5}},
            {"name": "Glow", "emissiveFactor": [0.2, 0.4, 0.6]},
        ],
        "accessors": b.accessors,
        "bufferViews": b.views,
        "buffers": [{"byteLength": len(b.data), "uri": b.uri()}],
    })

    # lights.gltf: punctual lights, two cameras, mobility and avatar tags, an emissive textured
    # material with KHR_materials_emissive_strength.
    b = Buffer()
    quad = b.floats(QUAD, "VEC3")
    quad_uv = b.floats([0, 0, 1, 0, 1, 1, 0, 1], "VEC2")
    quad_i = b.accessor(b.view(struct.pack("<6H", 0, 1, 2, 0, 2, 3)), USHORT, 6, "SCALAR")
    textured = {"primitives": [{"attributes": {"POSITION": quad, "TEXCOORD_0": quad_uv},
                                "indices": quad_i, "material": 0}]}
    plain = {"primitives": [{"attributes": {"POSITION": quad}, "indices": quad_i}]}
    light = lambda k: {"KHR_lights_punctual": {"light": k}}
    write(out / "lights.gltf", {
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_lights_punctual", "KHR_materials_emissive_strength"],
        "extensions": {"KHR_lights_punctual": {"lights": [
            {"type": "point", "color": [1, 0.5, 0.25], "intensity": 10},
            {"type": "spot", "intensity": 20, "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.6}},
            {"type": "directional", "color": [1, 1, 0.5], "intensity": 3},
        ]}},
        "cameras": [
            {"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1, "zfar": 100}},
            {"type": "perspective", "perspective": {"yfov": 1.0, "znear": 0.5}},
        ],
        "scene": 0,
        "scenes": [{"nodes": [0, 1, 2, 3, 4, 5, 8, 9]}],
        "nodes": [
            {"name": "Bulb", "translation": [0, 3, 0], "extensions": light(0)},
            {"name": "Spot", "translation": [1, 3, 0],
             "rotation": [-math.sqrt(0.5), 0, 0, math.sqrt(0.5)], "extensions": light(1)},
            {"name": "Sun", "extensions": light(2)},
            {"name": "SideCamera", "camera": 1},
            {"name": "MainCamera", "camera": 0, "translation": [0, 1.5, 4]},
            {"name": "Crate", "mesh": 1, "children": [6, 7], "extras": {"mobility": "mobile"}},
            {"name": "Lid", "mesh": 1, "translation": [0, 1, 0]},
            {"name": "Bolt", "mesh": 1, "extras": {"mobility": "static"}},
            {"name": "Walker", "mesh": 1, "scale": [2, 2, 2], "extras": {"avatar": True}},
            {"name": "Lamp", "mesh": 0},
        ],
        "meshes": [textured, plain],
        "materials": [{
            "name": "Emitter",
            "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicFactor": 0.25,
                                     "roughnessFactor": 0.75},
            "emissiveFactor": [1, 0.5, 0.25],
            "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4}},
        }],
        "textures": [{"source": 0}],
        "images": [{"name": "checker", "uri": "data:image/png;base64,"
                    + base64.b64encode(png(2, 2, TEXTURE)).decode()}],
        "accessors": b.accessors,
        "bufferViews": b.views,
        "buffers": [{"byteLength": len(b.data), "uri": b.uri()}],
    })

    # point_cache_room.gltf: a 2 m floor tagged for the point cache under a square blocker and
    # a downward emissive panel (test_demo_smoke.cpp bakes it through the demo).
    b = Buffer()

    def horizontal(half, y, up):
        corners = [(-half, -half), (half, -half), (half, half), (-half, half)]
        if not up:
            corners.reverse()
        values = [c for x, z in corners for c in (x, y, -z)]
        position = b.floats(values, "VEC3")
        normal = b.floats([0, 1 if up else -1, 0] * 4, "VEC3", bounds=False)
        indices = b.accessor(b.view(struct.pack("<6H", 0, 1, 2, 0, 2, 3)), USHORT, 6, "SCALAR")
        return position, normal, indices

    def mesh(name, quad, material):
        position, normal, indices = quad
        return {"name": name, "primitives": [{"attributes": {"POSITION": position, "NORMAL": normal},
                                               "indices": indices, "material": material}]}

    write(out / "point_cache_room.gltf", {
        "asset": {"version": "2.0", "generator": "make_corpus.py"},
        "scene": 0,
        "scenes": [{"nodes": [0, 1, 2, 3]}],
        "nodes": [
            {"name": "Floor", "mesh": 0, "extras": {"pointCache": True}},
            {"name": "Blocker", "mesh": 1},
            {"name": "Panel", "mesh": 2},
            {"name": "Camera", "camera": 0, "translation": [0, 2.5, 0],
             "rotation": [-math.sqrt(0.5), 0, 0, math.sqrt(0.5)]},
        ],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 1.0, "znear": 0.05}}],
        "meshes": [mesh("floor", horizontal(1, 0, True), 0),
                   mesh("blocker", horizontal(0.3, 0.75, True), 0),
                   mesh("panel", horizontal(0.25, 1.5, False), 1)],
        "materials": [
            {"name": "Grey", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1],
                                                      "metallicFactor": 0}},
            {"name": "Lamp", "pbrMetallicRoughness": {"baseColorFactor": [0, 0, 0, 1],
                                                      "metallicFactor": 0},
             "emissiveFactor": [1, 1, 1],
             "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 10}}},
        ],
        "extensionsUsed": ["KHR_materials_emissive_strength"],
        "accessors": b.accessors,
        "bufferViews": b.views,
        "buffers": [{"byteLength": len(b.data), "uri": b.uri()}],
    })

    # box.glb: binary container, the texture stored in a buffer view of the BIN chunk.
    b = Buffer()
    position = b.floats(QUAD, "VEC3")
    uv = b.floats([0, 0, 1, 0, 1, 1, 0, 1], "VEC2")
    indices = b.accessor(b.view(struct.pack("<6I", 0, 1, 2, 0, 2, 3)), UINT, 6, "SCALAR")
    image_view = b.view(png(2, 2, TEXTURE))
    (out / "box.glb").write_bytes(glb({
        "asset": {"version": "2.0"},
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "Box", "mesh": 0, "translation": [0, 0, -1]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": position, "TEXCOORD_0": uv},
                                    "indices": indices, "material": 0}]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
        "textures": [{"source": 0}],
        "images": [{"bufferView": image_view, "mimeType": "image/png"}],
        "accessors": b.accessors,
        "bufferViews": b.views,
        "buffers": [{"byteLength": len(b.data)}],
    }, b.data))


def bad():
    out = HERE / "bad"
    base = triangle_scene()

    def case(name, mutate):
        document = copy.deepcopy(base)
        mutate(document)
        write(out / name, document)

    def set_floats(document, values):
        """Replaces the triangle's three positions (the first 36 bytes of the buffer)."""
        data = bytearray(base64.b64decode(document["buffers"][0]["uri"].split(",")[1]))
        data[0:36] = struct.pack("<9f", *values)
        document["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(data).decode()

    def set_indices(document, indices):
        """Replaces the triangle's three indices (after the positions)."""
        data = bytearray(base64.b64decode(document["buffers"][0]["uri"].split(",")[1]))
        data[36:42] = struct.pack("<3H", *indices)
        document["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(data).decode()

    def primitive(d):
        return d["meshes"][0]["primitives"][0]

    case("missing_buffer_file.gltf", lambda d: d["buffers"][0].update(uri="nowhere.bin"))
    case("accessor_out_of_range.gltf", lambda d: primitive(d)["attributes"].update(POSITION=5))
    case("bufferview_out_of_range.gltf", lambda d: d["accessors"][0].update(bufferView=9))
    case("bufferview_past_buffer.gltf", lambda d: d["bufferViews"][1].update(byteLength=400))
    case("accessor_past_view.gltf", lambda d: d["accessors"][0].update(count=4))
    case("bad_component_type.gltf", lambda d: d["accessors"][0].update(componentType=DOUBLE))
    case("nan_position.gltf", lambda d: set_floats(d, [0, 0, 0, 1, 0, 0, 0, float("nan"), 0]))
    case("inf_position.gltf", lambda d: set_floats(d, [0, 0, 0, float("inf"), 0, 0, 0, 1, 0]))
    case("node_cycle.gltf", lambda d: d.update(nodes=[
        {"name": "A", "mesh": 0, "children": [1]}, {"name": "B", "children": [0]}]))
    case("two_parents.gltf", lambda d: d.update(nodes=[
        {"name": "A", "children": [2]}, {"name": "B", "children": [2]}, {"name": "C", "mesh": 0}],
        scenes=[{"nodes": [0, 1]}]))
    case("bad_scene_node.gltf", lambda d: d["scenes"][0].update(nodes=[0, 9]))
    case("bad_material.gltf", lambda d: primitive(d).update(material=5))
    case("uri_escape.gltf", lambda d: d["buffers"][0].update(uri="../good/triangle.bin", byteLength=72))
    case("uri_escape_encoded.gltf",
         lambda d: d["buffers"][0].update(uri="%2E%2E/good/triangle.bin", byteLength=72))
    case("uri_absolute.gltf", lambda d: d["buffers"][0].update(uri="/etc/passwd"))
    case("bad_base64.gltf", lambda d: d["buffers"][0].update(
        uri=d["buffers"][0]["uri"][:50] + "!!!!" + d["buffers"][0]["uri"][54:]))
    case("unknown_mobility.gltf", lambda d: d["nodes"][0].update(extras={"mobility": "flying"}))
    case("active_not_bool.gltf",
         lambda d: d["nodes"][0].update(extras={"mobility": "mobile", "active": "no"}))
    case("active_on_static.gltf",
         lambda d: d["nodes"][0].update(extras={"mobility": "static", "active": False}))
    case("sheared_matrix.gltf", lambda d: d["nodes"][0].update(
        matrix=[1, 0, 0, 0, 0.5, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]))
    case("index_out_of_range.gltf", lambda d: set_indices(d, [0, 1, 7]))
    case("unsupported_required_extension.gltf",
         lambda d: d.update(extensionsRequired=["KHR_draco_mesh_compression"]))
    def drawn_image(d, image):
        """The triangle textured with `image` (PNG bytes): an image a material draws."""
        primitive(d).update(material=0)
        d.update(materials=[{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
                 textures=[{"source": 0}],
                 images=[{"uri": "data:image/png;base64," + base64.b64encode(image).decode()}])

    case("corrupt_image.gltf", lambda d: drawn_image(d, png(2, 2, TEXTURE)[:30]))
    # A critical chunk of unknown type whose name is a line break and a bell: the decoder's
    # reason quotes the name, and the message must stay one printable line.
    odd = png(2, 2, TEXTURE)
    odd = odd[:33] + struct.pack(">I", 0) + b"\nND\x07" + struct.pack(">I", zlib.crc32(b"\nND\x07")) + odd[33:]
    case("image_chunk_control_bytes.gltf", lambda d: drawn_image(d, odd))

    text = json.dumps(base, indent=2)
    (out / "truncated.gltf").write_text(text[: len(text) // 2])
    (out / "invalid_json.gltf").write_text(text.replace('"scene": 0,', '"scene": 0,,', 1))
    (out / "empty.gltf").write_bytes(b"")
    good_glb = glb(base)
    (out / "bad_glb_magic.glb").write_bytes(b"glTX" + good_glb[4:])
    (out / "bad_glb_length.glb").write_bytes(good_glb[:8] + struct.pack("<I", len(good_glb) + 100) + good_glb[12:])


if __name__ == "__main__":
    good()
    bad()
