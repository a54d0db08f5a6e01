// fivebar's web page: upload with a dry run, the queue, the live view and the machine panel.
// Plain JavaScript, no library. Everything comes from this daemon's API (docs/serve.md):
// the upload form from GET /api/options, live state from the server-sent events of
// GET /api/events (read with fetch so the token travels in the Authorization header, never
// in a URL), actions through POST requests. Every refusal is the API's JSON error, shown.
'use strict';

const $ = (sel) => document.querySelector(sel);
const TOKEN_KEY = 'fivebar-token';
const S = {              // the page's state; window.fivebar for the browser tests
  options: [], features: {}, geometry: null, jobs: [], queue: [], status: null,
  trail: [], trailJob: null, plan: null, planJob: null, file: null, checkedKey: null,
  latencies: [], transport: [], lastMachineKey: null, events: 0, connected: false,
  firstFrameMs: null,
};
window.fivebar = S;

// ------------------------------------------------------------------ API
class ApiError extends Error {
  constructor(key, message, status) { super(message); this.key = key; this.status = status; }
}
function token() {
  return sessionStorage.getItem(TOKEN_KEY) || localStorage.getItem(TOKEN_KEY) || '';
}
function authHeaders(extra) {
  const h = Object.assign({}, extra || {});
  const t = token();
  if (t) h.Authorization = 'Bearer ' + t;
  return h;
}
async function api(method, path, opts) {
  const o = opts || {};
  const headers = authHeaders(o.type ? {'Content-Type': o.type} : {});
  let resp;
  try {
    resp = await fetch(path, {method, headers, body: o.body, cache: 'no-store'});
  } catch (e) {
    throw new ApiError('network', 'The daemon could not be reached (' + e.message + ').', 0);
  }
  const text = await resp.text();
  let data = null;
  try { data = text ? JSON.parse(text) : null; } catch (e) { data = null; }
  if (resp.status === 401) askToken();
  if (!resp.ok) {
    throw new ApiError((data && data.error) || 'http_' + resp.status,
      (data && data.message) || ('HTTP ' + resp.status + ' ' + resp.statusText), resp.status);
  }
  return data;
}

// ------------------------------------------------------------------ messages
const TITLES = {
  input_error: 'This file is not a drawing the plotter can read',
  job_error: 'The drawing cannot be plotted', invalid: 'The drawing cannot be plotted',
  bad_option: 'An option is not valid', bad_query: 'An option is not valid',
  too_large: 'The file is too large', empty_upload: 'The file is empty',
  bad_name: 'The file name is not accepted', bad_content_type: 'Wrong kind of upload',
  conflict: 'Not possible now', not_found: 'No such job (another tab or client removed it)',
  unauthorized: 'The token is missing or wrong', busy: 'The daemon is busy, try again shortly',
  stopping: 'The daemon is stopping', network: 'No connection',
  machine_error: 'The machine reported a fault', timeout: 'The machine took too long',
};
function showError(err, what) {
  const box = document.createElement('div');
  box.className = 'error';
  const title = document.createElement('b');
  title.textContent = (what ? what + ': ' : '') + (TITLES[err.key] || 'Refused');
  const msg = document.createElement('span');
  msg.className = 'message';
  msg.textContent = err.message;
  box.dataset.key = err.key;  // for the tests and the curious, not shown
  const close = document.createElement('button');
  close.type = 'button'; close.textContent = '×'; close.setAttribute('aria-label', 'dismiss');
  close.onclick = () => box.remove();
  box.append(close, title, msg);
  const list = $('#errors');
  list.prepend(box);
  while (list.children.length > 4) list.lastChild.remove();
}
function note(text) {
  const box = document.createElement('div');
  box.className = 'note'; box.textContent = text;
  $('#errors').prepend(box);
  setTimeout(() => box.remove(), 6000);
}
function clearErrors() { $('#errors').replaceChildren(); }
async function guarded(what, fn) {
  try { return await fn(); } catch (e) {
    if (e instanceof ApiError) showError(e, what); else showError(new ApiError('page', String(e), 0), what);
    return undefined;
  }
}

