#!/usr/bin/env python3
"""Writes tests/malformed/: broken glTF, GLB and JSON scene files, each spoiled in one
way, for the malformed-input tests (crates/caustics_cli/tests/malformed.rs and the
app test in tests/malformed_app.rs). Every file is derived from one small valid scene
(a glass sheet over a stone floor under a sun), so each shows one fault alone.
Run from the repository root: python3 scripts/malformed_corpus.py"""

import base64
import copy
import json
import math
import os
import struct

OUT = os.path.join("tests", "malformed")


def sheet():
    """A 3 x 3-vertex glass sheet at y = 1 and a 2-triangle floor: positions, normals, indices."""
    positions, normals = [], []
    for j in range(3):
        for i in range(3):
            positions += [i - 1.0, 1.0 + 0.05 * ((i + j) % 2), j - 1.0]
            normals += [0.0, 1.0, 0.0]
    indices = []
    for j in range(2):
        for i in range(2):
            p = j * 3 + i
            indices += [p, p + 3, p + 1, p + 1, p + 3, p + 4]
    return positions, normals, indices


def floor():
    positions = [-3.0, 0.0, -3.0, 3.0, 0.0, -3.0, -3.0, 0.0, 3.0, 3.0, 0.0, 3.0]
    normals = [0.0, 1.0, 0.0] * 4
    indices = [0, 2, 1, 1, 2, 3]
    return positions, normals, indices


def pack(meshes):
    """One buffer holding every mesh's positions, normals and indices; the accessors
    and views for them."""
    data, views, accessors = b"", [], []

    def add(blob, target):
        nonlocal data
        while len(data) % 4:
            data += b"\0"
        views.append({"buffer": 0, "byteOffset": len(data), "byteLength": len(blob), "target": target})
        data += blob
        return len(views) - 1

    prims = []
    for positions, normals, indices in meshes:
        n = len(positions) // 3
        lo = [min(positions[k::3]) for k in range(3)]
        hi = [max(positions[k::3]) for k in range(3)]
        pv = add(struct.pack(f"<{len(positions)}f", *positions), 34962)
        accessors.append({"bufferView": pv, "componentType": 5126, "count": n, "type": "VEC3", "min": lo, "max": hi})
        nv = add(struct.pack(f"<{len(normals)}f", *normals), 34962)
        accessors.append({"bufferView": nv, "componentType": 5126, "count": n, "type": "VEC3"})
        iv = add(struct.pack(f"<{len(indices)}I", *indices), 34963)
        accessors.append({"bufferView": iv, "componentType": 5125, "count": len(indices), "type": "SCALAR"})
        prims.append(len(accessors) - 3)
    return data, views, accessors, prims


