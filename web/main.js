// Page glue: wires the controls to the viewer (pkg/egoexo_viewer.js, wgpu) and to the
// worker (worker.js → pkg/egoexo_web_worker.js). Every computation happens in Rust, and so
// does every message to and from the worker: `WorkerClient` builds the requests and checks
// the events (docs/worker-protocol.md); this file reacts to them.

import initViewer, { Viewer, WorkerClient, fragment_with_time, parse_fragment, participant_colour, share_fragment } from './pkg/egoexo_viewer.js';
import { createLive } from './live.js';
import { exportPng, exportVideo } from './video.js';
import { deleteShare, fetchShare, forgetShare, loadShareConfig, megabytes, rememberShare, savedShares, uploadShare } from './share.js';

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
// Assets (samples among them) live beside this script, under the build's versioned folder.
const SAMPLES_URL = new URL('samples/samples.json', import.meta.url);

const state = {
  viewer: null,
  worker: null,
  client: null, // the WorkerClient of `worker`
  busy: false,
  session: null, // the import summary
  scene: null, // the last scene JSON (Uint8Array)
  summary: null, // the last reconstruction summary
  models: null, // the loaded models' summary: {model_sets: [{tracking_points, lookahead, …}], bytes}
  reconstructStarted: 0, // performance.now() when the reconstruction was asked for
  Viewer, // the viewer's class (off-screen renders in the tests)
  share: { apiBase: location.origin, server: null }, // the share API and its limits
  linkable: false, // whether the address can say what is shown (sample, ?url=, share)
  pendingTime: null, // where a link asked to open: {start, end}
  inputBytes: 0, // size of the opened file (does the recording fit in a share?)
  openedShare: null, // {includes_recording} of a share being shown
};
// For the end-to-end tests and the curious: the live objects.
window.egoexo = state;

function setState(name) {
  document.body.dataset.state = name;
}

// ---------------------------------------------------------------- errors and progress

function showError(title, message) {
  $('error-title').textContent = title;
  $('error-message').textContent = message;
  $('error-panel').hidden = false;
}

function clearError() {
  $('error-panel').hidden = true;
}

function showProgress(text, fraction) {
  $('progress-panel').hidden = false;
  $('progress-text').textContent = text;
  if (fraction === null) $('progress').removeAttribute('value');
  else $('progress').value = fraction;
}

function setBusy(busy) {
  state.busy = busy;
  for (const el of [$('file-input'), $('folder-input'), $('sample-button')]) el.disabled = busy;
  for (const el of document.querySelectorAll('#export-buttons button, #participants button')) el.disabled = busy;
  $('cancel-button').disabled = !busy;
  if (!busy) $('progress-panel').hidden = true;
}

function fail(title, message) {
  state.selecting = null;
  setBusy(false);
  showError(title, message);
  setState('error');
}

// ---------------------------------------------------------------- the worker

const STAGE_TITLES = {
  models: 'Could not load the models',
  import: 'Could not import the session',
  reconstruct: 'Reconstruction failed',
  export: 'Export failed',
  request: 'The worker refused a request',
};

function spawnWorker() {
  // `?workers=N` on the page sizes the worker's pool (docs/worker-protocol.md).
  const workerUrl = new URL('worker.js', import.meta.url);
  const pageWorkers = new URLSearchParams(location.search).get('workers');
  if (pageWorkers) workerUrl.searchParams.set('workers', pageWorkers);
  const worker = new Worker(workerUrl, { type: 'module' });
  const client = new WorkerClient(worker);
  // A replaced (crashed) worker's last messages may still be queued: ignore them.
  worker.onmessage = (event) => {
    if (state.worker !== worker) return;
    let message;
    try {
      message = client.receive(event.data);
    } catch (error) {
      restartWorker();
      fail('The worker stopped', error.message ?? String(error));
      return;
    }
    if (message) onWorkerEvent(message);
  };
  worker.onerror = (event) => {
    event.preventDefault();
    if (state.worker !== worker) return;
    restartWorker();
    fail('The worker stopped', event.message || 'the worker script failed to load');
  };
  state.worker = worker;
  state.client = client;
  // Start fetching the models now, while the user picks a session.
  client.warm_up();
}

function restartWorker() {
  state.worker?.terminate();
  spawnWorker();
}

// Performance marks (User Timing) of the page's first load, read by the e2e suite: models
// ready in the worker, the first session imported, the first skeleton on screen.
function markOnce(name) {
  if (performance.getEntriesByName(name, 'mark').length === 0) performance.mark(name);
}