// ------------------------------------------------------------------ formatting
function dur(s) {
  if (s === null || s === undefined || !isFinite(s)) return '–';
  s = Math.max(0, s);
  if (s < 60) return s.toFixed(1) + ' s';
  const m = Math.floor(s / 60);
  if (m < 60) return m + ' min ' + Math.round(s - 60 * m) + ' s';
  return Math.floor(m / 60) + ' h ' + (m % 60) + ' min';
}
function el(tag, cls, text) {
  const e = document.createElement(tag);
  if (cls) e.className = cls;
  if (text !== undefined) e.textContent = text;
  return e;
}

// ------------------------------------------------------------------ token
function askToken() {
  const d = $('#token-dialog');
  if (!d.open) d.showModal();
}
function setupToken() {
  $('#token-form').addEventListener('submit', () => {
    const t = $('#token-input').value.trim();
    $('#token-input').value = '';
    sessionStorage.setItem(TOKEN_KEY, t);
    if ($('#token-remember').checked) localStorage.setItem(TOKEN_KEY, t);
    $('#forget-token').hidden = false;
    clearErrors();
    loadOptions();
    restartEvents();
  });
  $('#forget-token').hidden = !token();
  $('#forget-token').onclick = () => {
    sessionStorage.removeItem(TOKEN_KEY); localStorage.removeItem(TOKEN_KEY);
    $('#forget-token').hidden = true;
    restartEvents();
  };
}

