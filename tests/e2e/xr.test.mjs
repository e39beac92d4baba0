// The WebXR page (web/xr.html) end to end in headless Chromium against `egoexo serve`: Meta's
// Immersive Web Emulation Runtime (npm `iwer`) plays a Quest 3 with known head, controller
// and hand poses; a viewer joined to the same room from another page decodes the relay's
// frames and finds those poses in session conventions (docs/live-protocol.md, "The WebXR
// page"), computed here from the documented frame conventions, not by the page's code.

import assert from 'node:assert/strict';
import { readFileSync } from 'node:fs';
import { createRequire } from 'node:module';
import { dirname, join } from 'node:path';
import { after, before, describe, test } from 'node:test';

import { metaQuest3 } from 'iwer';
import { relaxedHandPose } from 'iwer/lib/device/configs/hand/relaxed.js';

import { APP_URL, chromiumForFile } from './browser.mjs';

const IWER_BUNDLE = readFileSync(
  join(dirname(createRequire(import.meta.url).resolve('iwer/package.json')), 'build', 'iwer.js'),
  'utf8',
);
const SUBPROTOCOL = 'egoexo-live.1';
const LIVE_URL = (() => {
  const url = new URL('live', APP_URL);
  url.protocol = url.protocol === 'https:' ? 'wss:' : 'ws:';
  return url.href;
})();

// The emulated headset: standing at (0.1, 1.6, −0.3) looking down −Z; controllers held in
// front, turned and tilted so that no axis of the expected poses is trivial.
const yaw = (deg) => quatAxisAngle([0, 1, 0], (deg * Math.PI) / 180);
const HEADSET = { position: [0.1, 1.6, -0.3], quaternion: [0, 0, 0, 1] };
const LEFT = { position: [-0.25, 1.3, -0.55], quaternion: quatMul(yaw(20), quatAxisAngle([1, 0, 0], -0.4)) };
const RIGHT = { position: [0.32, 1.25, -0.5], quaternion: quatMul(yaw(-35), quatAxisAngle([0, 0, 1], 0.3)) };

// ---- Small vector and quaternion helpers ([x, y, z, w], column vectors). ----

function quatAxisAngle([x, y, z], angle) {
  const s = Math.sin(angle / 2);
  return [x * s, y * s, z * s, Math.cos(angle / 2)];
}

function quatMul([ax, ay, az, aw], [bx, by, bz, bw]) {
  return [
    aw * bx + ax * bw + ay * bz - az * by,
    aw * by - ax * bz + ay * bw + az * bx,
    aw * bz + ax * by - ay * bx + az * bw,
    aw * bw - ax * bx - ay * by - az * bz,
  ];
}

function rotate(q, v) {
  const [x, y, z] = quatMul(quatMul(q, [...v, 0]), [-q[0], -q[1], -q[2], q[3]]);
  return [x, y, z];
}

const add = (a, b) => a.map((v, i) => v + b[i]);
const scale = (a, s) => a.map((v) => v * s);
const neg = (a) => scale(a, -1);
const cross = ([ax, ay, az], [bx, by, bz]) => [ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx];

// A gl-matrix 4×4 (column-major) rigid transform → { axes: its X, Y, Z columns, origin }.
const fromMat4 = (m) => ({ axes: [m.slice(0, 3), m.slice(4, 7), m.slice(8, 11)], origin: m.slice(12, 15) });
// A pose (position, quaternion) → { axes, origin }.
const fromPose = ({ position, quaternion }) => ({
  axes: [[1, 0, 0], [0, 1, 0], [0, 0, 1]].map((e) => rotate(quaternion, e)),
  origin: position,
});
// `parent` ∘ `child`: the child frame's axes and origin in the parent's space.
const compose = (parent, child) => ({
  axes: child.axes.map((a) => parent.axes.reduce((s, p, i) => add(s, scale(p, a[i])), [0, 0, 0])),
  origin: parent.axes.reduce((s, p, i) => add(s, scale(p, child.origin[i])), parent.origin),
});

// ---- The documented conventions (docs/live-protocol.md, "The WebXR page"). ----

