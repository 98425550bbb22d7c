// The page: submit a scene with its parameters, list jobs, follow one job live (its events, the
// convergence plot, previews in 3D while it runs, the result when it succeeds). Everything it
// loads comes from the server that served it; the job parameters, their defaults and limits come
// from the server's /openapi.json (the same table its parser uses).
import { ApiError, json, request, followEvents, kFinal, randomKey, setToken, setUnauthorizedHandler, sleep, token } from './api.js';
import { ConvergencePlot } from './plot.js';

const $ = (id) => document.getElementById(id);

// The parameters shown first; the rest go under "More parameters". `threads` is the server's.
const kMainParams = ['method', 'convergence', 'resolution', 'max_shots', 'feps', 'aeps', 'beps', 'exposure'];
const kHiddenParams = new Set(['threads']);
const kPreviewSeconds = 3;
const kJobsPage = 15;

let viewer = null; // made on first use: WebGL is not needed until a job is shown
let viewerModule = null;
let viewerFailed = ''; // why there is no 3D view
let plot = null;
let params = []; // {name, schema, description, input}
let selectedFile = null;
let started = false;

// ---------------------------------------------------------------------------------------------
// Authentication

setUnauthorizedHandler((e) => showAuth(e.message));

function showAuth(serverMessage) {
  const had = Boolean(token());
  setToken('');
  $('app').hidden = true;
  $('sign-out').hidden = true;
  $('auth').hidden = false;
  $('auth-message').textContent = had
    ? `The server did not accept the token (${serverMessage}). Enter a valid one.`
    : `This server's API needs a bearer token (the server says: ${serverMessage}). Enter yours; the server's administrator gives them out.`;
  $('auth-token').focus();
  stopJob();
}

$('auth-form').addEventListener('submit', async (event) => {
  event.preventDefault();
  const value = $('auth-token').value.trim();
  if (!value) return;
  setToken(value);
  try {
    await request('/v1/jobs?limit=1');
  } catch (e) {
    setToken('');
    $('auth-message').textContent = e instanceof ApiError
      ? `The server did not accept this token (${e.message}).`
      : `The server could not be reached: ${e.message}`;
    $('auth-token').select();
    return;
  }
  $('auth-token').value = '';
  $('auth').hidden = true;
  start();
});

$('sign-out').addEventListener('click', () => {
  setToken('');
  location.hash = '';
  location.reload();
});

// ---------------------------------------------------------------------------------------------
// Start

async function start() {
  try {
    const doc = await json('/openapi.json');
    buildParams(doc);
  } catch (e) {
    if (e instanceof ApiError && e.status === 401) return; // the token prompt is up
    $('server').textContent = `The server could not be reached: ${e.message}`;
    return;
  }
  $('app').hidden = false;
  $('auth').hidden = true;
  $('sign-out').hidden = !token();
  $('server').textContent = token() ? 'Signed in with a token' : '';
  if (!started) {
    started = true;
    window.addEventListener('hashchange', route);
    setInterval(() => { if (jobsPage.length === 1 && !document.hidden) loadJobs(); }, 10000);
  }
  loadJobs();
  route();
}

// ---------------------------------------------------------------------------------------------
// Parameters and submission

function buildParams(doc) {
  const list = doc?.paths?.['/v1/jobs']?.post?.parameters ?? [];
  const main = $('params-main');
  const more = $('params-more');
  main.querySelectorAll('.field').forEach((f) => f.remove());
  more.querySelectorAll('.field').forEach((f) => f.remove());
  params = [];
  const query = list.filter((p) => p.in === 'query' && !kHiddenParams.has(p.name));
  query.sort((a, b) => rank(a.name) - rank(b.name));
  for (const p of query) {
    const field = makeField(p);
    (kMainParams.includes(p.name) ? main : more).append(field.element);
    params.push(field);
  }
}

function rank(name) {
  const i = kMainParams.indexOf(name);
  return i < 0 ? kMainParams.length : i;
}

