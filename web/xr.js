// The WebXR page: a headset's browser joins a live room as the wearer and streams, every XR
// frame, the viewer pose (head) and both wrists (controller grips, or tracked hands' wrist
// joints) to the relay (docs/live-protocol.md, "The WebXR page").
//
// This file reads WebXR and the clock and owns the socket. The geometry (XR spaces → session
// conventions), the frames, the hello, the pongs and which closes to retry are Rust, in
// pkg/egoexo_web_worker.js (crates/egoexo-web-worker/src/xr.rs over egoexo_core::xr).

import init, { XrJoin, XrSource, xr_pose_frame } from './pkg/egoexo_web_worker.js';
import { DeviceSocket } from './device-socket.js';
import { JoinForm, connectionHooks, message, setState, showError } from './device-page.js';

const $ = (id) => document.getElementById(id);
const ui = {
  connection: $('connection'),
  tracking: $('tracking'),
  framesSent: $('frames-sent'),
  rate: $('rate'),
};

// The page's clock in nanoseconds since the Unix epoch: it stamps the frames and answers the
// relay's pings, so the relay can put both on its own clock.
const epochNs = (performanceMs) => (performance.timeOrigin + performanceMs) * 1e6;
const nowNs = () => epochNs(performance.now());

const SIDES = [
  { handedness: 'left', grip: () => XrSource.LeftGrip, hand: () => XrSource.LeftHandWrist },
  { handedness: 'right', grip: () => XrSource.RightGrip, hand: () => XrSource.RightHandWrist },
];

const page = {
  form: null, // the JoinForm (made once the wasm module is in)
  xrMode: null, // 'immersive-vr', 'immersive-ar' or 'inline'
  run: null, // the running stream, below
};





// One stream: an XR session and the socket to the relay, reconnected on retryable closes
// while the session lasts.
class Stream {
  constructor(join, deviceId, session) {
    const hello = join.hello(deviceId);
    const label = join.label;
    this.session = session;
    this.ended = false;
    this.relay = new DeviceSocket({
      hello: () => hello,
      nowNs,
      ...connectionHooks(label, { state: 'streaming', doing: 'streaming to', onFail: (text) => this.fail(text) }),
    });
    this.frameTimes = []; // performance.now() of recent XR frames, for the rate
    this.tracking = '—';
    this.refSpace = null;
    this.gl = null;
    this.position = new Float32Array(3);
    this.orientation = new Float32Array(4);
    this.warned = false;
    this.uiTimer = setInterval(() => this.showStats(), 250);
  }

  // Ends the stream for good with an error the person can read once out of XR.
  fail(text) {
    this.stop();
    showError(text);
  }

  stop(closeReason = 'the wearer stopped streaming') {
    if (this.ended) return;
    this.ended = true;
    clearInterval(this.uiTimer);
    this.showStats();
    this.relay.close(closeReason);
    ui.connection.textContent = 'not connected';
    try {
      this.session.end().catch(() => {}); // already ended when the person left XR
    } catch {
      // ended already
    }
    if (page.run === this) page.run = null;
    page.form.running(false);
    if (document.body.dataset.state !== 'error') setState('ready');
  }

  async startXr() {
    const session = this.session;
    session.addEventListener('end', () => this.stop('the headset left XR'));
    const canvas = document.createElement('canvas');
    const gl = canvas.getContext('webgl2', { xrCompatible: true, alpha: false }) ??
      canvas.getContext('webgl', { xrCompatible: true, alpha: false });
    if (!gl) throw new Error('This browser has no WebGL, which WebXR needs to show anything.');
    await gl.makeXRCompatible?.();
    session.updateRenderState({ baseLayer: new XRWebGLLayer(session, gl) });
    this.gl = gl;
    // 'local-floor' puts the floor at y = 0; 'local' (origin at the head's first pose) will do.
    for (const type of ['local-floor', 'local']) {
      try {
        this.refSpace = await session.requestReferenceSpace(type);
        this.refSpaceType = type;
        break;
      } catch {
        // try the next
      }
    }
    if (!this.refSpace) throw new Error('This headset offers no tracked space (local-floor or local) to stream poses in.');
    session.requestAnimationFrame((t, frame) => this.onFrame(t, frame));
  }

  onFrame(time, frame) {
    if (this.ended) return;
    frame.session.requestAnimationFrame((t, f) => this.onFrame(t, f));
    const now = performance.now();
    this.frameTimes.push(now);
    while (this.frameTimes.length > 0 && this.frameTimes[0] < now - 1000) this.frameTimes.shift();
    // The poses are predicted for the display time: that is when they are true.
    const stamp = epochNs(frame.predictedDisplayTime ?? time);
    const viewer = frame.getViewerPose(this.refSpace);
    const tracked = [];
    this.send(XrSource.Viewer, stamp, viewer && !viewer.emulatedPosition ? viewer.transform : null);
    if (viewer && !viewer.emulatedPosition) tracked.push('head');
    for (const side of SIDES) {
      const { source, transform, what } = this.wrist(frame, side);
      this.send(source, stamp, transform);
      tracked.push(transform ? `${side.handedness} ${what}` : `${side.handedness} lost`);
    }
    this.tracking = tracked.join(' · ');
    this.draw(frame);
  }

