#!/usr/bin/env python3
"""Independent quantized-mesh implementations for the mesh CLI tests.

    qm_peers.py read PATH WEST SOUTH EAST NORTH MASK  # quantized-mesh-tile reads a Globus file
                                                      # (MASK: 1 if it has a water mask)
    qm_peers.py write PATH                        # quantized-mesh-encoder writes a tile

Both print JSON on stdout. Requires pip install quantized-mesh-tile quantized-mesh-encoder.
"""
import gzip
import io
import json
import sys

import numpy as np


def read(path, west, south, east, north, mask):
    from quantized_mesh_tile.terrain import TerrainTile
    data = open(path, "rb").read()
    if data[:2] == b"\x1f\x8b":
        data = gzip.decompress(data)
    tile = TerrainTile(west=west, south=south, east=east, north=north)
    tile.fromBytesIO(io.BytesIO(data), hasLighting=True, hasWatermask=mask)
    coords = tile.getVerticesCoordinates()
    print(json.dumps({
        "lon_lat_h": coords,
        "indices": list(tile.indices),
        "west": list(tile.westI), "south": list(tile.southI),
        "east": list(tile.eastI), "north": list(tile.northI),
        "normals": [list(n) for n in tile.vLight],
        "watermask": tile.watermask if mask else None,
        "min_height": tile.header["minimumHeight"], "max_height": tile.header["maximumHeight"],
    }))


def write(path):
    from quantized_mesh_encoder import encode
    from quantized_mesh_encoder.extensions import VertexNormalsExtension, WaterMaskExtension
    # A 9 x 9 vertex patch over 10.0..10.5 E, 45.0..45.5 N with a hill, two triangles a cell.
    n = 9
    west, south, east, north = 10.0, 45.0, 10.5, 45.5
    positions = []
    for j in range(n):
        for i in range(n):
            lon = west + (east - west) * i / (n - 1)
            lat = south + (north - south) * j / (n - 1)
            h = 200.0 + 900.0 * np.exp(-((i - 4) ** 2 + (j - 3) ** 2) / 6.0)
            positions.append((lon, lat, h))
    positions = np.array(positions, dtype=np.float64)
    indices = []
    for j in range(n - 1):
        for i in range(n - 1):
            a, b, c, d = j * n + i, j * n + i + 1, (j + 1) * n + i, (j + 1) * n + i + 1
            indices += [a, b, d, a, d, c]  # counter-clockwise with lat growing northwards
    indices = np.array(indices, dtype=np.uint32)
    normals = VertexNormalsExtension(indices=indices, positions=positions)
    mask = WaterMaskExtension(data=np.uint8(255))
    with open(path, "wb") as f:
        encode(f, positions, indices, bounds=(west, south, east, north), extensions=[normals, mask])
    print(json.dumps({"positions": positions.tolist(), "indices": indices.tolist(),
                      "bounds": [west, south, east, north]}))


if __name__ == "__main__":
    if sys.argv[1] == "read":
        read(sys.argv[2], *map(float, sys.argv[3:7]), sys.argv[7] == "1")
    else:
        write(sys.argv[2])
