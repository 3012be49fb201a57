// radcache dashboard: plain JS, no build step, nothing loaded from outside
// the server. Talks to the API described at /api/openapi.json:
// the live frame is an <img> on /api/jobs/ID/stream (multipart), progress and
// per-frame statistics come from /api/jobs/ID/events (SSE), the record
// overlay from /api/jobs/ID/records, or for a `movies` job /api/jobs/ID/movies
// (pixel positions computed by the server).
'use strict';

const $ = (id) => document.getElementById(id);
const SVG = 'http://www.w3.org/2000/svg';

// Errors are shown on the page (and counted in body[data-errors]) so that
// the browser test sees them in the DOM as well as in the console.
const errors = [];
function reportError(msg) {
  errors.push(String(msg));
  const pre = $('errors');
  pre.textContent = errors.join('\n');
  pre.hidden = false;
  document.body.dataset.errors = String(errors.length);
  console.error(String(msg));
}
window.addEventListener('error', (e) => reportError(e.message));
window.addEventListener('unhandledrejection', (e) => reportError(e.reason && e.reason.message || e.reason));

// A server started with --token needs it on every request: the page was
// opened as /?token=…, and every URL it requests carries it on.
const TOKEN = new URLSearchParams(location.search).get('token');
function withToken(path) {
  if (!TOKEN) return path;
  return `${path}${path.includes('?') ? '&' : '?'}token=${encodeURIComponent(TOKEN)}`;
}

async function api(path, options) {
  const r = await fetch(withToken(path), options);
  const text = await r.text();
  let body = null;
  try { body = text ? JSON.parse(text) : null; } catch (_) { body = null; }
  if (!r.ok) throw new Error((body && body.detail) || `${r.status} ${r.statusText}`);
  return body;
}

function el(tag, attrs, text) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
  if (text !== undefined) e.textContent = text;
  return e;
}

function svgEl(tag, attrs, text) {
  const e = document.createElementNS(SVG, tag);
  for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
  if (text !== undefined) e.textContent = text;
  return e;
}

function fmtSeconds(s) {
  if (s == null || !isFinite(s)) return '';
  if (s < 60) return `${s.toFixed(1)} s`;
  const m = Math.floor(s / 60);
  return `${m} min ${Math.round(s - 60 * m)} s`;
}

function fmtBytes(b) {
  if (b >= 1 << 20) return `${(b / (1 << 20)).toFixed(1)} MiB`;
  if (b >= 1 << 10) return `${(b / (1 << 10)).toFixed(1)} KiB`;
  return `${Math.round(b)} B`;
}

// ---------------------------------------------------------------- jobs

// The URL of job `id`'s resource `rest`. A job of `radcache render --job`
// may be named anything, `?`, `#` and `/` included: the id is a path
// segment, so it is percent-encoded.
function jobUrl(id, rest = '') {
  return `/api/jobs/${encodeURIComponent(id)}${rest}`;
}

const view = {
  id: null,        // selected job id
  generation: 0,   // bumped by every selection: answers to an older one are dropped
  job: null,       // its last known state (GET /api/jobs/ID)
  stats: new Map(),// frame -> statistics row
  events: null,    // EventSource (the only one open)
  follow: true,    // show the live stream and the newest frame's records
  liveStreams: 0,  // live streams opened for the job (each gets its own URL)
  liveBroken: false,// the live image's stream failed
  overlayFrame: null,
  overlayLoop: null,// the overlay requests in flight (a promise), if any
  overlayWanted: null,
};