function makeField(p) {
  const schema = p.schema ?? {};
  const element = document.createElement('div');
  element.className = 'field';
  const id = `param-${p.name}`;
  const label = document.createElement('label');
  label.htmlFor = id;
  label.textContent = p.name;
  let input;
  if (schema.enum) {
    input = document.createElement('select');
    for (const v of schema.enum) input.append(new Option(v, v));
  } else if (schema.type === 'boolean') {
    input = document.createElement('input');
    input.type = 'checkbox';
  } else if (schema.type === 'string') {
    // A colour as R,G,B (the sky): text, checked by the server.
    input = document.createElement('input');
    input.type = 'text';
    input.spellcheck = false;
    if (schema.pattern) input.pattern = schema.pattern;
  } else {
    input = document.createElement('input');
    input.type = 'number';
    input.step = schema.type === 'integer' ? '1' : 'any';
    if (schema.minimum !== undefined) input.min = String(schema.minimum);
    if (schema.maximum !== undefined) input.max = String(schema.maximum);
    input.inputMode = schema.type === 'integer' ? 'numeric' : 'decimal';
  }
  input.id = id;
  input.name = p.name;
  const hint = document.createElement('span');
  hint.className = 'hint';
  hint.id = `${id}-hint`;
  const range = schema.minimum !== undefined
    ? `${schema.minimum} to ${schema.maximum !== undefined ? schema.maximum : '∞'} · ` : '';
  const limits = document.createElement('span');
  limits.textContent = `${range}default ${schema.default}`;
  const about = document.createElement('span');
  about.className = 'about';
  about.textContent = ` · ${p.description ?? ''}`;
  hint.append(limits, about);
  label.title = p.description ?? '';
  const error = document.createElement('span');
  error.className = 'field-error';
  error.id = `${id}-error`;
  input.setAttribute('aria-describedby', `${hint.id} ${error.id}`);
  element.append(label, input, hint, error);
  const field = { name: p.name, schema, input, error, element };
  setDefault(field);
  input.addEventListener('input', () => clearFieldError(field));
  return field;
}

function setDefault(field) {
  const d = field.schema.default;
  if (field.input.type === 'checkbox') field.input.checked = Boolean(d);
  else field.input.value = d === undefined ? '' : String(d);
  clearFieldError(field);
}

function clearFieldError(field) {
  field.error.textContent = '';
  field.input.removeAttribute('aria-invalid');
}

function markField(name, message) {
  const field = params.find((f) => f.name === name);
  if (!field) return false;
  if (!field.element.closest('#params-main')) $('params-more-box').open = true;
  field.error.textContent = message;
  field.input.setAttribute('aria-invalid', 'true');
  field.input.focus();
  return true;
}

// The parameters that differ from their defaults, as the query string's values; a value the
// browser cannot read as a number is reported here (the server never sees it).
function changedParams() {
  const values = new URLSearchParams();
  for (const f of params) {
    if (f.input.type === 'checkbox') {
      if (f.input.checked !== Boolean(f.schema.default)) values.set(f.name, String(f.input.checked));
    } else if (f.input.type === 'number') {
      if (f.input.validity.badInput) throw new FieldError(f.name, `${f.name} must be a number`);
      const text = f.input.value.trim();
      if (text !== '' && Number(text) !== Number(f.schema.default)) values.set(f.name, text);
    } else if (f.input.value !== String(f.schema.default)) {
      values.set(f.name, f.input.value);
    }
  }
  return values;
}

class FieldError extends Error {
  constructor(name, message) {
    super(message);
    this.field = name;
  }
}

$('reset-params').addEventListener('click', () => params.forEach(setDefault));

function chooseFile(file) {
  selectedFile = file ?? null;
  $('scene-name').textContent = file ? `${file.name} (${formatBytes(file.size)})` : '';
  $('submit-error').textContent = '';
}

$('scene').addEventListener('change', () => chooseFile($('scene').files[0]));
const drop = $('drop');
drop.addEventListener('dragover', (e) => {
  e.preventDefault();
  e.dataTransfer.dropEffect = 'copy';
  drop.classList.add('over');
});
drop.addEventListener('dragleave', () => drop.classList.remove('over'));
drop.addEventListener('drop', (e) => {
  e.preventDefault();
  drop.classList.remove('over');
  const file = e.dataTransfer.files[0];
  if (file) chooseFile(file);
});
// A file dropped beside the drop zone must not replace the page.
window.addEventListener('dragover', (e) => e.preventDefault());
window.addEventListener('drop', (e) => e.preventDefault());

