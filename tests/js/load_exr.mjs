// Load EXR files with three.js's EXRLoader, as a web page would (tests/test_exr.py runs this in Node).
// Usage: node load_exr.mjs float|half FILE...; prints one JSON line per file: the size, the texture's
// type, the header as the loader parsed it, and the pixel values (RGBA, the loader's row order) as numbers.
import { readFileSync } from 'node:fs';
import * as THREE from 'three';
import { EXRLoader } from 'three/addons/loaders/EXRLoader.js';

const [precision, ...files] = process.argv.slice(2);
const type = { float: THREE.FloatType, half: THREE.HalfFloatType }[precision];
if (type === undefined) throw new Error(`precision must be float or half, got ${precision}`);
for (const file of files) {
  const bytes = readFileSync(file);
  const texture = new EXRLoader().setDataType(type).parse(
    bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength));
  const values = type === THREE.FloatType ? Array.from(texture.data)
    : Array.from(texture.data, (bits) => THREE.DataUtils.fromHalfFloat(bits));
  const header = {};
  for (const [key, value] of Object.entries(texture.header)) {
    header[key] = ArrayBuffer.isView(value) ? Array.from(value) : value;
  }
  console.log(JSON.stringify({ file, width: texture.width, height: texture.height,
    float: texture.type === THREE.FloatType, rgba: texture.format === THREE.RGBAFormat, header, values }));
}
