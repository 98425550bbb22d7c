// web-page.mjs SERVER OUT_DIR CASE [--timeout SECONDS]
//
// Browser tests of the page hemibake-server serves at /: the real server binary (SERVER) on a
// free loopback port with a store in a temporary folder, Debian's Chromium driven by
// playwright-core, the page used as a person would (file input, buttons, radio buttons). CASE:
//   bake      upload data/cornell-box.gltf, follow the job to succeeded, check the 3D view's
//             screenshots (lit and coloured: red and green walls; each display toggle changes
//             the image as it should), the plot, the job list and the GLB download;
//   bad-file  a file that is not glTF (dropped on the page) and an out-of-range parameter: the page shows the
//             server's own messages (asked for separately, with node's fetch);
//   cancel    a job that would run for long: its preview appears while it runs, then Cancel
//             ends it (the page and the API both say cancelled);
//   token     a server with bearer tokens: the page asks for one, refuses a wrong one with a
//             clear message, keeps a right one for the session (a reload does not ask again) and
//             follows a bake's events with it (the scene a GLB dropped on the page);
//   keyboard  a bake by keyboard alone on a laptop-sized window (Tab, Enter, the file chooser,
//             arrow keys in the 3D view and the display buttons), then the same page at 4K: no
//             sideways overflow, larger text, a larger 3D view;
//   jobs      17 jobs made through the API: the list's pages are the API's pages, and a job
//             opens from the list by keyboard;
//   failed    a job over the server's time budget (--job-seconds 3): the page shows it failed,
//             with the server's reason;
//   methods   hr and reference jobs (the baselines) bake through the page and show lit.
// Every case also checks that no request left the server's origin and that the page logged no
// error or warning and threw nothing (besides the failed loads the case provokes). Screenshots go
// to OUT_DIR. Exit status 0 when every check passes, 1 otherwise (the failed check on stderr), 2 on
// bad usage. HEMIBAKE_CHROMIUM overrides the browser (default /usr/bin/chromium).
import assert from 'node:assert/strict';
import { spawn } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';
import { createIO } from './gltf-io.mjs';
import { readPng } from './png.mjs';

const kHere = path.dirname(fileURLToPath(import.meta.url));
const kCornell = path.resolve(kHere, '../../data/cornell-box.gltf');
const kUsage = 'usage: node web-page.mjs SERVER OUT_DIR bake|bad-file|cancel|token|keyboard|jobs|failed|methods [--timeout SECONDS]';
const kChromiumFlags = [
  '--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking',
  '--disable-component-update', '--disable-sync', '--no-first-run', '--disable-quic',
  '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
];
const kBackground = [0x30, 0x30, 0x36]; // the 3D view's clear colour

function usage(message) {
  process.stderr.write(`web-page: ${message}\n${kUsage}\n`);
  process.exit(2);
}

// ---------------------------------------------------------------------------------------------
// The server

async function startServer(binary, { tokens = [], extra = [] } = {}) {
  const dir = fs.mkdtempSync(path.join(os.tmpdir(), 'hemibake-web-'));
  const args = ['--listen', '127.0.0.1:0', '--data', path.join(dir, 'store'), '--workers', '1', ...extra];
  if (tokens.length) {
    fs.writeFileSync(path.join(dir, 'tokens'), tokens.join('\n') + '\n');
    args.push('--tokens', path.join(dir, 'tokens'));
  }
  const child = spawn(binary, args, { stdio: ['ignore', 'pipe', 'pipe'] });
  let log = '';
  child.stderr.on('data', (d) => { log += d; });
  const origin = await new Promise((resolve, reject) => {
    let out = '';
    const timer = setTimeout(() => reject(new Error(`the server did not start: ${out}${log}`)), 20000);
    child.stdout.on('data', (d) => {
      out += d;
      const m = /serving (http:\/\/127\.0\.0\.1:\d+)\//.exec(out);
      if (m) {
        clearTimeout(timer);
        resolve(m[1]);
      }
    });
    child.once('exit', (code) => reject(new Error(`the server exited (${code}): ${out}${log}`)));
  });
  child.stdout.resume();
  return {
    origin,
    log: () => log,
    async stop() {
      if (child.exitCode === null) {
        child.kill('SIGTERM');
        await new Promise((resolve) => {
          const timer = setTimeout(() => { child.kill('SIGKILL'); resolve(); }, 10000);
          child.once('exit', () => { clearTimeout(timer); resolve(); });
        });
      }
      fs.rmSync(dir, { recursive: true, force: true });
    },
  };
}

// ---------------------------------------------------------------------------------------------
// The browser, with every request and every console message recorded