$('submit-form').addEventListener('submit', async (event) => {
  event.preventDefault();
  const errorBox = $('submit-error');
  const note = $('submit-note');
  errorBox.textContent = '';
  note.textContent = '';
  params.forEach(clearFieldError);
  if (!selectedFile) {
    errorBox.textContent = 'Choose a scene file (.glb or .gltf) first.';
    $('scene').focus();
    return;
  }
  let values;
  try {
    values = changedParams();
  } catch (e) {
    errorBox.textContent = e.message;
    markField(e.field, e.message);
    return;
  }
  const button = $('submit');
  button.disabled = true;
  note.textContent = `Uploading ${selectedFile.name} (${formatBytes(selectedFile.size)})…`;
  try {
    const head = new Uint8Array(await selectedFile.slice(0, 4).arrayBuffer());
    const binary = head.length === 4 && String.fromCharCode(...head) === 'glTF';
    const query = values.toString();
    const response = await request(`/v1/jobs${query ? `?${query}` : ''}`, {
      method: 'POST',
      headers: { 'Content-Type': binary ? 'model/gltf-binary' : 'model/gltf+json', 'Idempotency-Key': randomKey() },
      body: selectedFile,
    });
    const job = await response.json();
    const notes = [];
    if (response.headers.get('X-Hemibake-Cache') === 'hit') notes.push('The same scene and parameters were baked before: this is that job.');
    for (const w of warningsOf(response.headers.get('Warning'))) notes.push(`Warning: ${w}`);
    note.textContent = notes.join('\n');
    location.hash = `#/jobs/${job.id}`;
    loadJobs();
  } catch (e) {
    note.textContent = '';
    if (e instanceof ApiError) {
      const what = e.status === 422 ? 'The server cannot bake this file' : `The server refused the job (${e.status})`;
      errorBox.textContent = `${what}: ${e.message}`;
      const name = /^(?:params\.)?([a-z_]+) /.exec(e.message)?.[1];
      if (e.status === 400 && name) markField(name, e.message);
    } else {
      errorBox.textContent = `The upload failed: ${e.message}`;
    }
  } finally {
    button.disabled = false;
  }
});

// The texts of `199 hemibake "..."` warning values (several may be joined by commas).
function warningsOf(header) {
  if (!header) return [];
  const out = [];
  for (const m of header.matchAll(/"((?:[^"\\]|\\.)*)"/g)) out.push(m[1].replace(/\\(.)/g, '$1'));
  return out;
}

// ---------------------------------------------------------------------------------------------
// Job list (GET /v1/jobs, paged with its `next` cursor)

const jobsPage = [null]; // the `after` cursors of the pages seen; the last is the one shown
let nextCursor = null;
let shownJob = null;

async function loadJobs() {
  const after = jobsPage[jobsPage.length - 1];
  try {
    const body = await json(`/v1/jobs?limit=${kJobsPage}${after ? `&after=${encodeURIComponent(after)}` : ''}`);
    $('jobs-error').textContent = '';
    renderJobs(body.jobs ?? []);
    nextCursor = body.next ? new URL(body.next, location.origin).searchParams.get('after') : null;
  } catch (e) {
    if (e instanceof ApiError && e.status === 400 && after) {
      // The cursor's job expired: start again from the newest.
      jobsPage.length = 1;
      return loadJobs();
    }
    if (!(e instanceof ApiError && e.status === 401)) $('jobs-error').textContent = `The job list could not be read: ${e.message}`;
  }
  $('jobs-older').hidden = !nextCursor;
  $('jobs-newer').hidden = jobsPage.length === 1;
}

function renderJobs(jobs) {
  const list = $('jobs');
  // A refresh must not take the keyboard focus away from the job it was on.
  const focused = list.contains(document.activeElement) ? document.activeElement.dataset.jobId : null;
  list.replaceChildren(...jobs.map((job) => {
    const item = document.createElement('li');
    const link = document.createElement('a');
    link.href = `#/jobs/${encodeURIComponent(job.id)}`;
    link.dataset.jobId = job.id;
    if (job.id === shownJob) link.setAttribute('aria-current', 'true');
    const state = document.createElement('span');
    state.className = `state state-${job.state}`;
    state.textContent = job.state;
    const id = document.createElement('span');
    id.className = 'id';
    id.textContent = job.id.slice(0, 8);
    const time = document.createElement('time');
    const created = new Date(job.created * 1000);
    time.dateTime = created.toISOString();
    time.textContent = formatWhen(created);
    const detail = document.createElement('span');
    detail.className = 'detail';
    detail.textContent = `${job.params?.method ?? ''} · ${formatBytes(job.scene_bytes)}${job.seconds !== undefined ? ` · ${formatSeconds(job.seconds)}` : ''}`;
    link.append(state, id, time, detail);
    item.append(link);
    return item;
  }));
  if (focused) list.querySelector(`a[data-job-id="${CSS.escape(focused)}"]`)?.focus();
  $('jobs-empty').hidden = jobs.length > 0 || jobsPage.length > 1;
}