function onWorkerEvent(event) {
  if (live.onEvent(event)) return;
  switch (event.type) {
    case 'models':
      state.models = event.summary;
      markOnce('egoexo:models-ready');
      break;
    case 'ready':
    case 'cancelled':
      break;
    case 'status':
      if (state.busy) showProgress(event.text, null);
      break;
    case 'progress': {
      if (event.stage === 'import') {
        showProgress('importing the session…', null);
        break;
      }
      const fraction = event.total > 0 ? event.done / event.total : null;
      showProgress(`${event.label} — ${Math.round(100 * fraction)}%`, fraction);
      break;
    }
    case 'imported':
      markOnce('egoexo:imported');
      state.session = event.summary;
      showSession(event.summary);
      if (state.selecting) {
        // Another participant of the capture: their reconstruction follows when there is one.
        if (!(state.summary?.participants ?? []).some((p) => p.id === event.summary.participant)) {
          state.selecting = null;
          setBusy(false);
          setState('ready');
        }
        break;
      }
      startReconstruction();
      break;
    case 'reconstructed':
      if (state.selecting) {
        showScene(event.scene, event.summary, state.selecting.how, state.selecting.moment);
        state.selecting = null;
        break;
      }
      state.openedShare = null;
      showScene(event.scene, event.summary, `in ${((performance.now() - state.reconstructStarted) / 1000).toFixed(1)} s`);
      break;
    case 'share-sealed':
      onShareSealed(event);
      break;
    case 'share-opened':
      state.openedShare = { includes_recording: event.includes_recording };
      showSession(event.session);
      state.sharedBy = `(shared, made by ${event.created_by})`;
      showScene(event.scene, event.summary, state.sharedBy);
      break;
    case 'exported':
      download(event.file.bytes, event.file.file_name, event.file.mime_type);
      setBusy(false);
      setState('ready');
      break;
    case 'error':
      if (event.stage === 'share' && $('share-dialog').open) {
        $('share-status').textContent = `Could not make the share: ${event.message}`;
        setBusy(false);
        setState('ready');
      } else if (event.kind === 'share-invalid') {
        fail('Could not open the share', event.message);
      } else if (event.kind === 'models-missing') {
        fail(STAGE_TITLES.models, `${event.message}\nThis copy of the app was built without models/.`);
      } else {
        fail(STAGE_TITLES[event.stage] ?? 'Error', event.message);
      }
      break;
    case 'panic':
      // The worker's wasm module is dead after a panic: replace the worker.
      restartWorker();
      fail('The worker crashed (a bug in egoexo — please report it)', `${event.message}\nThe worker has been restarted.`);
      break;
    default:
      console.warn('unexpected worker event', event);
  }
}

// Reconstructs the open session offline (ego-exo and the ego-only overlay).
function startReconstruction() {
  setBusy(true);
  setState('busy');
  showProgress('reconstructing…', 0);
  state.reconstructStarted = performance.now();
  state.client.reconstruct(true);
}

const live = createLive(state, { fail, showSession, startReconstruction });

// ---------------------------------------------------------------- loading sessions

// Starts an import: `open(client)` sends the request (its bytes go to the worker).
function startJob(open) {
  if (state.busy) return;
  clearError();
  setBusy(true);
  setState('busy');
  showProgress('starting…', null);
  open(state.client);
}

// Says in the address what is shown (`#sample`, `?url=`, a share), or clears it for a local
// file, so that a copied address opens the same thing.
function setSource(fragment, linkable) {
  state.linkable = linkable;
  const url = new URL(location.href);
  if (!linkable) url.searchParams.delete('url');
  url.hash = fragment;
  history.replaceState(null, '', url);
}

async function openArchive(file) {
  const bytes = new Uint8Array(await file.arrayBuffer());
  setSource('', false);
  state.inputBytes = bytes.length;
  startJob((client) => client.open_archive(file.name, bytes));
}

async function openFolder(name, entries) {
  // entries: [{path, file}] with paths relative to the dropped folder's parent.
  const contents = await Promise.all(entries.map(async (e) => new Uint8Array(await e.file.arrayBuffer())));
  setSource('', false);
  state.inputBytes = contents.reduce((n, c) => n + c.length, 0);
  startJob((client) => client.open_files(name, entries.map((e) => e.path), contents));
}

