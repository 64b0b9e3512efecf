// Times @mapbox/martini on a raw little-endian f32 grid: node martini-bench.mjs GRID SIDE ERROR RUNS DUMP
// Prints JSON; the Martini object (index tables for the grid size) is built once, outside the
// timed part, as its README recommends; createTile + getMesh are timed together.
import fs from 'node:fs';
import Martini from '@mapbox/martini';

const [gridPath, sideArg, errorArg, runsArg, dumpPath] = process.argv.slice(2);
const side = Number(sideArg), maxError = Number(errorArg), runs = Number(runsArg);
const buf = fs.readFileSync(gridPath);
const terrain = new Float32Array(buf.buffer, buf.byteOffset, side * side);
const martini = new Martini(side);
// Warm up the JIT the same number of times as we measure.
for (let i = 0; i < runs; i++) martini.createTile(terrain).getMesh(maxError);
const times = [];
let mesh;
for (let i = 0; i < runs; i++) {
  const t = process.hrtime.bigint();
  mesh = martini.createTile(terrain).getMesh(maxError);
  times.push(Number(process.hrtime.bigint() - t) / 1e6);
}
times.sort((a, b) => a - b);
fs.writeFileSync(dumpPath, JSON.stringify({vertices: Array.from(mesh.vertices), triangles: Array.from(mesh.triangles)}));
console.log(JSON.stringify({vertices: mesh.vertices.length / 2, triangles: mesh.triangles.length / 3, build_ms: times[Math.floor(times.length / 2)]}));