$('jobs-refresh').addEventListener('click', loadJobs);
$('jobs-older').addEventListener('click', () => {
  if (!nextCursor) return;
  jobsPage.push(nextCursor);
  loadJobs();
});
$('jobs-newer').addEventListener('click', () => {
  jobsPage.length = 1;
  loadJobs();
});

// ---------------------------------------------------------------------------------------------
// One job, live

let job = null; // {id, state, controller, progress, result, preview}

function route() {
  const m = /^#\/jobs\/([^/]+)$/.exec(location.hash);
  const id = m ? decodeURIComponent(m[1]) : null;
  if (id !== shownJob) openJob(id);
}

function stopJob() {
  job?.controller.abort();
  job = null;
}

async function openJob(id) {
  stopJob();
  shownJob = id;
  document.querySelectorAll('#jobs a').forEach((a) => {
    if (a.dataset.jobId === id) a.setAttribute('aria-current', 'true');
    else a.removeAttribute('aria-current');
  });
  const section = $('job');
  section.removeAttribute('data-job-state');
  $('job-state').textContent = '';
  $('job-error').textContent = '';
  if (!id) {
    $('job-title').textContent = 'No job selected';
    $('job-hint').hidden = false;
    $('job-body').hidden = true;
    return;
  }
  // In one column the job is below the form: bring it into view.
  if (matchMedia('(max-width: 60rem)').matches) $('job').scrollIntoView({ block: 'start' });
  $('job-title').textContent = `Job ${id.slice(0, 8)}`;
  $('job-title').title = id;
  $('job-hint').hidden = true;
  $('job-body').hidden = false;
  for (const f of ['phase', 'shots', 'unshot', 'elements', 'elapsed', 'eta']) $(`f-${f}`).textContent = '–';
  $('download-result').disabled = true;
  $('download-preview').disabled = true;
  $('cancel').disabled = true;
  $('view-caption').textContent = 'Loading…';
  const current = { id, state: null, controller: new AbortController(), progress: null, result: null, preview: null, previewRequest: null };
  job = current;
  plot ??= new ConvergencePlot($('plot'));
  await ensureViewer();
  if (job !== current) return;
  viewer?.clear();

  let record;
  try {
    record = await json(`/v1/jobs/${encodeURIComponent(id)}`, { signal: current.controller.signal });
  } catch (e) {
    if (job !== current || current.controller.signal.aborted) return;
    $('job-error').textContent = e instanceof ApiError && e.status === 404
      ? `There is no job ${id} (it may have expired).` : `The job could not be read: ${e.message}`;
    $('view-caption').textContent = '';
    return;
  }
  if (job !== current) return;
  plot.clear(Number(record.params?.convergence));
  setState(current, record.state, record.error);
  if (record.progress) showProgress(current, record.progress, false);
  previewLoop(current);
  try {
    await followEvents(id, (event) => onEvent(current, event), current.controller.signal);
  } catch (e) {
    if (job === current && !(e instanceof ApiError && e.status === 401)) $('job-error').textContent = `The job's events could not be read: ${e.message}`;
  }
}

function onEvent(current, event) {
  if (job !== current) return;
  if (event.type === 'progress') showProgress(current, event.data, true);
  else if (event.type === 'state') setState(current, event.data.state, event.data.error);
}

// States only move forward on the page: a finished job's stream replays its history from the start.
function setState(current, state, error) {
  if (!state || kFinal.has(current.state) || state === current.state) return;
  current.state = state;
  if (kFinal.has(state)) current.previewRequest?.abort();
  $('job').dataset.jobState = state;
  const badge = $('job-state');
  badge.textContent = state;
  badge.className = `state state-${state}`;
  $('cancel').disabled = kFinal.has(state);
  $('f-eta').textContent = timeLeft(state, current.progress);
  if (error) $('job-error').textContent = `The bake failed: ${error}`;
  if (state === 'succeeded') loadResult(current);
  if (state === 'cancelled') $('view-caption').textContent = current.preview ? 'Cancelled; the last preview is shown.' : 'Cancelled.';
  if (state === 'failed' && !current.preview) $('view-caption').textContent = 'No result.';
  if (kFinal.has(state)) loadJobs();
}