async function openSample() {
  try {
    clearError();
    const list = await fetchOk(SAMPLES_URL).then((r) => r.json());
    const sample = list.samples[0];
    const bytes = new Uint8Array(await fetchOk(new URL(sample.file, SAMPLES_URL)).then((r) => r.arrayBuffer()));
    setSource(fragment_with_time(location.hash.startsWith('#sample') ? location.hash : '#sample', state.pendingTime?.start, state.pendingTime?.end), true);
    state.inputBytes = bytes.length;
    startJob((client) => client.open_archive(sample.file.split('/').pop(), bytes));
  } catch (error) {
    fail('Could not load the sample', error.message);
  }
}

// `?url=<https URL of a .egoexo or zip>`: a session hosted anywhere that allows CORS.
async function openUrl(address) {
  let url;
  try {
    url = new URL(address, location.href);
  } catch {
    fail('Could not open the URL', `\`${address}\` is not a URL.`);
    return;
  }
  let bytes;
  try {
    const response = await fetch(url);
    if (!response.ok) throw new Error(`HTTP ${response.status} ${response.statusText}`);
    bytes = new Uint8Array(await response.arrayBuffer());
  } catch (error) {
    fail('Could not open the URL', `${url.href}: ${error.message}\nThe server may not let other sites read the file ` +
      '(it must send Access-Control-Allow-Origin), or it cannot be reached.');
    return;
  }
  state.linkable = true;
  state.inputBytes = bytes.length;
  const name = decodeURIComponent(url.pathname.split('/').pop() || 'session.egoexo');
  startJob((client) => client.open_archive(name, bytes));
}

// `#share=<id>.<key>`: fetch the sealed share and open it in the worker.
async function openShareLink(share) {
  clearError();
  setBusy(true);
  setState('busy');
  showProgress('fetching the share…', null);
  let sealed;
  try {
    sealed = await fetchShare(state.share.apiBase, share.id);
  } catch (error) {
    fail(error.kind === 'expired' ? 'This share has expired' : error.kind === 'not-found' ? 'No such share' : 'Could not fetch the share', error.message);
    return;
  }
  state.linkable = true;
  state.inputBytes = 0;
  state.client.open_share(sealed, share.key);
}

async function fetchOk(url) {
  const response = await fetch(url);
  if (!response.ok) throw new Error(`${url.pathname}: HTTP ${response.status} ${response.statusText}`);
  return response;
}

// Reads a dropped directory (FileSystemDirectoryEntry) recursively.
async function readDirectory(entry, prefix, out) {
  const reader = entry.createReader();
  for (;;) {
    const batch = await new Promise((resolve, reject) => reader.readEntries(resolve, reject));
    if (batch.length === 0) return out;
    for (const child of batch) {
      const path = `${prefix}/${child.name}`;
      if (child.isDirectory) await readDirectory(child, path, out);
      else out.push({ path, file: await new Promise((resolve, reject) => child.file(resolve, reject)) });
    }
  }
}

async function onDrop(event) {
  event.preventDefault();
  $('drop-zone').classList.remove('over');
  if (state.busy) return;
  const items = [...event.dataTransfer.items].map((i) => i.webkitGetAsEntry?.()).filter(Boolean);
  const files = [...event.dataTransfer.files];
  try {
    if (items.length === 1 && items[0].isDirectory) {
      await openFolder(items[0].name, await readDirectory(items[0], items[0].name, []));
    } else if (files.length === 1) {
      await openArchive(files[0]);
    } else {
      fail('Could not import the session', `Dropped ${files.length} items; drop one .egoexo file, one zip or one folder.`);
    }
  } catch (error) {
    fail('Could not read the dropped files', error.message);
  }
}

// ---------------------------------------------------------------- results

function facts(dl, rows) {
  dl.replaceChildren(...rows.flatMap(([k, v]) => {
    const dt = document.createElement('dt');
    const dd = document.createElement('dd');
    dt.textContent = k;
    dd.textContent = v;
    return [dt, dd];
  }));
}

// A capture of several participants: one button per participant reconstructed, in its
// colour; the pressed one is shown (their facts, plots and exports).
function showParticipants(s) {
  const box = $('participants');
  const people = (s.participants ?? []).filter((p) => p.reconstruct);
  box.hidden = people.length === 0;
  box.replaceChildren(...people.map((p) => {
    const button = document.createElement('button');
    button.type = 'button';
    button.dataset.participant = p.id;
    button.setAttribute('aria-pressed', String(p.id === s.participant));
    const swatch = document.createElement('span');
    swatch.className = 'swatch';
    swatch.style.background = participant_colour(p.colour);
    button.append(swatch, p.id);
    button.title = `${p.devices.join(', ')}${p.camera ? `; camera ${p.camera}` : ''}`;
    button.addEventListener('click', () => selectParticipant(p.id));
    return button;
  }));
}

