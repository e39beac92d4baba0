// The observer page: a phone's or a laptop's camera joins a live room as a static observer
// and streams the keypoints its detector finds of the wearer (docs/live-protocol.md, "The
// observer page").
//
// This file owns the camera, the clock and the socket. The hello, the calibration, the frame
// times, where to crop, the detector and the data frames are Rust (pkg/egoexo_web_worker.js:
// crates/egoexo-web-worker/src/observe.rs); the detector runs in observe-worker.js, fed
// ImageBitmaps, so the page's thread only shows the preview.

import init, { XrJoin, observeCalibration, observeFrameTimeNs } from './pkg/egoexo_web_worker.js';
import { DeviceSocket } from './device-socket.js';
import { JoinForm, connectionHooks, message, setState, showError } from './device-page.js';

const $ = (id) => document.getElementById(id);
const ui = {
  target: $('target-input'),
  camera: $('camera-select'),
  fov: $('fov-input'),
  previewPanel: $('preview-panel'),
  video: $('preview-video'),
  overlay: $('preview-overlay'),
  connection: $('connection'),
  cameraInfo: $('camera-info'),
  captureRate: $('capture-rate'),
  detectRate: $('detect-rate'),
  cropSource: $('crop-source'),
  framesSent: $('frames-sent'),
  registration: $('registration'),
  screen: $('screen-state'),
};

const nowNs = () => (performance.timeOrigin + performance.now()) * 1e6;

const page = { form: null, run: null }; // form: the JoinForm (made once the wasm module is in)

// Detectors side by side, each in its own worker (tract runs one thread in each); a frame
// goes to whichever is free, so one detector's 50–70 ms (wasm, a laptop core) no longer caps
// the rate near 12 frames/s. Two, where the device has two cores or more (a phone has 6–8);
// more would take the cores the camera and the browser need. `?detectors=1` runs one.
function detectorCount(params) {
  const asked = Number(params.get('detectors'));
  if (Number.isInteger(asked) && asked >= 1 && asked <= 4) return asked;
  return Math.min(2, Math.max(1, navigator.hardwareConcurrency ?? 1));
}

// Keeps the screen on while observing: a phone on a stand would dim, lock and stop its camera.
// The Screen Wake Lock API; the browser lets go of the lock whenever the page is hidden, so it
// is taken again when the page is shown. `document.body.dataset.screen` says where it stands
// (held, released, refused, unsupported, off).
class ScreenAwake {
  constructor() {
    this.sentinel = null;
    this.pending = false;
    this.wanted = false;
    this.onVisibility = () => {
      if (this.wanted && document.visibilityState === 'visible') this.take();
    };
  }

  hold() {
    this.wanted = true;
    document.addEventListener('visibilitychange', this.onVisibility);
    this.take();
  }

  async take() {
    // One request at a time: the page shown again while the first is pending does not ask twice.
    if (this.pending || (this.sentinel && !this.sentinel.released)) return;
    if (!('wakeLock' in navigator)) {
      this.show('unsupported', 'may sleep: this browser cannot keep it on (no Screen Wake Lock) — keep it awake in the device\'s settings');
      return;
    }
    this.pending = true;
    try {
      const sentinel = await navigator.wakeLock.request('screen');
      if (!this.wanted) {
        sentinel.release().catch(() => {});
        return;
      }
      this.sentinel = sentinel;
      sentinel.addEventListener('release', () => {
        if (this.wanted) this.show('released', 'let go while the page was hidden: kept on again once it is shown');
      });
      this.show('held', 'kept on while observing');
    } catch (error) {
      this.show('refused', `may sleep: the browser refused to keep it on (${message(error)})`);
    } finally {
      this.pending = false;
    }
  }

  release() {
    this.wanted = false;
    document.removeEventListener('visibilitychange', this.onVisibility);
    this.sentinel?.release().catch(() => {});
    this.sentinel = null;
    this.show('off', '—');
  }

  show(state, text) {
    document.body.dataset.screen = state;
    ui.screen.textContent = text;
  }
}

// Frames per second over the last second, from the times they happened.
class Rate {
  constructor() { this.times = []; }
  tick(now = performance.now()) {
    this.times.push(now);
    while (this.times.length > 0 && this.times[0] < now - 1000) this.times.shift();
  }
  get hz() {
    const now = performance.now();
    return this.times.filter((t) => t >= now - 1000).length;
  }
}

