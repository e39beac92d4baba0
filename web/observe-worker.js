// The observer page's Web Worker: the keypoint detector (tract, in pkg/egoexo_web_worker.js)
// on each camera frame the page hands over as an ImageBitmap. Where to crop, the detector and
// the keypoints data frame are Rust (crates/egoexo-web-worker/src/observe.rs, LiveDetector);
// this file fetches the model, draws the crop on an OffscreenCanvas and passes bytes along.
//
// page → worker: {type: 'frame', bitmap, stampNs}  (the bitmap is transferred and closed here)
//                {type: 'region', min: [x, y], max: [x, y], atNs}  (a watching page's wearer
//                 region, the relay's `wearer-region` with its time on this page's clock)
// worker → page: {type: 'ready', inputSize, bones}
//                {type: 'keypoints', frame (ArrayBuffer, the data frame to send), keypoints,
//                 window, region, cropSource, detectMs, frames, found, width, height}
//                {type: 'error', message}

import init, { LiveDetector } from './pkg/egoexo_web_worker.js';

let detector = null;
let canvas = null;
let context = null;

function fail(error) {
  postMessage({ type: 'error', message: error instanceof Error ? error.message : String(error) });
}

async function fetchBytes(url) {
  const response = await fetch(url);
  if (!response.ok) throw new Error(`${url}: HTTP ${response.status}`);
  return new Uint8Array(await response.arrayBuffer());
}

async function load() {
  await init();
  const manifestUrl = new URL('models/manifest.json', import.meta.url);
  const manifest = await fetchBytes(manifestUrl);
  const file = LiveDetector.detectorFile(manifest);
  const model = await fetchBytes(new URL(file, manifestUrl));
  detector = new LiveDetector(manifest, model);
  const side = detector.inputSize;
  canvas = new OffscreenCanvas(side, side);
  context = canvas.getContext('2d', { willReadFrequently: true });
  postMessage({ type: 'ready', inputSize: side, bones: LiveDetector.bones() });
}

function detect({ bitmap, stampNs }) {
  const { width, height } = bitmap;
  const side = detector.inputSize;
  const draw = detector.crop(width, height, stampNs);
  context.fillStyle = '#000';
  context.fillRect(0, 0, side, side);
  if (draw.length === 8) context.drawImage(bitmap, ...draw);
  bitmap.close();
  const pixels = context.getImageData(0, 0, side, side).data;
  const cropSource = detector.cropSource;
  const started = performance.now();
  const frame = detector.detect(new Uint8Array(pixels.buffer, pixels.byteOffset, pixels.byteLength), stampNs);
  const detectMs = performance.now() - started;
  postMessage({
    type: 'keypoints',
    frame: frame.buffer,
    keypoints: detector.keypoints(),
    window: detector.window(),
    region: detector.region(),
    cropSource,
    detectMs,
    frames: detector.frames,
    found: detector.found,
    width,
    height,
  }, [frame.buffer]);
}

const ready = load().catch((error) => {
  fail(`The detector could not load: ${error instanceof Error ? error.message : error}`);
  throw error;
});

onmessage = async (event) => {
  const message = event.data;
  if (message?.type === 'region') {
    await ready.catch(() => {});
    try {
      detector?.propose(message.min[0], message.min[1], message.max[0], message.max[1], message.atNs);
    } catch (error) {
      // A region this page cannot use: the crop carries on without it.
      console.warn('egoexo observe: a wearer region was ignored:', error instanceof Error ? error.message : error);
    }
    return;
  }
  if (message?.type !== 'frame') return;
  try {
    await ready;
    detect(message);
  } catch (error) {
    message.bitmap?.close?.();
    fail(error);
  }
};
