// Page glue: wires the controls to the viewer (pkg/egoexo_viewer.js, wgpu) and to the
// worker (worker.js → pkg/egoexo_web_worker.js). Every computation happens in Rust, and so
// does every message to and from the worker: `WorkerClient` builds the requests and checks
// the events (docs/worker-protocol.md); this file reacts to them.

import initViewer, { Viewer, WorkerClient } from './pkg/egoexo_viewer.js';

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
const SAMPLES_URL = new URL('samples/samples.json', location.href);

const state = {
  viewer: null,
  worker: null,
  client: null, // the WorkerClient of `worker`
  busy: false,
  session: null, // the import summary
  scene: null, // the last scene JSON (Uint8Array)
  summary: null, // the last reconstruction summary
  reconstructStarted: 0, // performance.now() when the reconstruction was asked for
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
  for (const el of document.querySelectorAll('#export-buttons button')) el.disabled = busy;
  $('cancel-button').disabled = !busy;
  if (!busy) $('progress-panel').hidden = true;
}

function fail(title, message) {
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
  const worker = new Worker(new URL('worker.js', import.meta.url), { type: 'module' });
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

function onWorkerEvent(event) {
  switch (event.type) {
    case 'ready':
    case 'models':
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
      state.session = event.summary;
      showSession(event.summary);
      showProgress('reconstructing…', 0);
      state.reconstructStarted = performance.now();
      state.client.reconstruct(true);
      break;
    case 'reconstructed':
      showScene(event.scene, event.summary, performance.now() - state.reconstructStarted);
      break;
    case 'exported':
      download(event.file.bytes, event.file.file_name, event.file.mime_type);
      setBusy(false);
      setState('ready');
      break;
    case 'error':
      if (event.kind === 'models-missing') {
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

async function openArchive(file) {
  const bytes = new Uint8Array(await file.arrayBuffer());
  startJob((client) => client.open_archive(file.name, bytes));
}

async function openFolder(name, entries) {
  // entries: [{path, file}] with paths relative to the dropped folder's parent.
  const contents = await Promise.all(entries.map(async (e) => new Uint8Array(await e.file.arrayBuffer())));
  startJob((client) => client.open_files(name, entries.map((e) => e.path), contents));
}

async function openSample() {
  try {
    clearError();
    const list = await fetchOk(SAMPLES_URL).then((r) => r.json());
    const sample = list.samples[0];
    const bytes = new Uint8Array(await fetchOk(new URL(sample.file, SAMPLES_URL)).then((r) => r.arrayBuffer()));
    startJob((client) => client.open_archive(sample.file.split('/').pop(), bytes));
  } catch (error) {
    fail('Could not load the sample', error.message);
  }
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

function showSession(s) {
  $('session-panel').hidden = false;
  $('session-name').textContent = s.name;
  facts($('session-facts'), [
    ['source', s.source],
    ['timeline', `${s.frames} frames at ${s.fps} fps (${s.duration_s.toFixed(1)} s)`],
    ['wearer', `${s.tracking_points}-point tracking: ${s.devices.join(', ')}`],
    ['observers', s.observers.length === 0 ? 'none' : s.observers.map((o) =>
      `${o.id} (${o.camera}, keypoints in ${o.keypoint_frames} frames)`).join('; ')],
    ['ground truth', s.ground_truth ? 'yes' : 'no'],
  ]);
  $('session-warnings').replaceChildren(...s.warnings.map((w) => {
    const li = document.createElement('li');
    li.textContent = w;
    return li;
  }));
  $('result-facts').replaceChildren();
}

function showScene(scene, summary, elapsedMs) {
  const viewer = state.viewer;
  try {
    if (!viewer) throw new Error('the 3D view could not start (see above)');
    viewer.set_scene_json(scene);
    state.scene = scene;
    state.summary = summary;
  } catch (error) {
    fail('Cannot show the reconstruction', error.message ?? String(error));
    return;
  }
  const rows = [
    ['method', `${summary.method}, ${summary.tracking_points}-point`],
    ['reconstructed', `${summary.valid_frames} of ${summary.frames} frames in ${(elapsedMs / 1000).toFixed(1)} s`],
    ['exo evidence', `${summary.exo_evidence_frames} frames`],
  ];
  if (summary.accuracy) {
    const a = summary.accuracy;
    rows.push(['MPJPE vs ground truth', `${a.ego_exo_mpjpe_cm.toFixed(1)} cm` +
      (a.ego_only_mpjpe_cm == null ? '' : ` (ego-only ${a.ego_only_mpjpe_cm.toFixed(1)} cm)`)]);
  }
  facts($('result-facts'), rows);
  $('view-panel').hidden = false;
  const frames = viewer.frames();
  $('scrubber').max = String(Math.max(0, frames - 1));
  $('frame-count').textContent = `${frames} frames`;
  $('frame-count').hidden = false;
  applyToggles();
  viewer.seek(0);
  viewer.play();
  setBusy(false);
  setState('ready');
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
  v.set_show_ego_only($('show-ego-only').checked);
  v.set_show_ground_truth($('show-ground-truth').checked);
  v.set_show_rays($('show-rays').checked);
}

function onFrame(frame, timeSeconds) {
  const frames = state.viewer.frames();
  $('frame-readout').textContent = `frame ${frame + 1} / ${frames} · ${timeSeconds.toFixed(2)} s`;
  if (document.activeElement !== $('scrubber')) $('scrubber').value = String(frame);
  $('play-button').textContent = state.viewer.is_playing() ? 'Pause' : 'Play';
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

  for (const id of ['show-ego-only', 'show-ground-truth', 'show-rays']) $(id).addEventListener('change', applyToggles);
  $('play-button').addEventListener('click', () => state.viewer?.toggle_play());
  $('step-back').addEventListener('click', () => state.viewer?.step(-1));
  $('step-forward').addEventListener('click', () => state.viewer?.step(1));
  $('scrubber').addEventListener('input', (e) => state.viewer?.seek(Number(e.target.value)));
  $('speed').addEventListener('change', (e) => state.viewer?.set_speed(Number(e.target.value)));
  for (const button of document.querySelectorAll('#export-buttons button')) {
    button.addEventListener('click', () => {
      if (state.busy) return;
      setBusy(true);
      state.client.export(button.dataset.format);
    });
  }
}

await initViewer();
wireControls();
spawnWorker();
setBusy(false);
await startViewer();
if (document.body.dataset.state === 'starting') setState('idle');