async function refreshJobs() {
  const jobs = await api('/api/jobs');
  const body = $('jobs').tBodies[0];
  body.replaceChildren();
  for (const j of jobs) {
    const tr = el('tr', { class: 'job', 'data-id': j.id });
    if (j.id === view.id) tr.classList.add('selected');
    // Jobs `radcache render --db` left in the store are shown, not run here.
    const state = j.origin === 'render' ? `${j.state} (radcache render)` : j.state;
    tr.append(el('td', {}, j.id), el('td', {}, j.scene), el('td', {}, j.method), el('td', {}, j.size),
      el('td', { class: j.state === 'failed' ? 'error' : '' }, state));
    const td = el('td');
    const p = el('progress', { max: String(j.frames_total), value: String(j.frames_done) });
    td.append(p, ` ${j.frames_done}/${j.frames_total}`);
    tr.append(td);
    tr.addEventListener('click', () => selectJob(j.id).catch(reportError));
    body.append(tr);
  }
  return jobs;
}

function parseRange(text) {
  const [a, b] = text.split('..').map(Number);
  return [a, b];
}

// Every frame the job has or will have: its range, and the frames stored
// by earlier renders of it with other ranges (`radcache render --job`).
function frameRange(job) {
  let [a, b] = parseRange(job.frames);
  for (const r of job.stored_ranges || []) {
    const [s, e] = parseRange(r);
    a = Math.min(a, s);
    b = Math.max(b, e);
  }
  return [a, b];
}

// The settings that say most about a caching method's trade-off: the
// accuracy a (ic), a_t and δt_max (trc), τ_min (tcg), shadow samples N
// (movies); empty for path.
function keySettings(job) {
  const s = job.settings || {};
  const parts = [];
  if (s.accuracy != null) parts.push(`a ${s.accuracy}`);
  if (s.at != null) parts.push(`a_t ${s.at}`);
  if (s.max_life != null) parts.push(`δt_max ${s.max_life}`);
  if (s.tau_min != null) parts.push(`τ_min ${s.tau_min}`);
  if (s.shadow_samples != null) parts.push(`N ${s.shadow_samples}`);
  return parts.map((p) => `, ${p}`).join('');
}

// What the job's charts count follows its method: `movies` counts
// texture movies (opened, kept, closed, and the frames a closed one
// lasted), `path` keeps no cache, and only `trc` and `tcg` shoot the
// samples of records carried from frame to frame again.
function labelCharts(method) {
  const movies = method === 'movies';
  $('caption-records').textContent = movies ? 'texture movies per frame' : 'records per frame';
  $('caption-lifespan').textContent = movies
    ? 'mean length of the movies that ended, frames'
    : 'mean lifespan of the records computed, frames';
  $('figure-records').hidden = method === 'path';
  // `tcg`'s records have no set life: they age, a share of their samples
  // shot again each frame (the re-shot chart).
  $('figure-lifespan').hidden = method === 'path' || method === 'tcg';
  $('figure-reshot').hidden = !(method === 'trc' || method === 'tcg');
  // `path` has no records to lay over the frame.
  $('legend').hidden = method === 'path';
  $('show-overlay').parentElement.hidden = method === 'path';
}

function showProgress(job) {
  view.job = job;
  labelCharts(job.method);
  $('job-title').textContent = `${job.id}: ${job.scene}, ${job.method}, ${job.size}, ${job.spp} spp${keySettings(job)}, frames ${job.frames} — ${job.state}`;
  $('progress').max = job.frames_total;
  $('progress').value = job.frames_done;
  const others = (job.frames_stored ?? job.frames_done) - job.frames_done;
  $('progress-text').textContent = `${job.frames_done}/${job.frames_total} frames`
    + (others > 0 ? ` (and ${others} stored outside ${job.frames}: ${job.stored_ranges.join(', ')})` : '');
  $('eta').textContent = job.state === 'running' && job.eta_seconds != null
    ? `ETA ${fmtSeconds(job.eta_seconds)} (${fmtSeconds(job.seconds_per_frame)}/frame)` : job.state;
  $('cancel').disabled = !(job.state === 'queued' || job.state === 'running');
  $('resume').disabled = !(job.state === 'cancelled' || job.state === 'failed');
  $('delete').disabled = job.state === 'queued' || job.state === 'running';
  if (job.error) $('eta').textContent += ` — ${job.error}`;
}

