#!/usr/bin/env python3
"""Writes assets/scenes/pool.gltf: the rippled pool of shared/reference at 33 x 33
vertices, as glTF 2.0 with KHR_materials_transmission + KHR_materials_ior on the water,
a tiled floor and a KHR_lights_punctual sun. Standard library only; deterministic."""
import base64, json, math, struct, sys

N, SIZE, HEIGHT = 33, 4.0, 0.8
WAVES = [(8.0, 0.0, 0.07, 0.0), (0.0, 9.0, 0.05, 0.7)]
SUN = (0.3, -1.0, -0.2)

def water():
    pos, nrm, idx = [], [], []
    for j in range(N):
        for i in range(N):
            x, z = -SIZE / 2 + i * SIZE / (N - 1), -SIZE / 2 + j * SIZE / (N - 1)
            y = HEIGHT + sum(a * math.sin(kx * x + kz * z + p) for kx, kz, a, p in WAVES)
            dx = sum(a * kx * math.cos(kx * x + kz * z + p) for kx, kz, a, p in WAVES)
            dz = sum(a * kz * math.cos(kx * x + kz * z + p) for kx, kz, a, p in WAVES)
            l = math.sqrt(dx * dx + 1 + dz * dz)
            pos.append((x, y, z)); nrm.append((-dx / l, 1 / l, -dz / l))
    for j in range(N - 1):
        for i in range(N - 1):
            p = j * N + i
            idx += [p, p + N, p + 1, p + 1, p + N, p + N + 1]
    return pos, nrm, [(0.0, 0.0)] * len(pos), idx

def floor():
    h = 3.0
    pos = [(-h, 0, -h), (-h, 0, h), (h, 0, h), (h, 0, -h)]
    return pos, [(0, 1, 0)] * 4, [(0, 0), (0, 6), (6, 6), (6, 0)], [0, 1, 2, 0, 2, 3]

def quat_from_neg_z_to(d):
    l = math.sqrt(sum(c * c for c in d)); d = [c / l for c in d]
    a = (0.0, 0.0, -1.0)
    cross = (a[1] * d[2] - a[2] * d[1], a[2] * d[0] - a[0] * d[2], a[0] * d[1] - a[1] * d[0])
    w = 1.0 + sum(x * y for x, y in zip(a, d))
    q = (*cross, w); n = math.sqrt(sum(c * c for c in q))
    return [c / n for c in q]

def main(out):
    buf, views, accessors, meshes = bytearray(), [], [], []
    def add(data, fmt, count, kind, comp, target, minmax=None):
        while len(buf) % 4: buf.append(0)
        views.append({"buffer": 0, "byteOffset": len(buf), "byteLength": struct.calcsize(fmt) * len(data), "target": target})
        for item in data: buf.extend(struct.pack(fmt, *item) if isinstance(item, tuple) else struct.pack(fmt, item))
        acc = {"bufferView": len(views) - 1, "componentType": comp, "count": count, "type": kind}
        if minmax: acc["min"], acc["max"] = minmax
        accessors.append(acc); return len(accessors) - 1
    for name, (pos, nrm, uv, idx), material in [("water", water(), 0), ("floor", floor(), 1)]:
        mm = ([min(p[k] for p in pos) for k in range(3)], [max(p[k] for p in pos) for k in range(3)])
        a_pos = add(pos, "<3f", len(pos), "VEC3", 5126, 34962, mm)
        a_nrm = add(nrm, "<3f", len(nrm), "VEC3", 5126, 34962)
        a_uv = add(uv, "<2f", len(uv), "VEC2", 5126, 34962)
        a_idx = add(idx, "<I", len(idx), "SCALAR", 5125, 34963)
        meshes.append({"name": name, "primitives": [{"attributes": {"POSITION": a_pos, "NORMAL": a_nrm, "TEXCOORD_0": a_uv},
                                                    "indices": a_idx, "material": material}]})
    doc = {
        "asset": {"version": "2.0", "generator": "bevy_caustics scripts/make_pool_gltf.py"},
        "extensionsUsed": ["KHR_materials_transmission", "KHR_materials_ior", "KHR_lights_punctual"],
        "extensions": {"KHR_lights_punctual": {"lights": [{"type": "directional", "intensity": 1.0, "color": [1, 1, 1]}]}},
        "scene": 0,
        "scenes": [{"nodes": [0, 1, 2, 3]}],
        "nodes": [
            {"name": "water", "mesh": 0},
            {"name": "floor", "mesh": 1},
            {"name": "sun", "rotation": quat_from_neg_z_to(SUN), "extensions": {"KHR_lights_punctual": {"light": 0}}},
            {"name": "camera", "camera": 0, "translation": [0.0, 3.2, 3.6], "rotation": quat_from_neg_z_to((0.0, -3.2, -3.6))},
        ],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.785, "znear": 0.05, "zfar": 100.0, "aspectRatio": 1.333}}],
        "materials": [
            {"name": "water", "pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.97, 1.0, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.02},
             "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1.0}, "KHR_materials_ior": {"ior": 1.333}}},
            {"name": "tiles", "pbrMetallicRoughness": {"baseColorFactor": [0.75, 0.8, 0.8, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.9}},
        ],
        "meshes": meshes, "accessors": accessors, "bufferViews": views,
        "buffers": [{"byteLength": len(buf), "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(buf)).decode()}],
    }
    with open(out, "w") as f: json.dump(doc, f, indent=1)

if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "assets/scenes/pool.gltf")
