// Checks the checkers on make-sample.mjs's scene before C++ tests rely on them: `npm test`
// (node --test). The render test needs Debian's chromium.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { execFile } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const kHere = path.dirname(fileURLToPath(import.meta.url));
const kDir = fs.mkdtempSync(path.join(os.tmpdir(), 'hemibake-e2e-'));
process.on('exit', () => fs.rmSync(kDir, { recursive: true, force: true }));

// Runs `node SCRIPT ARGS...` here; resolves to {code, stdout, stderr} whatever the exit status.
function run(script, ...args) {
  return new Promise((resolve) => {
    execFile(process.execPath, [path.join(kHere, script), ...args], { timeout: 120_000 },
      (error, stdout, stderr) => resolve({ code: error ? error.code ?? 1 : 0, stdout, stderr }));
  });
}

async function sample(name, ...flags) {
  const file = path.join(kDir, name);
  const r = await run('make-sample.mjs', file, ...flags);
  assert.equal(r.code, 0, r.stderr);
  return file;
}

test('validate passes the Draco sample and its plain twin', async () => {
  for (const file of [await sample('draco.glb'), await sample('plain.glb', '--plain')]) {
    const r = await run('validate.mjs', file);
    assert.equal(r.code, 0, r.stdout + r.stderr);
    assert.match(r.stdout, /^plain: 0 errors, 0 warnings/m);
  }
});

test('validate fails COLOR_0 above 1 inside Draco data with ACCESSOR_NON_CLAMPED', async () => {
  const r = await run('validate.mjs', await sample('unclamped.glb', '--unclamped-color'));
  assert.equal(r.code, 1, r.stdout + r.stderr);
  assert.match(r.stdout, /^original: 0 errors/m); // the validator cannot see inside Draco
  assert.match(r.stdout, /error ACCESSOR_NON_CLAMPED at \/meshes\/0\/primitives\/0\/attributes\/COLOR_0/);
});

test('decode gets back the sample geometry with attributes kept per vertex', async () => {
  const out = path.join(kDir, 'draco.json');
  const r = await run('decode.mjs', await sample('draco2.glb'), out);
  assert.equal(r.code, 0, r.stderr);
  const json = JSON.parse(fs.readFileSync(out, 'utf8'));
  assert.deepEqual(json.extensionsRequired, ['KHR_draco_mesh_compression']);
  assert.deepEqual(json.primitives.map((p) => [p.meshName, p.nodes, p.vertexCount, p.triangleCount]),
    [['floor', ['floor'], 81, 128], ['box', ['box'], 24, 12]]);
  for (const p of json.primitives) {
    const { POSITION, COLOR_0, _RADIOSITY, TEXCOORD_0 } = p.attributes;
    assert.equal(POSITION.array.length, 3 * p.vertexCount);
    assert.equal(TEXCOORD_0.array.length, 2 * p.vertexCount);
    assert.equal(p.indices.length, 3 * p.triangleCount);
    assert.ok(p.indices.every((i) => i < p.vertexCount));
    assert.ok(COLOR_0.array.every((c) => c >= 0 && c <= 1));
    // Draco reorders vertices; the sample's radiosity is 1.5 x its colour at every vertex, so this
    // holds only if the decoder kept the attributes together (tolerance: 8- and 12-bit quantization).
    COLOR_0.array.forEach((c, i) => assert.ok(Math.abs(_RADIOSITY.array[i] - 1.5 * c) < 0.01, `vertex ${i / 3 | 0}`));
  }
  // The floor's positions are the 9 x 9 grid over [-2, 2]^2 at y = 0 (14-bit quantization).
  const floor = json.primitives[0].attributes.POSITION.array;
  const grid = new Set();
  for (let i = 0; i < floor.length; i += 3) {
    assert.ok(Math.abs(floor[i + 1]) < 1e-6);
    grid.add(`${Math.round(floor[i] * 2)},${Math.round(floor[i + 2] * 2)}`);
  }
  assert.equal(grid.size, 81);
});

test('decode and validate exit 1 on a Draco stream that is corrupt', async () => {
  const bytes = fs.readFileSync(await sample('corrupt.glb'));
  const binStart = 20 + bytes.readUInt32LE(12) + 8;
  for (let i = binStart; i < bytes.length; i += 3) bytes[i] ^= 0x5a;
  const file = path.join(kDir, 'corrupt.glb');
  fs.writeFileSync(file, bytes);
  assert.equal((await run('decode.mjs', file, path.join(kDir, 'corrupt.json'))).code, 1);
  assert.equal((await run('validate.mjs', file)).code, 1);
  const r = await run('render.mjs', file, path.join(kDir, 'corrupt.png'), '--timeout', '30');
  assert.equal(r.code, 1);
  assert.equal(JSON.parse(r.stdout).loaded, false);
});

test('render draws the coloured sample in Chromium', async () => {
  const png = path.join(kDir, 'draco.png');
  const r = await run('render.mjs', await sample('draco3.glb'), png);
  assert.equal(r.code, 0, r.stdout + r.stderr);
  const stats = JSON.parse(r.stdout);
  assert.equal(stats.loaded, true);
  assert.equal(stats.meshes, 2);
  assert.equal(stats.triangles, 140);
  assert.ok(stats.pixels.nonBackground > 0.15 && stats.pixels.nonBackground < 0.5, JSON.stringify(stats));
  assert.ok(stats.pixels.distinct > 1000, 'vertex colours are interpolated'); // flat colour would give a handful
  assert.ok(stats.pixels.stddev > 10);
  assert.equal(fs.readFileSync(png).subarray(1, 4).toString(), 'PNG');
});
