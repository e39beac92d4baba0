// The page's shared state and its chrome: the error and progress panels, the busy flag, the
// state the page is in (`body[data-state]`, which the e2e tests wait on), performance marks
// and downloads. Every other module of the page imports this one; it imports none of them.

export const $ = (id) => document.getElementById(id);
export const params = new URLSearchParams(location.search);

// Everything the page remembers between events. Only this module creates fields; the others
// read and set these. The e2e tests do not read it: they read `window.egoexo`
// (test-surface.js, docs/page-test-surface.md).
export const state = {
  viewer: null, // the Viewer (egoexo-viewer) drawing the canvas, once it started
  worker: null, // the current Web Worker (replaced when it crashes)
  client: null, // the WorkerClient of `worker`
  busy: false,
  session: null, // the import summary
  scene: null, // the last scene JSON (Uint8Array)
  summary: null, // the last reconstruction summary
  models: null, // the loaded models' summary: {model_sets: [{tracking_points, lookahead, …}], bytes}
  reconstructStarted: 0, // performance.now() when the reconstruction was asked for
  share: { apiBase: location.origin, server: null }, // the share API and its limits
  linkable: false, // whether the address can say what is shown (sample, ?url=, share)
  pendingTime: null, // where a link asked to open: {start, end}
  inputBytes: 0, // size of the opened file (does the recording fit in a share?)
  notRead: [], // files of a dropped folder left unread, with why (shown with the session's warnings)
  openedShare: null, // {includes_recording} of a share being shown
  sharedBy: null, // "(shared, made by …)" of the share being shown
  selecting: null, // {id, moment, how} while another participant of a capture is being opened
  videoExport: null, // the AbortController of a video being made
  plotAxis: null, // {left, width} of the timeline plots in CSS pixels, when drawn
  live: null, // the Live panel's state (live.js)
};

export function setState(name) {
  document.body.dataset.state = name;
}

export function showError(title, message) {
  $('error-title').textContent = title;
  $('error-message').textContent = message;
  $('error-panel').hidden = false;
}

export function clearError() {
  $('error-panel').hidden = true;
}

export function showProgress(text, fraction) {
  $('progress-panel').hidden = false;
  $('progress-text').textContent = text;
  if (fraction === null) $('progress').removeAttribute('value');
  else $('progress').value = fraction;
}

// The reconstruction on screen is about to be replaced: stop playing it, so that drawing it
// does not take the CPU from the import and reconstruction (measured in the e2e suite with a
// software renderer: the detector step of the next session took 30 s instead of 4.5 s per
// observer while the previous one played).
export function pauseShown() {
  state.viewer?.pause();
}

export function setBusy(busy) {
  state.busy = busy;
  for (const el of [$('file-input'), $('folder-input'), $('sample-button')]) el.disabled = busy;
  for (const el of document.querySelectorAll('#export-buttons button, #participants button')) el.disabled = busy;
  $('cancel-button').disabled = !busy;
  if (!busy) $('progress-panel').hidden = true;
}

export function fail(title, message) {
  state.selecting = null;
  setBusy(false);
  showError(title, message);
  setState('error');
}

// Performance marks (User Timing) of the page's first load, read by the e2e suite: models
// ready in the worker, the first session imported, the first skeleton on screen.
export function markOnce(name) {
  if (performance.getEntriesByName(name, 'mark').length === 0) performance.mark(name);
}

export function download(bytes, fileName, mimeType) {
  const url = URL.createObjectURL(new Blob([bytes], { type: mimeType }));
  const a = document.createElement('a');
  a.href = url;
  a.download = fileName;
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10_000);
}