// ------------------------------------------------------------------ upload form
// One form field in words: its label, the field, and its help visible under it (a phone
// has no hover). Values with units are text, sent as typed: the daemon reads them with the
// CLI's parser ("50%" is half size, "1in" 25.4 mm), so the page never guesses a unit.
function optionField(o) {
  const id = 'opt-' + o.query;
  const wrap = el('div', 'field');
  const help = el('small', 'help', o.page_help);
  help.id = id + '-help';
  if (o.kind === 'bool') {
    const label = el('label', 'check');
    const input = el('input'); input.type = 'checkbox'; input.id = id; input.name = o.query;
    input.checked = !!o.default;
    input.setAttribute('aria-describedby', help.id);
    label.append(input, document.createTextNode(' ' + o.label));
    wrap.append(label, help);
    return wrap;
  }
  const label = el('label');
  label.htmlFor = id;
  label.textContent = o.label;
  let input;
  if (o.kind === 'choice') {
    input = el('select');
    input.append(new Option('as the machine says', ''));
    for (const c of o.choices) input.append(new Option(c, c));
  } else {
    input = el('input');
    input.type = o.kind === 'int' ? 'number' : 'text';
    if (o.kind === 'int') { input.step = '1'; if (o.min !== null) input.min = o.min; if (o.max !== null) input.max = o.max; }
    input.autocomplete = 'off';
    input.spellcheck = false;
    input.placeholder = o.example ? 'e.g. ' + o.example
      : (o.default !== null && o.default !== undefined ? String(o.default) : '');
  }
  input.id = id; input.name = o.query;
  input.setAttribute('aria-describedby', help.id);
  wrap.append(label, input, help);
  return wrap;
}
// The options this machine takes from the page: the daemon jobs use its own profile's pen
// settings (the pen overrides are refused), and a pen machine has no laser.
function pageOptions() {
  return S.options.filter(o => !o.name.startsWith('pen_')
                               && !(o.name === 'laser' && S.features.pen));
}
function buildForm() {
  const form = $('#options');
  form.replaceChildren(...pageOptions().map(optionField));
  form.addEventListener('input', invalidate);
}
function queryString() {
  const q = new URLSearchParams();
  q.append('name', S.file.name);
  for (const o of pageOptions()) {
    const input = document.getElementById('opt-' + o.query);
    if (!input) continue;
    if (o.kind === 'bool') {
      if (input.checked !== !!o.default) q.append(o.query, input.checked ? 'true' : 'false');
    } else if (o.repeat) {
      for (const v of input.value.split(',')) if (v.trim()) q.append(o.query, v.trim());
    } else if (input.value.trim() !== '') {
      q.append(o.query, input.value.trim());
    }
  }
  return q.toString();
}
function uploadType(name) {
  return /\.svg$/i.test(name) ? 'image/svg+xml' : 'application/octet-stream';
}
function invalidate() {
  S.checkedKey = null;
  $('#queue-it').disabled = true;
  $('#check').disabled = !S.file;
}
function setFile(file) {
  if (!file) return;
  S.file = file;
  $('#drop-text').textContent = file.name + ' (' + file.size + ' bytes)';
  $('#drop').classList.add('has');
  $('#dryrun').hidden = true;
  invalidate();
}
function setupUpload() {
  const drop = $('#drop');
  $('#file').addEventListener('change', (e) => setFile(e.target.files[0]));
  drop.addEventListener('dragover', (e) => { e.preventDefault(); drop.classList.add('over'); });
  drop.addEventListener('dragleave', () => drop.classList.remove('over'));
  drop.addEventListener('drop', (e) => {
    e.preventDefault(); drop.classList.remove('over');
    if (e.dataTransfer && e.dataTransfer.files.length) setFile(e.dataTransfer.files[0]);
  });
  $('#check').onclick = dryRun;
  $('#queue-it').onclick = queueIt;
}
async function dryRun() {
  const key = queryString();
  $('#check').disabled = true;
  $('#dryrun').hidden = true;
  $('#check').textContent = 'Checking…';
  try {
    const r = await guarded('Check ' + S.file.name, () =>
      api('POST', '/api/dryrun?' + key, {body: S.file, type: uploadType(S.file.name)}));
    if (!r) return;
    $('#estimate').textContent = 'About ' + r.estimate + ' · ' + r.segments + ' segments · ' +
      'deviation ' + (r.max_dev_mm === null ? '?' : r.max_dev_mm.toFixed(4)) + ' mm (tolerance ' +
      r.tolerance_mm + ' mm) · mode ' + r.mode;
    $('#warnings').replaceChildren(...r.warnings.map((w) => el('li', '', w)));
    $('#preview').src = 'data:image/png;base64,' + r.preview_png;
    $('#report').textContent = r.report.join('\n');
    $('#dryrun').hidden = false;
    S.checkedKey = key;
    $('#queue-it').disabled = false;
  } finally {
    $('#check').textContent = 'Check (dry run)';
    $('#check').disabled = !S.file;
  }
}
async function queueIt() {
  const key = queryString();
  if (key !== S.checkedKey) { invalidate(); return; }
  $('#queue-it').disabled = true;
  const job = await guarded('Queue ' + S.file.name, () =>
    api('POST', '/api/jobs?' + key, {body: S.file, type: uploadType(S.file.name)}));
  if (job) note('Job ' + job.id + ' (' + job.name + ') is queued.');
  else $('#queue-it').disabled = false;
}
async function loadOptions() {
  const r = await guarded('Load the options', () => api('GET', '/api/options'));
  if (!r) return;
  S.options = r.options; S.features = r.features; S.geometry = r.geometry;
  buildForm();
  $('#pen').hidden = !S.features.pen;
  draw();
}

