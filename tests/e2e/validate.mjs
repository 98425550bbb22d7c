// validate.mjs IN.glb [--json REPORT.json]
//
// Runs the Khronos glTF-Validator on a GLB twice:
//   original  the file as it is. The validator does not decode Draco, so for a
//             KHR_draco_mesh_compression file only JSON-level checks apply (structure, indices,
//             extension lists, accessor declarations); the compressed data itself is not seen.
//   plain     a copy without Draco: gltf-transform decodes every compressed primitive (draco3dgltf),
//             the KHR_draco_mesh_compression extension is disposed and a plain GLB is written to
//             memory. This checks the decoded vertex data (for example float COLOR_0 outside
//             [0, 1] is the error ACCESSOR_NON_CLAMPED), as gltf-transform wrote it back: accessor
//             min/max, buffer layout and alignment are gltf-transform's, not the original's.
// Prints both reports (counts, then every error and warning with its JSON pointer; repeats of one
// code at one pointer share a line) and a last line `valid` or `INVALID`. Exit status: 0 when the
// plain copy has no errors and no warnings and the original has no errors; 1 otherwise, or when
// the file cannot be read or decoded; 2 on bad usage. --json writes both full validator reports.
import fs from 'node:fs';
import path from 'node:path';
import validator from 'gltf-validator';
import { createIO, fail } from './gltf-io.mjs';

const kScript = 'validate';
const kSeverity = ['error', 'warning', 'info', 'hint'];

const args = process.argv.slice(2);
let input, jsonOut;
for (let i = 0; i < args.length; ++i) {
  if (args[i] === '--json' && i + 1 < args.length) jsonOut = args[++i];
  else if (!args[i].startsWith('--') && input === undefined) input = args[i];
  else fail(kScript, `unexpected argument ${args[i]}; usage: node validate.mjs IN.glb [--json REPORT.json]`, 2);
}
if (!input) fail(kScript, 'usage: node validate.mjs IN.glb [--json REPORT.json]', 2);

async function validate(bytes, uri) {
  return validator.validateBytes(bytes, {
    uri,
    format: 'glb',
    maxIssues: 0, // report every issue
    // A GLB from the baker is self-contained; any external reference is an error of its own.
    externalResourceFunction: (ref) => Promise.reject(new Error(`external resource ${ref}`)),
  });
}

function print(label, report) {
  const { numErrors, numWarnings, numInfos, numHints } = report.issues;
  console.log(`${label}: ${numErrors} errors, ${numWarnings} warnings, ${numInfos} infos, ${numHints} hints`);
  // One line per (severity, code, pointer): a bad attribute repeats the same issue per element.
  const groups = new Map();
  for (const m of report.issues.messages) {
    if (m.severity > 1) continue;
    const key = `${kSeverity[m.severity]} ${m.code} at ${m.pointer ?? '(file)'}`;
    const group = groups.get(key);
    if (group) ++group.count;
    else groups.set(key, { first: m.message, count: 1 });
  }
  for (const [key, { first, count }] of groups) {
    console.log(`  ${key}: ${first}${count > 1 ? ` (and ${count - 1} more like it)` : ''}`);
  }
}

let bytes, original;
try {
  bytes = new Uint8Array(fs.readFileSync(input));
  original = await validate(bytes, path.basename(input));
} catch (e) {
  fail(kScript, `cannot validate ${input}: ${e.message ?? e}`);
}
print('original', original);

let plain;
try {
  const io = await createIO();
  const doc = await io.readBinary(bytes);
  for (const ext of doc.getRoot().listExtensionsUsed()) {
    if (ext.extensionName === 'KHR_draco_mesh_compression') ext.dispose();
  }
  plain = await validate(await io.writeBinary(doc), `${path.basename(input)} (Draco decoded)`);
  print('plain', plain);
} catch (e) {
  console.log(`plain: cannot decode with gltf-transform: ${e.message ?? e}`);
}

if (jsonOut) fs.writeFileSync(jsonOut, JSON.stringify({ original, plain: plain ?? null }, null, 1) + '\n');

const ok = original.issues.numErrors === 0 && plain !== undefined &&
  plain.issues.numErrors === 0 && plain.issues.numWarnings === 0;
console.log(ok ? 'valid' : 'INVALID');
process.exit(ok ? 0 : 1);
