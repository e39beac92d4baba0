// Saving what is shown: a video of the view (the loop range or the whole timeline), a
// picture of the frame, the reconstruction in an export format, and the session itself. The
// files are made by the viewer (video, picture) and the worker (exports, `.egoexo`).

import { $, download, setBusy, showError, state } from './page.js';
import { exportPng, exportVideo } from './video.js';

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

// Wires the video, picture, export-format and save-session buttons.
export function wireSaving() {
  $('video-button').addEventListener('click', saveVideo);
  $('video-cancel').addEventListener('click', () => state.videoExport?.abort());
  $('png-button').addEventListener('click', savePng);
  $('save-session').addEventListener('click', () => {
    if (state.busy) return;
    setBusy(true);
    state.client.save_session();
  });
  for (const button of document.querySelectorAll('#export-buttons button')) {
    button.addEventListener('click', () => {
      if (state.busy) return;
      setBusy(true);
      state.client.export(button.dataset.format);
    });
  }
}