// One run: the camera, the detector workers and the socket, reconnected on retryable closes.
class Observation {
  constructor(join, deviceId, target, stream, detectors) {
    this.join = join;
    this.joinLabel = join.label;
    this.deviceId = deviceId;
    this.target = target;
    this.stream = stream;
    this.track = stream.getVideoTracks()[0];
    this.ended = false;
    this.relay = new DeviceSocket({
      hello: () => this.hello,
      nowNs,
      ...connectionHooks(this.joinLabel, {
        state: 'observing',
        doing: 'observing for',
        // The camera first, then keypoints: viewers place keypoints with it.
        onWelcome: () => this.relay.sendText(this.calibration),
        onFail: (text) => this.fail(text),
      }),
      onObserverWorld: (world) => {
        this.world = world;
        this.showStats();
      },
      // Where the watching page sees the wearer in this camera's image: the next frames are
      // cropped there (the worker checks it).
      onWearerRegion: (region) => {
        this.regions += 1;
        for (const d of this.detectors) {
          d.worker.postMessage({ type: 'region', min: region.region.min, max: region.region.max, atNs: region.at_ns });
        }
      },
    });
    this.detectorCount = detectors;
    // Each: {worker, ready, busy, frames, found}.
    this.detectors = [];
    this.bones = new Uint8Array();
    this.captured = new Rate();
    this.detected = new Rate();
    this.detectMs = [];
    this.last = null; // the newest detection, for the overlay
    this.world = null; // the newest word from a watching page on this camera's registration
    this.regions = 0; // wearer regions heard from watching pages
    this.uiTimer = setInterval(() => this.showStats(), 250);
    this.awake = new ScreenAwake();
  }

  async start() {
    const settings = this.track.getSettings();
    const video = ui.video;
    // Shown before it plays: a video that is not rendered gets no frame callbacks.
    ui.previewPanel.hidden = false;
    video.srcObject = this.stream;
    await video.play();
    this.width = video.videoWidth || settings.width;
    this.height = video.videoHeight || settings.height;
    // Browsers do not report a camera's field of view; unless the person gives it, the focal
    // length is a guess that registration refines (the hello says so).
    const fov = ui.fov.value === '' ? Number.NaN : Number(ui.fov.value);
    const calibration = observeCalibration(this.width, this.height, fov);
    this.calibration = calibration.json;
    this.focalKnown = calibration.focalKnown;
    this.hello = this.join.observerHello(this.deviceId, this.target, this.focalKnown);
    ui.cameraInfo.textContent = `${this.track.label || 'camera'}, ${this.width}×${this.height}` +
      (this.focalKnown ? `, ${fov}° wide` : ' (field of view unknown: focal length guessed, registration refines it)');
    ui.overlay.width = this.width;
    ui.overlay.height = this.height;
    for (let i = 0; i < this.detectorCount; i += 1) {
      const detector = { worker: null, ready: false, busy: false, frames: 0, found: 0 };
      detector.worker = new Worker(new URL('observe-worker.js', import.meta.url), { type: 'module' });
      detector.worker.onmessage = (event) => this.onWorker(detector, event.data);
      detector.worker.onerror = (event) => this.fail(`The detector stopped: ${event.message ?? 'an error in its worker'}`);
      this.detectors.push(detector);
    }
    this.track.addEventListener('ended', () => this.fail('The camera stopped (unplugged, or taken by another app).'));
    this.relay.connect();
    this.awake.hold();
    this.nextFrame();
  }

  nextFrame() {
    if (this.ended) return;
    ui.video.requestVideoFrameCallback((now, metadata) => this.onVideoFrame(now, metadata));
  }

