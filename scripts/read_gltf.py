#!/usr/bin/env python3
"""Opens a .glb with pygltflib (a Python glTF 2.0 reader, installed into .tools/py by
scripts/setup.sh) and checks what an importer relies on: every mesh primitive's accessors
resolve to buffer data of the declared size, indices stay within the vertex count, images are
embedded PNGs, and node names. Prints a JSON summary; exits 1 on any problem.
Usage: python3 scripts/read_gltf.py FILE.glb"""
import json
import os
import struct
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".tools", "py"))
try:
    import pygltflib
except ImportError:
    print("read_gltf: pygltflib not found in .tools/py; run scripts/setup.sh", file=sys.stderr)
    sys.exit(2)

COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
FORMATS = {5120: "b", 5121: "B", 5122: "h", 5123: "H", 5125: "I", 5126: "f"}


def accessor_values(gltf, blob, index):
    accessor = gltf.accessors[index]
    view = gltf.bufferViews[accessor.bufferView]
    fmt = FORMATS[accessor.componentType]
    width = COMPONENTS[accessor.type]
    size = struct.calcsize(fmt)
    stride = view.byteStride or size * width
    start = (view.byteOffset or 0) + (accessor.byteOffset or 0)
    end = start + stride * (accessor.count - 1) + size * width
    if end > (view.byteOffset or 0) + view.byteLength or end > len(blob):
        raise ValueError(f"accessor {index} runs past its buffer view")
    return [
        struct.unpack_from("<" + fmt * width, blob, start + k * stride) for k in range(accessor.count)
    ]


def main(path):
    problems = []
    gltf = pygltflib.GLTF2().load(path)
    blob = gltf.binary_blob() or b""
    triangles = 0
    for m, mesh in enumerate(gltf.meshes):
        for p, primitive in enumerate(mesh.primitives):
            where = f"mesh {m} ({mesh.name}) primitive {p}"
            try:
                positions = accessor_values(gltf, blob, primitive.attributes.POSITION)
                if any(v != v for xyz in positions for v in xyz):
                    problems.append(f"{where}: NaN position")
                if primitive.indices is not None:
                    indices = [i[0] for i in accessor_values(gltf, blob, primitive.indices)]
                    if indices and max(indices) >= len(positions):
                        problems.append(f"{where}: index {max(indices)} >= {len(positions)} vertices")
                    triangles += len(indices) // 3
            except (ValueError, KeyError, TypeError, struct.error) as e:
                problems.append(f"{where}: {e}")
    for i, image in enumerate(gltf.images):
        if image.bufferView is None:
            problems.append(f"image {i} is not embedded")
            continue
        view = gltf.bufferViews[image.bufferView]
        start = view.byteOffset or 0
        if blob[start : start + 8] != b"\x89PNG\r\n\x1a\n":
            problems.append(f"image {i} is not a PNG")
    summary = {
        "file": path,
        "nodes": [n.name for n in gltf.nodes],
        "meshes": len(gltf.meshes),
        "images": len(gltf.images),
        "materials": len(gltf.materials),
        "triangles": triangles,
        "problems": problems,
    }
    print(json.dumps(summary))
    return 1 if problems else 0


if __name__ == "__main__":
    if len(sys.argv) != 2:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    sys.exit(main(sys.argv[1]))
