// The page's entry point: starts the viewer and the worker, routes the worker's events to the
// panels and wires the controls. Every computation happens in Rust, and so does every message
// to and from the worker: `WorkerClient` builds the requests and checks the events
// (docs/worker-protocol.md); the page's modules react to them:
//
//   page.js          shared state, errors, progress, busy, downloads (imports no other module)
//   view.js          the 3D view, its controls, the timeline plots
//   results.js       the session and result panels; reconstruct; switch participant
//   open.js          files, folders, the sample, ?url=, share links; what the address says
//   share-panel.js   the Share dialog and this browser's shares (share.js: the HTTP API)
//   save.js          video, picture, export formats, save the session (video.js: encoding)
//   live.js          the Live panel (docs/live-protocol.md)
//   test-surface.js  window.egoexo, what the e2e tests read (docs/page-test-surface.md)

import initViewer, { Viewer, WorkerClient } from './pkg/egoexo_viewer.js';
import { createLive } from './live.js';
import { openSample, openShareLink, openUrl, readAddress, wireOpen } from './open.js';
import { $, clearError, download, fail, markOnce, params, setBusy, setState, showError, showProgress, state } from './page.js';
import { showScene, showSession, startReconstruction } from './results.js';
import { wireSaving } from './save.js';
import { onShareSealed, showSavedShares, wireSharePanel } from './share-panel.js';
import { loadShareConfig } from './share.js';
import { installTestSurface } from './test-surface.js';
import { startViewer, wireViewControls } from './view.js';

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

const live = createLive(state, { fail, showSession, startReconstruction });

function wireControls() {
  wireOpen();
  $('cancel-button').addEventListener('click', () => {
    // The worker stops at its next window and keeps its models; events of the cancelled
    // job are dropped by the client.
    state.client.cancel();
    setBusy(false);
    showError('Cancelled', 'The reconstruction was cancelled.');
    setState('cancelled');
  });
  $('error-dismiss').addEventListener('click', clearError);
  $('rerun-button').addEventListener('click', () => {
    if (state.busy) return;
    clearError();
    startReconstruction();
  });
  wireViewControls();
  wireSaving();
  wireSharePanel();
  live.wire();
}

installTestSurface(state, Viewer, live);
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