  onVideoFrame(now, metadata) {
    if (this.ended) return;
    this.nextFrame();
    this.captured.tick();
    // When the camera's first frame was captured (Unix ms): what a test films from starts then.
    // The first frame this page sees is a later one (the camera runs from when it was opened,
    // while the page starts its detector), and its media time counts from the first.
    document.body.dataset.firstFrameMs ??= String(performance.timeOrigin
      + (metadata.captureTime ?? metadata.presentationTime ?? now) - 1000 * (metadata.mediaTime ?? 0));
    // One frame at a time in each detector: a frame that arrives while all are busy is
    // skipped, so what is sent is never stale.
    const free = this.detectors.find((d) => d.ready && !d.busy);
    if (!free || !this.relay.open) return;
    const stampNs = observeFrameTimeNs(performance.timeOrigin, metadata.captureTime ?? Number.NaN,
      metadata.presentationTime ?? now);
    if (stampNs === undefined) return;
    free.busy = true;
    createImageBitmap(ui.video).then((bitmap) => {
      if (this.ended) {
        bitmap.close();
        return;
      }
      free.worker.postMessage({ type: 'frame', bitmap, stampNs }, [bitmap]);
    }).catch((error) => {
      free.busy = false;
      console.warn('egoexo observe: a frame could not be read:', message(error));
    });
  }

  onWorker(detector, data) {
    if (this.ended) return;
    if (data.type === 'ready') {
      detector.ready = true;
      this.bones = data.bones;
      return;
    }
    if (data.type === 'error') {
      this.fail(data.message);
      return;
    }
    if (data.type !== 'keypoints') return;
    detector.busy = false;
    detector.frames = data.frames;
    detector.found = data.found;
    this.detected.tick();
    this.detectMs.push(data.detectMs);
    if (this.detectMs.length > 30) this.detectMs.shift();
    this.last = data;
    this.relay.sendFrame(data.frame);
    this.draw();
  }

  fail(text) {
    this.stop();
    showError(text);
  }

  stop(closeReason = 'the camera stopped observing') {
    if (this.ended) return;
    this.ended = true;
    clearInterval(this.uiTimer);
    this.awake.release();
    this.showStats();
    this.relay.close(closeReason);
    for (const d of this.detectors) d.worker.terminate();
    for (const track of this.stream.getTracks()) track.stop();
    ui.connection.textContent = 'not connected';
    if (page.run === this) page.run = null;
    page.form.running(false);
    if (document.body.dataset.state !== 'error') setState('ready');
  }

  // The preview's overlay: the searched window (dashed), the wearer region the ego signals
  // proposed (solid, when the frame was cropped there) and the person found.
  draw() {
    const canvas = ui.overlay;
    const ctx = canvas.getContext('2d');
    ctx.clearRect(0, 0, canvas.width, canvas.height);
    const last = this.last;
    if (!last) return;
    const scale = Math.max(1, canvas.width / 640);
    if (last.window.length === 3) {
      const [x, y, side] = last.window;
      ctx.setLineDash([8 * scale, 6 * scale]);
      ctx.lineWidth = 2 * scale;
      ctx.strokeStyle = '#f2c14e';
      ctx.strokeRect(x, y, side, side);
      ctx.setLineDash([]);
    }
    if (last.region.length === 4) {
      const [x0, y0, x1, y1] = last.region;
      ctx.lineWidth = 2 * scale;
      ctx.strokeStyle = '#4ea1f2';
      ctx.strokeRect(x0, y0, x1 - x0, y1 - y0);
    }
    const k = last.keypoints;
    const at = (i) => (Number.isNaN(k[3 * i]) ? null : [k[3 * i], k[3 * i + 1]]);
    ctx.strokeStyle = '#5fd38d';
    ctx.lineWidth = 3 * scale;
    for (let b = 0; b + 1 < this.bones.length; b += 2) {
      const p = at(this.bones[b]);
      const q = at(this.bones[b + 1]);
      if (!p || !q) continue;
      ctx.beginPath();
      ctx.moveTo(p[0], p[1]);
      ctx.lineTo(q[0], q[1]);
      ctx.stroke();
    }
    ctx.fillStyle = '#ffffff';
    for (let i = 0; i < k.length / 3; i += 1) {
      const p = at(i);
      if (!p) continue;
      ctx.beginPath();
      ctx.arc(p[0], p[1], 4 * scale, 0, 2 * Math.PI);
      ctx.fill();
    }
  }