async function startBrowser(origin, cleanup, { width = 1600, height = 1000 } = {}) {
  const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'hemibake-web-profile-'));
  cleanup.push(() => fs.rmSync(profile, { recursive: true, force: true }));
  const context = await chromium.launchPersistentContext(profile, {
    executablePath: process.env.HEMIBAKE_CHROMIUM || '/usr/bin/chromium',
    headless: true,
    args: kChromiumFlags,
    viewport: { width, height },
    deviceScaleFactor: 1,
    acceptDownloads: true,
    timeout: 30000,
  });
  cleanup.push(() => Promise.race([context.close(), new Promise((resolve) => setTimeout(resolve, 10000))]));
  const page = context.pages()[0] ?? await context.newPage();
  const record = { requests: [], problems: [], failedLoads: [] };
  // Requests of the page, its workers and its downloads: all must go to the server's origin.
  context.on('request', (r) => record.requests.push(r.url()));
  page.on('console', (m) => {
    if (m.type() !== 'error' && m.type() !== 'warning') return;
    // Chromium reports a 4xx or 5xx answer as a console error; the cases say which they expect.
    // Without a GPU (--disable-gpu) Chromium composites a WebGL canvas by reading its pixels back
    // every frame, and its GPU process says so on the page's console: the machine's doing, not
    // the page's (the page itself never reads pixels).
    if (/GL Driver Message \(OpenGL, Performance, .*\): GPU stall due to ReadPixels/.test(m.text())) return;
    if (/^Failed to load resource: the server responded with a status of (\d+)/.test(m.text())) {
      record.failedLoads.push(`${m.text()} (${m.location()?.url ?? ''})`);
    } else {
      record.problems.push(`console ${m.type()}: ${m.text()}`);
    }
  });
  page.on('pageerror', (e) => record.problems.push(`page error: ${e.message}`));
  page.on('crash', () => record.problems.push('page crashed'));
  page.on('requestfailed', (r) => {
    // Aborted fetches are the page's own doing (a stream or preview of a job it left).
    if (!/ERR_ABORTED/.test(r.failure()?.errorText ?? '')) record.problems.push(`request failed: ${r.url()} ${r.failure()?.errorText}`);
  });
  return { context, page, record };
}

function checkRecord(record, origin, { allowedFailedLoads = [] } = {}) {
  assert.ok(record.requests.length > 10, `only ${record.requests.length} requests were recorded`);
  for (const url of record.requests) {
    const u = new URL(url);
    // blob: URLs carry their creator's origin; data: URLs are in the page itself.
    const where = u.protocol === 'blob:' ? new URL(u.pathname).origin : u.protocol === 'data:' ? origin : u.origin;
    assert.equal(where, origin, `a request left the server's origin: ${url}`);
  }
  assert.deepEqual(record.problems, [], 'the page logged errors or warnings');
  // A preview asked for just before its job ends is answered 409 (the job finished before its
  // worker made one): a race the page cannot avoid and ignores; any case may meet it.
  const allowed = [...allowedFailedLoads, /status of 409 .*\/v1\/jobs\/[0-9a-f]+\/preview\)$/];
  for (const line of record.failedLoads) {
    assert.ok(allowed.some((re) => re.test(line)), `unexpected failed load: ${line}`);
  }
}

// ---------------------------------------------------------------------------------------------
// Pixels

// Statistics of a screenshot: the fraction of pixels that are not the view's background, and
// over those the mean and spread of the colour, the number of distinct colours, and the fractions
// that are clearly red or clearly green.
function pixelStats(png) {
  const { rgba, width, height } = png;
  let covered = 0;
  let red = 0;
  let green = 0;
  const sum = [0, 0, 0];
  const sumSq = [0, 0, 0];
  const distinct = new Set();
  for (let i = 0; i < width * height; ++i) {
    const r = rgba[4 * i];
    const g = rgba[4 * i + 1];
    const b = rgba[4 * i + 2];
    if (Math.abs(r - kBackground[0]) <= 2 && Math.abs(g - kBackground[1]) <= 2 && Math.abs(b - kBackground[2]) <= 2) continue;
    ++covered;
    [r, g, b].forEach((v, c) => { sum[c] += v; sumSq[c] += v * v; });
    distinct.add((r << 16) | (g << 8) | b);
    const [hue, saturation, value] = hsv(r, g, b);
    if ((hue < 20 || hue > 340) && saturation > 0.45 && value > 0.25) ++red;
    if (hue > 75 && hue < 165 && saturation > 0.35 && value > 0.2) ++green;
  }
  const mean = sum.map((s) => (covered ? s / covered : 0));
  const variance = covered ? sumSq.reduce((v, s, c) => v + s / covered - mean[c] * mean[c], 0) / 3 : 0;
  const round = (x) => Math.round(x * 1000) / 1000;
  return {
    covered: round(covered / (width * height)),
    mean: mean.map((m) => Math.round(m)),
    stddev: round(Math.sqrt(Math.max(0, variance))),
    distinct: distinct.size,
    red: round(red / Math.max(1, covered)),
    green: round(green / Math.max(1, covered)),
  };
}

// Hue in degrees, saturation and value in [0, 1].
function hsv(r, g, b) {
  const max = Math.max(r, g, b);
  const min = Math.min(r, g, b);
  const d = max - min;
  let hue = 0;
  if (d > 0) {
    if (max === r) hue = ((g - b) / d + 6) % 6;
    else if (max === g) hue = (b - r) / d + 2;
    else hue = (r - g) / d + 4;
  }
  return [hue * 60, max ? d / max : 0, max / 255];
}

async function shoot(page, selector, file) {
  const bytes = await page.locator(selector).screenshot({ path: file, timeout: 30000 });
  return pixelStats(readPng(bytes));
}

// Waits until the 3D view has drawn what was asked of it (two animation frames).
async function settled(page) {
  await page.evaluate(() => new Promise((resolve) => requestAnimationFrame(() => requestAnimationFrame(resolve))));
}

// ---------------------------------------------------------------------------------------------
// Cases