// The head: CPF +X left (viewer −X), +Y up (viewer +Y), +Z forward (viewer −Z), same origin.
const expectedHead = (viewer) => ({ axes: [neg(viewer.axes[0]), viewer.axes[1], neg(viewer.axes[2])], origin: viewer.origin });

// A wrist frame from its +Y (out of the back of the hand) and +Z (the thumb's side); +X = Y × Z
// (the subject's left when the arms are out sideways, palms down).
const wristFrame = (y, z, origin) => ({ axes: [cross(y, z), y, z], origin });

// From a controller's grip: the back of the right hand is grip +X, of the left grip −X; the
// thumb is grip −Z; the wrist sits 0.08 m up the arm (grip +Y) and 0.03 m towards the back of
// the hand from the grip's origin.
function expectedGripWrist(grip, side) {
  const back = side === 'right' ? grip.axes[0] : neg(grip.axes[0]);
  const origin = add(add(grip.origin, scale(grip.axes[1], 0.08)), scale(back, 0.03));
  return wristFrame(back, neg(grip.axes[2]), origin);
}

// From the hand-tracking wrist joint: +Y out of the back of the hand, −Z towards the fingers;
// the fingers point along the arm, outwards (+X for the left hand, −X for the right), so the
// thumb's side is Z = X × Y.
function expectedJointWrist(joint, side) {
  const y = joint.axes[1];
  const x = side === 'left' ? neg(joint.axes[2]) : joint.axes[2];
  return wristFrame(y, cross(x, y), joint.origin);
}

// iwer's emulation data: a controller's grip and a hand's wrist joint relative to its pose.
const gripOffset = (side) => fromMat4(metaQuest3.controllerConfig.layout[side].gripOffsetMatrix);
const MIRROR_TO_RIGHT = [1, -1, -1, 0, -1, 1, 1, 0, -1, 1, 1, 0, -1, 1, 1, 1];
const wristJointOffset = (side) => {
  const left = relaxedHandPose.jointTransforms.wrist.offsetMatrix;
  return fromMat4(side === 'left' ? left : left.map((v, i) => v * MIRROR_TO_RIGHT[i]));
};

// ---- Frames (docs/live-protocol.md, "Data frames"). ----

function decodeFrame(bytes) {
  const view = new DataView(Uint8Array.from(bytes).buffer);
  assert.equal(view.byteLength, 12 + 29, 'a pose frame is 41 bytes');
  assert.equal(view.getUint8(0), 1, 'op pose');
  assert.equal(view.getUint8(1), 0, 'flags');
  const f = (i) => view.getFloat32(13 + 4 * i, true);
  return {
    channel: view.getUint16(2, true),
    timestampNs: view.getBigInt64(4, true),
    valid: view.getUint8(12),
    position: [f(0), f(1), f(2)],
    quaternion: [f(3), f(4), f(5), f(6)],
  };
}

function assertFrame(actual, expected, what, tolerance = 2e-3) {
  const near = (a, b) => a.every((v, i) => Math.abs(v - b[i]) <= tolerance);
  const got = fromPose(actual);
  const names = ['X', 'Y', 'Z'];
  assert.ok(near(got.origin, expected.origin), `${what}: translation ${got.origin} ≠ expected ${expected.origin}`);
  for (let i = 0; i < 3; i++) {
    assert.ok(near(got.axes[i], expected.axes[i]), `${what}: +${names[i]} axis ${got.axes[i]} ≠ expected ${expected.axes[i]}`);
  }
  const length = Math.hypot(...actual.quaternion);
  assert.ok(Math.abs(length - 1) < 1e-5, `${what}: quaternion length ${length}`);
}

// ---- The relay, from node and from a viewer page. ----

async function createRoom() {
  const response = await fetch(new URL('api/live/rooms', APP_URL), { method: 'POST' });
  assert.equal(response.status, 201, await response.clone().text());
  return response.json();
}