// Shows job `id` and follows it. Another selection made while this one
// waits for an answer ends this one there: what it got belongs to a job no
// longer shown. A failed request is reported and the rest goes on: the job
// is followed whatever failed on the way.
async function selectJob(id) {
  const generation = ++view.generation;
  const current = () => view.generation === generation;
  stopFollowing();
  Object.assign(view, { id, job: null, stats: new Map(), follow: true, liveStreams: 0, liveBroken: false, overlayFrame: null, overlayWanted: null });
  $('follow').checked = true;
  history.replaceState(null, '', withToken(`/?job=${encodeURIComponent(id)}`));
  for (const tr of $('jobs').tBodies[0].rows) tr.classList.toggle('selected', tr.dataset.id === id);
  $('job-panel').hidden = false;
  $('overlay').replaceChildren();
  $('overlay-info').textContent = '';
  $('record-details').textContent = 'click a record for its details';
  drawCharts();
  try {
    const job = await api(jobUrl(id));
    if (!current()) return;
    showProgress(job);
    const [start, end] = frameRange(job);
    $('frame-slider').min = start;
    $('frame-slider').max = Math.max(start, end - 1);
    try {
      const stats = await api(jobUrl(id, '/stats'));
      if (!current()) return;
      for (const row of stats.frames) view.stats.set(row.frame, row);
    } catch (err) {
      if (!current()) return;
      reportError(err);
    }
    drawCharts();
    showLive();
    const last = lastFrame();
    if (last != null) {
      $('frame-slider').value = last;
      await requestOverlay(last);
      if (!current()) return;
    }
  } catch (err) {
    if (!current()) return;
    reportError(err);
  }
  follow(id);
}

function lastFrame() {
  let last = null;
  for (const f of view.stats.keys()) if (last == null || f > last) last = f;
  return last;
}

function stopFollowing() {
  if (view.events) view.events.close();
  view.events = null;
}

// Follows job `id`'s events, the only EventSource open.
function follow(id) {
  stopFollowing();
  const es = new EventSource(withToken(jobUrl(id, '/events')));
  view.events = es;
  const mine = () => view.events === es;
  es.addEventListener('progress', (e) => {
    if (!mine()) return;
    showProgress(JSON.parse(e.data));
  });
  es.addEventListener('frame', (e) => {
    if (!mine()) return;
    const row = JSON.parse(e.data);
    const fresh = !view.stats.has(row.frame);
    view.stats.set(row.frame, row);
    if (fresh) scheduleCharts();
    if (view.follow) {
      // A stream that failed shows no newer frame: a new one shows this.
      if (view.liveBroken) showLive();
      $('frame-slider').value = row.frame;
      $('frame-label').textContent = `frame ${row.frame}`;
      requestOverlay(row.frame);
    }
  });
  es.addEventListener('state', (e) => {
    const s = JSON.parse(e.data);
    if (s.final) {
      es.close();
      if (mine()) view.events = null;
    }
    refreshJobs().catch(reportError);
  });
  // The server closes the stream after the final state; anything else is a
  // lost connection (the server stopped), which EventSource retries by
  // itself. The live image's stream ended with it: once the events are
  // back, so is the server, and a new stream shows the frames to come.
  let lost = false;
  es.addEventListener('error', () => { lost = true; });
  es.addEventListener('open', () => {
    if (lost && mine() && view.follow) showLive();
    lost = false;
  });
}

// The live stream of the selected job, when following. Each stream opened
// for a job after the first has its own URL (a query the server ignores):
// the same URL again may be answered from the page's list of available
// images, with the last frame of a stream that ended.
function showLive() {
  const img = $('live');
  if (view.follow) {
    const n = view.liveStreams++;
    img.src = withToken(jobUrl(view.id, n ? `/stream?n=${n}` : '/stream'));
    view.liveBroken = false;
    const last = lastFrame();
    $('frame-label').textContent = last == null ? 'waiting for the first frame' : `frame ${last}`;
  }
}

function showFrame(frame) {
  $('live').src = withToken(jobUrl(view.id, `/frames/${frame}.png`));
  $('frame-label').textContent = `frame ${frame}`;
  requestOverlay(frame);
}

