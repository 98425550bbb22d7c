// The service's HTTP API as the page uses it: requests with the session's bearer token, errors as
// exceptions that carry the server's message, and the job event stream read with fetch (an
// EventSource cannot send an Authorization header).

const kTokenKey = 'hemibake-token';
/** The states a job does not leave. */
export const kFinal = new Set(['succeeded', 'failed', 'cancelled']);

/** An answer other than 2xx (or 304): `status` and the server's `{"error": ...}` message. */
export class ApiError extends Error {
  constructor(status, message, response) {
    super(message);
    this.name = 'ApiError';
    this.status = status;
    this.response = response;
  }
}

/** The token kept for this browser tab's session, or ''. */
export function token() {
  try {
    return sessionStorage.getItem(kTokenKey) ?? '';
  } catch {
    return ''; // storage disabled: the token lives as long as the page
  }
}

let memoryToken = '';

export function setToken(value) {
  memoryToken = value;
  try {
    if (value) sessionStorage.setItem(kTokenKey, value);
    else sessionStorage.removeItem(kTokenKey);
  } catch {
    // storage disabled: memoryToken serves
  }
}

function currentToken() {
  return token() || memoryToken;
}

function authHeaders(extra = {}) {
  const t = currentToken();
  return t ? { ...extra, Authorization: `Bearer ${t}` } : { ...extra };
}

// Called with the ApiError of every 401, so that the page can ask for a token.
let onUnauthorized = () => {};
export function setUnauthorizedHandler(f) {
  onUnauthorized = f;
}

async function errorOf(response) {
  let message = `${response.status} ${response.statusText}`.trim();
  try {
    const body = await response.json();
    if (body && typeof body.error === 'string') message = body.error;
  } catch {
    // not JSON: the status line serves
  }
  const e = new ApiError(response.status, message, response);
  if (response.status === 401) onUnauthorized(e);
  return e;
}

/**
 * fetch() on the service with the token. Resolves to the Response when it is 2xx; rejects with an
 * ApiError (the server's message) otherwise, and with the network's error when there is no answer.
 */
export async function request(path, { method = 'GET', headers = {}, body, signal } = {}) {
  const response = await fetch(path, { method, headers: authHeaders(headers), body, signal, cache: 'no-store' });
  if (!response.ok) throw await errorOf(response);
  return response;
}

export async function json(path, options) {
  return (await request(path, options)).json();
}

/** A random key for Idempotency-Key (crypto.randomUUID needs a secure context; this does not). */
export function randomKey() {
  const bytes = crypto.getRandomValues(new Uint8Array(16));
  return Array.from(bytes, (b) => b.toString(16).padStart(2, '0')).join('');
}

/**
 * Follows GET /v1/jobs/{id}/events: calls onEvent({id, type, data}) for every event (data parsed
 * as JSON), from the first one on, and reconnects with Last-Event-ID when the connection ends
 * before the job's final state event (a restarted server, a proxy's timeout). Resolves after that
 * event or when `signal` aborts; rejects with an ApiError for 401 and 404.
 */
export async function followEvents(id, onEvent, signal) {
  let last = 0;
  let delay = 1000;
  for (;;) {
    if (signal.aborted) return;
    let response;
    try {
      response = await fetch(`/v1/jobs/${encodeURIComponent(id)}/events`, {
        headers: authHeaders({ Accept: 'text/event-stream', ...(last ? { 'Last-Event-ID': String(last) } : {}) }),
        signal,
        cache: 'no-store',
      });
    } catch {
      if (signal.aborted) return;
      await sleep(delay, signal);
      delay = Math.min(delay * 2, 15000);
      continue;
    }
    if (response.status === 503) {
      const retry = Number(response.headers.get('Retry-After')) || 5;
      await response.body?.cancel();
      await sleep(retry * 1000, signal);
      continue;
    }
    if (!response.ok) throw await errorOf(response);
    delay = 1000;
    let finished = false;
    try {
      await readStream(response.body, (event) => {
        if (event.id) last = Number(event.id) || last;
        if (event.type === 'state' && kFinal.has(event.data?.state)) finished = true;
        onEvent(event);
      });
    } catch {
      // The connection broke in the middle: ask again for what followed the last event seen.
    }
    // The server ends the stream after the job's final event; any other end is a broken connection.
    if (finished || signal.aborted) return;
    await sleep(delay, signal);
  }
}

// Parses text/event-stream (the WHATWG format: fields, blank-line-separated events, comments).
// Returns when the server closes the stream.
async function readStream(body, onEvent) {
  const reader = body.pipeThrough(new TextDecoderStream()).getReader();
  let buffer = '';
  let event = { id: '', type: 'message', data: [] };
  for (;;) {
    const { value, done } = await reader.read();
    if (done) return;
    buffer += value;
    let newline;
    while ((newline = buffer.search(/\r\n|\r|\n/)) >= 0) {
      const line = buffer.slice(0, newline);
      buffer = buffer.slice(newline + (buffer.startsWith('\r\n', newline) ? 2 : 1));
      if (line === '') {
        if (event.data.length > 0) {
          const text = event.data.join('\n');
          let data;
          try {
            data = JSON.parse(text);
          } catch {
            data = text;
          }
          onEvent({ id: event.id, type: event.type, data });
        }
        event = { id: event.id, type: 'message', data: [] };
        continue;
      }
      if (line.startsWith(':')) continue; // a heartbeat
      const colon = line.indexOf(':');
      const field = colon < 0 ? line : line.slice(0, colon);
      let fieldValue = colon < 0 ? '' : line.slice(colon + 1);
      if (fieldValue.startsWith(' ')) fieldValue = fieldValue.slice(1);
      if (field === 'id') event.id = fieldValue;
      else if (field === 'event') event.type = fieldValue;
      else if (field === 'data') event.data.push(fieldValue);
    }
  }
}

export function sleep(ms, signal) {
  return new Promise((resolve) => {
    const timer = setTimeout(resolve, ms);
    signal?.addEventListener('abort', () => {
      clearTimeout(timer);
      resolve();
    }, { once: true });
  });
}
