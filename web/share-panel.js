// The Share dialog and the list of this browser's shares: ask the worker to seal the
// reconstruction (with or without its recording, within the server's limit), upload it,
// show and remember the link, delete a share. Sealing is the worker's (Rust); the HTTP calls
// are share.js's.

import { share_fragment } from './pkg/egoexo_viewer.js';
import { $, setBusy, setState, showError, state } from './page.js';
import { deleteShare, forgetShare, megabytes, rememberShare, savedShares, uploadShare } from './share.js';

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

export async function onShareSealed(event) {
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

export function showSavedShares() {
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

// Wires the Share button and the dialog's controls.
export function wireSharePanel() {
  $('share-button').addEventListener('click', openShareDialog);
  $('share-create').addEventListener('click', createShare);
  $('share-close').addEventListener('click', () => $('share-dialog').close());
  $('share-copy').addEventListener('click', () => copyText($('share-link').value, $('share-copy')));
}