  showStats() {
    const ended = this.ended;
    ui.captureRate.textContent = ended ? '—' : `${this.captured.hz} frames/s`;
    const ms = [...this.detectMs].sort((a, b) => a - b);
    const median = ms.length ? ms[Math.floor(ms.length / 2)] : null;
    const last = this.last;
    const ready = this.detectors.some((d) => d.ready);
    const frames = this.detectors.reduce((n, d) => n + d.frames, 0);
    const found = this.detectors.reduce((n, d) => n + d.found, 0);
    const side = this.detectors.length > 1 ? ` by ${this.detectors.length} detectors side by side` : '';
    ui.detectRate.textContent = ended || !ready
      ? (ready ? '—' : 'loading the detector…')
      : `${this.detected.hz} frames/s${median === null ? '' : `, ${median.toFixed(0)} ms each`}${side}` +
        (frames ? `; someone found in ${found} of ${frames} frames` : '');
    ui.cropSource.textContent = ended || !last ? '—' : last.cropSource;
    document.body.dataset.cropSource = last ? last.cropSource : '';
    document.body.dataset.regions = String(this.regions);
    const { sent, skipped } = this.relay;
    ui.framesSent.textContent = `${sent}${skipped ? ` (${skipped} skipped on a slow network)` : ''}`;
    // What the page watching the room says: registering (not used yet), then registered (its
    // rays are fused), with why.
    const world = this.world;
    ui.registration.textContent = ended ? '—'
      : world ? world.message : 'waiting for a page watching the room to register this camera';
    document.body.dataset.registration = ended || !world ? 'none' : world.state;
    document.body.dataset.detections = String(found);
  }
}

async function listCameras() {
  try {
    const devices = await navigator.mediaDevices.enumerateDevices();
    const cameras = devices.filter((d) => d.kind === 'videoinput' && d.deviceId);
    const chosen = ui.camera.value;
    ui.camera.replaceChildren(new Option('the default camera', ''));
    cameras.forEach((d, i) => ui.camera.append(new Option(d.label || `camera ${i + 1}`, d.deviceId)));
    ui.camera.value = chosen;
  } catch {
    // labels come after permission; the default camera still works
  }
}

async function startObserving() {
  // The ids are checked before the camera is asked for.
  const taken = page.form.take((join, deviceId) => join.observerHello(deviceId, ui.target.value, true));
  if (!taken) return;
  const { join, deviceId } = taken;
  let stream;
  try {
    const video = { width: { ideal: 640 }, height: { ideal: 480 } };
    if (ui.camera.value) video.deviceId = { exact: ui.camera.value };
    stream = await navigator.mediaDevices.getUserMedia({ video, audio: false });
  } catch (error) {
    page.form.running(false);
    const why = error?.name === 'NotAllowedError' ? 'permission to use the camera was refused' : message(error);
    showError(`No camera: ${why}.`);
    return;
  }
  listCameras();
  const detectors = detectorCount(new URLSearchParams(location.search));
  const run = new Observation(join, deviceId, ui.target.value.trim(), stream, detectors);
  page.run = run;
  page.form.running(true);
  try {
    await run.start();
  } catch (error) {
    run.fail(message(error));
  }
}

async function main() {
  await init();
  page.form = new JoinForm(XrJoin, {
    idKey: 'egoexo.observe.device-id',
    defaultId: 'camera',
    codeHelp: 'The code shown where the room was made, or open the observer link on this device.',
    enterLabel: 'Start observing',
    start: startObserving,
    page,
  });
  const params = new URLSearchParams(location.search);
  if (params.get('target')) ui.target.value = params.get('target');
  if (params.get('fov')) ui.fov.value = params.get('fov');
  if (params.get('device')) page.form.ui.device.value = params.get('device');
  if (!navigator.mediaDevices?.getUserMedia) {
    page.form.unsupported(window.isSecureContext
      ? 'This browser gives pages no camera.'
      : 'A camera needs a secure page: open this page over https:// (or on localhost, e.g. through `adb reverse`).');
    return;
  }
  if (!('requestVideoFrameCallback' in HTMLVideoElement.prototype)) {
    page.form.unsupported('This browser cannot hand a page its camera frames one by one (requestVideoFrameCallback).');
    return;
  }
  await listCameras();
  page.form.ready();
}

main().catch((error) => showError(`The page could not start: ${message(error)}`));