// What the "Time left" field says: nothing once the job ended without finishing its bake (the
// last progress event's estimate would stay on a cancelled or failed job).
function timeLeft(state, p) {
  if (state === 'cancelled' || state === 'failed') return '–';
  if (!p) return '–';
  return p.phase === 'done' ? '0 s' : p.eta_seconds >= 0 ? formatSeconds(p.eta_seconds) : 'unknown';
}

function showProgress(current, p, live) {
  current.progress = p;
  $('f-phase').textContent = p.phase ?? '–';
  $('f-shots').textContent = p.shots !== undefined ? p.shots.toLocaleString('en') : '–';
  $('f-unshot').textContent = p.unshot_fraction !== undefined ? formatFraction(p.unshot_fraction) : '–';
  $('f-elements').textContent = p.elements !== undefined ? p.elements.toLocaleString('en') : '–';
  $('f-elapsed').textContent = p.elapsed_seconds !== undefined ? formatSeconds(p.elapsed_seconds) : '–';
  $('f-eta').textContent = timeLeft(current.state, p);
  if (live && (p.phase === 'shooting' || p.phase === 'done')) plot.add(p.elapsed_seconds, p.unshot_fraction);
  if (p.phase !== 'shooting') current.previewRequest?.abort();
}

// While the job shoots, its latest preview every few seconds (a preview waits for the worker's
// next shot, so one request at a time). Other phases (hr, a reference job's tracing) have none.
async function previewLoop(current) {
  const signal = current.controller.signal;
  while (job === current && !kFinal.has(current.state)) {
    const phase = current.progress?.phase;
    let cost = 0;
    if (!viewer) {
      $('view-caption').textContent = viewerFailed;
    } else if (current.state === 'running' && phase === 'shooting') {
      try {
        // Given up when the job says it is done: the server would answer 409 once it ends.
        const ask = new AbortController();
        current.previewRequest = ask;
        const stop = () => ask.abort();
        signal.addEventListener('abort', stop, { once: true });
        let response;
        try {
          response = await request(`/v1/jobs/${encodeURIComponent(current.id)}/preview`, { signal: ask.signal });
        } finally {
          signal.removeEventListener('abort', stop);
          current.previewRequest = null;
        }
        const received = performance.now();
        const buffer = await response.arrayBuffer();
        if (job !== current || kFinal.has(current.state)) return;
        current.preview = buffer;
        const shown = await viewer.show(buffer, current.id);
        if (job !== current) return;
        // The wait for the worker's next shot costs nothing; writing, sending and drawing do.
        cost = writeMilliseconds(response) + (performance.now() - received);
        const p = current.progress;
        $('view-caption').textContent = `Preview${p ? ` after ${p.shots} shot${p.shots === 1 ? '' : 's'}, ${formatFraction(p.unshot_fraction)} unshot` : ''}: ` +
          `${shown.triangles.toLocaleString('en')} triangles (not converged; the ambient term stands in for the unshot light)`;
        $('download-preview').disabled = false;
      } catch (e) {
        if (signal.aborted) return;
        // Given up (the job is done), or 409: between phases, or it just finished; the state event
        // tells which. Others: try again.
        if (!(e instanceof ApiError) && e.name !== 'AbortError' && !current.preview) $('view-caption').textContent = `No preview yet: ${e.message}`;
      }
    } else if (current.state === 'queued') {
      $('view-caption').textContent = 'Queued: waiting for a worker.';
    } else if (current.state === 'running' && !current.preview) {
      $('view-caption').textContent = phase ? `No preview in the ${phase} phase.` : 'Starting…';
    }
    // A large scene's preview takes a while to write, send and draw: then the page asks less often.
    await sleep(Math.max(kPreviewSeconds * 1000, 2 * cost), signal);
  }
}

// The worker's time to write a preview, from the server's Server-Timing header (0 without one).
function writeMilliseconds(response) {
  const match = /(?:^|,)\s*write;dur=([\d.]+)/.exec(response.headers.get('Server-Timing') ?? '');
  return match ? Number(match[1]) : 0;
}

