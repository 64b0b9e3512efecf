"""Reads a PMTiles archive with the `pmtiles` Python package (an independent client) and
compares every tile with a directory pyramid {z}/{x}/{y}.ext built from the same job.

usage: read_pmtiles.py ARCHIVE DIR EXT LEVEL_OFFSET
Prints one JSON object: header fields, metadata, tiles compared. Exits non-zero on mismatch.
"""

import json
import os
import sys

from pmtiles.reader import MmapSource, Reader, all_tiles

archive, directory, ext, offset = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
with open(archive, "rb") as f:
    src = MmapSource(f)
    reader = Reader(src)
    header = reader.header()
    meta = reader.metadata()
    seen = 0
    for (z, x, y), data in all_tiles(src):
        path = os.path.join(directory, str(z - offset), str(x), f"{y}.{ext}")
        with open(path, "rb") as t:
            if t.read() != bytes(data):
                sys.exit(f"tile {z}/{x}/{y} differs from {path}")
        # Random access by z/x/y, as a map client does it (a sample: each get re-reads the
        # directories).
        if seen % 37 == 0 and reader.get(z, x, y) != bytes(data):
            sys.exit(f"get({z}, {x}, {y}) differs")
        seen += 1
    files = sum(1 for _, _, fs in os.walk(directory) for n in fs if n.endswith("." + ext))
    if seen != files:
        sys.exit(f"archive has {seen} tiles, directory {files}")
    print(json.dumps({
        "tiles": seen,
        "min_zoom": header["min_zoom"],
        "max_zoom": header["max_zoom"],
        "tile_type": header["tile_type"].value,
        "clustered": header["clustered"],
        "leaf_directory_length": header["leaf_directory_length"],
        "addressed": header["addressed_tiles_count"],
        "contents": header["tile_contents_count"],
        "bounds_e7": [header["min_lon_e7"], header["min_lat_e7"], header["max_lon_e7"], header["max_lat_e7"]],
        "metadata": meta,
    }))