// A viewer in its own page (Node 20 has no WebSocket without a flag): it answers pings —
// echoing the relay's time digit for digit, which a JS number cannot hold — and keeps every
// message for the test to take.
async function joinAsViewer(browser, room) {
  const context = await browser.newContext();
  const page = await context.newPage();
  const hello = JSON.stringify({ type: 'hello', protocol: 1, join: { room: room.room, secret: room.viewer_secret } });
  await page.evaluate(
    ({ url, subprotocol, hello }) => new Promise((resolve, reject) => {
      const socket = new WebSocket(url, subprotocol);
      socket.binaryType = 'arraybuffer';
      window.viewer = { texts: [], frames: [], closed: null };
      socket.onopen = () => {
        socket.send(hello);
        resolve();
      };
      socket.onerror = () => reject(new Error(`the viewer could not connect to ${url}`));
      socket.onclose = (e) => {
        window.viewer.closed = { code: e.code, reason: e.reason };
      };
      socket.onmessage = (e) => {
        if (typeof e.data !== 'string') {
          window.viewer.frames.push(Array.from(new Uint8Array(e.data)));
          return;
        }
        const ping = /^\{"type":"ping","relay_ns":(-?\d+)\}$/.exec(e.data);
        if (ping) {
          const deviceNs = BigInt(Math.round(performance.timeOrigin * 1e3)) * 1000n + BigInt(Math.round(performance.now() * 1e6));
          socket.send(`{"type":"pong","relay_ns":${ping[1]},"device_ns":${deviceNs}}`);
        } else {
          window.viewer.texts.push(e.data);
        }
      };
    }),
    { url: LIVE_URL, subprotocol: SUBPROTOCOL, hello },
  );
  const viewer = {
    texts: [],
    frames: [], // decoded, with `receivedNs` (this machine's clock, = the relay's here)
    async poll() {
      const taken = await page.evaluate(() => {
        const { texts, frames, closed } = window.viewer;
        window.viewer.texts = [];
        window.viewer.frames = [];
        return { texts, frames, closed };
      });
      assert.equal(taken.closed, null, `the relay closed the viewer: ${JSON.stringify(taken.closed)}`);
      const receivedNs = BigInt(Date.now()) * 1_000_000n;
      viewer.texts.push(...taken.texts.map((t) => JSON.parse(t)));
      viewer.frames.push(...taken.frames.map((b) => ({ ...decodeFrame(b), receivedNs })));
    },
    // The room-wide channel of a device's stream (from the latest `channels` message).
    channel(device, stream) {
      const channels = viewer.texts.filter((m) => m.type === 'channels').at(-1)?.channels ?? [];
      return channels.find((c) => c.device === device && c.stream === stream)?.channel;
    },
    // Polls until `done()` holds; the failure says what arrived.
    async until(done, what, timeout = 30_000) {
      const deadline = Date.now() + timeout;
      for (;;) {
        await viewer.poll();
        if (done()) return;
        if (Date.now() > deadline) {
          const kinds = [...new Set(viewer.texts.map((m) => m.type))];
          throw new Error(`waiting for ${what}: ${viewer.frames.length} frames, messages ${kinds} (${JSON.stringify(viewer.texts.filter((m) => m.type !== 'status').slice(-3))})`);
        }
        await new Promise((r) => setTimeout(r, 100));
      }
    },
    // Frames of one stream received since `since` (an index into `frames`).
    of(device, stream, since = 0) {
      const channel = viewer.channel(device, stream);
      return viewer.frames.slice(since).filter((f) => f.channel === channel);
    },
    close: () => context.close(),
  };
  return viewer;
}