function selectParticipant(id) {
  if (state.busy || state.session?.participant === id) return;
  // The moment shown, on the session clock: the other participant's timeline may start
  // elsewhere.
  const v = state.viewer;
  const moment = v && state.summary ? v.start_s() + v.time() : null;
  const how = state.openedShare ? state.sharedBy : '';
  state.selecting = { id, moment, how };
  setBusy(true);
  setState('busy');
  state.client.select_participant(id);
}

function showSession(s) {
  $('session-panel').hidden = false;
  $('session-name').textContent = s.name;
  showParticipants(s);
  facts($('session-facts'), [
    ['source', s.source],
    ['timeline', `${s.frames} frames at ${s.fps} fps (${s.duration_s.toFixed(1)} s)`],
    ['wearer', `${s.tracking_points}-point tracking: ${s.devices.join(', ')}`
      + (s.tracking_reason ? ` (${s.tracking_reason})` : '')],
    ...(s.wrists ?? []).map((w) => [`${w.side} wrist`,
      `tracked on ${w.tracked_percent.toFixed(1)}% of frames, longest gap ${w.longest_gap_s.toFixed(2)} s (${w.source})`]),
    ['floor', s.floor ? `${s.floor.height_m.toFixed(3)} m, from ${s.floor.source}` : 'unknown'],
    ...(s.observers.length === 0 ? [['observers', 'none']] : s.observers.map((o) =>
      [o.id, `${o.camera}, ` + (o.needs_detection
        ? `video ${o.video}: keypoints found by the detector when reconstructing`
        : `keypoints in ${o.keypoint_frames} frames`)
        + (o.world ? `; world: ${o.world}` : '') + (o.fused === false ? ' — not fused' : '')])),
    ['ground truth', s.ground_truth ? 'yes' : 'no'],
  ]);
  $('session-warnings').replaceChildren(...s.warnings.map((w) => {
    const li = document.createElement('li');
    li.textContent = w;
    return li;
  }));
  $('result-facts').replaceChildren();
}

function showScene(scene, summary, how, keepMoment = null) {
  const viewer = state.viewer;
  try {
    if (!viewer) throw new Error('the 3D view could not start (see above)');
    viewer.set_scene_json(scene);
    state.scene = scene;
    state.summary = summary;
    // The viewer draws in its next animation frame: the frame after that has the skeleton on
    // screen. Time to first skeleton = this mark's startTime (from navigation start).
    requestAnimationFrame(() => requestAnimationFrame(() => markOnce('egoexo:first-skeleton')));
  } catch (error) {
    fail('Cannot show the reconstruction', error.message ?? String(error));
    return;
  }
  const rows = [
    ['method', `${summary.method}, ${summary.tracking_points}-point`],
    ['reconstructed', `${summary.valid_frames} of ${summary.frames} frames ${how}`],
    ['exo evidence', `${summary.exo_evidence_frames} frames`],
  ];
  for (const d of summary.detection ?? []) {
    const rate = d.ms > 0 ? `, ${(d.detected / (d.ms / 1000)).toFixed(1)} detections/s` : '';
    rows.push([`detector (${d.observer})`, `the wearer in ${d.detected} of ${d.frames} video frames${rate}`]);
  }
  if (summary.accuracy) {
    const a = summary.accuracy;
    rows.push(['MPJPE vs ground truth', `${a.ego_exo_mpjpe_cm.toFixed(1)} cm` +
      (a.ego_only_mpjpe_cm == null ? '' : ` (ego-only ${a.ego_only_mpjpe_cm.toFixed(1)} cm)`)]);
  }
  // A capture: every participant's row, and who was who in cameras without identities.
  for (const p of summary.participants ?? []) {
    if (p.id === summary.participant) continue;
    rows.push([p.id, `${p.method}, ${p.valid_frames} of ${p.frames} frames` +
      (p.accuracy ? `, MPJPE ${p.accuracy.ego_exo_mpjpe_cm.toFixed(1)} cm` : '')]);
  }
  for (const a of summary.association ?? []) {
    const assigned = Object.entries(a.assigned).map(([id, n]) => `${n} to ${id}`).join(', ') || 'none assigned';
    rows.push([`people (${a.observer})`, `${a.detections} over ${a.frames} frames: ${assigned}; ${a.unassigned} bystanders`]);
  }
  facts($('result-facts'), rows);
  $('view-panel').hidden = false;
  const frames = viewer.frames();
  $('scrubber').max = String(Math.max(0, frames - 1));
  $('frame-count').textContent = `${frames} frames`;
  $('frame-count').hidden = false;
  applyToggles();
  showCameraChoices(viewer);
  drawPlots();
  $('rerun-button').hidden = !(state.openedShare?.includes_recording);
  // A share without its recording has no session to save.
  $('save-session').hidden = Boolean(state.openedShare && !state.openedShare.includes_recording);
  viewer.clear_loop();
  const time = state.pendingTime;
  state.pendingTime = null;
  if (keepMoment != null) {
    // Another participant of the same capture: the same moment on the session clock.
    viewer.seek(Math.max(0, Math.min(frames - 1, Math.round((keepMoment - viewer.start_s()) * viewer.fps()))));
  } else if (time) {
    // A link to a moment: show that frame (paused), or play its range in a loop.
    const fps = viewer.fps();
    const start = Math.min(frames - 1, Math.round(time.start * fps));
    viewer.seek(start);
    if (time.end != null) {
      viewer.set_loop(start, Math.min(frames - 1, Math.round(time.end * fps)));
      viewer.play();
    } else {
      viewer.pause();
    }
  } else {
    viewer.seek(0);
    viewer.play();
  }
  setBusy(false);
  setState('ready');
}

