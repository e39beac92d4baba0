// Opening a session: a dropped or picked file or folder, the sample, a session by URL
// (`?url=`), or a share link (`#share=`). The bytes go to the worker (which imports them);
// the address is kept saying what is shown, so that a copied link opens the same thing.

import { WorkerClient, fragment_with_time, parse_fragment } from './pkg/egoexo_viewer.js';
import { $, clearError, fail, pauseShown, setBusy, setState, showError, showProgress, state } from './page.js';
import { fetchShare } from './share.js';

// Assets (samples among them) live beside this script, under the build's versioned folder.
const SAMPLES_URL = new URL('samples/samples.json', import.meta.url);

// Starts an import: `open(client)` sends the request (its bytes go to the worker).
function startJob(open) {
  if (state.busy) return;
  clearError();
  pauseShown();
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
  state.notRead = [];
  startJob((client) => client.open_archive(file.name, bytes));
}

async function openFolder(name, dropped) {
  // dropped: [{path, file}] with paths relative to the dropped folder's parent. A raw VRS
  // recording, or a file larger than any session file may be, is left unread (Rust says
  // which, and why); the session's warnings list them.
  const notRead = [];
  const entries = dropped.filter((e) => {
    const why = WorkerClient.droppedFileNotRead(e.path, e.file.size);
    if (why) notRead.push(`${e.path}: ${why}`);
    return !why;
  });
  const contents = await Promise.all(entries.map(async (e) => new Uint8Array(await e.file.arrayBuffer())));
  setSource('', false);
  state.inputBytes = contents.reduce((n, c) => n + c.length, 0);
  state.notRead = notRead;
  startJob((client) => client.open_files(name, entries.map((e) => e.path), contents));
}

export async function openSample() {
  try {
    clearError();
    const list = await fetchOk(SAMPLES_URL).then((r) => r.json());
    const sample = list.samples[0];
    const bytes = new Uint8Array(await fetchOk(new URL(sample.file, SAMPLES_URL)).then((r) => r.arrayBuffer()));
    setSource(fragment_with_time(location.hash.startsWith('#sample') ? location.hash : '#sample', state.pendingTime?.start, state.pendingTime?.end), true);
    state.inputBytes = bytes.length;
    state.notRead = [];
    startJob((client) => client.open_archive(sample.file.split('/').pop(), bytes));
  } catch (error) {
    fail('Could not load the sample', error.message);
  }
}

// `?url=<https URL of a .egoexo or zip>`: a session hosted anywhere that allows CORS.
export async function openUrl(address) {
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
  state.notRead = [];
  const name = decodeURIComponent(url.pathname.split('/').pop() || 'session.egoexo');
  startJob((client) => client.open_archive(name, bytes));
}

// `#share=<id>.<key>`: fetch the sealed share and open it in the worker.
export async function openShareLink(share) {
  clearError();
  pauseShown();
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
  state.notRead = [];
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

// What the address asks for: a share, a session by URL, or the sample, maybe at a moment.
export function readAddress() {
  try {
    return parse_fragment(location.hash);
  } catch (error) {
    showError('This link is not valid', error.message ?? String(error));
    return { share: null, time: null, sample: false };
  }
}

// Wires the file and folder pickers, the sample button and the drop zone.
export function wireOpen() {
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
}