async function loadResult(current) {
  $('view-caption').textContent = 'Loading the result…';
  try {
    const response = await request(`/v1/jobs/${encodeURIComponent(current.id)}/result`, { signal: current.controller.signal });
    const buffer = await response.arrayBuffer();
    if (job !== current) return;
    current.result = buffer;
    $('download-result').disabled = false;
    if (!viewer) {
      $('view-caption').textContent = viewerFailed;
      return;
    }
    const shown = await viewer.show(buffer, current.id);
    if (job !== current) return;
    $('view-caption').textContent = `Result: ${shown.triangles.toLocaleString('en')} triangles, exposure ${shown.exposure.toPrecision(3)}` +
      (shown.radiosity ? '' : ' (no _RADIOSITY attribute: the radiosity view shows the baked colours)');
    $('view').dataset.loaded = current.id;
  } catch (e) {
    if (current.controller.signal.aborted) return;
    $('view-caption').textContent = `The result could not be shown: ${e.message}`;
  }
}

$('cancel').addEventListener('click', async () => {
  const current = job;
  if (!current) return;
  $('cancel').disabled = true;
  try {
    const record = await json(`/v1/jobs/${encodeURIComponent(current.id)}`, { method: 'DELETE' });
    if (job === current) setState(current, record.state, record.error);
  } catch (e) {
    if (job !== current) return;
    $('job-error').textContent = `The job could not be cancelled: ${e.message}`;
    $('cancel').disabled = kFinal.has(current.state);
  }
});

function download(buffer, name) {
  const url = URL.createObjectURL(new Blob([buffer], { type: 'model/gltf-binary' }));
  const a = document.createElement('a');
  a.href = url;
  a.download = name;
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 60000);
}

$('download-result').addEventListener('click', () => job?.result && download(job.result, `${job.id}.glb`));
$('download-preview').addEventListener('click', () => job?.preview && download(job.preview, `${job.id}-preview.glb`));

// ---------------------------------------------------------------------------------------------
// 3D view controls

// The 3D view, made on first use; null (with a message) where the browser has no WebGL.
async function ensureViewer() {
  if (viewer || viewerFailed) return;
  try {
    viewerModule ??= await import('./viewer.js');
    viewer = new viewerModule.Viewer($('view'));
  } catch (e) {
    viewerFailed = `The 3D view is not available in this browser (${e.message}); the GLB can still be downloaded.`;
    return;
  }
  // The browser may have restored the controls' state on a reload.
  viewer.setMode(document.querySelector('input[name="mode"]:checked')?.value ?? 'baked');
  viewer.setStops(Number($('exposure').value));
  viewer.setWireframe($('wireframe').checked);
  $('exposure').disabled = viewer.mode !== 'radiosity';
}

document.querySelectorAll('input[name="mode"]').forEach((radio) => radio.addEventListener('change', () => {
  if (radio.checked) viewer?.setMode(radio.value);
  $('exposure').disabled = radio.value !== 'radiosity';
}));
$('exposure').disabled = true;
$('exposure').addEventListener('input', () => {
  const stops = Number($('exposure').value);
  $('exposure-value').textContent = `${stops > 0 ? '+' : ''}${stops} EV`;
  viewer?.setStops(stops);
});
$('wireframe').addEventListener('change', () => viewer?.setWireframe($('wireframe').checked));
$('reset-view').addEventListener('click', () => viewer?.frame());

// ---------------------------------------------------------------------------------------------
// Formatting

function formatBytes(n) {
  if (!(n >= 0)) return '';
  if (n < 1024) return `${n} B`;
  if (n < 1024 * 1024) return `${(n / 1024).toFixed(1)} KB`;
  return `${(n / 1024 / 1024).toFixed(1)} MB`;
}

function formatSeconds(s) {
  if (!(s >= 0)) return '–';
  if (s < 10) return `${s.toFixed(2)} s`;
  if (s < 120) return `${s.toFixed(1)} s`;
  const m = Math.floor(s / 60);
  if (m < 120) return `${m} min ${Math.round(s - 60 * m)} s`;
  return `${Math.floor(m / 60)} h ${m % 60} min`;
}

function formatFraction(f) {
  if (!(f >= 0)) return '–';
  return f === 0 ? '0' : f >= 0.01 ? `${(f * 100).toFixed(1)} %` : f.toExponential(2);
}

function formatWhen(date) {
  const today = new Date();
  const sameDay = date.toDateString() === today.toDateString();
  return sameDay ? date.toLocaleTimeString() : date.toLocaleString();
}

start();