// ---------------------------------------------------------------- video and picture

async function saveVideo() {
  const v = state.viewer;
  if (!v || state.busy || state.videoExport) return;
  const loop = v.loop_range();
  const [first, last] = loop ? [loop[0], loop[1]] : [0, v.frames() - 1];
  const abort = new AbortController();
  state.videoExport = abort;
  $('video-progress-row').hidden = false;
  $('video-progress').value = 0;
  $('video-button').disabled = true;
  try {
    const mp4 = await exportVideo(v, {
      first, last, signal: abort.signal,
      onProgress: (f) => { $('video-progress').value = f; },
    });
    const session = state.session?.name ?? 'egoexo';
    download(mp4, `${session}-${state.summary?.method ?? 'view'}.mp4`, 'video/mp4');
  } catch (error) {
    if (error.name !== 'AbortError') showError('The video could not be made', error.message ?? String(error));
  } finally {
    state.videoExport = null;
    $('video-progress-row').hidden = true;
    $('video-button').disabled = false;
  }
}

async function savePng() {
  const v = state.viewer;
  if (!v) return;
  try {
    const blob = await exportPng(v);
    const session = state.session?.name ?? 'egoexo';
    download(new Uint8Array(await blob.arrayBuffer()), `${session}-frame-${v.frame() + 1}.png`, 'image/png');
  } catch (error) {
    showError('The picture could not be made', error.message ?? String(error));
  }
}

function download(bytes, fileName, mimeType) {
  const url = URL.createObjectURL(new Blob([bytes], { type: mimeType }));
  const a = document.createElement('a');
  a.href = url;
  a.download = fileName;
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10_000);
}

// ---------------------------------------------------------------- viewer and timeline

function applyToggles() {
  const v = state.viewer;
  if (!v) return;
  v.set_show_body($('show-body').checked);
  v.set_show_ego_only($('show-ego-only').checked);
  v.set_show_ground_truth($('show-ground-truth').checked);
  v.set_show_rays($('show-rays').checked);
}

// The camera controls for the scene just shown: follow as the viewer decided (on for a wearer
// who walks about, until the user chooses), and one view per observer.
function showCameraChoices(viewer) {
  $('follow').checked = viewer.follows();
  const select = $('view-from');
  const orbit = select.options[0];
  select.replaceChildren(orbit, ...viewer.observer_ids().map((id, i) => {
    const option = document.createElement('option');
    option.value = String(i);
    option.textContent = `observer ${id}`;
    return option;
  }));
  select.value = String(viewer.view_from_observer());
}

function setViewFrom(index) {
  const v = state.viewer;
  if (!v) return;
  v.set_view_from_observer(index);
  $('view-from').value = String(v.view_from_observer());
}

