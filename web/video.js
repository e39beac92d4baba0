// The 3D view as a video: the viewer draws each frame, the browser's WebCodecs VideoEncoder
// encodes it (H.264), and the viewer's Rust muxer (mux_h264_mp4) writes the MP4. The frames
// are the looped range (a `t=a-b` link) or the whole session, at the session's frame rate,
// seen by the camera as it is (orbit, follow mode or an observer's view).

import { mux_h264_mp4 } from './pkg/egoexo_viewer.js';

// Constrained baseline first: no B-frames, so decode order is display order.
const CODECS = ['avc1.42e033', 'avc1.42e01f', 'avc1.4d0033', 'avc1.640033'];
// Queued frames the encoder may hold before the loop waits for it.
const MAX_QUEUE = 4;
// The longest video made in one go (the encoded frames are held in memory until muxed): ten
// minutes at 30 fps. Longer sessions export a range (a `t=a-b` link plays and exports it).
export const MAX_VIDEO_FRAMES = 18_000;

function bytesOf(buffer) {
  return ArrayBuffer.isView(buffer)
    ? new Uint8Array(buffer.buffer, buffer.byteOffset, buffer.byteLength).slice()
    : new Uint8Array(buffer).slice();
}

// Encodes frames `first..=last` of `viewer` and returns the MP4 bytes. `onProgress(fraction)`
// follows the frames; aborting `signal` stops between frames (an AbortError).
export async function exportVideo(viewer, { first, last, onProgress, signal }) {
  if (typeof VideoEncoder === 'undefined') {
    throw new Error('this browser has no WebCodecs VideoEncoder; video export needs Chrome or Edge 94+, '
      + 'Safari 16.4+ or Firefox 130+');
  }
  const count = last - first + 1;
  if (count > MAX_VIDEO_FRAMES) {
    throw new Error(`${count} frames is more than one video holds (${MAX_VIDEO_FRAMES}, ten minutes at 30 fps): `
      + 'export a range instead — open a link with t=START-END (seconds) to loop it, then export');
  }
  const canvas = viewer.canvas();
  const width = canvas.width & ~1;
  const height = canvas.height & ~1;
  const fps = viewer.fps();
  const base = { width, height, framerate: fps, bitrate: Math.round(width * height * fps * 0.12), avc: { format: 'avc' } };
  let config = null;
  for (const codec of CODECS) {
    const candidate = { ...base, codec };
    if ((await VideoEncoder.isConfigSupported(candidate)).supported) {
      config = candidate;
      break;
    }
  }
  if (!config) throw new Error(`this browser cannot encode H.264 video of ${width}×${height} px`);

  const chunks = [];
  let description = null;
  let failure = null;
  const encoder = new VideoEncoder({
    output: (chunk, meta) => {
      const bytes = new Uint8Array(chunk.byteLength);
      chunk.copyTo(bytes);
      chunks.push({ bytes, key: chunk.type === 'key' });
      if (meta?.decoderConfig?.description) description = bytesOf(meta.decoderConfig.description);
    },
    error: (error) => { failure = error; },
  });
  encoder.configure(config);
  const shown = viewer.frame();
  const wasPlaying = viewer.is_playing();
  viewer.pause();
  try {
    const keyEvery = Math.max(1, Math.round(2 * fps));
    for (let i = 0; i < count; i += 1) {
      if (signal?.aborted) throw new DOMException('the video export was cancelled', 'AbortError');
      if (failure) throw failure;
      viewer.seek(first + i);
      viewer.render_now();
      const frame = new VideoFrame(canvas, {
        timestamp: Math.round((i * 1e6) / fps),
        duration: Math.round(1e6 / fps),
        visibleRect: { x: 0, y: 0, width, height },
      });
      encoder.encode(frame, { keyFrame: i % keyEvery === 0 });
      frame.close();
      while (encoder.encodeQueueSize > MAX_QUEUE && !failure) {
        await new Promise((resolve) => encoder.addEventListener('dequeue', resolve, { once: true }));
      }
      onProgress?.((i + 1) / count);
    }
    await encoder.flush();
    if (failure) throw failure;
  } finally {
    if (encoder.state !== 'closed') encoder.close();
    viewer.seek(shown);
    if (wasPlaying) viewer.play();
  }
  if (!description) throw new Error('the encoder gave no H.264 parameter sets (avcC description)');
  const sizes = new Uint32Array(chunks.map((c) => c.bytes.length));
  const keys = new Uint8Array(chunks.map((c) => (c.key ? 1 : 0)));
  const data = new Uint8Array(sizes.reduce((a, b) => a + b, 0));
  let at = 0;
  for (const c of chunks) {
    data.set(c.bytes, at);
    at += c.bytes.length;
  }
  return mux_h264_mp4(description, width, height, fps, data, sizes, keys);
}

// The frame shown now as a PNG (the canvas as the viewer draws it).
export async function exportPng(viewer) {
  viewer.render_now();
  const canvas = viewer.canvas();
  return new Promise((resolve, reject) => canvas.toBlob(
    (blob) => (blob ? resolve(blob) : reject(new Error('the canvas gave no image'))), 'image/png'));
}
