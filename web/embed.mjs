// embed.mjs OUT.cpp [--depfile OUT.d]
//
// Writes a C++ source that holds the web page's files as byte strings, for hemibake-server to
// serve at / and /assets/: the page's own sources (src/) and the three.js files it imports, from
// node_modules at the version package-lock.json pins (run `npm ci` here first; scripts/setup.sh
// does). For each file: its URL path, Content-Type, bytes, a gzip copy when that is smaller, and
// an ETag (a hash of the bytes). Also the page's Content-Security-Policy, which allows its one
// inline script (the import map) by hash. With --depfile it lists the files read, so that the
// build regenerates the source when one of them changes.
import crypto from 'node:crypto';
import fs from 'node:fs';
import path from 'node:path';
import zlib from 'node:zlib';
import { fileURLToPath } from 'node:url';

const kHere = path.dirname(fileURLToPath(import.meta.url));
const kThree = path.join(kHere, 'node_modules', 'three');

// URL path -> file. three's files keep their relative layout, so that their own imports
// ('../utils/BufferGeometryUtils.js', './three.core.js') resolve under /assets/three/.
const kFiles = [
  ['/', 'src/index.html'],
  ['/assets/app.js', 'src/app.js'],
  ['/assets/api.js', 'src/api.js'],
  ['/assets/plot.js', 'src/plot.js'],
  ['/assets/viewer.js', 'src/viewer.js'],
  ['/assets/app.css', 'src/app.css'],
  ['/assets/icon.svg', 'src/icon.svg'],
  ...[
    'LICENSE',
    'build/three.module.js',
    'build/three.core.js',
    'examples/jsm/loaders/GLTFLoader.js',
    'examples/jsm/loaders/DRACOLoader.js',
    'examples/jsm/controls/OrbitControls.js',
    'examples/jsm/utils/BufferGeometryUtils.js',
    'examples/jsm/utils/SkeletonUtils.js',
    'examples/jsm/libs/draco/draco_wasm_wrapper.js',
    'examples/jsm/libs/draco/draco_decoder.wasm',
    'examples/jsm/libs/draco/draco_decoder.js',
  ].map((f) => [`/assets/three/${f}`, path.join('node_modules/three', f)]),
];

const kTypes = {
  '.html': 'text/html; charset=utf-8',
  '.js': 'text/javascript; charset=utf-8',
  '.css': 'text/css; charset=utf-8',
  '.svg': 'image/svg+xml',
  '.wasm': 'application/wasm',
  '': 'text/plain; charset=utf-8', // LICENSE
};

function fail(message) {
  process.stderr.write(`embed: ${message}\n`);
  process.exit(1);
}

// three must be the version the lock file pins: a stale node_modules would embed another one.
function checkThree() {
  const lock = JSON.parse(fs.readFileSync(path.join(kHere, 'package-lock.json'), 'utf8'));
  const wanted = lock.packages?.['node_modules/three']?.version;
  let installed;
  try {
    installed = JSON.parse(fs.readFileSync(path.join(kThree, 'package.json'), 'utf8')).version;
  } catch {
    fail(`three is not installed in ${path.join(kHere, 'node_modules')}: run scripts/setup.sh (or npm ci in web/)`);
  }
  if (installed !== wanted) fail(`web/node_modules has three ${installed}, package-lock.json pins ${wanted}: run npm ci in web/`);
  return installed;
}

// A C++ string literal of `bytes`, cut into lines. Printable ASCII stays as it is; everything else
// is a three-digit octal escape (a hex escape would swallow the hex digits after it).
function literal(bytes) {
  const lines = [];
  let line = '';
  for (const b of bytes) {
    if (b >= 0x20 && b < 0x7f && b !== 0x22 && b !== 0x5c && b !== 0x3f) line += String.fromCharCode(b);
    else line += '\\' + b.toString(8).padStart(3, '0');
    if (line.length >= 120) {
      lines.push(`"${line}"`);
      line = '';
    }
  }
  if (line || lines.length === 0) lines.push(`"${line}"`);
  return lines.join('\n');
}