// ---------------------------------------------------------------- overlay

// At most one records request in flight; the newest wanted frame wins.
// The promise settles (never rejects) once no frame is wanted any more.
function requestOverlay(frame) {
  view.overlayWanted = frame;
  if (!view.overlayLoop) view.overlayLoop = loadOverlays();
  return view.overlayLoop;
}

// Fig. 11 of the TRC paper: red = short lifespan, green = long.
function lifespanColour(t) {
  return `hsl(${Math.round(120 * Math.min(1, Math.max(0, t)))}, 90%, 45%)`;
}

// Loads the wanted frames' overlays one at a time until none is wanted. An
// answer for a job no longer selected is dropped (what the new selection
// wants is loaded next); a failed request is reported.
async function loadOverlays() {
  try {
    while (view.overlayWanted != null) {
      const frame = view.overlayWanted;
      view.overlayWanted = null;
      const { generation, id } = view;
      const movies = view.job != null && view.job.method === 'movies';
      if (view.job != null && view.job.method === 'path') {
        // No records to show.
        $('overlay').replaceChildren();
        $('overlay-info').textContent = '';
        continue;
      }
      try {
        const r = await api(jobUrl(id, movies ? `/movies?frame=${frame}` : `/records?frame=${frame}&limit=20000`));
        if (view.generation !== generation) continue;
        if (movies) drawMovies(r); else drawOverlay(r);
      } catch (err) {
        if (view.generation === generation) reportError(err);
      }
    }
  } finally {
    view.overlayLoop = null;
  }
}

// The overlay emptied and sized for frame `r` (a /records or /movies answer).
function clearOverlay(r) {
  const svg = $('overlay');
  view.overlayFrame = r.frame;
  svg.setAttribute('viewBox', `0 0 ${r.width} ${r.height}`);
  svg.replaceChildren();
  $('frame-wrap').style.aspectRatio = `${r.width} / ${r.height}`;
  svg.style.display = $('show-overlay').checked ? '' : 'none';
  return svg;
}

// Shows `item` (of frame `r`) in the details box when `shape` is clicked.
function pickable(svg, shape, r, item) {
  shape.addEventListener('click', (e) => {
    e.stopPropagation();
    for (const p of svg.querySelectorAll('.picked')) p.classList.remove('picked');
    shape.classList.add('picked');
    $('record-details').textContent = JSON.stringify({ frame: r.frame, ...item }, null, 1);
  });
}

function drawOverlay(r) {
  const svg = clearOverlay(r);
  let maxLife = 1;
  for (const rec of r.records) maxLife = Math.max(maxLife, rec.lifespan);
  const logMax = Math.log(Math.max(2, maxLife));
  const radius = Math.max(r.width, r.height) / 90;
  let radiance = 0;
  for (const rec of r.records) {
    if (!rec.screen) continue;
    const [x, y] = rec.screen;
    if (x < 0 || y < 0 || x > r.width || y > r.height) continue;
    const c = svgEl('circle', {
      cx: x.toFixed(3), cy: y.toFixed(3), r: radius.toFixed(3),
      fill: lifespanColour(Math.log(rec.lifespan) / logMax),
      'data-id': String(rec.id), class: 'record',
    });
    let title = `record ${rec.id}: lifespan ${rec.lifespan}, created at frame ${rec.created}`;
    // A radiance record (glossy surface, --ic-glossy eas): ringed.
    if (rec.source_count != null) {
      radiance += 1;
      c.setAttribute('data-sources', String(rec.source_count));
      c.setAttribute('stroke', '#000');
      c.setAttribute('stroke-width', (radius / 2.5).toFixed(3));
      title += `, radiance record with ${rec.source_count} sources`;
    }
    c.append(svgEl('title', {}, title));
    pickable(svg, c, r, rec);
    svg.append(c);
  }
  $('legend-range').textContent = `(1–${maxLife} frames)`;
  $('overlay-info').textContent = `frame ${r.frame}: ${r.count} records alive` +
    (r.truncated ? ` (showing ${r.records.length})` : '') +
    (radiance ? `, ${radiance} shown are radiance records (ringed)` : '');
}

