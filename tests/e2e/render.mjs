// render.mjs IN.glb OUT.png [--camera x,y,z] [--target x,y,z] [--size WxH] [--timeout SECONDS]
//
// Renders a GLB the way a web viewer would: three.js's GLTFLoader and DRACOLoader in headless
// Chromium (Debian's, driven by playwright-core; WebGL on SwiftShader, no GPU needed). A loopback
// HTTP server on 127.0.0.1 (a free port) serves the page, the GLB and three.js's module files.
// Without --camera the view looks at the bounding box's centre from the +z side (raised by 15
// degrees) from the nearest distance at which the whole box fits the image (5% margin), with a
// 45-degree vertical field of view; --target defaults to that centre.
//
// Writes a screenshot to OUT.png and prints one line of JSON to stdout:
//   {"loaded": true, "meshes": n, "triangles": n,
//    "pixels": {"mean": [r, g, b], "stddev": x, "distinct": n, "nonBackground": fraction}, ...}
// where the pixel statistics cover the pixels the model covers (8-bit sRGB as displayed; see
// render-page.mjs). On failure it prints {"loaded": false, "error": "..."}, the error and the page's
// console errors to stderr, and exits 1; bad usage exits 2. Everything (browser, server, temporary
// profile) is stopped or removed before exit, and the whole run is bounded by --timeout
// (default 60 s). HEMIBAKE_CHROMIUM overrides the browser (default /usr/bin/chromium).
import fs from 'node:fs';
import http from 'node:http';
import os from 'node:os';
import path from 'node:path';
import { createRequire } from 'node:module';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const kScript = 'render';
const kUsage = 'usage: node render.mjs IN.glb OUT.png [--camera x,y,z] [--target x,y,z] [--size WxH] [--timeout SECONDS]';
const kHere = path.dirname(fileURLToPath(import.meta.url));
const kThreeRoot = path.resolve(path.dirname(createRequire(import.meta.url).resolve('three')), '..');
const kBackground = '#303036';
const kChromiumFlags = [
  '--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking',
  '--disable-component-update', '--disable-sync', '--no-first-run', '--disable-quic',
  // WebGL without a GPU: ANGLE on SwiftShader, which Chromium no longer falls back to by itself.
  '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
];

function usage(message) {
  process.stderr.write(`${kScript}: ${message}\n${kUsage}\n`);
  process.exit(2);
}

function parseArgs(argv) {
  const options = { width: 800, height: 600, timeout: 60 };
  const positional = [];
  const vector = (name, text) => {
    const v = (text ?? '').split(',').map(Number);
    if (v.length !== 3 || !v.every(Number.isFinite)) usage(`${name} needs x,y,z (got ${text})`);
    return v;
  };
  for (let i = 0; i < argv.length; ++i) {
    const a = argv[i];
    if (a === '--camera') options.camera = vector(a, argv[++i]);
    else if (a === '--target') options.target = vector(a, argv[++i]);
    else if (a === '--size') {
      const m = /^(\d+)x(\d+)$/.exec(argv[++i] ?? '');
      if (!m || +m[1] < 1 || +m[2] < 1 || +m[1] > 4096 || +m[2] > 4096) usage('--size needs WxH, each 1..4096');
      [options.width, options.height] = [+m[1], +m[2]];
    } else if (a === '--timeout') {
      options.timeout = Number(argv[++i]);
      if (!(options.timeout > 0)) usage('--timeout needs a positive number of seconds');
    } else if (a.startsWith('--')) usage(`unknown option ${a}`);
    else positional.push(a);
  }
  if (positional.length !== 2) usage('needs IN.glb and OUT.png');
  [options.input, options.output] = positional;
  return options;
}

const kTypes = { '.js': 'text/javascript', '.mjs': 'text/javascript', '.wasm': 'application/wasm' };

// Serves exactly: the page, its script, the model and files under three's build/ and examples/jsm/.
function startServer(html, model) {
  const files = {
    '/': ['text/html; charset=utf-8', Buffer.from(html)],
    '/page.mjs': ['text/javascript', fs.readFileSync(path.join(kHere, 'render-page.mjs'))],
    '/model.glb': ['model/gltf-binary', model],
  };
  const allowed = [path.join(kThreeRoot, 'build') + path.sep, path.join(kThreeRoot, 'examples', 'jsm') + path.sep];
  const server = http.createServer((req, res) => {
    const send = (status, type, body) => {
      res.writeHead(status, { 'Content-Type': type, 'Cache-Control': 'no-store' });
      res.end(body);
    };
    if (req.method !== 'GET') return send(405, 'text/plain', 'method not allowed');
    let url;
    try {
      url = decodeURIComponent(new URL(req.url, 'http://127.0.0.1').pathname);
    } catch {
      return send(400, 'text/plain', 'bad request');
    }
    if (files[url]) return send(200, ...files[url]);
    if (url === '/favicon.ico') return send(204, 'image/x-icon', ''); // keeps a 404 out of the console
    if (url.startsWith('/three/')) {
      const file = path.resolve(kThreeRoot, '.' + url.slice('/three'.length));
      if (allowed.some((dir) => file.startsWith(dir))) {
        fs.readFile(file, (err, body) => {
          if (err) send(404, 'text/plain', 'not found');
          else send(200, kTypes[path.extname(file)] ?? 'application/octet-stream', body);
        });
        return;
      }
    }
    send(404, 'text/plain', 'not found');
  });
  return new Promise((resolve, reject) => {
    server.once('error', reject);
    server.listen(0, '127.0.0.1', () => resolve(server));
  });
}