// ------------------------------------------------------------------ events
let eventsAbort = null;
function restartEvents() { if (eventsAbort) eventsAbort.abort(); }
async function listen() {
  for (;;) {
    const ctl = new AbortController();
    eventsAbort = ctl;
    try {
      const resp = await fetch('/api/events', {headers: authHeaders({Accept: 'text/event-stream'}),
        cache: 'no-store', signal: ctl.signal});
      if (resp.status === 401) { setLink(false, 'token needed'); askToken(); await waitAbort(ctl); continue; }
      if (!resp.ok) throw new Error('HTTP ' + resp.status);
      setLink(true);
      const reader = resp.body.pipeThrough(new TextDecoderStream()).getReader();
      let buf = '';
      for (;;) {
        const {value, done} = await reader.read();
        if (done) break;
        buf += value;
        let i;
        while ((i = buf.indexOf('\n\n')) >= 0) {
          onBlock(buf.slice(0, i));
          buf = buf.slice(i + 2);
        }
      }
    } catch (e) { /* reconnect below */ }
    setLink(false);
    await new Promise((r) => setTimeout(r, 1000));
  }
}
function waitAbort(ctl) {
  return new Promise((r) => ctl.signal.addEventListener('abort', r, {once: true}));
}
function onBlock(block) {
  let event = 'message';
  const data = [];
  for (const line of block.split('\n')) {
    if (line.startsWith('event:')) event = line.slice(6).trim();
    else if (line.startsWith('data:')) data.push(line.slice(5).replace(/^ /, ''));
  }
  if (!data.length) return;
  const msg = JSON.parse(data.join('\n'));
  S.events += 1;
  if (event === 'status') onStatus(msg);
  else if (event === 'jobs') { S.jobs = msg.jobs; S.queue = msg.queue; renderJobs(); }
  else if (event === 'trail') { S.trail = msg.points; S.trailJob = msg.job_id; draw(); }
}
function setLink(on, why) {
  S.connected = on;
  const b = $('#link');
  b.textContent = on ? 'live' : (why || 'offline');
  b.className = 'badge ' + (on ? 'on' : 'off');
}
function onStatus(msg) {
  const arrived = performance.timeOrigin + performance.now();
  const m = msg.machine;
  const key = JSON.stringify([m.connected, m.state, m.detail, m.position, m.laser]);
  if (key !== S.lastMachineKey && msg.changed_at) {
    if (S.lastMachineKey !== null) {
      S.latencies.push(arrived - msg.changed_at * 1000);
      S.transport.push(arrived - msg.sent_at * 1000);
    }
    S.lastMachineKey = key;
  }
  S.status = msg;
  if (msg.trail && msg.trail.length) S.trail.push(...msg.trail);
  if (msg.live && msg.live.job_id !== S.planJob) loadPlan(msg.live.job_id);
  renderStatus();
  renderLiveJob();
  draw();
}
async function loadPlan(jobId) {
  S.planJob = jobId;
  try {
    const r = await api('GET', '/api/jobs/' + jobId + '/path');
    if (S.planJob === jobId) { S.plan = r.points; draw(); }
  } catch (e) { S.plan = null; }
}

