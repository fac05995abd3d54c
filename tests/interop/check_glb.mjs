// Reads an isostream .glb with readers that share no code with ours, and compares it with the
// PLY of the same extraction: Khronos's glTF validator (the document), and glTF-Transform with
// Google's Draco decoder (draco3dgltf, the WebAssembly build three.js loads) for the mesh.
// Usage: node check_glb.mjs FILE.glb FILE.ply TOLERANCE
// TOLERANCE: the largest difference allowed between a decoded coordinate and the PLY's (world
// units; Draco quantizes positions). Exits 1 with the first difference found.
import fs from 'node:fs';
import validator from 'gltf-validator';
import { NodeIO } from '@gltf-transform/core';
import { KHRDracoMeshCompression } from '@gltf-transform/extensions';
import draco3d from 'draco3dgltf';

function fail(why) {
  console.error(`check_glb: ${why}`);
  process.exit(1);
}

// Exactly the binary PLY isostream writes (shared/ply_io.cpp): float x y z nx ny nz per vertex,
// faces as a uchar-counted uint list of 3 and a uchar surface.
function readPly(path) {
  const bytes = fs.readFileSync(path);
  const end = bytes.indexOf('end_header\n');
  if (end < 0) fail(`${path}: no PLY header`);
  const header = bytes.subarray(0, end).toString('latin1').split('\n');
  const expected = ['format binary_little_endian 1.0', 'property float x', 'property float y',
    'property float z', 'property float nx', 'property float ny', 'property float nz',
    'property list uchar uint vertex_indices', 'property uchar surface'];
  for (const line of expected)
    if (!header.includes(line)) fail(`${path}: header lacks "${line}"`);
  const count = (name) => Number(header.find((l) => l.startsWith(`element ${name} `)).split(' ')[2]);
  const vertices = count('vertex'), faces = count('face');
  const body = end + 'end_header\n'.length;
  // Small files share Node's buffer pool: the view must stop at the file's end.
  const view = new DataView(bytes.buffer, bytes.byteOffset + body, bytes.length - body);
  const position = new Float32Array(3 * vertices), normal = new Float32Array(3 * vertices);
  let at = 0;
  for (let v = 0; v < vertices; ++v) {
    for (let a = 0; a < 3; ++a, at += 4) position[3 * v + a] = view.getFloat32(at, true);
    for (let a = 0; a < 3; ++a, at += 4) normal[3 * v + a] = view.getFloat32(at, true);
  }
  const index = new Uint32Array(3 * faces), surface = new Uint8Array(faces);
  for (let f = 0; f < faces; ++f) {
    if (view.getUint8(at) !== 3) fail(`${path}: face ${f} is not a triangle`);
    at += 1;
    for (let c = 0; c < 3; ++c, at += 4) index[3 * f + c] = view.getUint32(at, true);
    surface[f] = view.getUint8(at++);
  }
  if (at !== view.byteLength) fail(`${path}: ${view.byteLength - at} bytes after the faces`);
  return { position, normal, index, surface, faces };
}

// The GLB's JSON chunk, as written.
function glbJson(bytes) {
  const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.length);
  if (view.getUint32(0, true) !== 0x46546c67 || view.getUint32(16, true) !== 0x4e4f534a)
    fail('not a GLB with a JSON chunk first');
  return JSON.parse(Buffer.from(bytes.buffer, bytes.byteOffset + 20, view.getUint32(12, true)));
}

const [glbPath, plyPath, toleranceText] = process.argv.slice(2);
const tolerance = Number(toleranceText);
if (!(tolerance > 0)) fail('usage: check_glb.mjs FILE.glb FILE.ply TOLERANCE');
const glbBytes = new Uint8Array(fs.readFileSync(glbPath));
const ply = readPly(plyPath);

// The document: no error and no warning. The validator cannot look inside Draco, so it notes
// the extension (and the buffer view only the extension uses) as information.
const report = await validator.validateBytes(glbBytes, { maxIssues: 100 });
if (report.issues.numErrors !== 0 || report.issues.numWarnings !== 0)
  fail(`validator: ${JSON.stringify(report.issues.messages)}`);