// View shortcuts (the viewer itself handles playback keys): B bodies, F follow, O next view,
// R re-frame, ? help. Ignored while typing in a field.
function onViewKey(e) {
  if (e.ctrlKey || e.metaKey || e.altKey || e.defaultPrevented) return;
  const t = e.target;
  const typing = t && (t.isContentEditable || ['TEXTAREA', 'SELECT'].includes(t.tagName)
    || (t.tagName === 'INPUT' && !['checkbox', 'radio', 'range', 'button'].includes(t.type)));
  if (typing) return;
  if (e.key === '?') {
    $('help-dialog').showModal();
    e.preventDefault();
    return;
  }
  const v = state.viewer;
  if (!v || v.frames() === 0) return;
  switch (e.key.toLowerCase()) {
    case 'b':
      $('show-body').checked = !$('show-body').checked;
      applyToggles();
      break;
    case 'f':
      $('follow').checked = !$('follow').checked;
      v.set_follow($('follow').checked);
      break;
    case 'o': {
      const views = v.observer_ids().length + 1;
      setViewFrom(((v.view_from_observer() + 2) % views) - 1);
      break;
    }
    case 'r':
      v.reset_camera();
      break;
    default:
      return;
  }
  e.preventDefault();
}

// ---------------------------------------------------------------- timeline plots

// The plots share the scrubber's time axis: the canvas spans the scrubber's track (its width
// less the thumb), so a frame sits at the same x in both. The viewer draws the image and
// says what lies where; the page only places it.
const SCRUBBER_THUMB_PX = 8;

function plotAxis() {
  const track = $('scrubber').getBoundingClientRect();
  const box = $('plots').getBoundingClientRect();
  return { left: track.left - box.left + SCRUBBER_THUMB_PX, width: Math.max(1, track.width - 2 * SCRUBBER_THUMB_PX) };
}

function drawPlots() {
  const v = state.viewer;
  const plots = $('plots');
  const layout = v && v.frames() > 1 ? v.plot_layout() : null;
  if (!layout || layout.rows.length === 0) {
    plots.hidden = true;
    state.plotAxis = null;
    return;
  }
  plots.hidden = false;
  const axis = plotAxis();
  const width = Math.round(axis.width);
  const canvas = $('plot-canvas');
  canvas.width = width;
  canvas.height = layout.height;
  canvas.style.width = `${width}px`;
  canvas.style.height = `${layout.height}px`;
  canvas.style.left = `${axis.left}px`;
  canvas.getContext('2d').putImageData(new ImageData(v.plot_image(width), width, layout.height), 0, 0);
  $('plot-labels').style.width = `${axis.left}px`;
  $('plot-labels').replaceChildren(...layout.rows.map((row) => {
    const label = document.createElement('span');
    label.textContent = row.kind === 'error' ? `${row.label} 0–${layout.error_max_cm}` : row.label;
    label.style.top = `${row.top + row.height / 2}px`;
    return label;
  }));
  state.plotAxis = { left: axis.left, width };
  movePlayhead(v.frame());
}

function movePlayhead(frame) {
  const axis = state.plotAxis;
  if (!axis || !state.viewer) return;
  $('plot-playhead').style.left = `${axis.left + state.viewer.plot_x_of_frame(frame, axis.width)}px`;
}

function wirePlots() {
  const canvas = $('plot-canvas');
  const frameAt = (e) => state.viewer.plot_frame_at(e.offsetX, canvas.clientWidth);
  canvas.addEventListener('click', (e) => state.viewer?.seek(frameAt(e)));
  canvas.addEventListener('mousemove', (e) => {
    if (!state.viewer) return;
    const hover = $('plot-hover');
    hover.textContent = state.viewer.plot_text(frameAt(e));
    hover.hidden = false;
    hover.style.left = `${Math.min(canvas.offsetLeft + e.offsetX + 12, $('plots').clientWidth - hover.offsetWidth - 4)}px`;
  });
  canvas.addEventListener('mouseleave', () => { $('plot-hover').hidden = true; });
  new ResizeObserver(() => drawPlots()).observe($('timeline'));
}

function onFrame(frame, timeSeconds) {
  movePlayhead(frame);
  const frames = state.viewer.frames();
  const playing = state.viewer.is_playing();
  $('frame-readout').textContent = `frame ${frame + 1} / ${frames} · ${timeSeconds.toFixed(2)} s`;
  if (document.activeElement !== $('scrubber')) $('scrubber').value = String(frame);
  $('play-button').textContent = playing ? 'Pause' : 'Play';
  // While the user scrubs or steps, the address follows: copying it shares the moment.
  if (state.linkable && !playing && frames > 0 && document.body.dataset.state === 'ready') {
    const url = new URL(location.href);
    url.hash = fragment_with_time(location.hash, timeSeconds);
    history.replaceState(null, '', url);
  }
}

// ---------------------------------------------------------------- sharing