// The XR page in a fresh context with iwer playing a Quest 3 before any of its scripts run.
async function openXrPage(browser, fragment = '') {
  const context = await browser.newContext({ viewport: { width: 900, height: 700 } });
  const setup = { headset: HEADSET, left: LEFT, right: RIGHT };
  await context.addInitScript({
    content: `${IWER_BUNDLE}
;(() => {
  const setup = ${JSON.stringify(setup)};
  const device = new IWER.XRDevice(IWER.metaQuest3);
  device.installRuntime({ forceInstall: true });
  device.position.set(...setup.headset.position);
  device.quaternion.set(...setup.headset.quaternion);
  for (const side of ['left', 'right']) {
    device.controllers[side].position.set(...setup[side].position);
    device.controllers[side].quaternion.set(...setup[side].quaternion);
  }
  // iwer reports every pose of a controller's spaces as emulatedPosition (not measured); a
  // headset reports that only while it does not track the controller, and the page sends
  // those poses as lost. Here the controllers are tracked, until a test says otherwise.
  window.setGripTracked = (side, tracked) => {
    const grip = device.controllers[side].inputSource.gripSpace;
    for (const key of Object.getOwnPropertySymbols(grip)) {
      if (grip[key] && typeof grip[key] === 'object' && 'emulated' in grip[key]) grip[key].emulated = !tracked;
    }
  };
  window.setGripTracked('left', true);
  window.setGripTracked('right', true);
  window.xrDevice = device;
})();`,
  });
  const page = await context.newPage();
  const errors = [];
  page.on('console', (m) => {
    if (m.type() === 'error') errors.push(`console: ${m.text()}`);
  });
  page.on('pageerror', (e) => errors.push(`uncaught: ${e.message}`));
  await page.goto(new URL(`xr.html${fragment}`, APP_URL).href);
  const waitState = async (states, timeout = 60_000) => {
    const list = [].concat(states);
    try {
      await page.waitForFunction((l) => l.includes(document.body.dataset.state), list, { timeout, polling: 100 });
    } catch (error) {
      const where = await page.evaluate(() => `state ${document.body.dataset.state}, error "${document.getElementById('error-message').textContent}", connection "${document.getElementById('connection').textContent}"`);
      throw new Error(`waiting for state ${list.join('/')}: ${error.message} (${where}; errors: ${JSON.stringify(errors)})`);
    }
    return page.evaluate(() => document.body.dataset.state);
  };
  return { page, context, errors, waitState, close: () => context.close() };
}

const browser = chromiumForFile();