function page(config) {
  // The import map lets three's addons import 'three' by name, as they are written to.
  return `<!doctype html>
<html><head><meta charset="utf-8"><title>hemibake render</title>
<style>html, body { margin: 0; background: ${kBackground}; overflow: hidden; }
canvas { display: block; }</style>
<script type="importmap">{"imports": {"three": "/three/build/three.module.js",
  "three/addons/": "/three/examples/jsm/"}}</script>
<script>window.__config = ${JSON.stringify(config)};</script>
<script type="module" src="/page.mjs"></script>
</head><body><canvas id="canvas" width="${config.width}" height="${config.height}"></canvas></body></html>`;
}

async function render(options, cleanup) {
  const deadline = Date.now() + options.timeout * 1000;
  const remaining = () => {
    const ms = deadline - Date.now();
    if (ms <= 0) throw new Error(`timed out after ${options.timeout} s`);
    return ms;
  };

  const model = fs.readFileSync(options.input);
  const config = {
    width: options.width, height: options.height, background: kBackground,
    camera: options.camera ?? null, target: options.target ?? null,
  };
  const server = await startServer(page(config), model);
  cleanup.push(() => { server.closeAllConnections(); server.close(); });
  const url = `http://127.0.0.1:${server.address().port}/`;

  const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'hemibake-render-'));
  const removeProfile = () => fs.rmSync(profile, { recursive: true, force: true });
  cleanup.push(removeProfile);
  process.once('exit', removeProfile); // also after the watchdog's exit
  const context = await chromium.launchPersistentContext(profile, {
    executablePath: process.env.HEMIBAKE_CHROMIUM || '/usr/bin/chromium',
    headless: true,
    args: kChromiumFlags,
    viewport: { width: options.width, height: options.height },
    deviceScaleFactor: 1,
    timeout: remaining(),
  });
  // Runs before the profile is removed (cleanup runs in reverse order).
  cleanup.push(() => Promise.race([context.close(), new Promise((resolve) => setTimeout(resolve, 10000))]));

  const tab = context.pages()[0] ?? await context.newPage();
  const pageErrors = [];
  tab.on('pageerror', (e) => pageErrors.push(`page error: ${e.message}`));
  tab.on('console', (m) => { if (m.type() === 'error') pageErrors.push(`console: ${m.text()}`); });
  tab.on('requestfailed', (r) => pageErrors.push(`request failed: ${r.url()} ${r.failure()?.errorText ?? ''}`));
  tab.on('crash', () => pageErrors.push('page crashed'));

  try {
    await tab.goto(url, { waitUntil: 'load', timeout: remaining() });
    await tab.waitForFunction(() => window.__result || window.__error, null, { timeout: remaining(), polling: 100 });
    const error = await tab.evaluate(() => window.__error);
    if (error) throw new Error(error);
    const result = await tab.evaluate(() => window.__result);
    await tab.screenshot({ path: options.output, timeout: remaining() });
    return result;
  } catch (e) {
    e.pageErrors = pageErrors;
    throw e;
  }
}

async function main() {
  const options = parseArgs(process.argv.slice(2));
  const started = Date.now();
  const cleanup = [];
  const runCleanup = async () => {
    while (cleanup.length > 0) {
      try { await cleanup.pop()(); } catch { /* best effort: the rest must still run */ }
    }
  };
  // A last resort if something ignores its timeout: playwright kills the browser on process exit.
  const watchdog = setTimeout(() => {
    process.stdout.write(JSON.stringify({ loaded: false, error: 'watchdog: did not finish in time' }) + '\n');
    process.stderr.write(`${kScript}: did not finish within ${options.timeout + 15} s\n`);
    process.exit(1);
  }, (options.timeout + 15) * 1000);

  let status = 0;
  try {
    const result = await render(options, cleanup);
    result.ms = Date.now() - started;
    process.stdout.write(JSON.stringify(result) + '\n');
  } catch (e) {
    status = 1;
    // Playwright names only the slice of the deadline that was left; name the whole.
    let message = String(e?.message ?? e).split('\n')[0];
    if (e?.name === 'TimeoutError') message = `timed out after ${options.timeout} s in ${message}`;
    process.stdout.write(JSON.stringify({ loaded: false, error: message }) + '\n');
    process.stderr.write(`${kScript}: ${options.input}: ${message}\n`);
    if (e?.message && e.message !== message) process.stderr.write(`${e.message}\n`);
    for (const line of e?.pageErrors ?? []) process.stderr.write(`  ${line}\n`);
  } finally {
    await runCleanup();
    clearTimeout(watchdog);
  }
  process.exit(status);
}

main();