function openShareDialog() {
  const dialog = $('share-dialog');
  const max = state.share.server?.max_share_bytes;
  const recording = $('share-recording');
  const canIncludeRecording = !state.openedShare || state.openedShare.includes_recording;
  recording.disabled = !canIncludeRecording;
  // On by default when the recording fits the server's limit (with room for the rest).
  recording.checked = canIncludeRecording && (!max || state.inputBytes < 0.9 * max);
  $('share-result').hidden = true;
  $('share-link').value = '';
  $('share-status').textContent = state.share.server
    ? `Shares up to ${megabytes(max)} are stored at ${state.share.apiBase}.`
    : `No share server answers at ${state.share.apiBase}: sharing is not available here.`;
  $('share-create').disabled = !state.share.server;
  dialog.showModal();
}

function createShare() {
  if (state.busy) return;
  $('share-create').disabled = true;
  $('share-result').hidden = true;
  $('share-status').textContent = 'Encrypting…';
  setBusy(true);
  state.client.create_share($('share-recording').checked);
}

async function onShareSealed(event) {
  const max = state.share.server?.max_share_bytes ?? Infinity;
  const size = event.sealed.length;
  if (size > max) {
    if (event.includes_recording) {
      $('share-status').textContent = `With the recording the share is ${megabytes(size)}, over this server's limit of ` +
        `${megabytes(max)}: sharing it without the recording…`;
      $('share-recording').checked = false;
      state.client.create_share(false);
      return;
    }
    $('share-status').textContent = `The share is ${megabytes(size)}; this server takes shares up to ${megabytes(max)}.`;
    $('share-create').disabled = false;
    setBusy(false);
    return;
  }
  $('share-status').textContent = `Uploading ${megabytes(size)} (encrypted)…`;
  const expiry = $('share-expiry').value;
  try {
    const created = await uploadShare(state.share.apiBase, event.sealed, expiry);
    const link = `${location.origin}${location.pathname}#${share_fragment(created.id, event.key)}`;
    $('share-link').value = link;
    $('share-result').hidden = false;
    $('share-status').textContent = `Anyone with this link can open it until ${new Date(created.expires_at).toLocaleString()}` +
      (event.includes_recording ? ' (with the recording).' : '.');
    rememberShare({
      id: created.id,
      name: state.summary ? $('session-name').textContent : 'reconstruction',
      link,
      created: new Date().toISOString(),
      expires_at: created.expires_at,
      delete_token: created.delete_token,
      api: state.share.apiBase,
    });
    showSavedShares();
  } catch (error) {
    $('share-status').textContent = `Could not upload the share: ${error.message}`;
  }
  $('share-create').disabled = false;
  setBusy(false);
  setState('ready');
}

async function copyText(text, button) {
  try {
    await navigator.clipboard.writeText(text);
  } catch {
    // No clipboard access (an insecure context): select the text for Ctrl-C.
    $('share-link').select();
  }
  const label = button.textContent;
  button.textContent = 'Copied';
  setTimeout(() => { button.textContent = label; }, 1500);
}

function showSavedShares() {
  const list = savedShares();
  $('shared-panel').hidden = list.length === 0;
  $('shared-list').replaceChildren(...list.map((entry) => {
    const li = document.createElement('li');
    const what = document.createElement('span');
    what.className = 'what';
    what.textContent = entry.name;
    const when = document.createElement('span');
    when.className = 'when';
    const expires = new Date(entry.expires_at);
    when.textContent = expires < new Date() ? 'expired' : `until ${expires.toLocaleString()}`;
    const copy = document.createElement('button');
    copy.type = 'button';
    copy.textContent = 'Copy link';
    copy.addEventListener('click', () => copyText(entry.link, copy));
    const remove = document.createElement('button');
    remove.type = 'button';
    remove.textContent = 'Delete';
    remove.setAttribute('aria-label', `Delete the share of ${entry.name}`);
    remove.addEventListener('click', async () => {
      try {
        await deleteShare(entry.api ?? state.share.apiBase, entry.id, entry.delete_token);
        forgetShare(entry.id);
        showSavedShares();
      } catch (error) {
        showError('Could not delete the share', error.message);
      }
    });
    li.append(what, when, copy, remove);
    return li;
  }));
}