def scene(meshes=None):
    """The valid scene as a glTF dict and its binary buffer."""
    data, views, accessors, prims = pack(meshes or [sheet(), floor()])
    gltf = {
        "asset": {"version": "2.0", "generator": "bevy_caustics malformed corpus"},
        "extensionsUsed": ["KHR_materials_transmission", "KHR_materials_ior", "KHR_lights_punctual"],
        "extensions": {"KHR_lights_punctual": {"lights": [{"type": "directional", "intensity": 10.0}]}},
        "scene": 0,
        "scenes": [{"nodes": [0, 1, 2]}],
        "nodes": [
            {"name": "glass", "mesh": 0},
            {"name": "floor", "mesh": 1},
            {"name": "sun", "rotation": [-0.7071068, 0.0, 0.0, 0.7071068], "extensions": {"KHR_lights_punctual": {"light": 0}}},
        ],
        "materials": [
            {"name": "glass", "pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 0.0},
             "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1.0}, "KHR_materials_ior": {"ior": 1.5}}},
            {"name": "stone", "pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 0.9}},
        ],
        "meshes": [
            {"name": "glass", "primitives": [{"attributes": {"POSITION": prims[0], "NORMAL": prims[0] + 1}, "indices": prims[0] + 2, "material": 0}]},
            {"name": "floor", "primitives": [{"attributes": {"POSITION": prims[1], "NORMAL": prims[1] + 1}, "indices": prims[1] + 2, "material": 1}]},
        ],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": len(data)}],
    }
    return gltf, data


def embedded(gltf, data):
    g = copy.deepcopy(gltf)
    g["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(data).decode()
    return g


def write(name, content):
    mode = "wb" if isinstance(content, bytes) else "w"
    with open(os.path.join(OUT, name), mode) as f:
        f.write(content)


def write_gltf(name, gltf, data):
    write(name, json.dumps(embedded(gltf, data), indent=1))


def glb(gltf, data, version=2, magic=b"glTF", json_chunk=None):
    text = json_chunk if json_chunk is not None else json.dumps(gltf).encode()
    while len(text) % 4:
        text += b" "
    while len(data) % 4:
        data += b"\0"
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(data), 0x004E4942) + data
    return magic + struct.pack("<II", version, 12 + len(body)) + body


def spoiled(edit):
    gltf, data = scene()
    data = bytearray(data)
    edit(gltf, data)
    return gltf, bytes(data)


def floats_at(gltf, accessor):
    view = gltf["bufferViews"][gltf["accessors"][accessor]["bufferView"]]
    return view["byteOffset"]


def main():
    os.makedirs(OUT, exist_ok=True)
    gltf, data = scene()
    valid = json.dumps(embedded(gltf, data), indent=1)

    # Controls: the scene itself, which loads and renders.
    write("control_valid.gltf", valid)
    write("control_valid.glb", glb(gltf, data))

    # Not glTF at all, or cut short.
    write("empty.gltf", "")
    write("not_json.gltf", "this is not a glTF file\n")
    write("truncated.gltf", valid[: len(valid) // 2])
    write("wrong_version.gltf", json.dumps(embedded(dict(gltf, asset={"version": "1.0"}), data)))

    def g(name, edit):
        write_gltf(name, *spoiled(edit))

    # Accessors that do not fit their data.
    g("accessor_count_past_view.gltf", lambda j, d: j["accessors"][0].update(count=1000))
    g("accessor_absurd_count.gltf", lambda j, d: j["accessors"][0].update(count=4000000000))
    g("position_wrong_type.gltf", lambda j, d: j["accessors"][0].update(type="VEC2"))
    g("position_wrong_component.gltf", lambda j, d: j["accessors"][0].update(componentType=5121))
    g("indices_float.gltf", lambda j, d: j["accessors"][2].update(componentType=5126))
    g("view_past_buffer.gltf", lambda j, d: j["bufferViews"][0].update(byteOffset=100000))
    g("buffer_length_past_data.gltf", lambda j, d: j["buffers"][0].update(byteLength=len(d) * 4))
    g("accessor_missing_view.gltf", lambda j, d: j["accessors"][0].update(bufferView=99))

    # Data that is there but wrong.
    def set_indices(j, d, value):
        off = floats_at(j, 2)
        struct.pack_into("<I", d, off, value)

    g("index_out_of_range.gltf", lambda j, d: set_indices(j, d, 9999))
    g("index_max_u32.gltf", lambda j, d: set_indices(j, d, 0xFFFFFFFF))

    def set_float(j, d, accessor, k, value):
        struct.pack_into("<f", d, floats_at(j, accessor) + 4 * k, value)

    g("nan_position.gltf", lambda j, d: set_float(j, d, 0, 4, math.nan))
    g("infinite_position.gltf", lambda j, d: set_float(j, d, 0, 1, math.inf))
    g("nan_normal.gltf", lambda j, d: set_float(j, d, 1, 3, math.nan))
    g("zero_normals.gltf", lambda j, d: [set_float(j, d, 1, k, 0.0) for k in range(27)])
    g("all_nan_positions.gltf", lambda j, d: [set_float(j, d, 0, k, math.nan) for k in range(27)])

    # Structure that points nowhere.
    gltf_missing, data_missing = scene()
    missing = copy.deepcopy(gltf_missing)
    missing["buffers"][0]["uri"] = "no_such_buffer.bin"
    write("missing_buffer_file.gltf", json.dumps(missing, indent=1))
    bad64 = embedded(gltf, data)
    bad64["buffers"][0]["uri"] = "data:application/octet-stream;base64,@@@not base64@@@"
    write("bad_base64.gltf", json.dumps(bad64))
    g("mesh_index_out_of_range.gltf", lambda j, d: j["nodes"][0].update(mesh=99))
    g("material_index_out_of_range.gltf", lambda j, d: j["meshes"][0]["primitives"][0].update(material=42))
    g("node_cycle.gltf", lambda j, d: j["nodes"][0].update(children=[0]))
    g("scene_node_out_of_range.gltf", lambda j, d: j["scenes"][0].update(nodes=[0, 1, 2, 77]))
    g("no_scenes.gltf", lambda j, d: (j.pop("scene"), j.update(scenes=[])))
    g("missing_position.gltf", lambda j, d: j["meshes"][0]["primitives"][0]["attributes"].pop("POSITION"))
    g("unknown_required_extension.gltf", lambda j, d: j.update(extensionsRequired=["EXT_no_such_thing"], extensionsUsed=j["extensionsUsed"] + ["EXT_no_such_thing"]))
    g("points_not_triangles.gltf", lambda j, d: j["meshes"][0]["primitives"][0].update(mode=0))
    g("two_indices.gltf", lambda j, d: j["accessors"][2].update(count=2))
    g("no_meshes.gltf", lambda j, d: (j.update(meshes=[]), j["nodes"][0].pop("mesh"), j["nodes"][1].pop("mesh")))

    # Values no renderer can use.
    g("impossible_ior.gltf", lambda j, d: j["materials"][0]["extensions"]["KHR_materials_ior"].update(ior=0.5))
    g("overflowing_translation.gltf", lambda j, d: j["nodes"][0].update(translation=[1e39, 0.0, 0.0]))
    g("zero_scale.gltf", lambda j, d: j["nodes"][0].update(scale=[0.0, 0.0, 0.0]))
    g("nan_light.gltf", lambda j, d: j["extensions"]["KHR_lights_punctual"]["lights"][0].update(intensity=1e39))

    # GLB containers.
    write("bad_magic.glb", glb(gltf, data, magic=b"gLTF"))
    write("truncated_header.glb", glb(gltf, data)[:10])
    whole = glb(gltf, data)
    write("truncated_body.glb", whole[: len(whole) // 2])
    write("glb_version_1.glb", glb(gltf, data, version=1))
    write("glb_json_chunk_not_json.glb", glb(gltf, data, json_chunk=b"{ not json"))
    lying = bytearray(whole)
    struct.pack_into("<I", lying, 12, 1 << 30)
    write("glb_chunk_length_past_end.glb", bytes(lying))

    # Scene descriptions (JSON).
    description = {
        "name": "sheet",
        "light": {"type": "directional", "direction": [0.2, -1.0, 0.1], "irradiance": 1.0},
        "generators": [{"shape": "heightfield", "material": "glass", "ior": 1.33, "n": 16, "size": 2.0, "height": 1.0, "waves": [[3.0, 1.0, 0.02, 0.0]]}],
        "receiver": {"y": 0.0, "size": 2.0},
        "max_depth": 4,
    }

    def d(name, edit):
        desc = copy.deepcopy(description)
        edit(desc)
        write(name, json.dumps(desc, indent=1))

    write("control_valid.json", json.dumps(description, indent=1))
    text = json.dumps(description)
    write("description_truncated.json", text[: len(text) // 2])
    write("description_empty.json", "")
    d("description_missing_light.json", lambda x: x.pop("light"))
    d("description_ior_as_text.json", lambda x: x["generators"][0].update(ior="glass"))
    d("description_impossible_ior.json", lambda x: x["generators"][0].update(ior=0.5))
    d("description_absurd_grid.json", lambda x: x["generators"][0].update(n=4000000000))
    d("description_zero_direction.json", lambda x: x["light"].update(direction=[0.0, 0.0, 0.0]))
    d("description_negative_irradiance.json", lambda x: x["light"].update(irradiance=-5.0))
    d("description_overflowing_number.json", lambda x: x["light"].update(irradiance=1e39))
    d("description_unknown_shape.json", lambda x: x["generators"][0].update(shape="teapot"))
    d("description_point_light.json", lambda x: x["light"].update(type="point"))
    d("description_no_generators.json", lambda x: x.update(generators=[]))
    d("description_nan_wave.json", lambda x: x["generators"][0].update(waves=[[1e39, 1.0, 1e39, 0.0]]))


if __name__ == "__main__":
    main()