async function openPage(page, origin) {
  await page.goto(`${origin}/`, { waitUntil: 'load' });
}

async function submitCornell(page, paramsToSet = {}) {
  await page.locator('#scene').setInputFiles(kCornell);
  if (Object.keys(paramsToSet).length) {
    await page.locator('#params-more-box summary').click();
    for (const [name, value] of Object.entries(paramsToSet)) await page.locator(`#param-${name}`).fill(String(value));
  }
  await page.locator('#submit').click();
  await page.waitForFunction(() => /^#\/jobs\/./.test(location.hash), null, { timeout: 30000 });
  return page.evaluate(() => decodeURIComponent(location.hash.slice('#/jobs/'.length)));
}

// Drops a file on the page's drop zone as a drag from the desktop would: a DataTransfer holding a
// File, with dragenter, dragover and drop events.
async function dropFile(page, file) {
  const bytes = fs.readFileSync(file).toString('base64');
  await page.evaluate(([name, data]) => {
    const binary = atob(data);
    const array = Uint8Array.from(binary, (c) => c.charCodeAt(0));
    const transfer = new DataTransfer();
    transfer.items.add(new File([array], name));
    const zone = document.getElementById('drop');
    for (const type of ['dragenter', 'dragover', 'drop']) {
      zone.dispatchEvent(new DragEvent(type, { dataTransfer: transfer, bubbles: true, cancelable: true }));
    }
  }, [path.basename(file), bytes]);
}

async function watchStates(page) {
  // Every value data-job-state takes, in order, as the page sets it.
  await page.evaluate(() => {
    window.__states = [];
    const job = document.getElementById('job');
    new MutationObserver(() => {
      const s = job.getAttribute('data-job-state');
      if (s && window.__states[window.__states.length - 1] !== s) window.__states.push(s);
    }).observe(job, { attributes: true, attributeFilter: ['data-job-state'] });
  });
}

// HEAD over a real connection: the GET's headers, Content-Length included, and no body.
async function checkHead(origin) {
  for (const file of ['/', '/assets/three/examples/jsm/libs/draco/draco_decoder.wasm']) {
    const get = await fetch(`${origin}${file}`, { headers: { 'Accept-Encoding': 'identity' } });
    const body = Buffer.from(await get.arrayBuffer());
    const head = await fetch(`${origin}${file}`, { method: 'HEAD', headers: { 'Accept-Encoding': 'identity' } });
    assert.equal(head.status, 200, `HEAD ${file}`);
    assert.equal(head.headers.get('content-type'), get.headers.get('content-type'), `HEAD ${file}`);
    assert.equal(head.headers.get('etag'), get.headers.get('etag'), `HEAD ${file}`);
    assert.equal(Number(head.headers.get('content-length')), body.length, `HEAD ${file}`);
    assert.equal((await head.arrayBuffer()).byteLength, 0, `HEAD ${file} has a body`);
  }
}

async function bake({ server, page, record, out, log }) {
  await checkHead(server.origin);
  await openPage(page, server.origin);
  await page.locator('#app').waitFor({ state: 'visible' });
  assert.equal(await page.locator('#auth').isVisible(), false, 'no token is configured, yet the page asks for one');
  // The parameters come from the server's table: every query parameter but threads is a field,
  // with the default and the limits the API description gives.
  const doc = await (await fetch(`${server.origin}/openapi.json`)).json();
  const described = doc.paths['/v1/jobs'].post.parameters.filter((p) => p.in === 'query' && p.name !== 'threads');
  for (const p of described) {
    const input = page.locator(`#param-${p.name}`);
    assert.equal(await input.count(), 1, `no field for ${p.name}`);
    if (p.schema.type === 'number' || p.schema.type === 'integer') {
      assert.equal(Number(await input.inputValue()), p.schema.default, `${p.name}'s default`);
      assert.equal(await input.getAttribute('min'), String(p.schema.minimum), `${p.name}'s minimum`);
    }
  }
  await watchStates(page);
  const id = await submitCornell(page);
  log(`job ${id}`);
  await page.locator('#job[data-job-state="succeeded"]').waitFor({ timeout: 120000 });
  const states = await page.evaluate(() => window.__states);
  log(`data-job-state: ${states.join(' -> ')}`);
  assert.equal(states[states.length - 1], 'succeeded');
  assert.ok(states.every((s) => ['queued', 'running', 'succeeded'].includes(s)), `states ${states}`);
  const job = await (await fetch(`${server.origin}/v1/jobs/${id}`)).json();
  assert.equal(job.state, 'succeeded');

  // The result in the 3D view.
  await page.waitForFunction((jobId) => document.getElementById('view').dataset.loaded === jobId, id, { timeout: 60000 });
  await settled(page);
  const baked = await shoot(page, '#view', path.join(out, 'web-bake-baked.png'));
  log(`baked view: ${JSON.stringify(baked)}`);
  assert.ok(baked.covered > 0.3, 'the model covers too little of the view');
  assert.ok(baked.red > 0.08, 'no red wall');
  assert.ok(baked.green > 0.08, 'no green wall');
  assert.ok(baked.distinct > 1000, 'too few distinct colours for smooth light');
  assert.ok(baked.stddev > 15, 'a uniform image');
  const luminance = (baked.mean[0] + baked.mean[1] + baked.mean[2]) / 3;
  assert.ok(luminance > 40 && luminance < 230, `mean level ${luminance}: not lit, or washed out`);

  // The wireframe of the adaptive mesh: dark lines over the same image darken it and add the
  // blends of line and surface colours.
  const level = (s) => s.mean[0] + s.mean[1] + s.mean[2];
  await page.locator('#wireframe').check();
  await settled(page);
  const wire = await shoot(page, '#view', path.join(out, 'web-bake-wireframe.png'));
  log(`wireframe: ${JSON.stringify(wire)}`);
  assert.ok(level(wire) < level(baked) * 0.92 && wire.distinct > baked.distinct * 1.3, 'the mesh lines do not show');
  assert.ok(Math.abs(wire.covered - baked.covered) < 0.02, 'the wireframe changed what the model covers');
  await page.locator('#wireframe').uncheck();

  // Base colour: flat materials, no light, so few colours; red and green walls still.
  await page.locator('input[name="mode"][value="base"]').check();
  await settled(page);
  const base = await shoot(page, '#view', path.join(out, 'web-bake-base.png'));
  log(`base colour: ${JSON.stringify(base)}`);
  assert.ok(base.red > 0.08 && base.green > 0.08, 'the base colours lack the red or green wall');
  assert.ok(base.distinct < baked.distinct / 4, 'the base colour view still varies like the light');

  // Radiosity with exposure: lit like the baked view at 0 EV; two stops up is brighter.
  await page.locator('input[name="mode"][value="radiosity"]').check();
  await settled(page);
  const radiosity = await shoot(page, '#view', path.join(out, 'web-bake-radiosity.png'));
  log(`radiosity: ${JSON.stringify(radiosity)}`);
  assert.ok(radiosity.red > 0.08 && radiosity.green > 0.08 && radiosity.distinct > 1000, 'the radiosity view is not lit and coloured');
  await page.locator('#exposure').fill('2');
  await settled(page);
  const brighter = await shoot(page, '#view', path.join(out, 'web-bake-radiosity-plus2.png'));
  log(`radiosity +2 EV: ${JSON.stringify(brighter)}`);
  assert.ok(level(brighter) > level(radiosity) * 1.15, 'raising the exposure did not brighten the view');

  // The plot has its line (the accent colour) and the facts their numbers.
  const plot = readPng(await page.locator('#plot').screenshot({ path: path.join(out, 'web-bake-plot.png') }));
  let accent = 0;
  for (let i = 0; i < plot.width * plot.height; ++i) {
    const [r, g, b] = plot.rgba.subarray(4 * i, 4 * i + 3);
    if (r > 180 && g > 120 && g < 190 && b < 100) ++accent;
  }
  log(`plot: ${accent} pixels of the line; ${await page.locator('#plot').getAttribute('aria-label')}`);
  assert.ok(accent > 50, 'the convergence plot has no line');
  // Its points are the stream's shooting progress events, read here with node's fetch.
  const stream = await (await fetch(`${server.origin}/v1/jobs/${id}/events`)).text();
  const progress = stream.split('\n\n').filter((e) => /^event: progress$/m.test(e))
    .map((e) => JSON.parse(/^data: (.*)$/m.exec(e)[1]))
    .filter((p) => (p.phase === 'shooting' || p.phase === 'done') && p.unshot_fraction > 0);
  assert.ok(progress.length >= 2, `only ${progress.length} progress events`);
  assert.equal(await page.locator('#plot').getAttribute('data-points'), String(progress.length));
  const last = progress[progress.length - 1];
  assert.match(await page.locator('#plot').getAttribute('aria-label'), new RegExp(`to ${last.unshot_fraction.toExponential(2).replace('+', '\\+')} at`));
  assert.equal(await page.locator('#f-shots').textContent(), job.progress.shots.toLocaleString('en'));
  await page.screenshot({ path: path.join(out, 'web-bake-page.png') });

  // The job list shows it, succeeded.
  await page.locator(`#jobs a[data-job-id="${id}"] .state-succeeded`).waitFor({ timeout: 15000 });

  // The GLB download is the server's result, byte for byte.
  const [download] = await Promise.all([page.waitForEvent('download'), page.locator('#download-result').click()]);
  const file = path.join(out, 'web-bake-download.glb');
  await download.saveAs(file);
  const served = Buffer.from(await (await fetch(`${server.origin}/v1/jobs/${id}/result`)).arrayBuffer());
  assert.ok(fs.readFileSync(file).equals(served), 'the downloaded GLB differs from the result');
  assert.equal(download.suggestedFilename(), `${id}.glb`);
  checkRecord(record, server.origin);
}

async function badFile({ server, page, record, out, log }) {
  await openPage(page, server.origin);
  await page.locator('#app').waitFor({ state: 'visible' });
  // A file that is not glTF: the page shows the server's message for it.
  const bad = path.join(out, 'not-a-scene.gltf');
  fs.writeFileSync(bad, '{"asset": {"version": "2.0"}, "meshes": [{"primitives": [{"attributes": {"POSITION": 7}}]}]}');
  const expected = await (await fetch(`${server.origin}/v1/jobs`, {
    method: 'POST', headers: { 'Content-Type': 'model/gltf+json' }, body: fs.readFileSync(bad),
  })).json();
  log(`server says: ${expected.error}`);
  await dropFile(page, bad);
  await page.locator('#scene-name', { hasText: 'not-a-scene.gltf' }).waitFor();
  await page.locator('#submit').click();
  const box = page.locator('#submit-error');
  await box.filter({ hasText: expected.error }).waitFor({ timeout: 30000 });
  assert.ok((await box.textContent()).includes(expected.error));
  assert.equal(await page.evaluate(() => location.hash), '', 'a refused file opened a job');
  await page.screenshot({ path: path.join(out, 'web-bad-file.png') });

  // An out-of-range parameter: the server's message, next to the form and at the field.
  const refused = await (await fetch(`${server.origin}/v1/jobs?convergence=5`, {
    method: 'POST', headers: { 'Content-Type': 'model/gltf+json' }, body: fs.readFileSync(kCornell),
  })).json();
  log(`server says: ${refused.error}`);
  await page.locator('#scene').setInputFiles(kCornell);
  await page.locator('#param-convergence').fill('5');
  await page.locator('#submit').click();
  await box.filter({ hasText: refused.error }).waitFor({ timeout: 30000 });
  assert.equal(await page.locator('#param-convergence-error').textContent(), refused.error);
  assert.equal(await page.locator('#param-convergence').getAttribute('aria-invalid'), 'true');
  await page.screenshot({ path: path.join(out, 'web-bad-parameter.png') });
  checkRecord(record, server.origin, { allowedFailedLoads: [/status of 422 .*\/v1\/jobs/, /status of 400 .*\/v1\/jobs/] });
}

async function cancel({ server, page, record, out, log }) {
  await openPage(page, server.origin);
  await page.locator('#app').waitFor({ state: 'visible' });
  await watchStates(page);
  // A job of about two minutes: a convergence of 1e-30 with finer hemicubes and every shot
  // projected anew (no replays), about 0.1 s a shot.
  const id = await submitCornell(page, { convergence: '1e-30', resolution: 600, shot_cache_mb: 0 });
  log(`job ${id}`);
  await page.locator('#job[data-job-state="running"]').waitFor({ timeout: 60000 });
  // A preview appears while it runs, and is lit.
  await page.locator('#view-caption', { hasText: /^Preview after/ }).waitFor({ timeout: 60000 });
  await settled(page);
  const preview = await shoot(page, '#view', path.join(out, 'web-cancel-preview.png'));
  log(`preview: ${JSON.stringify(preview)}; ${await page.locator('#view-caption').textContent()}`);
  assert.ok(preview.covered > 0.3 && preview.red > 0.08 && preview.green > 0.08, 'the preview is not lit and coloured');
  // The preview is refreshed: a later one, after more shots, replaces it within a few seconds.
  const firstCaption = await page.locator('#view-caption').textContent();
  await page.waitForFunction((caption) => {
    const now = document.getElementById('view-caption').textContent;
    return now.startsWith('Preview after') && now !== caption;
  }, firstCaption, { timeout: 20000 });
  log(`a later preview: ${await page.locator('#view-caption').textContent()}`);
  const shots = Number((await page.locator('#f-shots').textContent()).replace(/,/g, ''));
  assert.ok(shots > 0, 'no shots shown while running');
  assert.equal(await page.locator('#f-phase').textContent(), 'shooting');
  const eta = await page.locator('#f-eta').textContent();
  log(`while running: ${shots} shots, time left ${eta}, unshot ${await page.locator('#f-unshot').textContent()}`);
  assert.match(eta, /^(\d.* s|\d+ min \d+ s|\d+ h \d+ min|unknown)$/, 'no time left shown');
  await page.locator('#cancel').click();
  await page.locator('#job[data-job-state="cancelled"]').waitFor({ timeout: 30000 });
  const job = await (await fetch(`${server.origin}/v1/jobs/${id}`)).json();
  assert.equal(job.state, 'cancelled');
  assert.ok(await page.locator('#cancel').isDisabled(), 'Cancel stays enabled after the job ended');
  // The worker stops: no progress event after the cancellation, and the server's state stays.
  await new Promise((resolve) => setTimeout(resolve, 1500));
  assert.equal(await page.locator('#f-eta').textContent(), '–', 'a cancelled job still shows a time left');
  assert.equal((await (await fetch(`${server.origin}/v1/jobs/${id}`)).json()).state, 'cancelled');
  const states = await page.evaluate(() => window.__states);
  log(`data-job-state: ${states.join(' -> ')}`);
  assert.deepEqual(states.slice(-2), ['running', 'cancelled']);
  await page.locator(`#jobs a[data-job-id="${id}"] .state-cancelled`).waitFor({ timeout: 15000 });
  await page.screenshot({ path: path.join(out, 'web-cancel-page.png') });
  checkRecord(record, server.origin);
}

async function tokenCase({ server, page, record, out, log }) {
  await openPage(page, server.origin);
  const auth = page.locator('#auth');
  await auth.waitFor({ state: 'visible', timeout: 30000 });
  assert.equal(await page.locator('#app').isVisible(), false, 'the app shows without a token');
  const first = await page.locator('#auth-message').textContent();
  log(`without a token: ${first}`);
  assert.match(first, /a bearer token is required/);
  await page.screenshot({ path: path.join(out, 'web-token-asked.png') });

  await page.locator('#auth-token').fill('wrong-token');
  await page.keyboard.press('Enter');
  await page.locator('#auth-message', { hasText: 'the bearer token is not valid' }).waitFor({ timeout: 15000 });
  log(`a wrong token: ${await page.locator('#auth-message').textContent()}`);
  assert.equal(await page.locator('#app').isVisible(), false);
  assert.equal(await page.evaluate(() => sessionStorage.getItem('hemibake-token')), null, 'a refused token was kept');

  await page.locator('#auth-token').fill('s3cret-token');
  await page.keyboard.press('Enter');
  await page.locator('#app').waitFor({ state: 'visible', timeout: 15000 });
  assert.equal(await page.evaluate(() => sessionStorage.getItem('hemibake-token')), 's3cret-token');

  // Kept for the session: a reload goes straight to the page.
  await page.reload({ waitUntil: 'load' });
  await page.locator('#app').waitFor({ state: 'visible', timeout: 15000 });
  assert.equal(await auth.isVisible(), false, 'a reload asked for the token again');

  // A bake followed through its event stream, which needs the token too.
  const sent = [];
  page.on('request', (r) => { if (new URL(r.url()).pathname.startsWith('/v1/')) sent.push([r.url(), r.headers().authorization]); });
  // The scene as a GLB this time (written by gltf-transform), dropped on the drop zone.
  const glb = path.join(out, 'cornell-box.glb');
  const io = await createIO();
  await io.write(glb, await io.read(kCornell));
  assert.equal(fs.readFileSync(glb).toString('latin1', 0, 4), 'glTF');
  await dropFile(page, glb);
  await page.locator('#scene-name', { hasText: 'cornell-box.glb' }).waitFor();
  await page.locator('#submit').click();
  await page.waitForFunction(() => /^#\/jobs\/./.test(location.hash), null, { timeout: 30000 });
  const id = await page.evaluate(() => decodeURIComponent(location.hash.slice('#/jobs/'.length)));
  await page.locator('#job[data-job-state="succeeded"]').waitFor({ timeout: 120000 });
  await page.waitForFunction((jobId) => document.getElementById('view').dataset.loaded === jobId, id, { timeout: 60000 });
  await settled(page);
  const view = await shoot(page, '#view', path.join(out, 'web-token-result.png'));
  const job = await (await fetch(`${server.origin}/v1/jobs/${id}`, { headers: { Authorization: 'Bearer s3cret-token' } })).json();
  assert.equal(job.scene_bytes, fs.statSync(glb).size, 'the server did not get the GLB');
  log(`result: ${JSON.stringify(view)}`);
  assert.ok(view.red > 0.08 && view.green > 0.08);
  assert.ok(sent.some(([url]) => url.endsWith(`/v1/jobs/${id}/events`)), 'the page did not read the event stream');
  for (const [url, header] of sent) assert.equal(header, 'Bearer s3cret-token', `${url} went without the token`);
  // The server still refuses the API without the token; the page itself needs none.
  assert.equal((await fetch(`${server.origin}/v1/jobs`)).status, 401);
  assert.equal((await fetch(`${server.origin}/v1/jobs/${id}/events`)).status, 401);
  assert.equal((await fetch(`${server.origin}/`)).status, 200);

  // Forgetting the token asks again.
  await page.locator('#sign-out').click();
  await auth.waitFor({ state: 'visible', timeout: 15000 });
  checkRecord(record, server.origin, { allowedFailedLoads: [/status of 401 /] });
}

// The page by keyboard alone on a laptop screen (1366 x 768), then on a 4K screen: nothing runs
// off the side, text grows with the screen, the 3D view takes the room it is given.
async function keyboard({ server, page, record, out, log }) {
  await page.setViewportSize({ width: 1366, height: 768 });
  await openPage(page, server.origin);
  await page.locator('#app').waitFor({ state: 'visible' });
  // Tab from the top of the page to the file input; Space opens the file chooser. On a loaded
  // machine (the tests two at a time) Space once opened no chooser within 30 s: the page is
  // tabbed to the input again and Space pressed again, three times at most.
  const focusedId = () => page.evaluate(() => document.activeElement?.id ?? '');
  let chooser = null;
  for (let attempt = 0; attempt < 3 && !chooser; ++attempt) {
    let steps = 0;
    while ((await focusedId()) !== 'scene') {
      await page.keyboard.press('Tab');
      assert.ok(++steps < 10, 'the file input is not reached by Tab');
    }
    const drop = await page.evaluate(() => getComputedStyle(document.getElementById('drop')).outlineStyle);
    assert.notEqual(drop, 'none', 'the focused file input shows no focus ring');
    [chooser] = await Promise.all([
      page.waitForEvent('filechooser', { timeout: 15000 }).catch(() => null),
      page.keyboard.press('Space'),
    ]);
    if (!chooser) log('Space on the focused file input opened no file chooser within 15 s; again');
  }
  assert.ok(chooser, 'Space on the focused file input opened no file chooser (3 tries)');
  await chooser.setFiles(kCornell);
  await page.locator('#scene-name', { hasText: 'cornell-box.gltf' }).waitFor();
  // On to the Bake button and press it.
  let steps = 0;
  while ((await focusedId()) !== 'submit') {
    await page.keyboard.press('Tab');
    assert.ok(++steps < 40, 'the Bake button is not reached by Tab');
  }
  await page.keyboard.press('Enter');
  await page.locator('#job[data-job-state="succeeded"]').waitFor({ timeout: 120000 });
  await page.waitForFunction(() => document.getElementById('view').dataset.loaded, null, { timeout: 60000 });
  // The 3D view takes the focus and turns with the arrow keys (OrbitControls pans with them).
  await page.locator('#view').focus();
  await settled(page);
  const before = await page.locator('#view').screenshot();
  for (let i = 0; i < 6; ++i) await page.keyboard.press('ArrowLeft');
  await settled(page);
  const after = await page.locator('#view').screenshot({ path: path.join(out, 'web-keyboard-panned.png') });
  assert.ok(!before.equals(after), 'the arrow keys did not move the view');
  // The display radio buttons change with the arrow keys.
  await page.locator('input[name="mode"][value="baked"]').focus();
  await page.keyboard.press('ArrowRight');
  assert.equal(await page.locator('input[name="mode"]:checked').getAttribute('value'), 'radiosity');
  const overflow = () => page.evaluate(() => document.documentElement.scrollWidth - window.innerWidth);
  assert.ok((await overflow()) <= 0, 'the page runs off the side of a laptop screen');
  await page.screenshot({ path: path.join(out, 'web-laptop.png') });
  const laptop = await page.evaluate(() => ({
    font: parseFloat(getComputedStyle(document.documentElement).fontSize),
    view: document.getElementById('view').getBoundingClientRect().width,
  }));

  await page.setViewportSize({ width: 3840, height: 2160 });
  await settled(page);
  assert.ok((await overflow()) <= 0, 'the page runs off the side of a 4K screen');
  const big = await page.evaluate(() => ({
    font: parseFloat(getComputedStyle(document.documentElement).fontSize),
    view: document.getElementById('view').getBoundingClientRect().width,
  }));
  log(`laptop: ${JSON.stringify(laptop)}, 4K: ${JSON.stringify(big)}`);
  assert.ok(big.font >= laptop.font * 1.3, 'the text does not grow on a 4K screen');
  assert.ok(big.view >= laptop.view * 2, 'the 3D view does not use a 4K screen');
  const view = await shoot(page, '#view', path.join(out, 'web-4k-view.png'));
  assert.ok(view.red > 0.08 && view.green > 0.08, 'the 3D view is not drawn after the resize');
  await page.screenshot({ path: path.join(out, 'web-4k.png') });
  checkRecord(record, server.origin);
}

// The job list pages through GET /v1/jobs as the API does, and a job opens from it.
async function jobs({ server, page, record, out, log }) {
  // 17 small jobs (distinct max_shots, so none is a cached answer of another), through the API.
  const scene = fs.readFileSync(kCornell);
  for (let k = 1; k <= 17; ++k) {
    const r = await fetch(`${server.origin}/v1/jobs?max_shots=${k}`, { method: 'POST', headers: { 'Content-Type': 'model/gltf+json' }, body: scene });
    assert.equal(r.status, 202, await r.text());
  }
  const first = await (await fetch(`${server.origin}/v1/jobs?limit=15`)).json();
  const second = await (await fetch(`${server.origin}${first.next}`)).json();
  assert.equal(first.jobs.length, 15);
  assert.equal(second.jobs.length, 2);
  await openPage(page, server.origin);
  await page.locator('#app').waitFor({ state: 'visible' });
  const shown = () => page.locator('#jobs a').evaluateAll((links) => links.map((a) => a.dataset.jobId));
  await page.locator('#jobs a').first().waitFor();
  assert.deepEqual(await shown(), first.jobs.map((j) => j.id), 'the first page is not the API\'s first page');
  await page.locator('#jobs-older').click();
  await page.waitForFunction((n) => document.querySelectorAll('#jobs a').length === n, second.jobs.length);
  assert.deepEqual(await shown(), second.jobs.map((j) => j.id), 'the second page is not the API\'s second page');
  assert.equal(await page.locator('#jobs-older').isVisible(), false, 'an Older button after the last page');
  await page.screenshot({ path: path.join(out, 'web-jobs-older.png') });
  await page.locator('#jobs-newer').click();
  await page.waitForFunction((n) => document.querySelectorAll('#jobs a').length === n, 15);
  // The oldest job of the first page, opened by keyboard from the list; a refresh of the list in
  // between leaves the focus where it was.
  const id = first.jobs[14].id;
  await page.locator(`#jobs a[data-job-id="${id}"]`).focus();
  const refreshed = page.waitForResponse((r) => r.url().includes('/v1/jobs?limit='));
  await page.locator('#jobs-refresh').evaluate((b) => b.click());
  await refreshed;
  await settled(page);
  assert.equal(await page.evaluate(() => document.activeElement?.dataset.jobId), id, 'a refresh of the list took the focus');
  await page.keyboard.press('Enter');
  await page.waitForFunction((jobId) => location.hash === `#/jobs/${jobId}`, id);
  await page.locator('#job[data-job-state="succeeded"]').waitFor({ timeout: 120000 });
  assert.equal((await (await fetch(`${server.origin}/v1/jobs/${id}`)).json()).state, 'succeeded');
  assert.equal(await page.locator('#job-title').getAttribute('title'), id);
  assert.equal(await page.locator(`#jobs a[data-job-id="${id}"]`).getAttribute('aria-current'), 'true');
  checkRecord(record, server.origin);
}

// A job that fails (the server's time budget is 3 s here): the page says so with the server's reason.
async function failed({ server, page, record, out, log }) {
  await openPage(page, server.origin);
  await page.locator('#app').waitFor({ state: 'visible' });
  await watchStates(page);
  const id = await submitCornell(page, { convergence: '1e-30', resolution: 600, shot_cache_mb: 0 });
  await page.locator('#job[data-job-state="failed"]').waitFor({ timeout: 60000 });
  const job = await (await fetch(`${server.origin}/v1/jobs/${id}`)).json();
  assert.equal(job.state, 'failed');
  log(`server: ${job.error}; page: ${await page.locator('#job-error').textContent()}`);
  assert.ok(job.error.includes('time budget'), job.error);
  assert.equal(await page.locator('#job-error').textContent(), `The bake failed: ${job.error}`);
  assert.ok(await page.locator('#cancel').isDisabled());
  assert.ok(await page.locator('#download-result').isDisabled(), 'a failed job offers a result');
  const states = await page.evaluate(() => window.__states);
  assert.deepEqual(states.slice(-2), ['running', 'failed']);
  await page.locator(`#jobs a[data-job-id="${id}"] .state-failed`).waitFor({ timeout: 15000 });
  await page.screenshot({ path: path.join(out, 'web-failed.png') });
  await page.locator('#plot').screenshot({ path: path.join(out, 'web-failed-plot.png') });
  checkRecord(record, server.origin);
}

// The baselines through the page: hierarchical radiosity and a path-traced reference (few paths)
// bake, and their results show lit and coloured.
async function methods({ server, page, record, out, log }) {
  await openPage(page, server.origin);
  await page.locator('#app').waitFor({ state: 'visible' });
  for (const [method, more] of [['hr', {}], ['reference', { samples: 16 }]]) {
    await page.locator('#scene').setInputFiles(kCornell);
    await page.locator('#param-method').selectOption(method);
    if (more.samples) {
      await page.locator('#params-more-box').evaluate((d) => { d.open = true; });
      await page.locator('#param-samples').fill(String(more.samples));
    }
    const before = await page.evaluate(() => location.hash);
    await page.locator('#submit').click();
    await page.waitForFunction((h) => /^#\/jobs\/./.test(location.hash) && location.hash !== h, before);
    const id = await page.evaluate(() => decodeURIComponent(location.hash.slice('#/jobs/'.length)));
    await page.locator('#job[data-job-state="succeeded"]').waitFor({ timeout: 120000 });
    await page.waitForFunction((jobId) => document.getElementById('view').dataset.loaded === jobId, id, { timeout: 60000 });
    await settled(page);
    const job = await (await fetch(`${server.origin}/v1/jobs/${id}`)).json();
    assert.equal(job.params.method, method);
    const view = await shoot(page, '#view', path.join(out, `web-method-${method}.png`));
    log(`${method}: ${JSON.stringify(view)}`);
    assert.ok(view.covered > 0.3 && view.red > 0.08 && view.green > 0.08 && view.distinct > 500, `the ${method} result is not lit and coloured`);
    await page.locator('#reset-params').click();
  }
  checkRecord(record, server.origin);
}

const kCases = { bake, 'bad-file': badFile, cancel, token: tokenCase, keyboard, jobs, failed, methods };

async function main() {
  const argv = process.argv.slice(2);
  let timeout = 240;
  const positional = [];
  for (let i = 0; i < argv.length; ++i) {
    if (argv[i] === '--timeout') timeout = Number(argv[++i]);
    else if (argv[i].startsWith('--')) usage(`unknown option ${argv[i]}`);
    else positional.push(argv[i]);
  }
  if (positional.length !== 3 || !kCases[positional[2]] || !(timeout > 0)) usage('needs SERVER, OUT_DIR and a known CASE');
  const [binary, out, name] = positional;
  fs.mkdirSync(out, { recursive: true });
  const started = Date.now();
  const log = (line) => process.stdout.write(`[${((Date.now() - started) / 1000).toFixed(1)} s] ${line}\n`);
  const watchdog = setTimeout(() => {
    process.stderr.write(`web-page: ${name} did not finish within ${timeout} s\n`);
    process.exit(1);
  }, timeout * 1000);
  const cleanup = [];
  let server;
  let status = 0;
  try {
    server = await startServer(binary, {
      tokens: name === 'token' ? ['s3cret-token'] : [],
      extra: name === 'failed' ? ['--job-seconds', '3'] : [],
    });
    cleanup.push(() => server.stop());
    log(`server at ${server.origin}`);
    const { page, record } = await startBrowser(server.origin, cleanup);
    page.setDefaultTimeout(30000);
    cleanup.push(async () => {
      if (status !== 0) await page.screenshot({ path: path.join(out, `web-${name}-failure.png`), fullPage: true, timeout: 10000 });
    });
    await kCases[name]({ server, page, record, out, log });
    log(`${record.requests.length} requests, all to ${server.origin}; failed loads: ${record.failedLoads.length}`);
    log('passed');
  } catch (e) {
    status = 1;
    process.stderr.write(`web-page: ${name} failed: ${e.stack ?? e}\n`);
    if (server) process.stderr.write(`server log:\n${server.log()}\n`);
  }
  while (cleanup.length) {
    try { await cleanup.pop()(); } catch { /* the rest must still run */ }
  }
  clearTimeout(watchdog);
  process.exit(status);
}

main();