  // The wrist pose of one side: the tracked hand's wrist joint, else the controller's grip.
  wrist(frame, side) {
    const input = [...frame.session.inputSources].find((s) => s.handedness === side.handedness);
    if (input?.hand && frame.getJointPose) {
      const joint = input.hand.get('wrist');
      const pose = joint ? frame.getJointPose(joint, this.refSpace) : null;
      return { source: side.hand(), transform: pose && !pose.emulatedPosition ? pose.transform : null, what: 'hand' };
    }
    if (input?.gripSpace) {
      const pose = frame.getPose(input.gripSpace, this.refSpace);
      return { source: side.grip(), transform: pose && !pose.emulatedPosition ? pose.transform : null, what: 'controller' };
    }
    return { source: side.grip(), transform: null, what: 'controller' };
  }

  send(source, stampNs, transform) {
    if (!this.relay.open) return;
    let bytes;
    try {
      if (transform) {
        const { position: p, orientation: q } = transform;
        this.position.set([p.x, p.y, p.z]);
        this.orientation.set([q.x, q.y, q.z, q.w]);
      }
      bytes = xr_pose_frame(source, stampNs, this.position, this.orientation, transform !== null);
    } catch (error) {
      // A pose the runtime got wrong (not finite, not a rotation) is sent as lost.
      if (!this.warned) console.warn('egoexo xr: a pose was not usable:', message(error));
      this.warned = true;
      bytes = xr_pose_frame(source, stampNs, this.position, this.orientation, false);
    }
    this.relay.sendFrame(bytes);
  }

  // What the wearer sees: the colour of the connection (green streaming, amber connecting,
  // red stopped).
  draw(frame) {
    const gl = this.gl;
    const layer = frame.session.renderState.baseLayer;
    if (!gl || !layer) return;
    gl.bindFramebuffer(gl.FRAMEBUFFER, layer.framebuffer);
    const state = document.body.dataset.state;
    const [r, g, b] = state === 'streaming' ? [0.03, 0.2, 0.1] : state === 'error' ? [0.35, 0.04, 0.04] : [0.3, 0.2, 0.02];
    gl.clearColor(r, g, b, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
  }

  showStats() {
    const { sent, skipped } = this.relay;
    ui.framesSent.textContent = `${sent}${skipped ? ` (${skipped} skipped on a slow network)` : ''}`;
    const hz = this.frameTimes.length;
    ui.rate.textContent = this.ended ? '—' : `${hz} Hz (${this.refSpaceType ?? 'no'} space)`;
    ui.tracking.textContent = this.ended ? '—' : this.tracking;
  }
}

async function enterXr() {
  // The device id is checked before entering XR.
  const taken = page.form.take((join, deviceId) => join.hello(deviceId));
  if (!taken) return;
  const { join, deviceId } = taken;
  let session;
  try {
    // Asked for first, while the click still counts as the person's gesture.
    const features = page.xrMode === 'inline'
      ? { optionalFeatures: ['local-floor', 'local'] }
      : { optionalFeatures: ['local-floor', 'local', 'hand-tracking'] };
    session = await navigator.xr.requestSession(page.xrMode, features);
  } catch (error) {
    page.form.running(false);
    showError(`The headset did not start XR: ${message(error)}`);
    return;
  }
  const run = new Stream(join, deviceId, session);
  page.run = run;
  page.form.running(true);
  run.relay.connect();
  try {
    await run.startXr();
  } catch (error) {
    run.fail(message(error));
  }
}

async function detectXr() {
  if (!navigator.xr) {
    return window.isSecureContext
      ? 'This browser has no WebXR. Open this page in a headset\'s browser (Meta Quest Browser).'
      : 'WebXR needs a secure page: open this page over https:// (or on localhost).';
  }
  for (const mode of ['immersive-vr', 'immersive-ar', 'inline']) {
    try {
      if (await navigator.xr.isSessionSupported(mode)) {
        page.xrMode = mode;
        return null;
      }
    } catch {
      // not this mode
    }
  }
  return 'This browser has WebXR but cannot start an XR session here.';
}

async function main() {
  await init();
  page.form = new JoinForm(XrJoin, {
    idKey: 'egoexo.xr.device-id',
    defaultId: 'quest',
    codeHelp: 'The code shown where the room was made, or open the device link on this headset.',
    enterLabel: 'Enter XR',
    start: enterXr,
    page,
  });
  const unsupported = await detectXr();
  if (unsupported) {
    page.form.unsupported(unsupported);
    return;
  }
  if (page.xrMode === 'inline') {
    page.form.note('No immersive XR here: streaming from an inline session, if this device tracks one.');
  }
  page.form.ready();
}

main().catch((error) => showError(`The page could not start: ${message(error)}`));