// A `movies` job's texture movies: a square at the centre of each movie's
// patch, sized by its resolution, coloured by how long it has been open
// (the records' lifespan colours).
function drawMovies(r) {
  const svg = clearOverlay(r);
  let maxAge = 1;
  for (const m of r.movies) maxAge = Math.max(maxAge, r.frame - m.start + 1);
  const logMax = Math.log(Math.max(2, maxAge));
  const unit = Math.max(r.width, r.height) / 90;
  for (const m of r.movies) {
    if (!m.screen) continue;
    const [x, y] = m.screen;
    if (x < 0 || y < 0 || x > r.width || y > r.height) continue;
    const age = r.frame - m.start + 1;
    const side = unit * (1 + Math.log2(Math.max(1, m.resolution)) / 4);
    const sq = svgEl('rect', {
      x: (x - side / 2).toFixed(3), y: (y - side / 2).toFixed(3),
      width: side.toFixed(3), height: side.toFixed(3),
      fill: lifespanColour(Math.log(age) / logMax), class: 'movie',
    });
    sq.append(svgEl('title', {}, `movie of triangle ${m.triangle} (${m.back ? 'back' : 'front'}, patch ${m.patch}): ${m.resolution} texels an edge, open since frame ${m.start}`));
    pickable(svg, sq, r, m);
    svg.append(sq);
  }
  $('legend-range').textContent = `(open 1–${maxAge} frames)`;
  $('overlay-info').textContent = `frame ${r.frame}: ${r.count} movies open, ${r.global_vertices} global-pass vertices`;
}

// ---------------------------------------------------------------- charts

let chartsScheduled = false;
function scheduleCharts() {
  if (chartsScheduled) return;
  chartsScheduled = true;
  requestAnimationFrame(() => { chartsScheduled = false; drawCharts(); });
}

function drawCharts() {
  const rows = [...view.stats.values()].sort((a, b) => a.frame - b.frame);
  const series = (name, colour, f) => ({ name, colour, points: rows.map((r) => [r.frame, f(r)]) });
  lineChart($('chart-records'), [
    series('alive', '#1565c0', (r) => r.records_alive),
    { ...series('created', '#2e7d32', (r) => r.records_created), dash: '5 3' },
    series('reused', '#f9a825', (r) => r.records_reused),
    series('replaced', '#ef6c00', (r) => r.records_replaced),
    series('dropped', '#c62828', (r) => r.records_dropped),
  ], (v) => String(Math.round(v)));
  lineChart($('chart-reshot'), [series('samples re-shot', '#ef6c00', (r) => r.samples_reshot || 0)], (v) => String(Math.round(v)));
  // A frame that computed no record has no mean lifespan (the stats say
  // null): a gap in the line, not a fall to zero.
  lineChart($('chart-lifespan'), [series('mean lifespan', '#2e7d32', (r) => r.mean_lifespan)], (v) => v.toFixed(1));
  lineChart($('chart-time'), [series('seconds', '#6a1b9a', (r) => r.seconds)], (v) => `${v.toPrecision(2)} s`);
  lineChart($('chart-bytes'), [
    series('cache (memory)', '#1565c0', (r) => r.cache_bytes || 0),
    series('frame written', '#6a1b9a', (r) => r.stored_bytes || 0),
    series('EXR (stored)', '#00838f', (r) => r.exr_bytes || 0),
    series('samples (raw)', '#ef6c00', (r) => r.samples_raw_bytes || 0),
  ], fmtBytes);
}