// ------------------------------------------------------------------ rendering: machine
function renderStatus() {
  const st = S.status, m = st.machine;
  const state = m.connected ? (m.state || '?') : 'not connected';
  const ms = $('#mstate');
  ms.textContent = 'machine ' + state;
  ms.className = 'badge ' + (!m.connected || m.state === 'Alarm' ? 'off' : m.state === 'Hold' ? 'warn' : 'on');
  $('#m-conn').textContent = m.connected ? 'connected to ' + m.port : 'not connected: ' + (m.error || '?');
  $('#m-state').textContent = state + (m.motors_off ? ', motors off' : '') +
    (m.pose_known ? ', position known' : ', position unknown (home it)');
  $('#m-steps').textContent = m.position ? 'A ' + m.position.a + ', B ' + m.position.b : '–';
  $('#m-fw').textContent = m.firmware ? m.firmware.version + ' (protocol ' + m.firmware.protocol + ')' : '–';
  $('#alarm').hidden = !m.alarm;
  $('#alarm-text').textContent = m.alarm ? 'Alarm — ' + m.alarm : '';
  renderCompiling(st.compiling || []);
  const p = st.pose;
  $('#pos').textContent = p ? 'x ' + p.pen[0].toFixed(2) + ' mm, y ' + p.pen[1].toFixed(2) + ' mm (mode ' + p.mode + ')' : '–';
}
// drawings being compiled (no job yet): "compiling x.svg: ordering paths 45% (12 s)"
function renderCompiling(list) {
  const ul = $('#compiling');
  ul.hidden = !list.length;
  ul.replaceChildren(...list.map(c => {
    const li = document.createElement('li');
    li.textContent = 'compiling ' + c.name + ': ' + c.stage +
      (c.progress === null ? '' : ' ' + Math.round(100 * c.progress) + '%') +
      ' (' + Math.round(c.elapsed_s) + ' s)' + (c.note ? ' — ' + c.note : '');
    return li;
  }));
}
// 'copy 2 of 3 · ' for a job that draws several copies (its options.copies), else ''
function copyOf(n, job) {
  const copies = (job && job.options && job.options.copies) || 1;
  return copies > 1 ? 'copy ' + (n || 1) + ' of ' + copies + ' · ' : '';
}
function renderLiveJob() {
  const lv = S.status && S.status.live;
  const job = lv ? S.jobs.find((j) => j.id === lv.job_id) : null;
  $('#live-job').textContent = lv ? '· job ' + lv.job_id + (job ? ' ' + job.name : '') + (lv.paused ? ' (paused)' : '') : '';
  $('#seg').textContent = lv ? copyOf(lv.copy_number, job) + 'segment ' + lv.segments_done + ' of ' + lv.segments_total : '–';
  $('#elapsed').textContent = lv ? dur(lv.elapsed_s) : '–';
  $('#remaining').textContent = lv ? dur(lv.remaining_s) : '–';
  const box = $('#live-buttons');
  const shape = lv ? lv.job_id + (lv.paused ? ' paused' : ' running') : '';
  if (box.dataset.shape !== shape) {  // rebuilt only when they change: no click is lost
    box.dataset.shape = shape;
    box.replaceChildren();
    if (lv) {
      box.append(lv.paused ? button('Resume', () => act(lv.job_id, 'resume'), 'primary')
        : button('Pause', () => act(lv.job_id, 'pause')), button('Cancel', () => act(lv.job_id, 'cancel')));
    }
  }
  renderOverrides(lv, job);
  if (lv && job && ['running', 'paused'].includes(job.state)) {
    const row = document.querySelector('[data-job="' + lv.job_id + '"]');
    if (row) {
      const copies = (job.options && job.options.copies) || 1;  // the share of every copy
      row.querySelector('progress').value = lv.segments_total ? ((lv.copy_number || 1) - 1 + lv.segments_done / lv.segments_total) / copies : 0;
      row.querySelector('.eta').textContent = copyOf(lv.copy_number, job) + 'segment ' + lv.segments_done + ' of ' + lv.segments_total + ' · ' + dur(lv.remaining_s) + ' left';
    }
  }
}

// Live overrides (POST /api/jobs/{id}/overrides), 10 % a click; the values are the daemon's.
function renderOverrides(lv, job) {
  const ov = lv && lv.overrides; $('#overrides').hidden = !ov;
  for (const g of ov ? document.querySelectorAll('#overrides .ov') : []) {
    const v = ov[g.dataset.ov + '_pct'];
    g.hidden = g.dataset.ov === 'power' && !(job && job.options.laser);
    g.querySelector('output').textContent = v + '%';
    g.querySelector('[data-sign="-1"]').disabled = v <= Number(g.dataset.min); g.querySelector('[data-sign="1"]').disabled = v >= Number(g.dataset.max);
  }
}