describe('the WebXR page on an emulated Quest 3', () => {
  let room;
  let xr;
  let viewer;

  before(async () => {
    room = await createRoom();
    viewer = await joinAsViewer(browser(), room);
    xr = await openXrPage(browser(), `#live=${room.room}.${room.device_secret}`);
    assert.equal(await xr.waitState(['ready', 'error', 'unsupported']), 'ready', await xr.page.locator('body').innerText());
  });
  after(async () => {
    await xr?.close();
    await viewer?.close();
  });

  test('the link names the room, and Enter XR starts streaming', async () => {
    const { page } = xr;
    assert.equal(await page.locator('#code-input').isVisible(), false, 'a link needs no code');
    assert.match(await page.locator('#link-note').innerText(), new RegExp(`room ${room.room.slice(0, 6)}`));
    assert.ok(!(await page.locator('body').innerText()).includes(room.device_secret), 'the secret is never shown');
    await page.getByRole('button', { name: 'Enter XR' }).click();
    assert.equal(await xr.waitState(['streaming', 'error']), 'streaming', JSON.stringify(xr.errors));
    assert.equal(await page.evaluate(() => window.xrDevice.activeSession !== undefined), true, 'in XR');
  });

  test('head and controller grips arrive in session conventions, at a plausible rate', async () => {
    const enough = () => ['head', 'left-wrist', 'right-wrist'].every((s) => viewer.of('quest', s).length >= 60);
    await viewer.until(enough, '60 frames of each stream');
    const head = viewer.of('quest', 'head');
    const left = viewer.of('quest', 'left-wrist');
    const right = viewer.of('quest', 'right-wrist');
    // The controllers appear in the session's first frames; from then on every pose is tracked.
    for (const [name, frames] of [['head', head], ['left wrist', left], ['right wrist', right]]) {
      const firstValid = frames.findIndex((f) => f.valid === 1);
      assert.ok(firstValid >= 0 && firstValid < 10, `${name}: tracked from frame ${firstValid}`);
      assert.ok(frames.slice(firstValid).every((f) => f.valid === 1), `${name}: every pose after is tracked`);
    }
    // The emulated head at (0.1, 1.6, −0.3) facing −Z: CPF at the same place, turned half
    // about +Y (its +Z forward is world −Z, its +X left is world −X).
    assertFrame(head.at(-1), expectedHead(fromPose(HEADSET)), 'head');
    assertFrame(head.at(-1), { axes: [[-1, 0, 0], [0, 1, 0], [0, 0, -1]], origin: [0.1, 1.6, -0.3] }, 'head (literal)');
    for (const [side, frames, pose] of [['left', left, LEFT], ['right', right, RIGHT]]) {
      const grip = compose(fromPose(pose), gripOffset(side));
      assertFrame(frames.at(-1), expectedGripWrist(grip, side), `${side} wrist`);
    }

    // Stamps: the frame's display time on the relay clock (this machine's), in order, at the
    // page's frame rate (headless Chromium draws at up to 60 Hz).
    for (let i = 1; i < head.length; i++) assert.ok(head[i].timestampNs > head[i - 1].timestampNs, 'stamps increase');
    const last = head.at(-1);
    const skewMs = Number(last.receivedNs - last.timestampNs) / 1e6;
    assert.ok(skewMs > -1000 && skewMs < 5000, `a stamp is ${skewMs} ms before its arrival`);
    const recent = head.slice(-40);
    const hz = ((recent.length - 1) * 1e9) / Number(recent.at(-1).timestampNs - recent[0].timestampNs);
    assert.ok(hz > 10 && hz < 250, `head at ${hz.toFixed(1)} Hz`);
    // The three streams of one XR frame share its stamp. The streams arrive separately: under
    // load the newest head frame's wrists may still be on their way, so look at the recent ones.
    const wristStamps = new Set([...left, ...right].map((f) => f.timestampNs));
    const shared = head.slice(-30).filter((f) => wristStamps.has(f.timestampNs)).length;
    assert.ok(shared > 0, `none of the last ${Math.min(30, head.length)} head stamps is a wrist's`);

    const text = await xr.page.locator('#status-panel').innerText();
    assert.match(text, /head · left controller · right controller/);
    const sent = Number(await xr.page.locator('#frames-sent').innerText());
    assert.ok(sent >= head.length, `the page counts ${sent} frames sent`);
    assert.match(await xr.page.locator('#rate').innerText(), /^\d+ Hz \(local-floor space\)$/);
  });

  test('the relay lists the headset as a wearer streaming head and wrists', async () => {
    const status = () => viewer.texts.filter((m) => m.type === 'status').at(-1)?.devices.find((d) => d.device === 'quest');
    await viewer.until(() => {
      const s = status();
      return s && s.rates_hz.length === 3 && s.rates_hz.every(([, hz]) => hz > 5) && s.clock_offset_ns !== null;
    }, 'a status with the headset streaming');
    const s = status();
    assert.equal(s.role, 'wearer');
    assert.equal(s.connected, true);
    assert.deepEqual(s.rates_hz.map(([stream]) => stream).sort(), ['head', 'left-wrist', 'right-wrist']);
    // Its XR space is a world of its own, and its hello said so: every channel carries it.
    const channels = viewer.texts.filter((m) => m.type === 'channels').at(-1).channels.filter((c) => c.device === 'quest');
    assert.equal(channels.length, 3);
    assert.ok(channels.every((c) => c.world === 'own'), JSON.stringify(channels));
    // Same machine, same clock: the measured offset is small.
    assert.ok(Math.abs(s.clock_offset_ns) < 1e9, `clock offset ${s.clock_offset_ns} ns`);
  });

  test('a turned head and a moved controller arrive as their new poses', async () => {
    const turned = { position: [0.4, 1.55, 0.2], quaternion: yaw(90) };
    const moved = { position: [0.1, 1.0, -0.2], quaternion: quatMul(yaw(-90), quatAxisAngle([1, 0, 0], 0.5)) };
    const since = viewer.frames.length;
    await xr.page.evaluate(({ turned, moved }) => {
      window.xrDevice.position.set(...turned.position);
      window.xrDevice.quaternion.set(...turned.quaternion);
      window.xrDevice.controllers.right.position.set(...moved.position);
      window.xrDevice.controllers.right.quaternion.set(...moved.quaternion);
    }, { turned, moved });
    const expectedRight = expectedGripWrist(compose(fromPose(moved), gripOffset('right')), 'right');
    const near = (f, origin) => f.valid === 1 && f.position.every((v, i) => Math.abs(v - origin[i]) < 2e-3);
    await viewer.until(
      () => viewer.of('quest', 'head', since).some((f) => near(f, turned.position)) &&
        viewer.of('quest', 'right-wrist', since).some((f) => near(f, expectedRight.origin)),
      'the new poses',
    );
    const head = viewer.of('quest', 'head', since).at(-1);
    // Turned 90° left: looking down world −X, with the left hand side towards +Z.
    assertFrame(head, { axes: [[0, 0, 1], [0, 1, 0], [-1, 0, 0]], origin: turned.position }, 'turned head');
    assertFrame(head, expectedHead(fromPose(turned)), 'turned head (convention)');
    assertFrame(viewer.of('quest', 'right-wrist', since).at(-1), expectedRight, 'moved right wrist');
  });

  test('a controller that loses tracking is sent as lost, never as its last pose', async () => {
    // Not measured (the headset lost sight of it and guesses): sent as lost.
    const guessed = viewer.frames.length;
    await xr.page.evaluate(() => window.setGripTracked('left', false));
    await viewer.until(() => viewer.of('quest', 'left-wrist', guessed).filter((f) => f.valid === 0).length >= 5, 'a guessed left wrist sent as lost');
    await xr.page.evaluate(() => window.setGripTracked('left', true));
    await viewer.until(() => viewer.of('quest', 'left-wrist', guessed).at(-1)?.valid === 1, 'the left wrist tracked again');

    // Gone (switched off, out of range): sent as lost too.
    const since = viewer.frames.length;
    await xr.page.evaluate(() => {
      window.xrDevice.controllers.left.connected = false;
    });
    await viewer.until(() => viewer.of('quest', 'left-wrist', since).filter((f) => f.valid === 0).length >= 10, 'lost left wrist frames');
    const after = viewer.of('quest', 'left-wrist', since);
    const firstLost = after.findIndex((f) => f.valid === 0);
    assert.ok(after.slice(firstLost).every((f) => f.valid === 0), 'once lost, no pose is repeated');
    assert.ok(viewer.of('quest', 'right-wrist', since).slice(-5).every((f) => f.valid === 1), 'the other hand carries on');
    await xr.page.waitForFunction(() => /head · left lost · right controller/.test(document.getElementById('tracking').textContent), null, { timeout: 5_000 });

    const back = viewer.frames.length;
    await xr.page.evaluate(() => {
      window.xrDevice.controllers.left.connected = true;
    });
    await viewer.until(() => viewer.of('quest', 'left-wrist', back).some((f) => f.valid === 1), 'the left wrist back');
  });

  test('tracked hands stream their wrist joints', async () => {
    const hands = {
      left: { position: [-0.3, 1.2, -0.4], quaternion: quatMul(yaw(30), quatAxisAngle([0, 0, 1], -0.6)) },
      right: { position: [0.35, 1.1, -0.35], quaternion: quatMul(yaw(-60), quatAxisAngle([1, 0, 0], 0.7)) },
    };
    await xr.page.evaluate((hands) => {
      const device = window.xrDevice;
      device.primaryInputMode = 'hand';
      for (const side of ['left', 'right']) {
        device.hands[side].position.set(...hands[side].position);
        device.hands[side].quaternion.set(...hands[side].quaternion);
      }
    }, hands);
    await xr.page.waitForFunction(() => /left hand · right hand/.test(document.getElementById('tracking').textContent), null, { timeout: 10_000 });
    const mark = viewer.frames.length;
    await viewer.until(() => ['left-wrist', 'right-wrist'].every((s) => viewer.of('quest', s, mark).filter((f) => f.valid === 1).length >= 10), 'hand wrist frames');
    for (const side of ['left', 'right']) {
      const joint = compose(fromPose(hands[side]), wristJointOffset(side));
      const frames = viewer.of('quest', `${side}-wrist`, mark).filter((f) => f.valid === 1);
      assertFrame(frames.at(-1), expectedJointWrist(joint, side), `${side} hand wrist`);
    }
  });

  test('the page exposes the Rust conversion, and it agrees with the convention', async () => {
    const result = await xr.page.evaluate(async ({ pose }) => {
      const href = document.querySelector('link[rel="modulepreload"]').href;
      const m = await import(href);
      const p = new Float32Array(pose.position);
      const q = new Float32Array(pose.quaternion);
      return Object.fromEntries(['Viewer', 'LeftGrip', 'RightGrip', 'LeftHandWrist', 'RightHandWrist']
        .map((s) => [s, Array.from(m.xr_session_pose(m.XrSource[s], p, q))]));
    }, { pose: RIGHT });
    const as = (a) => ({ position: a.slice(0, 3), quaternion: a.slice(3) });
    const xrPose = fromPose(RIGHT);
    assertFrame(as(result.Viewer), expectedHead(xrPose), 'viewer', 1e-5);
    assertFrame(as(result.RightGrip), expectedGripWrist(xrPose, 'right'), 'right grip', 1e-5);
    assertFrame(as(result.LeftGrip), expectedGripWrist(xrPose, 'left'), 'left grip', 1e-5);
    assertFrame(as(result.LeftHandWrist), expectedJointWrist(xrPose, 'left'), 'left hand wrist', 1e-5);
    assertFrame(as(result.RightHandWrist), expectedJointWrist(xrPose, 'right'), 'right hand wrist', 1e-5);
    const error = await xr.page.evaluate(async () => {
      const m = await import(document.querySelector('link[rel="modulepreload"]').href);
      try {
        m.xr_session_pose(m.XrSource.Viewer, new Float32Array([0, 0]), new Float32Array([0, 0, 0, 1]));
        return null;
      } catch (e) {
        return `${e.constructor.name}: ${e.message}`;
      }
    });
    assert.equal(error, 'Error: a position needs 3 numbers, got 2');
  });

  test('leaving XR closes the socket and the relay shows the device gone', async () => {
    await xr.page.evaluate(() => window.xrDevice.activeSession.end());
    assert.equal(await xr.waitState(['ready', 'error']), 'ready');
    assert.match(await xr.page.locator('#close-reason').innerText(), /—|left XR|stopped/);
    await viewer.until(() => {
      const s = viewer.texts.filter((m) => m.type === 'status').at(-1)?.devices.find((d) => d.device === 'quest');
      return s && !s.connected;
    }, 'the headset shown disconnected');
    assert.deepEqual(xr.errors, []);
  });
});