// A line chart drawn by hand into an <svg>: axes, min/max labels, one path
// per series, a legend. A point whose value is null is a gap in its line.
function lineChart(svg, series, fmt) {
  const W = 480, H = 170, L = 56, R = 8, T = 22, B = 22;
  svg.setAttribute('viewBox', `0 0 ${W} ${H}`);
  svg.replaceChildren();
  // The frames span every point; the values only those that have one.
  const frames = series.flatMap((s) => s.points);
  const pts = frames.filter((p) => p[1] != null);
  if (pts.length === 0) {
    svg.append(svgEl('text', { x: W / 2, y: H / 2, 'text-anchor': 'middle' }, 'no frames yet'));
    return;
  }
  let x0 = Math.min(...frames.map((p) => p[0])), x1 = Math.max(...frames.map((p) => p[0]));
  let y1 = Math.max(...pts.map((p) => p[1]));
  const y0 = 0;
  if (x1 === x0) { x0 -= 0.5; x1 += 0.5; }
  if (!(y1 > y0)) y1 = y0 + 1;
  const sx = (x) => L + (W - L - R) * (x - x0) / (x1 - x0);
  const sy = (y) => H - B - (H - T - B) * (y - y0) / (y1 - y0);
  svg.append(
    svgEl('line', { class: 'axis', x1: L, y1: H - B, x2: W - R, y2: H - B }),
    svgEl('line', { class: 'axis', x1: L, y1: T, x2: L, y2: H - B }),
    svgEl('text', { x: L - 4, y: T + 4, 'text-anchor': 'end' }, fmt(y1)),
    svgEl('text', { x: L - 4, y: H - B, 'text-anchor': 'end' }, fmt(y0)),
    svgEl('text', { x: L, y: H - 6, 'text-anchor': 'middle' }, String(Math.ceil(x0))),
    svgEl('text', { x: W - R, y: H - 6, 'text-anchor': 'end' }, `frame ${Math.floor(x1)}`),
  );
  let lx = L + 4;
  for (const s of series) {
    if (s.points.length === 0) continue;
    // Each run of points between gaps is a subpath; a lone point, which
    // draws no line, also gets a dot.
    let d = '', pen = false;
    const dots = [];
    s.points.forEach(([x, y], i) => {
      if (y == null) { pen = false; return; }
      if (!pen && (i + 1 === s.points.length || s.points[i + 1][1] == null)) dots.push([x, y]);
      d += `${pen ? 'L' : 'M'}${sx(x).toFixed(1)},${sy(y).toFixed(1)}`;
      pen = true;
    });
    const path = svgEl('path', { class: 'series', d, stroke: s.colour, 'data-series': s.name });
    // Dashed where it may lie on another series (ic creates every record alive).
    if (s.dash) path.setAttribute('stroke-dasharray', s.dash);
    svg.append(path);
    for (const [x, y] of dots) {
      svg.append(svgEl('circle', { class: 'dot', cx: sx(x).toFixed(1), cy: sy(y).toFixed(1), r: 3, fill: s.colour }));
    }
    const label = svgEl('text', { x: lx, y: 12, fill: s.colour }, s.name);
    label.style.fill = s.colour;
    svg.append(label);
    lx += 9 + 6 * s.name.length;
  }
}

// ---------------------------------------------------------------- bench

async function loadBench() {
  const charts = await api('/api/charts');
  const box = $('bench');
  box.replaceChildren();
  // The charts, then their data files on a line of their own.
  const data = el('p', {}, 'data: ');
  for (const c of charts) {
    if (c.type === 'image/svg+xml') box.append(el('img', { src: withToken(c.url), alt: c.name, title: c.name }));
    else data.append(el('a', { href: withToken(c.url) }, c.name), ' ');
  }
  if (data.children.length) box.append(data);
}

// ---------------------------------------------------------------- wiring

// "max_life=5, at=0.02" → {max_life: "5", at: "0.02"}: the job request's
// settings, which the server checks (values as text, as the bench takes them).
function parseSettings(text) {
  const settings = {};
  for (const part of text.split(/[\s,]+/).filter(Boolean)) {
    const eq = part.indexOf('=');
    if (eq <= 0) throw new Error(`setting "${part}" is not NAME=VALUE`);
    settings[part.slice(0, eq)] = part.slice(eq + 1);
  }
  return settings;
}