// ------------------------------------------------------------------ rendering: queue
function button(label, fn, cls) {
  const b = el('button', cls || '', label);
  b.type = 'button';
  b.onclick = fn;
  return b;
}
async function act(id, what, query) {
  const path = what === 'delete' ? '/api/jobs/' + id : '/api/jobs/' + id + '/' + what;
  return guarded('Job ' + id + ' ' + what, () =>
    api(what === 'delete' ? 'DELETE' : 'POST', path + (query ? '?' + query : '')));
}
function jobOrder() {
  const active = S.jobs.filter((j) => ['running', 'paused', 'held'].includes(j.state));
  const byId = new Map(S.jobs.map((j) => [j.id, j]));
  const queued = S.queue.map((id) => byId.get(id)).filter(Boolean);
  const done = S.jobs.filter((j) => ['done', 'failed', 'cancelled'].includes(j.state)).reverse();
  return [active, queued, done];
}
function jobButtons(j, waitingIndex, waiting) {
  const out = [];
  if (j.state === 'running') out.push(button('Pause', () => act(j.id, 'pause')));
  if (j.state === 'paused') out.push(button('Resume', () => act(j.id, 'resume'), 'primary'));
  if (j.state === 'held' && !j.question) out.push(button('Resume', () => act(j.id, 'resume'), 'primary'));
  if (j.state === 'queued' && waitingIndex >= 0) {
    const up = button('↑', () => act(j.id, 'move', 'index=' + (waitingIndex - 1)));
    up.disabled = waitingIndex === 0; up.setAttribute('aria-label', 'run earlier');
    const down = button('↓', () => act(j.id, 'move', 'index=' + (waitingIndex + 1)));
    down.disabled = waitingIndex === waiting - 1; down.setAttribute('aria-label', 'run later');
    out.push(up, down);
  }
  if (!['done', 'failed', 'cancelled'].includes(j.state)) out.push(button('Cancel', () => act(j.id, 'cancel')));
  else out.push(button('Delete', () => act(j.id, 'delete')));
  return out;
}
function jobInfo(j, eta) {
  if (j.state === 'queued') return 'starts in about ' + dur(eta) + ' · takes ' + dur(j.estimated_s);
  if (['running', 'paused', 'held'].includes(j.state)) {
    return copyOf(j.copy_number, j) + 'segment ' + j.segments_done + ' of ' + j.segments_total + ' · ' + dur(j.remaining_s) + ' left';
  }
  return j.segments_done + ' of ' + j.segments_total + ' segments · ran ' + dur(j.elapsed_s);
}
const rows = new Map();  // job id → [li, shape]: a row is rebuilt only when its buttons change
function jobItem(j, eta, waitingIndex, waiting) {
  const shape = JSON.stringify([j.state, j.question, j.message, j.name, waitingIndex, waiting]);
  const old = rows.get(j.id);
  let li;
  if (old && old[1] === shape) {
    li = old[0];
  } else {
    li = el('li', 'job');
    li.dataset.job = j.id;
    li.dataset.state = j.state;
    const top = el('div', 'top');
    top.append(el('span', 'name', '#' + j.id + ' ' + j.name), el('span', 'state ' + j.state, j.state));
    const bar = el('progress');
    bar.max = 1;
    li.append(top, bar, el('div', 'eta'));
    if (j.question) li.append(el('div', 'question', 'Waiting for your answer: see the top of the page.'));
    else if (j.message) li.append(el('div', 'msg', j.message));
    const btns = el('div', 'buttons');
    btns.append(...jobButtons(j, waitingIndex, waiting));
    li.append(btns);
    rows.set(j.id, [li, shape]);
  }
  li.querySelector('progress').value = j.progress;
  li.querySelector('.eta').textContent = jobInfo(j, eta);
  return li;
}
// Why a job waits, at the top of the first screen: the question the machine needs a person
// to answer (asked here only), or the pen change it stopped for, with the buttons.
function renderWaiting() {
  const j = S.jobs.find((x) => x.state === 'held' || x.state === 'paused');
  const box = $('#waiting');
  const shape = j ? JSON.stringify([j.id, j.state, j.question, j.message]) : '';
  $('#at-home-row').hidden = !!S.features.endstops || !!(j && j.question);
  if (box.dataset.shape === shape) return;
  box.dataset.shape = shape;
  box.hidden = !j;
  if (!j) { box.replaceChildren(); return; }
  const what = el('p', 'why');
  const name = 'Job #' + j.id + ' (' + j.name + ')';
  const btns = el('div', 'buttons');
  if (j.question) {
    what.textContent = name + ' waits for your answer: ' + j.question;
    btns.append(button('Yes, they are', () => act(j.id, 'resume', 'confirm=true'), 'primary'),
      button('Cancel the job', () => act(j.id, 'cancel')));
  } else if (j.state === 'paused' && /^pen change/.test(j.message || '')) {
    what.textContent = name + ' waits for a pen change: ' + j.message.replace(/^pen change:\s*/, '');
    btns.append(button('Continue', () => act(j.id, 'resume'), 'primary'), button('Cancel the job', () => act(j.id, 'cancel')));
  } else {
    what.textContent = name + (j.state === 'paused' ? ' is paused' : ' is held') + (j.message ? ': ' + j.message : '.');
    btns.append(button('Resume', () => act(j.id, 'resume'), 'primary'), button('Cancel the job', () => act(j.id, 'cancel')));
  }
  box.replaceChildren(what, btns);
}
function renderJobs() {
  renderWaiting();
  const [active, queued, done] = jobOrder();
  let eta = active.reduce((t, j) => t + (j.remaining_s || 0), 0);
  const waiting = queued.filter((j) => !j.started_at);
  const items = active.map((j) => jobItem(j, 0, -1, 0));
  for (const j of queued) {
    items.push(jobItem(j, eta, waiting.indexOf(j), waiting.length));
    eta += j.remaining_s || j.estimated_s;
  }
  items.push(...done.map((j) => jobItem(j, 0, -1, 0)));
  const shown = new Set(items.map((li) => Number(li.dataset.job)));
  for (const id of [...rows.keys()]) if (!shown.has(id)) rows.delete(id);
  const list = $('#jobs');
  // Move rows only where the order changed, so a row under the pointer stays put.
  items.forEach((li, i) => { if (list.children[i] !== li) list.insertBefore(li, list.children[i] || null); });
  while (list.children.length > items.length) list.lastChild.remove();
  $('#queue-empty').hidden = items.length > 0;
  if (S.status) renderLiveJob();
}