const io = new NodeIO().registerExtensions([KHRDracoMeshCompression]).registerDependencies({
  'draco3d.decoder': await draco3d.createDecoderModule(),
});
const doc = await io.readBinary(glbBytes);
const meshes = doc.getRoot().listMeshes();
if (ply.faces === 0) {
  if (meshes.length !== 0) fail(`an empty PLY, but ${meshes.length} meshes in the GLB`);
  console.log('check_glb: empty mesh, valid document');
  process.exit(0);
}
if (meshes.length !== 1 || meshes[0].listPrimitives().length !== 1)
  fail('expected one mesh with one primitive (one draw order across surfaces)');
const prim = meshes[0].listPrimitives()[0];
if (prim.getMode() !== 4) fail(`primitive mode ${prim.getMode()}, not TRIANGLES`);
const attribute = (name) => {
  const a = prim.getAttribute(name);
  if (!a) fail(`no ${name} attribute`);
  return a.getArray();
};
const position = attribute('POSITION'), normal = attribute('NORMAL');
const surfaceOf = attribute('_SURFACE'), color = attribute('COLOR_0');
const index = prim.getIndices().getArray();
if (index.length !== ply.index.length)
  fail(`${index.length / 3} triangles decoded, ${ply.faces} in the PLY`);

// Triangle by triangle in draw order: the same corners (within the quantization), in the same
// rotation, on the same surface.
const surfaceColor = new Map();
for (let t = 0; t < ply.faces; ++t) {
  for (let c = 0; c < 3; ++c) {
    const g = index[3 * t + c], p = ply.index[3 * t + c];
    for (let a = 0; a < 3; ++a) {
      const d = Math.abs(position[3 * g + a] - ply.position[3 * p + a]);
      if (!(d <= tolerance))
        fail(`triangle ${t} corner ${c} axis ${a}: ${position[3 * g + a]} vs ${ply.position[3 * p + a]}`);
    }
    if (surfaceOf[g] !== ply.surface[t])
      fail(`triangle ${t} corner ${c}: surface ${surfaceOf[g]}, the PLY's ${ply.surface[t]}`);
    const n = [0, 1, 2].map((a) => ply.normal[3 * p + a]);
    const m = [0, 1, 2].map((a) => normal[3 * g + a]);
    const len = Math.hypot(...n);
    if (len > 0 && m[0] * n[0] + m[1] * n[1] + m[2] * n[2] < 0.99 * len)
      fail(`triangle ${t} corner ${c}: normal ${m} vs ${n}`);
    const rgba = Array.from(color.subarray(4 * g, 4 * g + 4)).join(',');
    const seen = surfaceColor.get(surfaceOf[g]);
    if (seen === undefined) surfaceColor.set(surfaceOf[g], rgba);
    else if (seen !== rgba) fail(`surface ${surfaceOf[g]} has colours ${seen} and ${rgba}`);
  }
}
if (new Set(surfaceColor.values()).size !== surfaceColor.size)
  fail(`surfaces share a colour: ${JSON.stringify([...surfaceColor])}`);

// POSITION's min and max as written must be the decoded bounds (the spec requires them, and
// viewers frame the model by them).
const json = glbJson(glbBytes);
const accessor = json.accessors[json.meshes[0].primitives[0].attributes.POSITION];
for (let a = 0; a < 3; ++a) {
  let lo = Infinity, hi = -Infinity;
  for (let v = a; v < position.length; v += 3) lo = Math.min(lo, position[v]), hi = Math.max(hi, position[v]);
  if (Math.fround(accessor.min[a]) !== lo || Math.fround(accessor.max[a]) !== hi)
    fail(`POSITION bounds on axis ${a}: [${accessor.min[a]}, ${accessor.max[a]}], decoded [${lo}, ${hi}]`);
}
console.log(`check_glb: ${ply.faces} triangles, ${surfaceColor.size} surface(s), ` +
  `${position.length / 3} vertices, ${index.BYTES_PER_ELEMENT * 8}-bit indices: as the PLY`);