$('new-job').addEventListener('submit', async (e) => {
  e.preventDefault();
  $('form-error').textContent = '';
  const body = Object.fromEntries(new FormData(e.target));
  if (body.spp === '') delete body.spp; else body.spp = Number(body.spp);
  try {
    if (body.settings.trim() === '') delete body.settings; else body.settings = parseSettings(body.settings);
    const r = await api('/api/jobs', { method: 'POST', headers: { 'Content-Type': 'application/json' }, body: JSON.stringify(body) });
    await refreshJobs();
    await selectJob(r.id);
  } catch (err) {
    // A refused request is the user's to fix, not a page error.
    $('form-error').textContent = err.message;
  }
});

// The stored frame nearest `frame`: the newest at or before it, else the
// first after it; null while none is.
function storedFrameNear(frame) {
  let before = null, after = null;
  for (const f of view.stats.keys()) {
    if (f <= frame) { if (before == null || f > before) before = f; }
    else if (after == null || f < after) after = f;
  }
  return before ?? after;
}

// The slider spans the job's frames, rendered or not: one not rendered yet
// has no image or records, and the slider stops at the nearest one that is.
$('frame-slider').addEventListener('input', (e) => {
  const frame = storedFrameNear(Number(e.target.value));
  if (frame == null) {
    e.target.value = e.target.min;
    return;
  }
  e.target.value = frame;
  view.follow = false;
  $('follow').checked = false;
  showFrame(frame);
});

$('follow').addEventListener('change', (e) => {
  view.follow = e.target.checked;
  if (view.follow) {
    showLive();
    const last = lastFrame();
    if (last != null) { $('frame-slider').value = last; requestOverlay(last); }
  }
});

// Marks the frame shown (the browser test checks it): set on every image
// (each part of the stream, each single frame).
$('live').addEventListener('load', (e) => {
  e.target.dataset.loaded = `${e.target.naturalWidth}x${e.target.naturalHeight}`;
});
// A stream cut off (the server stopped) is opened again on the next frame.
$('live').addEventListener('error', () => {
  if (view.follow) view.liveBroken = true;
});

$('show-overlay').addEventListener('change', (e) => {
  $('overlay').style.display = e.target.checked ? '' : 'none';
});

// The answers below are for the job clicked, which may no longer be shown.
$('cancel').addEventListener('click', () => {
  const id = view.id;
  api(jobUrl(id, '/cancel'), { method: 'POST' }).then((job) => {
    if (view.id === id) showProgress(job);
  }).then(refreshJobs).catch(reportError);
});
$('delete').addEventListener('click', () => {
  const id = view.id;
  if (!window.confirm(`Delete job ${id} with its frames and records?`)) return;
  api(jobUrl(id), { method: 'DELETE' }).then(() => {
    if (view.id !== id) return;
    view.generation += 1;
    stopFollowing();
    Object.assign(view, { id: null, job: null });
    $('job-panel').hidden = true;
    history.replaceState(null, '', withToken('/'));
  }).then(refreshJobs).catch(reportError);
});
$('resume').addEventListener('click', () => {
  const id = view.id;
  api(jobUrl(id, '/resume'), { method: 'POST' }).then(() => {
    if (view.id === id) return selectJob(id);
  }).then(refreshJobs).catch(reportError);
});

// A failed request is reported; it stops neither the page getting ready
// nor the refreshes.
async function main() {
  // The job list changes when jobs are created elsewhere; refresh it now and then.
  setInterval(() => refreshJobs().catch(reportError), 5000);
  let jobs = [];
  try {
    jobs = await refreshJobs();
  } catch (err) {
    reportError(err);
  }
  const wanted = new URLSearchParams(location.search).get('job');
  const pick = jobs.find((j) => j.id === wanted) || jobs[jobs.length - 1];
  await Promise.all([loadBench().catch(reportError), pick ? selectJob(pick.id).catch(reportError) : null]);
  document.body.dataset.ready = '1';
}

main().catch(reportError);