// ------------------------------------------------------------------ live view
let drawPending = false;
function draw() {
  if (drawPending) return;
  drawPending = true;
  requestAnimationFrame(() => { drawPending = false; paint(); });
}
function bounds() {
  const xs = [], ys = [];
  const add = (p) => { xs.push(p[0]); ys.push(p[1]); };
  const g = S.geometry;
  if (g) { add([0, 0]); add([g.w, 0]); }
  const pose = S.status && S.status.pose;
  if (pose) pose.points.forEach(add);
  if (S.plan) S.plan.forEach(add);
  S.trail.forEach(add);
  if (!xs.length) return null;
  let [x0, x1, y0, y1] = [Math.min(...xs), Math.max(...xs), Math.min(...ys), Math.max(...ys)];
  const pad = Math.max(x1 - x0, y1 - y0, 20) * 0.06;
  return [x0 - pad, x1 + pad, y0 - pad, y1 + pad];
}
function paint() {
  const c = $('#view');
  const w = c.clientWidth || 640;
  const h = Math.round(w * 0.62);
  const dpr = window.devicePixelRatio || 1;
  if (c.width !== Math.round(w * dpr)) { c.width = Math.round(w * dpr); c.height = Math.round(h * dpr); }
  const ctx = c.getContext('2d');
  ctx.setTransform(1, 0, 0, 1, 0, 0);
  ctx.clearRect(0, 0, c.width, c.height);
  const b = bounds();
  if (!b) return;
  const k = Math.min(c.width / (b[1] - b[0]), c.height / (b[3] - b[2]));
  const ox = (c.width - k * (b[1] - b[0])) / 2, oy = (c.height - k * (b[3] - b[2])) / 2;
  const X = (x) => ox + (x - b[0]) * k, Y = (y) => c.height - oy - (y - b[2]) * k;
  const line = (pts, style, width, dash, only) => {
    ctx.strokeStyle = style; ctx.lineWidth = width * dpr; ctx.setLineDash(dash.map((d) => d * dpr));
    ctx.beginPath();
    let pen = false;
    for (let i = 0; i < pts.length; i++) {
      const p = pts[i];
      if (only !== undefined && i > 0 && p[2] !== only) { pen = false; continue; }
      if (pen) ctx.lineTo(X(p[0]), Y(p[1])); else ctx.moveTo(X(p[0]), Y(p[1]));
      pen = true;
    }
    ctx.stroke();
  };
  if (S.plan) { line(S.plan, '#c9ced6', 1, [4, 4], 0); line(S.plan, '#b5bcc7', 1.2, [], 1); }
  if (S.trail.length) { line(S.trail, '#9aa3ad', 1, [3, 3], 0); line(S.trail, '#1d5fbf', 2.5, [], 1); }
  const pose = S.status && S.status.pose;
  if (pose) {
    ctx.setLineDash([]);
    ctx.strokeStyle = '#e07a10'; ctx.lineWidth = 3 * dpr; ctx.beginPath();
    pose.points.forEach((p, i) => (i ? ctx.lineTo(X(p[0]), Y(p[1])) : ctx.moveTo(X(p[0]), Y(p[1]))));
    ctx.stroke();
    ctx.fillStyle = '#20262e';
    for (const p of pose.points) { ctx.beginPath(); ctx.arc(X(p[0]), Y(p[1]), 3.5 * dpr, 0, 7); ctx.fill(); }
    ctx.fillStyle = '#b3261e';
    ctx.beginPath(); ctx.arc(X(pose.pen[0]), Y(pose.pen[1]), 5 * dpr, 0, 7); ctx.fill();
  }
}