test('after a retryable close (the server restarting) the page reconnects and streams on', async () => {
  const room = await createRoom();
  const viewer = await joinAsViewer(browser(), room);
  const xr = await openXrPage(browser(), `#live=${room.room}.${room.device_secret}`);
  try {
    // The page's sockets pass through the test, which can close one as a restarting server would.
    const sockets = [];
    await xr.page.routeWebSocket(/\/live$/, (ws) => {
      sockets.push({ ws, server: ws.connectToServer() });
    });
    assert.equal(await xr.waitState(['ready', 'error']), 'ready');
    await xr.page.getByRole('button', { name: 'Enter XR' }).click();
    assert.equal(await xr.waitState(['streaming', 'error']), 'streaming');
    await viewer.until(() => viewer.of('quest', 'head').length >= 10, 'frames before the restart');
    const { ws, server } = sockets[0];
    await ws.close({ code: 1001, reason: 'the server is restarting' });
    await server.close();
    await xr.waitState(['reconnecting', 'error'], 5_000);
    assert.match(await xr.page.locator('#close-reason').innerText(), /the server is restarting \(1001\)/);
    assert.equal(await xr.waitState(['streaming', 'error']), 'streaming', await xr.page.locator('#connection').innerText());
    assert.equal(sockets.length, 2, 'one new connection');
    const since = viewer.frames.length;
    await viewer.until(() => viewer.of('quest', 'head', since).filter((f) => f.valid === 1).length >= 10, 'frames after reconnecting');
    assert.deepEqual(xr.errors, []);
  } finally {
    await xr.close();
    await viewer.close();
  }
});