// The hash source of an inline script for Content-Security-Policy: sha256 of its text, base64.
function scriptHashes(html) {
  const hashes = [];
  for (const m of html.matchAll(/<script\b([^>]*)>([\s\S]*?)<\/script>/g)) {
    if (/\bsrc=/.test(m[1])) continue;
    hashes.push(`'sha256-${crypto.createHash('sha256').update(m[2], 'utf8').digest('base64')}'`);
  }
  return hashes;
}

function main() {
  const args = process.argv.slice(2);
  let out;
  let depfile;
  for (let i = 0; i < args.length; ++i) {
    if (args[i] === '--depfile') depfile = args[++i];
    else if (!out && !args[i].startsWith('--')) out = args[i];
    else fail(`unexpected argument ${args[i]}\nusage: node embed.mjs OUT.cpp [--depfile OUT.d]`);
  }
  if (!out || (depfile === undefined && args.includes('--depfile'))) fail('usage: node embed.mjs OUT.cpp [--depfile OUT.d]');
  const version = checkThree();

  const read = [path.join(kHere, 'package-lock.json'), fileURLToPath(import.meta.url)];
  const entries = [];
  let csp = '';
  for (const [url, file] of kFiles) {
    const full = path.join(kHere, file);
    const bytes = fs.readFileSync(full);
    read.push(full);
    const type = kTypes[path.extname(file)];
    if (!type) fail(`no content type for ${file}`);
    const etag = `"${crypto.createHash('sha256').update(bytes).digest('hex').slice(0, 32)}"`;
    const gz = zlib.gzipSync(bytes, { level: 9 });
    entries.push({ url, type, bytes, gzip: gz.length < bytes.length * 0.9 ? gz : null, etag });
    if (url === '/') {
      // Everything from the server itself: scripts, styles, fetches and the Draco decoder's worker
      // (DRACOLoader starts it from a blob: URL and compiles the decoder's WebAssembly).
      csp = [
        "default-src 'self'",
        `script-src 'self' 'wasm-unsafe-eval' ${scriptHashes(bytes.toString('utf8')).join(' ')}`,
        "worker-src 'self' blob:",
        "img-src 'self' blob: data:",
        "style-src 'self'",
        "connect-src 'self' blob: data:",
        "object-src 'none'",
        "base-uri 'none'",
        "frame-ancestors 'none'",
        "form-action 'none'",
      ].join('; ');
    }
  }

  let cpp = `// Generated by web/embed.mjs from web/src and three ${version}; do not edit.\n`;
  cpp += '#include "web_assets.h"\n\nnamespace hemibake::server::web {\nnamespace {\n\n';
  entries.forEach((e, i) => {
    cpp += `// ${e.url}\nconstexpr char kBody${i}[] =\n${literal(e.bytes)};\n`;
    if (e.gzip) cpp += `constexpr char kGzip${i}[] =\n${literal(e.gzip)};\n`;
    cpp += '\n';
  });
  cpp += '}  // namespace\n\n';
  cpp += `const char* const kThreeVersion = "${version}";\n`;
  cpp += `const char* const kContentSecurityPolicy = ${literal(Buffer.from(csp))};\n\n`;
  cpp += 'const Asset kAssets[] = {\n';
  entries.forEach((e, i) => {
    const gz = e.gzip ? `{kGzip${i}, ${e.gzip.length}}` : '{}';
    cpp += `    {"${e.url}", "${e.type}", {kBody${i}, ${e.bytes.length}}, ${gz}, ${literal(Buffer.from(e.etag))}},\n`;
  });
  cpp += '};\nconst size_t kAssetCount = sizeof(kAssets) / sizeof(kAssets[0]);\n\n}  // namespace hemibake::server::web\n';

  fs.mkdirSync(path.dirname(path.resolve(out)), { recursive: true });
  fs.writeFileSync(out, cpp);
  if (depfile) {
    const escape = (p) => p.replace(/ /g, '\\ ');
    fs.writeFileSync(depfile, `${escape(out)}: ${read.map(escape).join(' \\\n  ')}\n`);
  }
}

main();