// ------------------------------------------------------------------ machine panel
function machineAction(what, path) {
  return guarded(what, () => api('POST', path));
}
function setupMachine() {
  $('#home').onclick = () => machineAction('Home', '/api/machine/home' +
    ($('#at-home').checked ? '?at_home=true' : ''));
  $('#motors-off').onclick = () => machineAction('Motors off', '/api/machine/motors_off');
  $('#clear-alarm').onclick = () => machineAction('Clear alarm', '/api/machine/clear_alarm');
  for (const b of document.querySelectorAll('.pad button')) {
    b.onclick = () => {
      const mm = parseFloat($('#jog-mm').value);
      const q = 'dx=' + mm * Number(b.dataset.dx) + '&dy=' + mm * Number(b.dataset.dy);
      machineAction('Jog', '/api/machine/jog?' + q);
    };
  }
  for (const b of document.querySelectorAll('[data-motor]')) {
    b.onclick = () => {
      const steps = Math.round(Number($('#jog-steps').value) * Number(b.dataset.sign));
      machineAction('Jog motor ' + b.dataset.motor, '/api/machine/jog?motor=' + b.dataset.motor + '&steps=' + steps);
    };
  }
  // Pen up/down: shown only when GET /api/options says the machine has a pen servo.
  for (const b of document.querySelectorAll('#pen button')) {
    b.onclick = () => machineAction(b.textContent, '/api/machine/pen?down=' + b.dataset.down);
  }
  for (const b of document.querySelectorAll('#overrides button')) {  // live overrides
    b.onclick = () => {
      const lv = S.status && S.status.live, g = b.closest('.ov'), k = g.dataset.ov;
      if (lv && lv.overrides) act(lv.job_id, 'overrides', k + '=' + Math.min(Number(g.dataset.max),
        Math.max(Number(g.dataset.min), lv.overrides[k + '_pct'] + 10 * Number(b.dataset.sign))));
    };
  }
  window.addEventListener('resize', draw);
}

S.act = act;  // the browser tests act as a second tab would, with stale buttons
document.addEventListener('DOMContentLoaded', () => {
  requestAnimationFrame(() => { S.firstFrameMs = performance.now(); });
  setupToken();
  setupUpload();
  setupMachine();
  loadOptions();
  listen();
});