describe('joining by code', () => {
  test('a typed device code (any case, with spaces) joins the room', async () => {
    const room = await createRoom();
    const xr = await openXrPage(browser());
    try {
      assert.equal(await xr.waitState(['ready', 'error']), 'ready');
      const typed = room.device_code.toLowerCase().replace('-', ' ');
      await xr.page.getByLabel('Device code').fill(typed);
      await xr.page.getByLabel('Device id').fill('quest-by-code');
      await xr.page.getByRole('button', { name: 'Enter XR' }).click();
      assert.equal(await xr.waitState(['streaming', 'error']), 'streaming');
      assert.match(await xr.page.locator('#connection').innerText(), new RegExp(`code ${room.device_code}`));
      await xr.page.waitForFunction(() => Number(document.getElementById('frames-sent').textContent) > 10, null, { timeout: 20_000 });
      assert.deepEqual(xr.errors, []);
    } finally {
      await xr.close();
    }
  });

  test('a wrong code says so on the page, and leaves XR', async () => {
    const room = await createRoom();
    // A code of the right form that opens no room (not this one's).
    const wrong = room.device_code === 'ZZZ-ZZZ' ? 'YYY-YYY' : 'ZZZ-ZZZ';
    const xr = await openXrPage(browser());
    try {
      assert.equal(await xr.waitState(['ready', 'error']), 'ready');
      await xr.page.getByLabel('Device code').fill(wrong);
      await xr.page.getByRole('button', { name: 'Enter XR' }).click();
      assert.equal(await xr.waitState(['error', 'streaming']), 'error');
      const alert = await xr.page.getByRole('alert').innerText();
      assert.match(alert, /no room has this code/);
      assert.match(alert, /4001/);
      await xr.page.waitForFunction(() => window.xrDevice.activeSession === undefined, null, { timeout: 10_000 });
      assert.equal(await xr.page.getByRole('button', { name: 'Enter XR' }).isEnabled(), true, 'the person can try again');
    } finally {
      await xr.close();
    }
  });

  test('a code that cannot be one is refused before anything connects', async () => {
    const xr = await openXrPage(browser());
    try {
      assert.equal(await xr.waitState(['ready', 'error']), 'ready');
      await xr.page.getByLabel('Device code').fill('7KQ-M40');
      await xr.page.getByRole('button', { name: 'Enter XR' }).click();
      assert.equal(await xr.waitState(['error']), 'error');
      assert.match(await xr.page.getByRole('alert').innerText(), /“7KQ-M40” is not a device code.*without I, L or O/s);
      assert.equal(await xr.page.evaluate(() => window.xrDevice.activeSession), undefined, 'XR was not entered');
      await xr.page.getByLabel('Device code').fill('');
      await xr.page.getByRole('button', { name: 'Enter XR' }).click();
      assert.match(await xr.page.getByRole('alert').innerText(), /Type the device code/);
    } finally {
      await xr.close();
    }
  });

  test('a damaged link says so', async () => {
    const xr = await openXrPage(browser(), '#live=abc');
    try {
      assert.equal(await xr.waitState(['error', 'ready']), 'error');
      assert.match(await xr.page.getByRole('alert').innerText(), /link's #live=… part is damaged/);
    } finally {
      await xr.close();
    }
  });
});

test('xr.html is served as a page: no-cache, the strict CSP, versioned assets', async () => {
  const response = await fetch(new URL('xr.html', APP_URL));
  assert.equal(response.status, 200);
  assert.equal(response.headers.get('cache-control'), 'no-cache');
  const csp = response.headers.get('content-security-policy');
  assert.ok(csp.includes("script-src 'self' 'wasm-unsafe-eval'") && !csp.includes('unsafe-inline'), csp);
  const html = await response.text();
  assert.match(html, /<script type="module" src="v\/[0-9a-f]{16}\/xr\.js"><\/script>/);
  assert.ok(!/<script(?![^>]*\bsrc=)[^>]*>/.test(html) && !/\sstyle="/.test(html), 'no inline scripts or styles');
});