async function startViewer() {
  const canvas = $('view');
  const preference = params.get('backend') ?? 'auto';
  try {
    state.viewer = await Viewer.create(canvas, preference);
  } catch (error) {
    $('backend').textContent = 'renderer: unavailable';
    showError('The 3D view could not start', error.message ?? String(error));
    return;
  }
  $('backend').textContent = `renderer: ${state.viewer.backend()}`;
  state.viewer.on_frame(onFrame);
  const resize = () => {
    const box = $('canvas-box').getBoundingClientRect();
    state.viewer.resize(box.width, box.height, window.devicePixelRatio || 1);
  };
  new ResizeObserver(resize).observe($('canvas-box'));
  resize();
}

function wireControls() {
  $('file-input').addEventListener('change', (e) => {
    const file = e.target.files[0];
    e.target.value = '';
    if (file) openArchive(file);
  });
  $('folder-input').addEventListener('change', (e) => {
    const files = [...e.target.files];
    e.target.value = '';
    if (files.length === 0) return;
    const name = files[0].webkitRelativePath.split('/')[0] || 'folder';
    openFolder(name, files.map((file) => ({ path: file.webkitRelativePath || file.name, file })));
  });
  $('sample-button').addEventListener('click', openSample);
  $('cancel-button').addEventListener('click', () => {
    // The worker stops at its next window and keeps its models; events of the cancelled
    // job are dropped by the client.
    state.client.cancel();
    setBusy(false);
    showError('Cancelled', 'The reconstruction was cancelled.');
    setState('cancelled');
  });
  $('error-dismiss').addEventListener('click', clearError);

  const zone = $('drop-zone');
  zone.addEventListener('dragover', (e) => {
    e.preventDefault();
    zone.classList.add('over');
  });
  zone.addEventListener('dragleave', () => zone.classList.remove('over'));
  zone.addEventListener('drop', onDrop);
  // A file dropped anywhere else must not make the browser navigate away from the page.
  window.addEventListener('dragover', (e) => e.preventDefault());
  window.addEventListener('drop', (e) => {
    if (!zone.contains(e.target)) onDrop(e);
  });

  for (const id of ['show-body', 'show-ego-only', 'show-ground-truth', 'show-rays']) {
    $(id).addEventListener('change', applyToggles);
  }
  $('follow').addEventListener('change', (e) => state.viewer?.set_follow(e.target.checked));
  $('view-from').addEventListener('change', (e) => setViewFrom(Number(e.target.value)));
  $('help-button').addEventListener('click', () => $('help-dialog').showModal());
  $('video-button').addEventListener('click', saveVideo);
  $('video-cancel').addEventListener('click', () => state.videoExport?.abort());
  $('png-button').addEventListener('click', savePng);
  $('help-close').addEventListener('click', () => $('help-dialog').close());
  window.addEventListener('keydown', onViewKey);
  $('play-button').addEventListener('click', () => state.viewer?.toggle_play());
  $('step-back').addEventListener('click', () => state.viewer?.step(-1));
  $('step-forward').addEventListener('click', () => state.viewer?.step(1));
  $('scrubber').addEventListener('input', (e) => state.viewer?.seek(Number(e.target.value)));
  $('speed').addEventListener('change', (e) => state.viewer?.set_speed(Number(e.target.value)));
  $('share-button').addEventListener('click', openShareDialog);
  $('share-create').addEventListener('click', createShare);
  $('share-close').addEventListener('click', () => $('share-dialog').close());
  $('share-copy').addEventListener('click', () => copyText($('share-link').value, $('share-copy')));
  $('rerun-button').addEventListener('click', () => {
    if (state.busy) return;
    clearError();
    startReconstruction();
  });
  $('save-session').addEventListener('click', () => {
    if (state.busy) return;
    setBusy(true);
    state.client.save_session();
  });
  live.wire();
  wirePlots();
  for (const button of document.querySelectorAll('#export-buttons button')) {
    button.addEventListener('click', () => {
      if (state.busy) return;
      setBusy(true);
      state.client.export(button.dataset.format);
    });
  }
}

// What the address asks for: a share, a session by URL, or the sample, maybe at a moment.
function readAddress() {
  try {
    return parse_fragment(location.hash);
  } catch (error) {
    showError('This link is not valid', error.message ?? String(error));
    return { share: null, time: null, sample: false };
  }
}

await initViewer();
wireControls();
spawnWorker();
setBusy(false);
showSavedShares();
const address = readAddress();
state.pendingTime = address.time;
state.share = await loadShareConfig();
await startViewer();
if (document.body.dataset.state === 'starting') setState('idle');
if (address.live) live.join(address.live.room, address.live.secret);
else if (address.share) await openShareLink(address.share);
else if (params.get('url')) await openUrl(params.get('url'));
else if (address.sample) await openSample();
