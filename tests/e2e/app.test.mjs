// The app end to end in headless Chromium, against dist/ as `cargo xtask serve` builds it.
// Run by `cargo xtask test` (EGOEXO_E2E_URL points at the served dist/); screenshots go to
// target/e2e/.

import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import { cpSync, mkdtempSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { after, before, describe, test } from 'node:test';

import { OUT, decodePng, launch, openApp, savePng, skeletonPixels } from './browser.mjs';

const REPO = new URL('../../', import.meta.url).pathname;
// The CLI the tests make sessions with (the same build as the server's).
const BIN = process.env.EGOEXO_BIN ?? join(REPO, 'target/debug/egoexo');
// The tests' Python (PyAV decodes the video export); `cargo xtask test` sets it.
const PYTHON = process.env.EGOEXO_PYTHON;
const SAMPLES = JSON.parse(readFileSync(join(REPO, 'public/samples/samples.json'), 'utf8'));
const SAMPLE = SAMPLES.samples[0];
// A multi-device Aria MPS folder (egoexo-session's committed fixture).
const ARIA_FOLDER = join(REPO, 'crates/egoexo-session/tests/fixtures/aria_mps');
// The wearer's glasses as MPS writes them: trajectory/ (semidense points) + hand_tracking/ (v2),
// the right hand out of view from 0.2 to 0.5 s, the left from 0.8 to 1.3 s.
const HANDS_FOLDER = join(REPO, 'crates/egoexo-session/tests/fixtures/aria_mps_hands');
// Skeleton pixels of each side a drawn body must show (a blank or background-only canvas has
// none; the body is small in the viewer's whole-scene framing).
const MIN_SIDE_PIXELS = 20;

let browser;
before(async () => {
  browser = await launch();
});
after(async () => {
  await browser?.close();
});

describe('the sample, WebGL2 canvas', () => {
  let app;
  before(async () => {
    app = await openApp(browser, '?backend=webgl2');
  });
  after(async () => {
    await app?.close();
  });

  test('reconstructs with a real progress bar and shows the frame count', async () => {
    const { page } = app;
    assert.equal(await app.waitState(['idle', 'error']), 'idle', await app.text('#error-message'));
    assert.match(await app.text('#backend'), /webgl2/i);
    const seen = [];
    const watcher = setInterval(async () => {
      try {
        seen.push(await page.evaluate(() => [document.getElementById('progress').value, document.getElementById('progress-text').textContent]));
      } catch {}
    }, 50);
    await page.click('#sample-button');
    const state = await app.waitState(['ready', 'error']);
    clearInterval(watcher);
    assert.equal(state, 'ready', await app.text('#error-message'));
    assert.equal(await app.text('#frame-count'), `${SAMPLE.frames} frames`);
    assert.equal(await page.evaluate(() => window.egoexo.viewer.frames()), SAMPLE.frames);
    assert.ok(seen.some(([v]) => v > 0 && v < 1), `no intermediate progress seen: ${JSON.stringify(seen.slice(0, 20))}`);
    assert.ok(seen.some(([, t]) => /exo fusion/.test(t)), 'the fusion stage was shown');
    const facts = await app.text('#session-facts');
    assert.match(facts, /observer-1/);
    assert.match(facts, /3-point tracking/);
    assert.match(await app.text('#result-facts'), /MPJPE vs ground truth/);
    // The ego-only overlay reuses the ego pass: EgoNet ran once per window for the whole job,
    // and the overlay ran the shipped fusion with every observer masked (fusion_ego_only).
    const summary = await page.evaluate(() => window.egoexo.summary);
    assert.ok(summary.windows > 0, JSON.stringify(summary));
    const w = summary.windows;
    assert.deepEqual(summary.network_runs, { egonet: w, gate: w, fusion: w, fusion_ego_only: w });
  });

  test('plays: the frame advances, and the timeline steps and scrubs', async () => {
    const { page } = app;
    const frame = () => page.evaluate(() => window.egoexo.viewer.frame());
    const first = await frame();
    await page.waitForTimeout(600);
    assert.notEqual(await frame(), first, 'the skeleton moves');
    await page.click('#play-button');
    assert.equal(await page.evaluate(() => window.egoexo.viewer.is_playing()), false);
    await page.evaluate(() => {
      const scrubber = document.getElementById('scrubber');
      scrubber.value = '300';
      scrubber.dispatchEvent(new Event('input'));
    });
    assert.equal(await frame(), 300);
    await page.click('#step-forward');
    assert.equal(await frame(), 301);
    await page.waitForFunction(() => document.getElementById('frame-readout').textContent.startsWith('frame 302 /'));
  });

  test('draws the skeleton (screenshot has its colours)', async () => {
    const { page } = app;
    await page.screenshot({ path: join(OUT, 'app-webgl2.png') });
    await page.uncheck('#show-rays');
    await page.uncheck('#show-ground-truth');
    await page.evaluate(() => window.egoexo.viewer.seek(300));
    await page.waitForTimeout(300);
    const shot = await page.locator('#view').screenshot({ path: join(OUT, 'sample-webgl2.png') });
    const { rgba } = decodePng(shot);
    const { left, right } = skeletonPixels(rgba);
    assert.ok(left >= MIN_SIDE_PIXELS && right >= MIN_SIDE_PIXELS, `skeleton pixels: left ${left}, right ${right}`);
  });

  test('the toggles change the picture', async () => {
    const { page } = app;
    const before = decodePng(await page.locator('#view').screenshot()).rgba;
    await page.check('#show-ego-only');
    await page.check('#show-rays');
    await page.waitForTimeout(300);
    const after = decodePng(await page.locator('#view').screenshot({ path: join(OUT, 'sample-ego-only-overlay.png') })).rgba;
    let changed = 0;
    for (let i = 0; i < before.length; i += 4) if (before[i] !== after[i] || before[i + 2] !== after[i + 2]) changed += 1;
    assert.ok(changed > 100, `${changed} pixels changed`);
  });

  test('the viewer: a body of capsules (B: stick figures), the follow camera, each observer\'s view (O), the help overlay (?)', async () => {
    const { page } = app;
    const viewer = (f, ...args) => page.evaluate(([f, args]) => window.egoexo.viewer[f](...args), [f, args]);
    const shot = async (name) => decodePng(await page.locator('#view').screenshot(name ? { path: join(OUT, name) } : {}));
    const settle = () => page.waitForTimeout(250);
    await viewer('pause');
    await page.uncheck('#show-rays');
    await page.uncheck('#show-ego-only');
    await page.uncheck('#show-ground-truth');
    await page.uncheck('#follow');
    await viewer('reset_camera');
    await viewer('seek', 300);
    await settle();
    const body = skeletonPixels((await shot('sample-body.png')).rgba);
    await page.keyboard.press('b');
    await settle();
    assert.equal(await page.isChecked('#show-body'), false, 'B switches to stick figures');
    const stick = skeletonPixels((await shot('sample-stick.png')).rgba);
    await page.keyboard.press('b');
    assert.equal(await page.isChecked('#show-body'), true);
    // Capsules sized like a body cover several times the stick figure's pixels.
    assert.ok(body.left > 1.8 * stick.left && body.right > 1.8 * stick.right,
      `body ${JSON.stringify(body)} vs stick ${JSON.stringify(stick)}`);

    // Following: the wearer stays near the middle of the view wherever it walks.
    await page.keyboard.press('f');
    assert.equal(await page.isChecked('#follow'), true);
    assert.equal(await viewer('follows'), true);
    const centroid = ({ rgba, width, height }) => {
      let n = 0; let sx = 0; let sy = 0;
      for (let i = 0; i < rgba.length; i += 4) {
        const [r, g, b] = [rgba[i], rgba[i + 1], rgba[i + 2]];
        const left = b >= 140 && r <= 0.4 * b && g <= 0.65 * b && g >= r;
        const right = r >= 140 && g <= 0.58 * r && g >= 0.28 * r && b <= 0.3 * r;
        if (left || right) { const p = i / 4; sx += p % width; sy += Math.floor(p / width); n += 1; }
      }
      return { x: sx / n / width, y: sy / n / height, n };
    };
    const followed = [];
    for (const frame of [60, 600, 1100]) {
      await viewer('seek', frame);
      await settle();
      followed.push(centroid(await shot(`sample-follow-${frame}.png`)));
    }
    for (const c of followed) {
      assert.ok(c.n > 200 && Math.abs(c.x - 0.5) < 0.15 && Math.abs(c.y - 0.5) < 0.25, `followed body at ${JSON.stringify(c)}`);
    }
    await page.keyboard.press('f');
    assert.equal(await viewer('follows'), false);

    // Through each observer's camera: its frustum becomes the view, its keypoints (gate-coloured
    // markers) are drawn over the body; O cycles orbit → observer 1 → observer 2 → orbit.
    // Rays off: the only gate-coloured things in an observer's view are its own keypoints.
    await page.uncheck('#show-rays');
    const ids = await viewer('observer_ids');
    assert.ok(ids.length >= 1, 'the sample has observers');
    // For each observer, a frame where it sees the wearer (the most keypoints with rays).
    const seeing = await page.evaluate(() => {
      const raw = window.egoexo.scene;
      const s = typeof raw === 'string' ? JSON.parse(raw) : JSON.parse(new TextDecoder().decode(raw));
      return s.observers.map((o) => {
        let best = 0; let most = -1;
        for (let f = 0; f < s.frames; f += 1) {
          let n = 0;
          for (let k = 0; k < 13; k += 1) if (o.rays[4 * (13 * f + k) + 3] > 0.5) n += 1;
          if (n > most) { most = n; best = f; }
        }
        return best;
      });
    });
    for (let i = 0; i < ids.length; i += 1) {
      await viewer('seek', seeing[i]);
      await page.keyboard.press('o');
      assert.equal(await viewer('view_from_observer'), i);
      assert.equal(await page.inputValue('#view-from'), String(i));
      await settle();
      const image = await shot(`sample-observer-${ids[i]}.png`);
      const { left, right } = skeletonPixels(image.rgba);
      assert.ok(left + right > 80, `the wearer is in observer ${ids[i]}'s view: ${left} + ${right}`);
      let markers = 0;
      for (let p = 0; p < image.rgba.length; p += 4) {
        const [r, g, b] = [image.rgba[p], image.rgba[p + 1], image.rgba[p + 2]];
        if (g > 150 && b < 0.45 * g && r < 1.1 * g) markers += 1; // the gate's yellow → green (not the body's orange)
      }
      assert.ok(markers > 40, `observer ${ids[i]}: ${markers} gate-coloured keypoint pixels`);
    }
    await page.keyboard.press('o');
    assert.equal(await viewer('view_from_observer'), -1);
    await assert.rejects(viewer('set_view_from_observer', ids.length), /no observer/);

    // The timeline plots: a strip per observer and the error over time, under the scrubber;
    // hovering says the values, clicking seeks.
    assert.equal(await page.isVisible('#plots'), true);
    const labels = await app.text('#plot-labels');
    for (const id of ids) assert.match(labels, new RegExp(id));
    assert.match(labels, /error \(cm\) 0–\d+/);
    const canvas = page.locator('#plot-canvas');
    const box = await canvas.boundingBox();
    const track = await page.locator('#scrubber').boundingBox();
    assert.ok(box.x > track.x && box.x + box.width < track.x + track.width + 1, 'the plots span the scrubber');
    await canvas.hover({ position: { x: box.width * 0.4, y: 5 } });
    const hover = await app.text('#plot-hover');
    assert.match(hover, /joints in view/);
    assert.match(hover, /MPJPE \d+\.\d cm/);
    await canvas.click({ position: { x: box.width * 0.25, y: box.height - 10 } });
    const frames = await viewer('frames');
    const clicked = await viewer('frame');
    assert.ok(Math.abs(clicked - 0.25 * (frames - 1)) <= 2, `clicked at a quarter, now at frame ${clicked} of ${frames}`);
    const playhead = await page.locator('#plot-playhead').boundingBox();
    assert.ok(Math.abs(playhead.x - (box.x + box.width * 0.25)) <= 3, `playhead at ${playhead.x}`);
    await page.screenshot({ path: join(OUT, 'app-plots.png') });

    await page.keyboard.press('?');
    assert.equal(await page.evaluate(() => document.getElementById('help-dialog').open), true);
    assert.match(await app.text('#help-dialog'), /follow the wearer/);
    await page.screenshot({ path: join(OUT, 'app-help.png') });
    await page.click('#help-close');
    await page.screenshot({ path: join(OUT, 'app-1280x800.png') });
  });

  test('the 3D view exports as an MP4 (looped frames, session rate; decoded by PyAV) and a PNG; a video export cancels', async () => {
    const { page } = app;
    assert.ok(PYTHON, 'EGOEXO_PYTHON (the tests\' venv, `cargo xtask setup`) decodes the video');
    const viewer = (f, ...args) => page.evaluate(([f, args]) => window.egoexo.viewer[f](...args), [f, args]);
    await viewer('set_view_from_observer', -1);
    await viewer('pause');
    await viewer('set_loop', 100, 159);
    const fps = await viewer('fps');
    const [download] = await Promise.all([
      page.waitForEvent('download', { timeout: 180_000 }),
      page.click('#video-button'),
    ]);
    const path = join(OUT, 'sample-view.mp4');
    await download.saveAs(path);
    assert.match(download.suggestedFilename(), /\.mp4$/);
    // An independent decoder (FFmpeg, through PyAV) reads every frame back.
    const probe = `
import av, json, sys
with av.open(sys.argv[1]) as c:
    s = c.streams.video[0]
    frames = [f.to_ndarray(format="rgb24") for f in c.decode(s)]
    lit = [float((f.max(axis=2) > 80).mean()) for f in frames]
    print(json.dumps({"codec": s.codec_context.name, "frames": len(frames), "width": s.codec_context.width,
                      "height": s.codec_context.height, "rate": float(s.average_rate), "lit": min(lit)}))
`;
    const info = JSON.parse(execFileSync(PYTHON, ['-c', probe, path], { encoding: 'utf8' }));
    assert.equal(info.codec, 'h264');
    assert.equal(info.frames, 60, JSON.stringify(info));
    assert.ok(Math.abs(info.rate - fps) < 0.01, JSON.stringify(info));
    const canvas = await page.evaluate(() => [window.egoexo.viewer.canvas().width, window.egoexo.viewer.canvas().height]);
    assert.deepEqual([info.width, info.height], canvas.map((v) => v & ~1));
    assert.ok(info.lit > 0.002, `every frame shows the scene, not a blank canvas: ${JSON.stringify(info)}`);
    assert.equal(await page.isVisible('#video-progress-row'), false);

    // The whole session, cancelled part-way: no file, no error, the progress bar gone.
    await viewer('clear_loop');
    let downloaded = false;
    page.once('download', () => { downloaded = true; });
    await page.click('#video-button');
    await page.waitForFunction(() => document.getElementById('video-progress').value > 0.02, null, { timeout: 60_000 });
    await page.click('#video-cancel');
    await page.waitForFunction(() => document.getElementById('video-progress-row').hidden, null, { timeout: 30_000 });
    await page.waitForTimeout(500);
    assert.equal(downloaded, false);
    assert.equal(await page.isVisible('#error-panel'), false);

    const [png] = await Promise.all([page.waitForEvent('download'), page.click('#png-button')]);
    const pngPath = join(OUT, 'sample-frame.png');
    await png.saveAs(pngPath);
    const image = decodePng(readFileSync(pngPath));
    assert.deepEqual([image.width, image.height], canvas);
  });

  test('exports download the worker\'s files', async () => {
    const { page } = app;
    const expectations = { bvh: 'HIERARCHY', csv: 'frame,time_s', glb: 'glTF', npz: 'PK' };
    for (const [format, magic] of Object.entries(expectations)) {
      const [download] = await Promise.all([page.waitForEvent('download'), page.click(`[data-format=${format}]`)]);
      const session = await page.evaluate(() => window.egoexo.session.name);
      assert.equal(download.suggestedFilename(), `${session}-ego-exo.${format}`);
      const path = join(OUT, `export.${format}`);
      await download.saveAs(path);
      assert.equal(readFileSync(path).subarray(0, magic.length).toString('latin1'), magic, format);
    }
    await app.waitState('ready');
  });

  test('WebGPU renders the scene off-screen (pixel read-back)', async () => {
    const { page } = app;
    const result = await page.evaluate(async () => {
      const { Viewer } = window.egoexo;
      const [w, h] = [960, 720];
      try {
        const rgba = await Viewer.render_offscreen(window.egoexo.scene, 300, w, h, 'webgpu');
        let binary = '';
        for (let i = 0; i < rgba.length; i += 0x8000) binary += String.fromCharCode(...rgba.subarray(i, i + 0x8000));
        return { w, h, base64: btoa(binary) };
      } catch (error) {
        return { error: String(error?.message ?? error) };
      }
    });
    assert.equal(result.error, undefined, `render_offscreen failed: ${result.error}`);
    const rgba = Buffer.from(result.base64, 'base64');
    assert.equal(rgba.length, result.w * result.h * 4);
    savePng('offscreen-webgpu.png', result.w, result.h, rgba);
    const { left, right } = skeletonPixels(rgba);
    assert.ok(left >= MIN_SIDE_PIXELS && right >= MIN_SIDE_PIXELS, `skeleton pixels: left ${left}, right ${right}`);
  });

  test('no console errors, no uncaught exceptions', () => {
    assert.deepEqual(app.errors, []);
  });
});

describe('bad input and failures', () => {
  test('a malformed file shows the importer\'s exact message and the page keeps working', async () => {
    const app = await openApp(browser, '?backend=webgl2');
    try {
      await app.waitState('idle');
      await app.page.setInputFiles('#file-input', { name: 'broken.egoexo', mimeType: 'application/zip', buffer: Buffer.from('this is not a zip archive') });
      assert.equal(await app.waitState(['error', 'ready']), 'error');
      assert.equal(await app.text('#error-title'), 'Could not import the session');
      assert.match(await app.text('#error-message'), /^broken\.egoexo: not a readable zip archive \(truncated or corrupt\?\): /);

      // Dropped onto the page: a zip of something that is no session names what it holds.
      await app.page.click('#error-dismiss');
      const dataTransfer = await app.page.evaluateHandle(() => {
        const dt = new DataTransfer();
        dt.items.add(new File(['just some notes'], 'notes.txt', { type: 'text/plain' }));
        return dt;
      });
      await app.page.dispatchEvent('#drop-zone', 'drop', { dataTransfer });
      assert.equal(await app.waitState(['error', 'ready']), 'error');
      assert.match(await app.text('#error-message'), /^notes\.txt: not a readable zip archive/);

      // Not frozen, not blank: the controls answer and the canvas is still there.
      assert.equal(await app.page.locator('#sample-button').isEnabled(), true);
      assert.equal(await app.page.locator('#view').isVisible(), true);
      assert.deepEqual(app.errors, []);
    } finally {
      await app.close();
    }
  });

  test('a dropped Aria MPS folder imports and reconstructs', async () => {
    const app = await openApp(browser, '?backend=webgl2');
    try {
      await app.waitState('idle');
      await app.page.setInputFiles('#folder-input', ARIA_FOLDER);
      assert.equal(await app.waitState(['ready', 'error']), 'ready', await app.text('#error-message'));
      assert.match(await app.text('#session-facts'), /multi-device Aria MPS folder/);
      assert.match(await app.text('#frame-count'), /^\d+ frames$/);
      assert.deepEqual(app.errors, []);
    } finally {
      await app.close();
    }
  });

  test('a dropped Nymeria sequence with two participants (people files): both reconstructed, the cameras\' people associated', async () => {
    // The Nymeria fixture plus people files: the observer's camera sees the wearer and a
    // bystander, the wearer's camera the observer.
    const dir = mkdtempSync(join(tmpdir(), 'egoexo-nymeria-two-'));
    const sequence = join(dir, 'sequence');
    cpSync(join(REPO, 'crates/egoexo-session/tests/fixtures/nymeria'), sequence, { recursive: true });
    cpSync(join(REPO, 'crates/egoexo-session/tests/fixtures/nymeria_people'), sequence, { recursive: true });
    const app = await openApp(browser, '?backend=webgl2');
    try {
      await app.waitState('idle');
      await app.page.setInputFiles('#folder-input', sequence);
      assert.equal(await app.waitState(['ready', 'error']), 'ready', await app.text('#error-message'));
      assert.deepEqual(await app.page.locator('#participants button').allTextContents(), ['wearer', 'observer']);
      const summary = await app.page.evaluate(() => window.egoexo.summary);
      assert.deepEqual(summary.participants.map((p) => p.id), ['wearer', 'observer']);
      assert.ok(summary.participants.every((p) => p.valid_frames > 0), JSON.stringify(summary.participants));
      const observerCamera = summary.association.find((a) => a.observer === 'observer');
      assert.equal(observerCamera.assigned.wearer, 61, JSON.stringify(summary.association));
      assert.ok(observerCamera.unassigned > 0, 'the bystander matches nobody');
      assert.match(await app.text('#result-facts'), /people \(observer\)\s*\d+ over \d+ frames: 61 to wearer; \d+ bystanders/);
      await app.page.click('[data-participant=observer]');
      assert.equal(await app.waitState(['ready', 'error']), 'ready', await app.text('#error-message'));
      assert.equal(await app.page.evaluate(() => window.egoexo.summary.participant), 'observer');
      assert.deepEqual(app.errors, []);
    } finally {
      await app.close();
      rmSync(dir, { recursive: true, force: true });
    }
  });

  test('an MPS folder with hand tracking: wrist coverage, the floor, 3-point with wrists that come and go, wrists drawn only where tracked', async () => {
    const app = await openApp(browser, '?backend=webgl2');
    try {
      await app.waitState('idle');
      await app.page.setInputFiles('#folder-input', HANDS_FOLDER);
      assert.equal(await app.waitState(['ready', 'error']), 'ready', await app.text('#error-message'));
      const facts = await app.text('#session-facts');
      assert.match(facts, /single Aria MPS device folder/);
      // Warnings about the whole session read as sentences (no empty file name before a colon).
      const warnings = await app.page.$$eval('#session-warnings li', (items) => items.map((li) => li.textContent));
      assert.ok(warnings.some((w) => w.startsWith('one device: a session without observers')), JSON.stringify(warnings));
      assert.ok(warnings.every((w) => !w.startsWith(':') && !w.startsWith(' ')), JSON.stringify(warnings));
      assert.match(facts, /3-point tracking: head, left_wrist, right_wrist \(the wrists are tracked on \d+% \(left\) and \d+% \(right\) of the head's frames: the 3-point model uses them where they are/);
      assert.match(facts, /left wrist\s*tracked on \d+\.\d% of frames, longest gap 0\.[45]\d s \(MPS wrist_and_palm_poses\.csv v2/);
      assert.match(facts, /right wrist\s*tracked on \d+\.\d% of frames, longest gap 0\.[23]\d s/);
      assert.match(facts, /floor\s*-?0\.0\d\d m, from semidense points \(\d+ well-constrained points at the floor/);
      const scene = await app.page.evaluate(() => {
        const raw = window.egoexo.scene;
        const s = typeof raw === 'string' ? JSON.parse(raw)
          : (raw instanceof ArrayBuffer || ArrayBuffer.isView(raw)) ? JSON.parse(new TextDecoder().decode(raw)) : raw;
        return { floor_y: s.floor_y, fps: s.fps, devices: s.devices.map((d) => ({ name: d.name, valid: d.valid })) };
      });
      assert.ok(Math.abs(scene.floor_y) < 0.01, `the scene stands on the session's floor: ${scene.floor_y}`);
      const valid = (name, t) => scene.devices.find((d) => d.name === name).valid[Math.round(t * scene.fps)];
      assert.equal(valid('right_wrist', 0.35), false, 'the right wrist is not drawn while out of view');
      assert.equal(valid('right_wrist', 1.0), true);
      assert.equal(valid('left_wrist', 1.0), false, 'the left wrist is not drawn while out of view');
      assert.equal(valid('left_wrist', 0.4), true);
      await app.page.evaluate(() => window.egoexo.viewer.seek(20));
      await app.page.waitForTimeout(250);
      await app.page.screenshot({ path: join(OUT, 'mps-one-device.png') });
      assert.deepEqual(app.errors, []);
    } finally {
      await app.close();
    }
  });

  test('cancel stops the reconstruction between windows, and the same worker takes the next job', async () => {
    const app = await openApp(browser, '?backend=webgl2');
    try {
      await app.waitState('idle');
      // Cancel as soon as the page shows a reconstruction stage, in the page itself: a click
      // from the test process could come after the (quick) reconstruction has finished.
      const stage = await app.page.evaluate(() => new Promise((resolve) => {
        window.workerEvents = [];
        window.egoexo.worker.addEventListener('message', (e) => window.workerEvents.push([e.data.type, e.data.job]));
        window.workerBeforeCancel = window.egoexo.worker;
        const text = document.getElementById('progress-text');
        const observer = new MutationObserver(() => {
          if (!/ego pass|exo fusion|overlay/.test(text.textContent)) return;
          observer.disconnect();
          window.cancelledJob = window.egoexo.client.current_job();
          document.getElementById('cancel-button').click();
          resolve(text.textContent);
        });
        observer.observe(text, { childList: true, characterData: true, subtree: true });
        document.getElementById('sample-button').click();
      }));
      assert.match(stage, /ego pass|exo fusion|overlay/);
      assert.equal(await app.waitState(['cancelled', 'ready']), 'cancelled');
      // The worker answers the cancel itself, and the cancelled job never delivers a result.
      await app.page.waitForFunction(() => window.workerEvents.some(([type, job]) => type === 'cancelled' && job === window.cancelledJob));
      await app.page.waitForTimeout(500);
      assert.equal(await app.page.evaluate(() => document.body.dataset.state), 'cancelled');
      const results = await app.page.evaluate(() => window.workerEvents.filter(([type, job]) => type === 'reconstructed' && job === window.cancelledJob));
      assert.deepEqual(results, []);
      assert.equal(await app.text('#error-title'), 'Cancelled');
      assert.equal(await app.page.locator('#progress-panel').isHidden(), true);
      // The same worker (its models still loaded) answers the next job: a quick failing import.
      assert.equal(await app.page.evaluate(() => window.egoexo.worker === window.workerBeforeCancel), true);
      await app.page.setInputFiles('#file-input', { name: 'empty.zip', mimeType: 'application/zip', buffer: Buffer.alloc(0) });
      assert.equal(await app.waitState(['error', 'ready']), 'error');
      assert.match(await app.text('#error-message'), /^empty\.zip: the file is empty/);
      assert.deepEqual(app.errors, []);
    } finally {
      await app.close();
    }
  });

  test('a pool of two workers reconstructs the sample byte for byte as one worker does', async () => {
    // The npz export and the summary of the sample with `workers` workers. A short session's
    // first job leaves the helpers for later (they start once it is done), so with a pool the
    // sample runs again until the helper has computed chunks of a job (at most `runs` times).
    const reconstruct = async (workers, runs) => {
      const app = await openApp(browser, `?backend=webgl2&workers=${workers}`);
      try {
        assert.equal(await app.waitState(['idle', 'error']), 'idle', await app.text('#error-message'));
        const summaries = [];
        for (let run = 0; run < runs; run++) {
          // The state is `ready` from the last run until the click takes effect.
          await app.page.evaluate(() => {
            document.body.dataset.state = 'clicked';
            document.getElementById('sample-button').click();
          });
          assert.equal(await app.waitState(['ready', 'error']), 'ready', await app.text('#error-message'));
          summaries.push(await app.page.evaluate(() => window.egoexo.summary));
          if (summaries.at(-1).pool?.helper_chunks > 0) break;
        }
        const [download] = await Promise.all([app.page.waitForEvent('download'), app.page.click('[data-format=npz]')]);
        const path = join(OUT, `pool-${workers}.npz`);
        await download.saveAs(path);
        assert.deepEqual(app.errors, []);
        return { npz: readFileSync(path), summaries };
      } finally {
        await app.close();
      }
    };
    const one = await reconstruct(1, 1);
    const two = await reconstruct(2, 6);
    assert.equal(one.summaries[0].pool, undefined, JSON.stringify(one.summaries[0]));
    assert.equal(two.summaries[0].pool, undefined, 'the first job of a short session runs in one worker');
    const last = two.summaries.at(-1);
    const pool = last.pool;
    assert.ok(pool, JSON.stringify(two.summaries));
    assert.equal(pool.workers, 2);
    assert.equal(pool.failed_helpers, 0);
    assert.ok(pool.chunks >= 2 && pool.helper_chunks > 0 && pool.helper_chunks <= pool.chunks, JSON.stringify(pool));
    console.log(`# pool of 2 (job ${two.summaries.length}): ${pool.helper_chunks} of ${pool.chunks} chunks (${pool.chunk_windows} windows each) computed by the helper`);
    assert.deepEqual(last.network_runs, one.summaries[0].network_runs);
    assert.ok(one.npz.equals(two.npz), 'the pooled reconstruction differs from the single worker\'s');
  });

  test('a worker panic is caught, reported, and the worker replaced', async () => {
    const app = await openApp(browser, '?backend=webgl2');
    try {
      await app.waitState('idle');
      await app.page.evaluate(() => window.egoexo.client.panic_for_test());
      assert.equal(await app.waitState(['error']), 'error');
      assert.match(await app.text('#error-title'), /worker crashed/);
      assert.match(await app.text('#error-message'), /a panic requested by the test suite/);
      await app.page.setInputFiles('#file-input', { name: 'broken.zip', mimeType: 'application/zip', buffer: Buffer.from('nope') });
      await app.page.waitForFunction(() => document.getElementById('error-title').textContent === 'Could not import the session');
      // The only console errors are the panic's own report.
      assert.ok(app.errors.length > 0 && app.errors.every((e) => e.includes('panicked')), app.errors.join('\n'));
    } finally {
      await app.close();
    }
  });

  test('models are fetched once, then come from the Cache API; a damaged model is refused', async () => {
    let fetched = 0;
    const count = (context) => context.route('**/*.onnx', (route) => {
      fetched += 1;
      return route.continue();
    });
    const app = await openApp(browser, '?backend=webgl2', { setup: count });
    try {
      await app.waitState('idle');
      const cached = () => app.page.evaluate(async () => (await (await caches.open('egoexo-models')).keys()).length);
      // Every model fetched so far is in the cache (the downloads run in parallel: wait for all).
      for (let tries = 0; fetched === 0 || (await cached()) < fetched; tries += 1) {
        assert.ok(tries < 1200, 'the models were never cached');
        await app.page.waitForTimeout(100);
      }
      const first = fetched;
      assert.ok(first > 0, 'the models were fetched');
      await app.page.reload();
      await app.waitState('idle');
      // Open something, so the new worker has certainly loaded its models.
      await app.page.setInputFiles('#file-input', { name: 'x.zip', mimeType: 'application/zip', buffer: Buffer.from('x') });
      assert.equal(await app.waitState(['error', 'ready']), 'error');
      assert.equal(await app.text('#error-title'), 'Could not import the session');
      assert.equal(fetched, first, 'no model was fetched again');

      // A corrupted download in a fresh context: the sha256 check names the file.
      const corrupt = async (context) => {
        await context.route('**/*.onnx', async (route) => {
          const response = await route.fetch({ timeout: 120_000 });
          const body = Buffer.from(await response.body());
          body[body.length >> 1] ^= 0xff;
          await route.fulfill({ response, body });
        });
      };
      const fresh = await openApp(browser, '?backend=webgl2', { setup: corrupt });
      try {
        // The worker loads the models as the page starts: the failure shows without a click.
        await fresh.waitState('error', 120_000);
        assert.equal(await fresh.text('#error-title'), 'Could not load the models');
        assert.match(await fresh.text('#error-message'), /\.onnx` does not match the manifest: sha256 [0-9a-f]{64}, expected [0-9a-f]{64}/);
        // Trying a session tries the models again, and fails the same way.
        await fresh.page.click('#error-dismiss');
        await fresh.page.click('#sample-button');
        await fresh.page.waitForFunction(() => !document.getElementById('error-panel').hidden, null, { timeout: 120_000 });
        assert.equal(await fresh.text('#error-title'), 'Could not load the models');
      } finally {
        await fresh.close();
      }
    } finally {
      await app.close();
    }
  });

  test('the automatic backend choice ends with a working renderer', async () => {
    const app = await openApp(browser);
    try {
      assert.equal(await app.waitState(['idle', 'error']), 'idle', await app.text('#error-message'));
      assert.match(await app.text('#backend'), /renderer: (webgpu|webgl2)/i);
      assert.deepEqual(app.errors, []);
    } finally {
      await app.close();
    }
  });
});

describe('observer video: the detector step in the worker', () => {
  // A simulated walk whose two observers bring only H.264 video (the wearer rendered through
  // each camera) and no keypoints, made by the CLI; the CLI's own detector step (OpenH264,
  // resample_rgb) on the same file is the reference for the page's (WebCodecs, canvas crop).
  test('a session with observer video and no keypoints reconstructs with its observers, detected in the worker', async () => {
    const session = join(OUT, 'walk-video.egoexo');
    const byCli = join(OUT, 'walk-video-cli.egoexo');
    execFileSync(BIN, ['walk', '--seconds', '4', '--video', '256', '--seed', '3', '-o', session], { stdio: ['ignore', 'ignore', 'inherit'] });
    execFileSync(BIN, ['keypoints', session, '-o', byCli, '--force', '--models', join(REPO, 'models')], { stdio: ['ignore', 'ignore', 'inherit'] });
    const app = await openApp(browser, '?backend=webgl2');
    try {
      await app.waitState('idle');
      // Cancel while the detector runs: the job ends `cancelled`, nothing of it is kept.
      const file = { name: 'walk-video.egoexo', mimeType: 'application/zip', buffer: readFileSync(session) };
      const cancelling = app.page.evaluate(() => new Promise((resolve) => {
        const text = document.getElementById('progress-text');
        const observer = new MutationObserver(() => {
          if (!/^detecting keypoints .* — [1-9]\d*%$/.test(text.textContent)) return;
          observer.disconnect();
          document.getElementById('cancel-button').click();
          resolve(text.textContent);
        });
        observer.observe(text, { childList: true, characterData: true, subtree: true });
      }));
      await app.page.setInputFiles('#file-input', file);
      assert.match(await cancelling, /detecting keypoints/);
      assert.equal(await app.waitState(['cancelled', 'ready', 'error']), 'cancelled');
      await app.page.evaluate(() => {
        window.progressSeen = [];
        const text = document.getElementById('progress-text');
        new MutationObserver(() => window.progressSeen.push(text.textContent))
          .observe(text, { childList: true, characterData: true, subtree: true });
      });
      await app.page.setInputFiles('#file-input', file);
      assert.equal(await app.waitState(['ready', 'error']), 'ready', await app.text('#error-message'));
      const seen = await app.page.evaluate(() => window.progressSeen);
      assert.ok(seen.some((t) => /^detecting keypoints in the observers' video — \d+%$/.test(t)), JSON.stringify(seen.slice(0, 12)));
      const summary = await app.page.evaluate(() => window.egoexo.summary);
      assert.deepEqual(summary.detection.map((d) => d.observer), ['observer-1', 'observer-2']);
      for (const d of summary.detection) {
        assert.equal(d.frames, 120, JSON.stringify(d));
        assert.ok(d.detected >= 80, `the wearer is in view most of the walk: ${JSON.stringify(d)}`);
      }
      assert.ok(summary.exo_evidence_frames > 20, JSON.stringify(summary));
      assert.ok(Object.values(summary.observer_ray_frames).every((n) => n > 20), JSON.stringify(summary.observer_ray_frames));
      const facts = await app.text('#result-facts');
      assert.match(facts, /detector \(observer-1\)\s*the wearer in \d+ of 120 video frames, \d+\.\d detections\/s/);
      const rates = summary.detection.map((d) => d.detected / (d.ms / 1000));
      console.log(`detector step in the worker: ${summary.detection.map((d, i) => `${d.observer} ${d.detected}/${d.frames} frames, ${rates[i].toFixed(1)} detections/s`).join('; ')}`);
      writeFileSync(join(OUT, 'detection-worker.json'), JSON.stringify({ detection: summary.detection, detections_per_s: rates }, null, 1));

      // The page's keypoints against the CLI's: the same frames found, the same places.
      const [download] = await Promise.all([app.page.waitForEvent('download'), app.page.click('#save-session')]);
      const byPage = join(OUT, 'walk-video-page.egoexo');
      await download.saveAs(byPage);
      const compare = execFileSync(PYTHON ?? 'python3', ['-c', `
import json, sys, zipfile, statistics
def tracks(path):
    z = zipfile.ZipFile(path)
    out = {}
    for name in z.namelist():
        if name.endswith('keypoints.jsonl'):
            for line in z.read(name).decode().splitlines():
                r = json.loads(line)
                out.setdefault(r['observer'], {})[r['timestamp_ns']] = r['keypoints']
    return out
page, cli = tracks(sys.argv[1]), tracks(sys.argv[2])
report = {}
for obs, frames in cli.items():
    both = agree = 0
    errors = []
    for t, kps in frames.items():
        other = page[obs][t]
        has_a, has_b = any(k is not None for k in kps), any(k is not None for k in other)
        both += 1
        agree += has_a == has_b
        for a, b in zip(kps, other):
            if a is not None and b is not None:
                errors.append(((a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2) ** 0.5)
    report[obs] = {'frames': both, 'same_detected': agree / both, 'median_px': statistics.median(errors), 'keypoints': len(errors)}
print(json.dumps(report))
`, byPage, byCli], { encoding: 'utf8' });
      const report = JSON.parse(compare);
      console.log(`page vs CLI keypoints: ${compare.trim()}`);
      assert.deepEqual(Object.keys(report).sort(), ['observer-1', 'observer-2']);
      for (const r of Object.values(report)) {
        assert.equal(r.frames, 120);
        assert.ok(r.same_detected >= 0.95, JSON.stringify(report));
        // 256 px images: two decoders and two resamplers, the same windows and mapping.
        assert.ok(r.median_px < 2.5, JSON.stringify(report));
      }
      // At import the page said where the keypoints would come from.
      assert.match(await app.text('#session-facts'), /video observers\/observer-1\/rgb\.mp4: keypoints found by the detector/);

      // The same session as a dropped folder (its MP4s among the files): the same step.
      const folder = join(OUT, 'walk-video-folder');
      rmSync(folder, { recursive: true, force: true });
      execFileSync(BIN, ['walk', '--seconds', '4', '--video', '256', '--seed', '3', '--folder', '-o', folder], { stdio: ['ignore', 'ignore', 'inherit'] });
      // The state is `ready` from the last run until the drop takes effect.
      await app.page.evaluate(() => { document.body.dataset.state = 'dropped'; });
      await app.page.setInputFiles('#folder-input', folder);
      assert.equal(await app.waitState(['ready', 'error']), 'ready', await app.text('#error-message'));
      const fromFolder = await app.page.evaluate(() => window.egoexo.summary);
      assert.deepEqual(fromFolder.detection.map((d) => [d.observer, d.detected]), summary.detection.map((d) => [d.observer, d.detected]));
      assert.deepEqual(app.errors, []);
    } finally {
      await app.close();
    }
  });
});

describe('startup', () => {
  test('time to first skeleton, cold and warm (performance marks; printed and kept in first-skeleton.json)', async () => {
    // `#sample` opens the sample as the page loads. Cold: a fresh context (empty HTTP cache
    // and Cache API). Warm: the same page reloaded (wasm from the HTTP cache, models from the
    // Cache API). Each time is the page's `egoexo:first-skeleton` mark (navigation start → the
    // frame after the scene was handed to the viewer).
    const app = await openApp(browser, '?backend=webgl2#sample');
    // Also the worker's own account of the models: read (Cache API or network) and
    // check + load (sha256, tract), ms.
    const marks = () => app.page.evaluate(() => ({
      ...Object.fromEntries(['egoexo:models-ready', 'egoexo:imported', 'egoexo:first-skeleton'].map((name) => [
        name.replace('egoexo:', ''), performance.getEntriesByName(name, 'mark')[0]?.startTime ?? null,
      ])),
      'models-read': window.egoexo.models?.read_ms ?? null,
      'models-load': window.egoexo.models?.load_ms ?? null,
      'models-cached-files': window.egoexo.models?.cached_files ?? null,
    }));
    const firstSkeleton = async () => {
      assert.equal(await app.waitState(['ready', 'error']), 'ready', await app.text('#error-message'));
      await app.page.waitForFunction(() => performance.getEntriesByName('egoexo:first-skeleton', 'mark').length > 0,
        null, { timeout: 60_000, polling: 50 });
      return marks();
    };
    try {
      const cold = await firstSkeleton();
      await app.page.reload();
      const warm = await firstSkeleton();
      for (const [name, run] of [['cold', cold], ['warm', warm]]) {
        for (const [mark, ms] of Object.entries(run)) {
          assert.ok(Number.isFinite(ms) && ms >= 0, `${name} ${mark}: ${ms}`);
        }
        assert.ok(run.imported <= run['first-skeleton'], `${name}: ${JSON.stringify(run)}`);
        assert.ok(run['models-read'] + run['models-load'] <= run['models-ready'], `${name}: ${JSON.stringify(run)}`);
      }
      // Cold: every model from the network; warm: every one from the Cache API.
      assert.equal(cold['models-cached-files'], 0);
      assert.ok(warm['models-cached-files'] > 0, JSON.stringify(warm));
      const report = { cold_ms: cold, warm_ms: warm, goal_warm_first_skeleton_ms: 2000 };
      writeFileSync(join(OUT, 'first-skeleton.json'), `${JSON.stringify(report, null, 1)}\n`);
      console.log(`time to first skeleton: cold ${cold['first-skeleton'].toFixed(0)} ms, warm ${warm['first-skeleton'].toFixed(0)} ms`
        + ` (models ready ${cold['models-ready'].toFixed(0)} / ${warm['models-ready'].toFixed(0)} ms: read`
        + ` ${cold['models-read']} / ${warm['models-read']}, check + load ${cold['models-load']} / ${warm['models-load']})`);
      assert.deepEqual(app.errors, []);
    } finally {
      await app.close();
    }
  });
});
